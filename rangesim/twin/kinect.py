"""Twins of labelled Kinect-type recordings (mOSD): a scene fitted to the frame itself, scanned again.

A recorded frame of the Object Segmentation Database holds a table and objects standing on it,
each pixel labelled (0 no data, 1-9 table, 20-29 first object, 30-39 second, ...). The twin:

1. **Table**: a plane fitted by RANSAC to the table pixels (:func:`fit_plane`), made a flat
   polygon over the convex hull of its inliers.
2. **Objects**: each labelled segment, seen from above the table, is an upright box or an
   upright cylinder standing on it (the database's shapes). Its points are projected into the
   table plane; the convex hull of that footprint is fitted by the minimum-area rectangle and
   by a circle, and the shape with the smaller outline residual wins; the height is the 99th
   percentile of the points' heights above the table (:func:`fit_upright_object`).
3. **Scan**: the fitted scene, in the recording's camera frame, is scanned by a structured-light
   sensor (``kinect_v1`` by default) whose field of view is the recording's (its focal length
   fitted from the organized points: u = f x / z + c_x). Points at exactly zero depth are no
   data (OpenNI's marker, :func:`zero_depth_as_no_data`). A frame that cannot be a camera-frame
   organized cloud (no valid point, z <= 0, points off their pixels' rays, x mirrored), or whose
   depths lie outside the sensor's working range (e.g. millimetres stored as metres), is
   refused with a one-line RangesimError.
4. **Compare** (:func:`compare_kinect`): valid-mask IoU; the residual of recording and twin
   against the fitted surfaces per depth bin, with the z^2 coefficient of each (the law
   sigma_z = z^2 sigma_d / (f b)); the depth-level gaps in units of the twin's disparity step
   z^2 / (8 f b); edge F1 twin vs recorded; ``noise_std_ratio``, the robust std of the twin's
   residuals over the recording's on pixels both measured (as :mod:`rangesim.twin.comparison`);
   ``z_spread``, the robust std of each residual over the twin's predicted noise ``sigma``
   (:mod:`rangesim.sensor.matching_noise`): 1 where the noise law holds; and
   ``local_plane_std_mm`` (:func:`local_plane_std`), the noise about planes fitted to each
   frame's own depths in small patches of the fitted scene's planar faces, which leaves the
   fitted scene's error (a real table is not a plane) and the camera's calibration out.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from rangesim.core.conics import fit_circle
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.twin.realism import clipped_std, robust_std

__all__ = ["fit_plane", "fit_upright_object", "scene_from_labels", "kinect_twin", "compare_kinect", "local_plane_std",
           "DEPTH_BINS", "zero_depth_as_no_data"]

#: depth bins (mm) of the residual-vs-depth statistics
DEPTH_BINS: tuple[tuple[float, float], ...] = ((500.0, 750.0), (750.0, 1000.0), (1000.0, 1500.0), (1500.0, 2500.0),
                                               (2500.0, 4000.0))
#: the RANSAC plane's inlier distance, mm
PLANE_TOL_MM = 8.0
#: most rms (px) of the focal-length fit u = f x / z + c_x of a camera-frame organized cloud
#: (the recordings fit to 1e-4 px; a cloud in another frame misses by many pixels)
FOCAL_FIT_RMS_PX = 0.5
#: least share of a recording's valid depths inside the sensor's working range
IN_RANGE_SHARE = 0.1
#: an object's footprint uses its points this high above the table (mm, and share of its height)
OBJECT_MIN_HEIGHT_MM = 10.0
OBJECT_MIN_HEIGHT_SHARE = 0.1


@dataclass
class FittedShape:
    """One fitted object: ``kind`` ("table", "box", "cylinder"), its mesh (camera frame, mm), parameters."""

    kind: str
    label: int
    mesh: trimesh.Trimesh
    params: dict[str, Any]


def fit_plane(points: np.ndarray, rng: np.random.Generator, iterations: int = 300,
              tol_mm: float = PLANE_TOL_MM) -> tuple[np.ndarray, float, np.ndarray]:
    """RANSAC plane n . p + d = 0 with unit n facing the camera (d > 0 for a plane in front of it).

    Returns ``(n, d, inliers)``; the plane is refitted by least squares to its inliers.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> p = np.c_[rng.uniform(-100, 100, (500, 2)), np.full(500, 900.0)]
    >>> n, d, inl = fit_plane(p, rng)
    >>> (np.round(n, 6) + 0.0).tolist(), round(d, 3), bool(inl.all())
    ([0.0, 0.0, -1.0], 900.0, True)
    """
    p = np.asarray(points, np.float64)
    if len(p) < 3:
        raise RangesimError("fewer than 3 points to fit a plane")
    best = None
    for _ in range(iterations):
        a, b, c = p[rng.choice(len(p), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-9:
            continue
        n /= norm
        count = np.count_nonzero(np.abs((p - a) @ n) < tol_mm)
        if best is None or count > best[0]:
            best = (count, n, a)
    if best is None:
        raise RangesimError("the points are collinear: no plane")
    _, n, a = best
    inliers = np.abs((p - a) @ n) < tol_mm
    centre = p[inliers].mean(axis=0)
    _, _, vt = np.linalg.svd(p[inliers] - centre, full_matrices=False)
    n = vt[2]
    d = -float(n @ centre)
    if d < 0:  # face the camera at the origin: the origin on the positive side
        n, d = -n, -d
    inliers = np.abs(p @ n + d) < tol_mm
    return n, d, inliers


def _plane_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e1 = np.cross(n, [0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _min_area_rectangle(q: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """(centre (2,), width, depth, angle) of the smallest rectangle around 2-D points (hull edges)."""
    hull = q[ConvexHull(q).vertices]
    best = None
    for k in range(len(hull)):
        edge = hull[(k + 1) % len(hull)] - hull[k]
        angle = math.atan2(edge[1], edge[0])
        c, s = math.cos(angle), math.sin(angle)
        r = hull @ np.array([[c, -s], [s, c]])
        lo, hi = r.min(axis=0), r.max(axis=0)
        area = float(np.prod(hi - lo))
        if best is None or area < best[0]:
            centre = np.array([[c, s], [-s, c]]).T @ ((lo + hi) / 2)  # back to plane coordinates
            best = (area, centre, float(hi[0] - lo[0]), float(hi[1] - lo[1]), angle)
    _, centre, width, depth, angle = best
    return centre, width, depth, angle


def _rectangle_residual(hull: np.ndarray, centre, width, depth, angle) -> float:
    c, s = math.cos(angle), math.sin(angle)
    r = (hull - centre) @ np.array([[c, -s], [s, c]])
    dx, dy = np.abs(r[:, 0]) - width / 2, np.abs(r[:, 1]) - depth / 2
    return float(np.sqrt(np.mean(np.minimum(np.abs(dx), np.abs(dy)) ** 2)))


def fit_upright_object(points: np.ndarray, n: np.ndarray, d: float, label: int) -> FittedShape:
    """An upright box or cylinder standing on the plane (n, d) through the segment's points (mm)."""
    p = np.asarray(points, np.float64)
    height = p @ n + d  # above the table, towards the camera
    top = float(np.percentile(height, 99))
    if len(p) < 20 or top <= 1.0:
        raise RangesimError(f"segment {label}: too few points above the table to fit an object")
    # the footprint from points clearly above the table: segment pixels whose depth is the
    # table's (mixed or fattened at the outline) would widen it
    raised = height > max(OBJECT_MIN_HEIGHT_MM, OBJECT_MIN_HEIGHT_SHARE * top)
    if np.count_nonzero(raised) < 20:
        raise RangesimError(f"segment {label}: too few points above the table to fit an object")
    e1, e2 = _plane_basis(n)
    q = np.c_[p[raised] @ e1, p[raised] @ e2]
    hull = q[ConvexHull(q).vertices]
    centre_r, width, depth, angle = _min_area_rectangle(q)
    rect_res = _rectangle_residual(hull, centre_r, width, depth, angle)
    centre_c, radius, circ_res = fit_circle(hull)
    base = -d * n  # the plane's point nearest the camera
    # the object's frame: e1, e2 in the plane, n up (towards the camera)
    if circ_res < rect_res:
        mesh = trimesh.creation.cylinder(radius=radius, height=top, sections=96)
        centre2 = centre_c
        kind, params = "cylinder", {"radius_mm": radius, "height_mm": top, "outline_rms_mm": circ_res}
        rot = np.eye(3)
    else:
        mesh = trimesh.creation.box(extents=(width, depth, top))
        centre2 = centre_r
        kind, params = "box", {"size_mm": [width, depth, top], "angle_deg": math.degrees(angle),
                               "outline_rms_mm": rect_res}
        c, s = math.cos(angle), math.sin(angle)
        rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    frame = np.c_[e1, e2, n] @ rot
    origin = base + (centre2[0] - base @ e1) * e1 + (centre2[1] - base @ e2) * e2 + (top / 2) * n
    transform = np.eye(4)
    transform[:3, :3] = frame
    transform[:3, 3] = origin
    mesh.apply_transform(transform)
    return FittedShape(kind, int(label), mesh, params)


def _table_mesh(points: np.ndarray, n: np.ndarray, d: float) -> trimesh.Trimesh:
    """A flat polygon over the convex hull of the table points, in the plane (n, d)."""
    e1, e2 = _plane_basis(n)
    q = np.c_[points @ e1, points @ e2]
    hull = q[ConvexHull(q).vertices]
    centre = hull.mean(axis=0)
    hull = centre + (hull - centre) * 1.02  # reach the outermost pixels' footprints
    base = -d * n
    off = base - (base @ e1) * e1 - (base @ e2) * e2
    verts = np.array([off + a * e1 + b * e2 for a, b in np.vstack([centre, hull])])
    k = len(hull)
    faces = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    mesh = trimesh.Trimesh(verts, faces, process=False)
    if np.mean(mesh.face_normals @ n) < 0:
        mesh.invert()
    return mesh


def scene_from_labels(scan: RangeScan, labels: np.ndarray, *, seed: int = 0) -> list[FittedShape]:
    """The fitted table and objects of a labelled organized recording (camera frame, mm)."""
    labels = np.asarray(labels)
    if labels.shape != scan.shape:
        raise RangesimError(f"labels {labels.shape} do not match the scan {scan.shape}")
    valid = scan.valid & np.isfinite(scan.xyz).all(axis=2)
    table = valid & (labels >= 1) & (labels <= 9)
    if np.count_nonzero(table) < 100:
        raise RangesimError("the recording has fewer than 100 table pixels (labels 1-9): no table to fit")
    rng = np.random.default_rng(seed)
    tp = scan.xyz[table].astype(np.float64)
    n, d, inliers = fit_plane(tp, rng)
    shapes = [FittedShape("table", 1, _table_mesh(tp[inliers], n, d),
                          {"normal": n.tolist(), "offset_mm": d, "inliers": int(inliers.sum())})]
    for obj in sorted({int(v) // 10 for v in np.unique(labels[valid]) if v >= 20}):
        seg = valid & (labels // 10 == obj)
        try:
            shapes.append(fit_upright_object(scan.xyz[seg].astype(np.float64), n, d, obj * 10))
        except RangesimError:
            continue
    return shapes


def zero_depth_as_no_data(scan: RangeScan) -> tuple[RangeScan, int]:
    """(the scan with its points at exactly zero depth made invalid, how many there were).

    OpenNI's depth images (a Kinect's driver) store 0 where the matcher found no disparity,
    and a cloud converted from them without PCL's NaN for such pixels holds them as (0, 0, 0);
    no camera measures a point on its own centre, so they are the recording's no-data marker.
    """
    zero = scan.valid & (scan.depth == 0)
    count = int(np.count_nonzero(zero))
    if count == 0:
        return scan, 0
    warnings.warn(f"{count:,} of the recording's points lie at depth 0: read as no data (OpenNI's marker for "
                  "a pixel without a match)", stacklevel=2)
    nan = np.float32(np.nan)
    return replace(scan, valid=scan.valid & ~zero, depth=np.where(zero, nan, scan.depth),
                   xyz=np.where(zero[..., None], nan, scan.xyz),
                   status=np.where(zero, np.uint8(Status.MISS), scan.status)), count


def _fitted_focal(scan: RangeScan) -> float:
    """Focal length (px) of an organized camera-frame scan from its points: u = f x / z + c_x.

    Raises a one-line RangesimError (no source: the caller names the recording) when the
    points cannot be a camera-frame organized cloud: none valid, depths not in front of the
    camera, points not on their pixels' rays, or x mirrored (f < 0).
    """
    v = scan.valid & np.isfinite(scan.xyz).all(axis=2)
    if not v.any():
        raise RangesimError("the recording has no valid point (all NaN, or at depth 0: no data)")
    p = scan.xyz[v].astype(np.float64)
    behind = int(np.count_nonzero(p[:, 2] <= 0))
    if behind:
        raise RangesimError(f"{behind:,} of the recording's {len(p):,} valid points have depth z <= 0: not an "
                            "organized cloud in the camera's frame (x right, y down, z forward)")
    _, j = np.nonzero(v)
    a = np.c_[p[:, 0] / p[:, 2], np.ones(len(p))]
    if len(p) < 10 or np.ptp(a[:, 0]) == 0:
        raise RangesimError(f"the recording has {len(p):,} valid points over {np.unique(j).size} columns: too few "
                            "to fit its focal length")
    sol, *_ = np.linalg.lstsq(a, j + 0.5, rcond=None)
    f = float(sol[0])
    rms = float(np.sqrt(np.mean((a @ sol - (j + 0.5)) ** 2)))
    # a camera-frame organized cloud puts every point on its pixel's ray (mOSD, PCL: 1e-4 px)
    if not (math.isfinite(f) and rms <= FOCAL_FIT_RMS_PX):
        raise RangesimError(f"the recording's points are not on their pixels' rays (u = f x / z + c_x leaves "
                            f"{rms:.3g} px rms): not an organized cloud in the camera's frame")
    if f <= 0:
        raise RangesimError(f"the recording's fitted focal length is {f:.1f} px: its x axis is mirrored (x must "
                            "grow to the right along each row of the organized cloud)")
    return f


def _check_working_range(scan: RangeScan, sensor) -> None:
    """Refuse a recording whose depths lie outside the sensor's working range (mm read as metres?)."""
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    z = scan.depth[scan.valid].astype(np.float64)
    inside = np.count_nonzero((z >= near) & (z <= far))
    if inside >= IN_RANGE_SHARE * z.size:
        return
    lo, hi = np.percentile(z, [1, 99])
    problem = (f"its depths lie at {lo:,.0f}-{hi:,.0f} mm (1st-99th percentile), {inside:,} of {z.size:,} inside "
               f"{sensor.name}'s working range {near:g}-{far:g} mm")
    scaled = z / 1000.0
    if np.count_nonzero((scaled >= near) & (scaled <= far)) >= IN_RANGE_SHARE * z.size:
        problem += ": depths in mm? the recording is read as metres (PCD coordinates are metres)"
    raise RangesimError(f"the recording cannot be twinned: {problem}")


def kinect_twin(recorded: RangeScan, labels: np.ndarray, sensor: Any = "kinect_v1", *, seed: int = 0
                ) -> tuple[RangeScan, list[FittedShape]]:
    """Scan the scene fitted to a labelled recording with a structured-light sensor at its intrinsics."""
    from rangesim.scene import load_scene
    from rangesim.sensor import load_sensor, scan

    sensor = load_sensor(sensor)
    if sensor.mode != "structured_light":
        raise RangesimError(f"sensor {sensor.name} is not a structured-light sensor (mode {sensor.mode})")
    recorded, _ = zero_depth_as_no_data(recorded)
    h, w = recorded.shape
    f = _fitted_focal(recorded)
    fov = math.degrees(2 * math.atan(w / 2 / f))
    try:
        sensor = sensor.with_params({"camera.width": w, "camera.height": h, "camera.fov_deg": fov})
    except RangesimError as exc:  # the recording's size and focal length, not the preset, are at fault
        problem = str(exc).removeprefix(f"{exc.source}: ") if exc.source else str(exc)
        raise RangesimError(f"{sensor.name} at the recording's {w} x {h} px and fitted focal length {f:.1f} px: "
                            f"{problem}") from exc
    shapes = scene_from_labels(recorded, labels, seed=seed)
    _check_working_range(recorded, sensor)
    scene = load_scene([s.mesh for s in shapes])
    twin_scan = scan(scene, sensor, pose=np.eye(4), seed=seed)
    twin_scan.meta["twin"] = {"model": "structured_light_fitted_scene", "focal_px": f, "fov_deg": fov,
                              "shapes": [{"kind": s.kind, "label": s.label, **s.params} for s in shapes]}
    return twin_scan, shapes


def _by_depth(values: np.ndarray, depth: np.ndarray, statistic, name: str, count: str
              ) -> dict[str, dict[str, float]]:
    """Per :data:`DEPTH_BINS` bin (mm) of ``depth``: ``statistic`` of the finite ``values`` there
    (as ``name``) and how many there are (as ``count``)."""
    out = {}
    for lo, hi in DEPTH_BINS:
        sel = np.isfinite(values) & (depth >= lo) & (depth < hi)
        out[f"{lo:.0f}-{hi:.0f}"] = {name: statistic(values[sel]), count: int(np.count_nonzero(sel))}
    return out


def _depth_binned(residual: np.ndarray, depth: np.ndarray) -> dict[str, dict[str, float]]:
    return _by_depth(residual, depth, robust_std, "robust_std", "count")


def _z2_coefficient(residual: np.ndarray, depth: np.ndarray) -> float:
    """k of sigma_z = k z^2 (z in m): the robust std of residual / z^2."""
    ok = np.isfinite(residual) & np.isfinite(depth)
    return robust_std(residual[ok] / (depth[ok] / 1000.0) ** 2)


#: side of the patches of :func:`local_plane_std`, px
PATCH_PX = 24


def local_plane_std(depth: np.ndarray, z_true: np.ndarray, usable: np.ndarray, patch: int = PATCH_PX
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Depth noise about local planes: per ``patch`` x ``patch`` px tile, the std (clipped at 4
    std) of ``depth`` about the plane fitted to it (1 / z = a + b u + c v, least squares).

    Only tiles whose ``usable`` pixels (measured, both frames) cover 90 % of them and whose
    true depth ``z_true`` is itself a plane there (within 0.05 mm: one face of the fitted scene,
    no edge) count, so a tile's residual is the sensor's noise and quantisation, not the
    shape's or the fit's error.

    Returns
    -------
    std : (K,) float, mm, per counted tile
    depth : (K,) float, mm, the tile's median true depth
    """
    h, w = depth.shape
    v, u = np.mgrid[:patch, :patch]
    design = np.column_stack([np.ones(patch * patch), u.ravel(), v.ravel()]).astype(np.float64)
    stds, depths = [], []
    for i in range(0, h - patch + 1, patch):
        for j in range(0, w - patch + 1, patch):
            ok = usable[i:i + patch, j:j + patch].ravel()
            if ok.mean() < 0.9:
                continue
            zt = z_true[i:i + patch, j:j + patch].ravel().astype(np.float64)[ok]
            if np.abs(zt - _plane_through(design[ok], zt)).max() > 0.05:
                continue  # an edge or a curved face crosses the tile
            z = depth[i:i + patch, j:j + patch].ravel().astype(np.float64)[ok]
            stds.append(clipped_std(z - _plane_through(design[ok], z)))
            depths.append(float(np.median(zt)))
    return np.asarray(stds), np.asarray(depths)


def _plane_through(design: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The depths of the plane fitted to depths ``z`` at pixels (1, u, v) ``design``: a plane's
    inverse depth is linear in the pixel (n . X = d with X = z (u', v', 1)), its depth is not."""
    coef, *_ = np.linalg.lstsq(design, 1.0 / z, rcond=None)
    return 1.0 / (design @ coef)


def _local_plane_binned(stds: np.ndarray, depths: np.ndarray) -> dict[str, dict[str, float]]:
    return _by_depth(stds, depths, lambda v: float(np.median(v)) if v.size else float("nan"), "median_std", "tiles")


def _level_gaps_in_steps(depth: np.ndarray, fb: float) -> dict[str, float]:
    """Gaps between adjacent distinct depth levels, in units of the 1/8 px step z^2 / (8 f b)."""
    z = np.unique(np.round(depth[np.isfinite(depth)].astype(np.float64), 4))
    if z.size < 3:
        return {"median": float("nan"), "p10": float("nan"), "p90": float("nan"), "levels": int(z.size)}
    gaps = np.diff(z) / ((0.5 * (z[1:] + z[:-1])) ** 2 / (8 * fb))
    return {"median": float(np.median(gaps)), "p10": float(np.percentile(gaps, 10)),
            "p90": float(np.percentile(gaps, 90)), "levels": int(z.size)}


def compare_kinect(recorded: RangeScan, labels: np.ndarray, sensor: Any = "kinect_v1", *, seed: int = 0,
                   detectors=None, return_scans: bool = False):
    """Twin a labelled structured-light recording and compare (see the module docstring)."""
    from rangesim.twin.calibration import mask_iou
    from rangesim.twin.comparison import edge_agreement

    recorded, zeros = zero_depth_as_no_data(recorded)
    twin_scan, shapes = kinect_twin(recorded, labels, sensor, seed=seed)
    truth = twin_scan.xyz_true
    fb = float(twin_scan.meta["sensor"]["laser"]["baseline"]) * twin_scan.K[0, 0]
    common = recorded.valid & twin_scan.valid & np.isfinite(truth).all(axis=2)
    z_true = truth[..., 2].astype(np.float64)
    rec_res = np.where(common, recorded.depth - z_true, np.nan)
    twin_res = np.where(common, twin_scan.depth - z_true, np.nan)
    edge_maps: dict = {}
    metrics = {
        "iou": mask_iou(recorded.valid, twin_scan.valid),
        "iou_no_physics": mask_iou(recorded.valid, np.isfinite(truth).all(axis=2)),
        "shapes": twin_scan.meta["twin"]["shapes"],
        "focal_px": twin_scan.meta["twin"]["focal_px"],
        "residual_by_depth": {"recorded": _depth_binned(rec_res, z_true), "twin": _depth_binned(twin_res, z_true)},
        "z2_coefficient_mm_per_m2": {"recorded": _z2_coefficient(rec_res, z_true),
                                     "twin": _z2_coefficient(twin_res, z_true)},
        "depth_level_gaps_in_steps": {"recorded": _level_gaps_in_steps(recorded.depth[recorded.valid], fb),
                                      "twin": _level_gaps_in_steps(twin_scan.depth[twin_scan.valid], fb)},
        "valid": {"recorded": int(recorded.valid.sum()), "twin": int(twin_scan.valid.sum()),
                  "both": int(np.count_nonzero(recorded.valid & twin_scan.valid))},
        "zero_depth_no_data": zeros,
        "edges": edge_agreement(recorded, twin_scan, detectors, edge_maps=edge_maps),
    }
    # the noise about local planes of the scene's flat faces: each frame's own, no fit's error
    rec_local, local_z = local_plane_std(recorded.depth, z_true, common)
    twin_local, _ = local_plane_std(twin_scan.depth, z_true, common)
    both = rec_local > 0  # (a tile of one recorded level has no spread to compare with)
    metrics["local_plane_std_mm"] = {"recorded": _local_plane_binned(rec_local, local_z),
                                     "twin": _local_plane_binned(twin_local, local_z),
                                     "ratio_median": float(np.median(twin_local[both] / rec_local[both]))
                                     if both.any() else float("nan")}
    # robust std of the twin's residuals over the recording's, as rangesim.twin.comparison reports it
    rec_std, twin_std = robust_std(rec_res[common]), robust_std(twin_res[common])
    metrics["noise_std_ratio"] = float(twin_std / rec_std) if rec_std > 0 else float("nan")
    # both residuals over the noise the twin's model predicts there (scan.sigma): about 1 for
    # the twin if the law holds on this geometry, and for the recording if it is the device's
    sigma = twin_scan.sigma
    if sigma is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            scored = common & np.isfinite(sigma) & (sigma > 0)
            metrics["z_spread"] = {"recorded": robust_std(rec_res[scored] / sigma[scored]),
                                   "twin": robust_std(twin_res[scored] / sigma[scored])}
    if return_scans:
        return metrics, twin_scan, edge_maps
    return metrics
