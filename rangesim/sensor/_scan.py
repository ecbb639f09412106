"""``scan()``: join a scene and a sensor into a RangeScan (the sensor's mode picks the method)."""
from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import check_pose
from rangesim.core.memory import check_memory, memory_budget
from rangesim.core.rangescan import RangeScan
from rangesim.scene.scene import Scene, load_scene
from rangesim.sensor.bands import RESULT_BYTES_PER_PIXEL, band_rows
from rangesim.sensor.config import Sensor, load_sensor


def default_pose(scene: Scene, sensor: Sensor) -> np.ndarray:
    """The scene's [view], or a pose that frames the whole scene inside the working range.

    The camera looks at the bounding-box centre from above and in front (elevation about
    54 degrees) at a distance where the bounding sphere fills 90 % of the narrower field of
    view, kept inside [near + radius, far - radius] where the working range allows.
    """
    if scene.view is not None:
        return scene.view
    radius = scene.bounding_radius
    fov = math.radians(sensor.params["camera"]["fov_deg"])
    narrow = 2 * math.atan(math.tan(fov / 2) * min(1.0, sensor.height / sensor.width))
    fit = radius / math.sin(0.45 * narrow)
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    distance = min(max(fit, near + radius), max(near + radius, far - radius))
    if radius > distance * math.sin(narrow / 2):  # the working range holds it only closer than it fits
        warnings.warn(f"{sensor.name}: the scene ({2 * radius:.0f} mm across) fits the view from {fit:.0f} mm away "
                      f"(its centre), which puts its far side past the working range ({near:g}-{far:g} mm); placed "
                      f"at {distance:.0f} mm it is cropped at the image's edges (give a pose or a scene [view], or "
                      "a sensor whose range reaches)", stacklevel=3)
    return scene.framing_pose(distance)


#: measured peak memory per pixel of each mode (bytes; 2000 x 2000 px scans, NumPy and Dr.Jit
#: buffers together), and the fixed cost of a scan; see :func:`scan_memory_estimate`. The
#: structured-light figure is what does not grow with the disparity search (the rest below)
BYTES_PER_PIXEL = {"geometric": 500, "rendered": 600, "structured_light": 600}
BASE_BYTES = 300 * 1024**2
#: structured light: the block matcher's float32 cost volume, bytes per pixel and searched
#: disparity; the dot pattern's fine grid (``OVERSAMPLE``^2 float32 samples per projector
#: pixel, twice while it is blurred), bytes per projector pixel; the reference and its box
#: sums, bytes per reference pixel (peak RSS of 320 x 240 to 1280 x 960 px scans with 44 to
#: 271 disparities: the estimate is 2-20 % above it)
COST_VOLUME_BYTES = 4
PATTERN_BYTES = 2 * 16 * 4
REFERENCE_BYTES = 100
#: a scan with fewer valid pixels than this fraction (or none) is reported by :func:`empty_scan_reason`
ALMOST_EMPTY = 0.001
#: a scene under two pixels yet at least this many mm across is blamed on the camera's pixels
#: (an extreme field of view or a tiny image), a smaller one on its units (a part written in
#: metres or inches comes out 25-1000x too small: a 10 m or 400 mm part)
PLAUSIBLE_SCENE_MM = 10.0


class EmptyScanWarning(UserWarning):
    """A scan has no (or almost no) valid pixel; the message says why."""


def scan_memory_estimate(sensor: Sensor, keep_frames: bool = False) -> tuple[float, str]:
    """(bytes, the parameters that set them) of a scan with this sensor, before it is run.

    Pixels x bytes per pixel of the mode; in the rendered mode with ``keep_frames`` also the
    frame stack (frames x pixels x 4 bytes; ``render.frames = "auto"`` is estimated as one
    frame per ``laser.step`` across the field of view at the far end of the working range);
    in the structured-light mode also the block matcher's cost volume (pixels x searched
    disparities x 4 bytes: the disparities f |b| / z over the working range), the dot pattern
    and the reference, whose widths grow with the disparities too.
    """
    w, h = sensor.width, sensor.height
    pixels = float(w) * float(h)
    what = f"camera.width x camera.height = {w:,} x {h:,} px"
    estimate = BASE_BYTES + pixels * BYTES_PER_PIXEL.get(sensor.mode, BYTES_PER_PIXEL["geometric"])
    if sensor.mode == "structured_light":
        from rangesim.sensor.structured_light import matching_layout

        d_min, d_max, _, margin, x_lo, x_hi = matching_layout(sensor)
        searched = d_max - d_min + 3  # block_match scores one disparity beyond each end
        estimate += (pixels * searched * COST_VOLUME_BYTES + float(h) * (x_hi - x_lo) * PATTERN_BYTES
                     + float(h) * (w + 2 * margin) * REFERENCE_BYTES)
        r = sensor.params["range"]
        what += (f" x {searched:,} disparities searched ({d_min:,}-{d_max:,} px: f |b| / z over range.near-range.far "
                 f"= {r['near']:g}-{r['far']:g} mm, laser.baseline {sensor.params['laser']['baseline']:g} mm)")
    if sensor.mode == "rendered":
        render = sensor.params["render"]
        estimate += pixels * 16 * int(render["spp"])
        if keep_frames:
            frames = render["frames"]
            if frames == "auto":
                far = sensor.params["range"]["far"]
                fov = math.radians(sensor.params["camera"]["fov_deg"])
                frames = max(3, int(math.ceil(2 * far * math.tan(fov / 2) / sensor.params["laser"]["step"])))
            estimate += pixels * 4.0 * frames
            what += f" x {frames:,} frames (--keep-frames)"
    return estimate, what


def _winding_number(mesh, point: np.ndarray) -> float:
    """Generalised winding number of a closed mesh at a point: about 1 inside, 0 outside."""
    tri = np.asarray(mesh.vertices, float)[np.asarray(mesh.faces)] - point
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    div = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
        + np.einsum("ij,ij->i", b, c) * la
    return float(np.sum(2 * np.arctan2(det, div)) / (4 * np.pi))


def empty_scan_reason(result: RangeScan, scene: Scene, sensor: Sensor) -> str | None:
    """Why a scan has no (or almost no) valid pixel, in one line; None if it has enough.

    Examples of the reasons: hits outside the working range (with their depths), a scene
    smaller than a pixel (a bare mesh in metres), a camera inside a part, no surface in view,
    the laser (or projector) shadowed, the signal below ``noise.min_signal``, no block match
    (structured light).
    """
    total = int(result.status.size)
    n_valid = int(np.count_nonzero(result.status == Status.VALID))
    if total == 0 or n_valid >= max(1, ALMOST_EMPTY * total):
        return None
    head = f"{n_valid:,} valid pixels of {total:,}" if n_valid else "no valid pixel"
    head = f"{sensor.name}: {head}"
    pose = np.asarray(result.pose, float)
    eye = pose[:3, 3]
    # a camera inside a closed part sees only its inside
    try:
        for obj in scene.objects:
            mesh = obj.mesh
            if len(mesh.faces) <= 2_000_000 and mesh.is_watertight and _winding_number(mesh, eye) > 0.5:
                return (f"{head}: the camera at ({eye[0]:.1f}, {eye[1]:.1f}, {eye[2]:.1f}) mm is inside "
                        f"{obj.name!r}")
    except Exception:  # noqa: BLE001 -- a diagnosis must never fail the scan
        pass
    counts = {code: int(np.count_nonzero(result.status == code)) for code in Status}
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    n_hits = total - counts[Status.MISS]
    distance = float(np.linalg.norm(eye - scene.bounds.mean(axis=0)))
    size = 2 * scene.bounding_radius
    footprint = max(distance, 1e-9) / sensor.focal_px
    invalid_hits = counts[Status.OUT_OF_RANGE] + counts[Status.SHADOW] + counts[Status.DROPOUT]
    if size < 2 * footprint and invalid_hits == 0:  # (failed hits: their statuses below say why)
        across = (f"{head}: the scene is only {size:.3g} mm across, {max(size / footprint, 0):.2g} pixel at "
                  f"{distance:.0f} mm")
        fov = float(sensor.params["camera"]["fov_deg"])
        pixel_deg = fov / sensor.width  # the mean over the (horizontal) field
        if size >= PLAUSIBLE_SCENE_MM:  # the camera's pixels, not the scene's units
            return (f"{across}: each pixel spans {pixel_deg:.2g} degrees (a {fov:g} degree field of view over "
                    f"{sensor.width} x {sensor.height} pixels)")
        return (f"{across} (a bare mesh in metres or inches? give its units: a scene .toml's `units`, or "
                f"`rangesim scan --units m` for a mesh file)")
    lo, hi = scene.bounds
    nearest = float(np.linalg.norm(eye - np.clip(eye, lo, hi)))
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    in_camera = (corners - eye) @ pose[:3, :3]  # world -> camera frame (the camera looks along +z)
    if n_hits == 0 and np.all(in_camera[:, 2] <= 0):
        return f"{head}: the scene lies behind the camera (the pose looks away from it)"
    if n_hits == 0 and nearest > far:
        return (f"{head}: the scene lies {nearest:,.0f} mm or more from the camera, beyond the end of "
                f"{sensor.name}'s working range {near:g}-{far:g} mm")
    if n_hits == 0:
        return (f"{head}: the camera sees no surface (nothing of the scene within its "
                f"{sensor.params['camera']['fov_deg']:g} degree field of view from this pose)")
    if invalid_hits == 0:  # every hit measured: the scene covers too few pixels
        return (f"{head}: every hit was measured, but the scene covers only {n_hits:,} of the {total:,} pixels "
                f"({size:.3g} mm across, {size / footprint:.3g} pixels at {distance:.0f} mm)")
    worst = max((Status.OUT_OF_RANGE, Status.SHADOW, Status.DROPOUT), key=lambda code: counts[code])
    if worst == Status.OUT_OF_RANGE and result.xyz_true is not None:
        z = np.asarray(result.xyz_true, float)[..., 2][result.status == Status.OUT_OF_RANGE]
        z = z[np.isfinite(z)]
        if z.size:
            share = f"all {n_hits:,}" if counts[worst] == n_hits else f"{counts[worst]:,} of the {n_hits:,}"
            inside = (z >= near) & (z <= far)
            if np.mean(inside) > 0.5:  # the surfaces are in range: their measured depths were not
                return (f"{head}: {share} hits lie at {z.min():.0f}-{z.max():.0f} mm, inside {sensor.name}'s "
                        f"working range {near:g}-{far:g} mm, but the depth noise put {np.count_nonzero(inside):,} of "
                        f"their measured depths outside it (check the [noise] settings)")
            hint = ""
            if z.max() < near and nearest == 0:  # the camera among the scene's surfaces
                hint = (f" (the camera at ({eye[0]:.3g}, {eye[1]:.3g}, {eye[2]:.3g}) mm is inside the scene's "
                        "bounding box: a pose written in metres?)")
            shown = "-".join(f"{v:.0f}" if v >= 10 else f"{v:.3g}" for v in (z.min(), z.max()))
            return (f"{head}: {share} hits lie at {shown} mm, outside "
                    f"{sensor.name}'s working range {near:g}-{far:g} mm{hint}")
    if worst == Status.OUT_OF_RANGE:
        return f"{head}: {counts[worst]:,} of the {n_hits:,} hits lie outside the working range {near:g}-{far:g} mm"
    structured = sensor.mode == "structured_light"
    if worst == Status.SHADOW:
        source = "the projector" if structured else "the laser"
        return f"{head}: {source} cannot reach {counts[worst]:,} of the {n_hits:,} surface points the camera sees"
    if structured:
        # a structured-light dropout is a pixel the block matcher found no reliable match for
        sl = sensor.params["structured_light"]
        return (f"{head}: the block matcher found no reliable match at {counts[worst]:,} of the {n_hits:,} hits "
                f"(too few projected dots in its {sl['window']:g} px window, or below structured_light.min_score "
                f"{sl['min_score']:g} / the uniqueness and left-right checks: a small image or a dim pattern)")
    return (f"{head}: the return signal of {counts[worst]:,} of the {n_hits:,} hits is below noise.min_signal "
            f"({sensor.params['noise']['min_signal']:g}; grazing or dark surfaces)")


def scan(scene: Any, sensor: Any, pose: np.ndarray | None = None, seed: int = 0,
         keep_frames: bool = False) -> "RangeScan | tuple[RangeScan, Any]":
    """Scan a scene with a range sensor.

    Parameters
    ----------
    scene : Scene, str, Path, trimesh.Trimesh or list of them
        Anything :func:`rangesim.load_scene` accepts.
    sensor : Sensor, str, Path or dict
        Anything :func:`rangesim.load_sensor` accepts.
    pose : (4, 4) array, optional
        Camera-to-world transform (OpenCV camera axes); default: the scene's [view], or a
        pose framing the scene (:func:`default_pose`).
    seed : int
        Seed of the noise; the same seed gives the same scan, another seed changes only the
        noise.
    keep_frames : bool
        Rendered mode only: also return the raw frame stack
        (:class:`rangesim.sensor.rendered.FrameStack`).

    Returns
    -------
    RangeScan, or (RangeScan, FrameStack) with ``keep_frames``

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.scan("scenes/green_piece.toml", "white_scanner", seed=0)
    >>> scan.depth.shape == (scan.meta["sensor"]["camera"]["height"],
    ...                      scan.meta["sensor"]["camera"]["width"])
    True
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RangesimError(f"seed must be a non-negative integer, got {seed!r}")
    scene = load_scene(scene)
    sensor = load_sensor(sensor)
    if pose is None:
        pose = default_pose(scene, sensor)
    pose = check_pose(pose)
    if keep_frames and sensor.mode != "rendered":
        raise RangesimError("only the rendered mode has frames (set mode = \"rendered\")", source=sensor.source)
    if sensor.mode not in ("geometric", "rendered", "structured_light"):
        raise RangesimError(f"sensor mode {sensor.mode!r} is not available", source=sensor.source)
    estimate, what = scan_memory_estimate(sensor, keep_frames)
    rows_per_band = None
    budget, _ = memory_budget()
    if sensor.mode == "geometric" and budget is not None and estimate > budget:
        # too big in one piece: in bands of rows, when a band fits next to the result
        rows_per_band = band_rows(sensor, budget, BASE_BYTES, BYTES_PER_PIXEL["geometric"])
        if rows_per_band is None:
            minimum = BASE_BYTES + sensor.width * sensor.height * RESULT_BYTES_PER_PIXEL
            check_memory(max(estimate, minimum), what + " (even in bands of rows)", source=sensor.source)
    else:
        check_memory(estimate, what, source=sensor.source)
    if rows_per_band is not None:
        from rangesim.sensor.bands import scan_in_bands

        output = scan_in_bands(scene, sensor, pose, int(seed), rows_per_band)
    elif sensor.mode == "geometric":
        from rangesim.sensor.geometric import scan_geometric

        output = scan_geometric(scene, sensor, pose, int(seed))
    elif sensor.mode == "rendered":
        from rangesim.sensor.rendered import scan_rendered

        output = scan_rendered(scene, sensor, pose, int(seed), keep_frames=keep_frames)
    else:
        from rangesim.sensor.structured_light import scan_structured_light

        output = scan_structured_light(scene, sensor, pose, int(seed))
    result = output[0] if isinstance(output, tuple) else output
    reason = empty_scan_reason(result, scene, sensor)
    if reason is not None:
        warnings.warn(reason, EmptyScanWarning, stacklevel=2)
    return output
