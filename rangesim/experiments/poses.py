"""Random camera poses on a spherical cap around a part, for sweeps and datasets.

A pose table (the ``[pose]`` table of a sweep file, the ``--cap-deg`` / ``--distance`` /
``--axis`` / ``--target`` options of ``rangesim dataset``) has these keys, all optional:

============== ============================================================================
key            meaning
============== ============================================================================
target         (3,) world point the camera looks at, mm; default: the centre of the
               bounding box of the scene's first object (the part; scene files list it
               first)
axis           (3,) world direction of the cap's axis, from the target towards the camera;
               default: towards the scene's ``[view]`` position, else (0, -1, 1.4)
elevation_deg  axis elevation above the world xy plane, degrees (with ``azimuth_deg``,
               instead of ``axis``)
azimuth_deg    axis azimuth from world +x towards +y, degrees
cap_deg        half-angle of the cap, degrees, 0..180 (0: always on the axis);
               default :data:`DEFAULT_CAP_DEG`
distance       camera-to-target distance, mm: one number, or [min, max] drawn uniformly;
               default [near + r, far - r] of the sensor's working range, r the part's
               bounding radius (the distance that frames the part when that interval is
               empty)
============== ============================================================================

Directions are uniform in solid angle over the cap: the polar angle theta from the axis has
cos(theta) uniform in [cos(cap), 1] and the azimuth phi is uniform in [0, 2 pi). The camera
sits at ``target + distance * direction`` and looks at the target with world +z up (+y when
the direction is within 0.06 degrees of vertical).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.geometry import look_at

#: keys a pose table accepts
POSE_KEYS = ("target", "axis", "elevation_deg", "azimuth_deg", "cap_deg", "distance")
#: default half-angle of the cap of view directions, degrees
DEFAULT_CAP_DEG = 30.0
#: direction towards the camera when the scene has no [view] (as Scene.framing_pose)
FALLBACK_AXIS = (0.0, -1.0, 1.4)


@dataclass(frozen=True)
class ViewSample:
    """One camera pose drawn from a cap.

    Attributes
    ----------
    pose : (4, 4) float64
        Camera-to-world transform (OpenCV camera axes).
    distance_mm : float
        Camera centre to target, mm.
    polar_deg : float
        Angle between the viewing direction (target to camera) and the cap axis, degrees.
    elevation_deg, azimuth_deg : float
        Elevation above the world xy plane and azimuth from +x towards +y of the direction
        from the target to the camera, degrees.
    target : (3,) float64
        The point looked at, world mm.
    """

    pose: np.ndarray
    distance_mm: float
    polar_deg: float
    elevation_deg: float
    azimuth_deg: float
    target: np.ndarray


def _plain(value: Any) -> str:
    """A value as its user wrote it: plain numbers (``nan``, ``1.5``), not ``np.float64(nan)``."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_plain(v) for v in value) + "]"
    if isinstance(value, (np.integer, np.floating)):
        value = value.item()
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value)


def _vec3(value: Any, key: str, source: Any) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = np.empty(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise RangesimError(f"pose.{key} must be 3 finite numbers, got {_plain(value)}", source=source)
    return v


def _number(value: Any, key: str, source: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise RangesimError(f"pose.{key} must be a number, got {_plain(value)}", source=source)
    if not math.isfinite(float(value)):
        raise RangesimError(f"pose.{key} must be finite, got {_plain(value)}", source=source)
    return float(value)


def check_pose_table(table: Mapping[str, Any], source: Any = None) -> dict[str, Any]:
    """Validate a pose table (see the module docstring) and return it with plain values.

    Raises
    ------
    RangesimError
        Unknown keys, wrong types or shapes, a cap outside 0..180 degrees, a non-positive
        or inverted distance range, ``axis`` together with ``elevation_deg``/``azimuth_deg``.
    """
    unknown = sorted(set(table) - set(POSE_KEYS))
    if unknown:
        raise RangesimError(f"unknown pose key(s) {', '.join(unknown)}; known: {', '.join(POSE_KEYS)}",
                            source=source)
    out: dict[str, Any] = {}
    for key in ("target", "axis"):
        if key in table:
            v = _vec3(table[key], key, source)
            if key == "axis" and np.linalg.norm(v) == 0:
                raise RangesimError("pose.axis must not be zero", source=source)
            out[key] = v.tolist()
    angles = [k for k in ("elevation_deg", "azimuth_deg") if k in table]
    if angles and "axis" in table:
        raise RangesimError("give pose.axis or pose.elevation_deg/azimuth_deg, not both", source=source)
    for key in angles:
        out[key] = _number(table[key], key, source)
    if "elevation_deg" in out and not -90.0 <= out["elevation_deg"] <= 90.0:
        raise RangesimError(f"pose.elevation_deg must lie in -90..90, got {out['elevation_deg']}", source=source)
    if "cap_deg" in table:
        cap = _number(table["cap_deg"], "cap_deg", source)
        if not 0.0 <= cap <= 180.0:
            raise RangesimError(f"pose.cap_deg must lie in 0..180, got {cap}", source=source)
        out["cap_deg"] = cap
    if "distance" in table:
        d = table["distance"]
        if isinstance(d, (list, tuple)):
            if len(d) != 2:
                raise RangesimError(f"pose.distance must be a number or [min, max], got {_plain(d)}", source=source)
            lo, hi = (_number(x, "distance", source) for x in d)
        else:
            lo = hi = _number(d, "distance", source)
        if lo <= 0 or hi < lo:
            raise RangesimError(f"pose.distance must be positive with min <= max, got {_plain(d)}", source=source)
        out["distance"] = [lo, hi]
    return out


def check_distance_in_range(cap: Mapping[str, Any], scene: Any, sensor: Any, source: Any = None) -> None:
    """Refuse a distance range that puts the whole part outside the working range in every view.

    The part (the first object) reaches ``radius`` mm around the target; at a camera distance
    ``d`` its depths lie within ``d - radius .. d + radius``. If even the nearest camera sees it
    only beyond ``range.far``, or the farthest only before ``range.near``, every view is empty.
    """
    part = scene.objects[0].mesh
    target = np.asarray(cap["target"], dtype=np.float64)
    radius = float(np.linalg.norm(part.vertices - target, axis=1).max())
    lo, hi = (float(x) for x in cap["distance"])
    near, far = float(sensor.params["range"]["near"]), float(sensor.params["range"]["far"])
    if lo - radius > far or hi + radius < near:
        raise RangesimError(
            f"distance {lo:g}-{hi:g} mm puts the whole part (radius {radius:.0f} mm around the target) outside "
            f"{sensor.name}'s working range {near:g}-{far:g} mm: every view would be empty", source=source)
    if not _part_seen_from_cap(cap, part.vertices, sensor):
        raise RangesimError(
            f"the part is outside {sensor.name}'s field of view or working range {near:g}-{far:g} mm from every "
            f"pose of the cap (target {_plain(cap['target'])}, distance {lo:g}-{hi:g} mm, cap "
            f"{float(cap['cap_deg']):g} deg): every view would be empty; aim the target at the part", source=source)


#: the grid of poses over a cap that :func:`_part_seen_from_cap` tries: polar angles, azimuths,
#: distances (over the cap's range, and again over the part of it that can put the part within
#: the working range)
CAP_GRID = (9, 24, 5)


def _part_seen_from_cap(cap: Mapping[str, Any], vertices: np.ndarray, sensor: Any) -> bool:
    """Whether the part's bounding sphere meets the camera's viewing cone and working range from
    at least one pose of a grid over the cap (poses look at the target, as :func:`sample_view`'s).

    The cone's half-angle is the image diagonal's (the corner pixel farthest from the principal
    point) widened by the grid's angular spacing, so the test errs towards "seen": it refuses only
    a cap from which the sphere stays outside the cone, or wholly before ``near`` or past ``far``
    in depth along the optical axis (the range the scanner applies), everywhere.
    """
    lo_b, hi_b = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo_b + hi_b) / 2.0
    sphere = float(np.linalg.norm(vertices - centre, axis=1).max())
    target = np.asarray(cap["target"], dtype=np.float64)
    cap_rad = math.radians(float(cap["cap_deg"]))
    n_polar, n_azimuth, n_distance = CAP_GRID
    u, v = np.meshgrid(np.linspace(0.0, 1.0, n_polar), np.arange(n_azimuth) / n_azimuth)
    directions = cap_directions(u.ravel(), v.ravel(), np.asarray(cap["axis"], dtype=np.float64), cap["cap_deg"])
    lo, hi = (float(x) for x in cap["distance"])
    near, far = float(sensor.params["range"]["near"]), float(sensor.params["range"]["far"])
    # the distances over the whole range, and as many over the part of it that can hold the
    # sphere within near..far (a wide range's even grid can step over a narrow working range)
    reach = sphere + float(np.linalg.norm(centre - target))
    d_lo, d_hi = max(lo, near - reach), min(hi, far + reach)
    distances = np.linspace(lo, hi, n_distance)
    if d_lo <= d_hi:
        distances = np.concatenate([distances, np.linspace(d_lo, d_hi, n_distance)])
    positions = target + distances[:, None, None] * directions[None]  # (D, N, 3)
    to_part = centre - positions
    dist = np.linalg.norm(to_part, axis=-1)
    K = sensor.K
    corners = np.array([[0.0, 0.0], [sensor.width, 0.0], [0.0, sensor.height], [sensor.width, sensor.height]])
    tan_corner = np.hypot((corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1]).max()
    spacing = cap_rad / (n_polar - 1) + math.sin(min(cap_rad, math.pi / 2)) * 2.0 * math.pi / n_azimuth
    cone = math.atan(tan_corner) + spacing
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_off = np.einsum("dnk,nk->dn", to_part, -directions) / dist
        off_axis = np.arccos(np.clip(cos_off, -1.0, 1.0))
        widening = np.arcsin(np.clip(sphere / dist, 0.0, 1.0))
    inside = dist <= sphere
    in_cone = inside | (off_axis <= cone + widening)
    # the working range bounds depth along the optical axis, not distance: the sphere's nearest
    # depth is at most dist cos(the least off-axis angle it spans) - sphere (an off-centre part
    # farther than far in a straight line can lie within it); its farthest at most dist + sphere
    nearest_depth = dist * np.cos(np.clip(off_axis - widening, 0.0, None)) - sphere
    in_range = (nearest_depth <= far) & (dist + sphere >= near)
    return bool(np.any(in_cone & in_range))


def axis_from_angles(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit world direction at an elevation above the xy plane and an azimuth from +x to +y."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def resolve_pose_table(table: Mapping[str, Any], scene: Any, sensor: Any) -> dict[str, Any]:
    """Fill in a checked pose table's defaults from the scene and the sensor.

    Parameters
    ----------
    table : mapping
        Output of :func:`check_pose_table`.
    scene : Scene
    sensor : Sensor

    Returns
    -------
    dict
        ``target`` (3,), ``axis`` (3,) unit, ``cap_deg`` float, ``distance`` [min, max] (mm).
    """
    part = scene.objects[0].mesh
    lo_b, hi_b = np.asarray(part.bounds[0], float), np.asarray(part.bounds[1], float)
    target = np.asarray(table.get("target", (lo_b + hi_b) / 2), dtype=np.float64)
    if "axis" in table:
        axis = np.asarray(table["axis"], dtype=np.float64)
    elif "elevation_deg" in table or "azimuth_deg" in table:
        default = _default_axis(scene, target)
        el0 = math.degrees(math.asin(np.clip(default[2], -1, 1)))
        az0 = math.degrees(math.atan2(default[1], default[0]))
        axis = axis_from_angles(table.get("elevation_deg", el0), table.get("azimuth_deg", az0))
    else:
        axis = _default_axis(scene, target)
    axis = axis / np.linalg.norm(axis)
    if "distance" in table:
        distance = [float(x) for x in table["distance"]]
    else:
        radius = float(np.linalg.norm(part.vertices - target, axis=1).max())
        near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
        lo, hi = near + radius, far - radius
        if hi < lo:
            from rangesim.sensor import default_pose  # the distance that frames the scene

            d = float(np.linalg.norm(default_pose(scene, sensor)[:3, 3] - target))
            lo = hi = d
        distance = [float(lo), float(hi)]
    return {"target": target.tolist(), "axis": axis.tolist(),
            "cap_deg": float(table.get("cap_deg", DEFAULT_CAP_DEG)), "distance": distance}


def _default_axis(scene: Any, target: np.ndarray) -> np.ndarray:
    if scene.view is not None:
        d = np.asarray(scene.view)[:3, 3] - target
        if np.linalg.norm(d) > 0:
            return d / np.linalg.norm(d)
    d = np.asarray(FALLBACK_AXIS, dtype=np.float64)
    return d / np.linalg.norm(d)


def cap_frame(axis: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose third column is the unit ``axis`` (first two: any orthonormal pair)."""
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def cap_directions(u: np.ndarray, v: np.ndarray, axis: np.ndarray, cap_deg: float) -> np.ndarray:
    """Unit directions uniform in solid angle over a cap, from uniform numbers in [0, 1).

    Parameters
    ----------
    u, v : (N,) float arrays in [0, 1)
        ``cos(theta) = 1 - u (1 - cos(cap))`` and ``phi = 2 pi v``.
    axis : (3,) array
        The cap's axis (normalised here).
    cap_deg : float
        Half-angle of the cap, degrees.

    Returns
    -------
    (N, 3) float64 unit vectors within ``cap_deg`` of ``axis``.
    """
    cos_t = 1.0 - np.asarray(u, dtype=np.float64) * (1.0 - math.cos(math.radians(cap_deg)))
    sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
    phi = 2.0 * np.pi * np.asarray(v, dtype=np.float64)
    local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)
    return local @ cap_frame(axis).T


def sample_view(resolved: Mapping[str, Any], rng: np.random.Generator) -> ViewSample:
    """Draw one pose from a resolved pose table (:func:`resolve_pose_table`).

    Three uniform numbers are drawn from ``rng`` whatever the table says (polar, azimuth,
    distance), so the same generator state gives the same direction with another distance
    range, and the same distance fraction with another cap.
    """
    u, v, w = rng.random(3)
    target = np.asarray(resolved["target"], dtype=np.float64)
    axis = np.asarray(resolved["axis"], dtype=np.float64)
    direction = cap_directions(np.array([u]), np.array([v]), axis, resolved["cap_deg"])[0]
    lo, hi = resolved["distance"]
    distance = float(lo + w * (hi - lo))
    position = target + distance * direction
    up = (0.0, 0.0, 1.0) if abs(direction[2]) < 1.0 - 5e-7 else (0.0, 1.0, 0.0)
    pose = look_at(position, target, up=up)
    polar = math.degrees(math.acos(float(np.clip(direction @ (axis / np.linalg.norm(axis)), -1, 1))))
    return ViewSample(
        pose=pose, distance_mm=distance, polar_deg=polar,
        elevation_deg=math.degrees(math.asin(float(np.clip(direction[2], -1, 1)))),
        azimuth_deg=math.degrees(math.atan2(direction[1], direction[0])),
        target=target,
    )
