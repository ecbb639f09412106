"""The geometric laser-stripe scanner: visibility, signal and noise decided by physical rules.

Steps (each in its own module, each vectorised over all pixels):

1. ``rays``: one ``ray_intersect`` of all camera rays (pinhole, OpenCV axes).
2. ``laser``: the sheet that lights each hit and where its light comes from.
3. ``shadows``: one ``ray_test`` towards the laser -> status 2 where blocked, or where the
   laser is behind the visible surface.
4. ``signal``: Lambertian return with inverse-square falloff -> status 3 below ``min_signal``.
5. working range on the true depth -> status 4 outside [near, far].
6. ``mixed_pixels``: centroid shift where a finite-width stripe straddles a depth edge.
7. ``noise`` + ``triangulation``: peak localisation error (Gaussian, speckle, quantisation)
   moves the point inside the laser sheet along the camera-ray/sheet intersection.

Precedence of status codes: miss (1) > out of range (4) > laser shadow (2) > dropout (3).
"""
from __future__ import annotations

import numpy as np

import rangesim
from rangesim.core.constants import Status
from rangesim.core.geometry import transform_points
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.config import Sensor
from rangesim.sensor.laser import sheet_through
from rangesim.sensor.mixed_pixels import peak_window_px, stripe_mixing_shift
from rangesim.sensor.noise import peak_error_px, speckle_sigma_mm
from rangesim.sensor.rays import cast_primary
from rangesim.sensor.shadows import occluded
from rangesim.sensor.signal import return_signal
from rangesim.sensor.triangulation import depth_per_pixel, triangulate

#: rays end at this multiple of the far limit: surfaces beyond are "no surface" (Mitsuba #61)
MAX_RAY_FACTOR = 2.0
#: below this |n . r| (sheet nearly containing the camera ray) triangulation is undefined
MIN_SHEET_ANGLE = 1e-3


def scan_geometric(scene, sensor: Sensor, pose: np.ndarray, seed: int) -> RangeScan:
    """Scan ``scene`` from camera-to-world ``pose``; see the module docstring."""
    p = sensor.params
    h, w = sensor.height, sensor.width
    K = sensor.K
    f = K[0, 0]
    near, far = p["range"]["near"], p["range"]["far"]
    mscene = scene.mitsuba_scene()
    watertight = np.array([o.watertight for o in scene.objects])
    albedos = np.array([o.albedo for o in scene.objects], dtype=np.float64)

    # 1. primary rays: directions with z = 1, so t * d / |d| has depth t / |d|
    hits = cast_primary(mscene, K, h, w, pose, MAX_RAY_FACTOR * far * _max_ray_stretch(K, h, w), watertight)
    n_pix = h * w
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    rays = np.stack(
        [(jj.ravel() + 0.5 - K[0, 2]) / f, (ii.ravel() + 0.5 - K[1, 2]) / K[1, 1], np.ones(n_pix)], axis=1
    )
    hit = hits.hit
    points = np.full((n_pix, 3), np.nan)
    points[hit] = rays[hit] * (hits.t[hit] / np.linalg.norm(rays[hit], axis=1))[:, None]
    rot = pose[:3, :3]
    normals = np.full((n_pix, 3), np.nan)
    normals[hit] = hits.normal_world[hit] @ rot  # world -> camera
    flip = np.einsum("ij,ij->i", normals[hit], points[hit]) > 0
    normals[np.flatnonzero(hit)[flip]] *= -1  # the visible side faces the camera

    # 2-5. laser geometry, shadows, signal, working range (on the hit pixels only)
    status = np.full(n_pix, Status.MISS, dtype=np.uint8)
    sources = np.full((n_pix, 3), np.nan)
    sheet_n = np.full((n_pix, 3), np.nan)
    signal = np.zeros(n_pix)
    idx = np.flatnonzero(hit)
    ph = points[idx]
    sources[idx], sheet_n[idx] = sheet_through(ph, p["laser"]["sweep"], p["laser"]["baseline"], sensor.tilt_rad)
    signal[idx], cos_i = return_signal(
        albedos[hits.part[idx]], normals[idx], ph, sources[idx], sensor.reference_distance
    )
    in_range = (ph[:, 2] >= near) & (ph[:, 2] <= far)
    blocked = occluded(
        mscene,
        transform_points(pose, ph),
        hits.normal_world[idx],
        transform_points(pose, sources[idx]),
        active=in_range & (cos_i > 0),
    )
    shadow = (cos_i <= 0) | blocked
    lit = ~shadow
    signal[idx[shadow]] = 0.0
    n_dot_r = np.abs(np.einsum("ij,ij->i", sheet_n[idx], rays[idx]))
    weak = (signal[idx] < p["noise"]["min_signal"]) | (signal[idx] <= 0) | (n_dot_r < MIN_SHEET_ANGLE)
    status[idx] = np.select(
        [~in_range, shadow, weak], [Status.OUT_OF_RANGE, Status.SHADOW, Status.DROPOUT], Status.VALID
    )
    valid = status == Status.VALID

    # 6. mixed pixels at depth edges
    lit_all = np.zeros(n_pix, dtype=bool)
    lit_all[idx] = lit
    window = peak_window_px(p["laser"]["stripe_width"], f, near)
    shift = stripe_mixing_shift(
        points.reshape(h, w, 3), sheet_n.reshape(h, w, 3), lit_all.reshape(h, w),
        signal.reshape(h, w), valid.reshape(h, w), p["laser"]["stripe_width"], window,
    ).ravel()

    # 7. noise: random numbers drawn for every pixel, so a pixel's noise depends only on the seed
    rng = np.random.default_rng(seed)
    gaussian = rng.standard_normal(n_pix)
    phase = rng.random(n_pix)
    v = np.flatnonzero(valid)
    dzdu = depth_per_pixel(points[v], sheet_n[v], rays[v], f)
    speckle_px = speckle_sigma_mm(
        points[v], sources[v], p["noise"]["speckle_contrast"], p["laser"]["wavelength_nm"],
        p["camera"]["aperture_mm"],
    ) / dzdu
    sigma = np.hypot(p["noise"]["sigma_px"], speckle_px)
    error = peak_error_px(sigma, p["noise"]["quantization_px"], gaussian[v], phase[v])
    measured = np.full((n_pix, 3), np.nan)
    measured[v] = triangulate(points[v], sheet_n[v], rays[v], shift[v] + error, f)

    meta = {
        "sensor": sensor.to_dict(),
        "sensor_source": sensor.source,
        "mode": "geometric",
        "seed": int(seed),
        "rangesim_version": rangesim.__version__,
        "K": K.tolist(),
        "laser_origin": sensor.laser_origin.tolist(),
        "scene": scene.source,
        "objects": [o.name for o in scene.objects],
        "peak_window_px": window,
        "recast_rays": hits.recast,
        "units": "mm",
    }
    xyz = measured.reshape(h, w, 3).astype(np.float32)
    return RangeScan(
        depth=xyz[..., 2].copy(),
        xyz=xyz,
        valid=valid.reshape(h, w),
        normal=normals.reshape(h, w, 3).astype(np.float32),
        intensity=signal.reshape(h, w).astype(np.float32),
        part=hits.part.reshape(h, w),
        face=hits.face.reshape(h, w),
        status=status.reshape(h, w),
        pose=pose,
        meta=meta,
        xyz_true=points.reshape(h, w, 3).astype(np.float32),
    )


def _max_ray_stretch(K, h, w) -> float:
    """Length of the longest pixel ray with unit depth (corner pixel), so maxt covers far."""
    return float(np.hypot(np.hypot(w / 2 / K[0, 0], h / 2 / K[1, 1]), 1.0))
