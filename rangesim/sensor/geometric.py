"""The geometric laser-stripe scanner: visibility, signal and noise decided by physical rules.

Steps (each in its own module; all per-pixel work runs as fused Dr.Jit kernels on the
Mitsuba variant's backend, LLVM on the CPU or CUDA on a GPU):

1. ``rays``: one ``ray_intersect`` of all camera rays (pinhole, OpenCV axes).
2. ``laser``: the sheet that lights each hit and where its light comes from.
3. ``shadows``: one ``ray_test`` towards the laser -> status 2 where blocked, or where the
   laser is behind the visible surface.
4. ``signal``: Lambertian return with inverse-square falloff -> status 3 below ``min_signal``.
5. working range on the true depth -> status 4 outside [near, far].
6. ``mixed_pixels`` (NumPy, near depth edges only): centroid shift where a finite-width
   stripe straddles a depth edge.
7. ``noise`` + ``triangulation``: peak localisation error (Gaussian, speckle, quantisation)
   moves the point inside the laser sheet along the camera-ray/sheet intersection.

Precedence of status codes: miss (1) > out of range (4) > laser shadow (2) > dropout (3).
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from rangesim.core.backend import mitsuba
from rangesim.core.constants import Status
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.config import Sensor
from rangesim.sensor.laser import sheet_through
from rangesim.sensor.mixed_pixels import peak_window_px, stripe_mixing_shift
from rangesim.sensor.noise import peak_error_px, pixel_random, speckle_sigma_mm
from rangesim.sensor.metadata import scan_meta
from rangesim.sensor.rays import camera_hits
from rangesim.sensor.shadows import laser_reach
from rangesim.sensor.signal import return_signal
from rangesim.sensor.triangulation import depth_per_pixel, triangulate

#: below this |n . r| (sheet nearly containing the camera ray) triangulation is undefined
MIN_SHEET_ANGLE = 1e-3


def scan_geometric(scene, sensor: Sensor, pose: np.ndarray, seed: int) -> RangeScan:
    """Scan ``scene`` from camera-to-world ``pose``; see the module docstring."""
    mi = mitsuba()
    p = sensor.params
    h, w = sensor.height, sensor.width
    K = sensor.K
    f = float(K[0, 0])
    near, far = p["range"]["near"], p["range"]["far"]
    mscene = scene.mitsuba_scene()

    # 1. primary rays
    view = camera_hits(scene, sensor, pose)
    hits, points, normals = view.hits, view.points, view.normals
    hit = hits.hit
    rays = hits.rays

    # 2-5. laser geometry, shadows, signal, working range
    sources, sheet_n = sheet_through(points, p["laser"]["sweep"], p["laser"]["baseline"], sensor.tilt_rad)
    albedo = dr.gather(mi.Float, mi.Float(np.array([o.albedo for o in scene.objects], np.float32)), hits.part, hit)
    signal, _ = return_signal(albedo, normals, points, sources, sensor.reference_distance)
    in_range, lit = laser_reach(mscene, view, sources, pose, near, far)
    signal = dr.select(lit, signal, 0.0)
    weak = (signal < p["noise"]["min_signal"]) | (signal <= 0) | (dr.abs(dr.dot(sheet_n, rays)) < MIN_SHEET_ANGLE)
    status = dr.zeros(mi.UInt32, h * w)  # Status.VALID
    for code, condition in ((Status.DROPOUT, weak), (Status.SHADOW, ~lit), (Status.OUT_OF_RANGE, ~in_range),
                            (Status.MISS, ~hit)):  # lowest precedence first
        status = dr.select(condition, int(code), status)
    valid = status == int(Status.VALID)
    dr.eval(points, normals, sources, sheet_n, signal, status, lit)

    # 6. mixed pixels at depth edges
    window = peak_window_px(p["laser"]["stripe_width"], f, near)
    shift = stripe_mixing_shift(points, sheet_n, lit, signal, valid, w, p["laser"]["stripe_width"], window)

    # 7. peak localisation noise, triangulated against the sheet
    gaussian, phase = pixel_random(np.random.default_rng(seed), h * w)
    speckle_mm = speckle_sigma_mm(
        points, sources, p["noise"]["speckle_contrast"], p["laser"]["wavelength_nm"], p["camera"]["aperture_mm"]
    )
    speckle_px = speckle_mm / depth_per_pixel(points, sheet_n, rays, f)
    sigma = dr.sqrt(p["noise"]["sigma_px"] ** 2 + dr.square(speckle_px))
    error = peak_error_px(sigma, p["noise"]["quantization_px"], gaussian, phase)
    measured = dr.select(valid, triangulate(points, sheet_n, rays, shift + error, f), dr.nan)
    points = dr.select(hit, points, dr.nan)
    normals = dr.select(hit, normals, dr.nan)
    outputs = {
        "xyz": dr.ravel(measured), "xyz_true": dr.ravel(points), "normal": dr.ravel(normals),
        "intensity": signal, "status": status, "part": hits.part, "face": hits.face,
    }
    dr.eval(*outputs.values())
    arrays = {name: np.asarray(value) for name, value in outputs.items()}

    meta = scan_meta(scene, sensor, seed, "geometric", peak_window_px=window, recast_rays=hits.recast)
    xyz = arrays["xyz"].reshape(h, w, 3)
    status_np = arrays["status"].astype(np.uint8).reshape(h, w)
    return RangeScan(
        depth=xyz[..., 2].copy(),
        xyz=xyz,
        valid=status_np == Status.VALID,
        normal=arrays["normal"].reshape(h, w, 3),
        intensity=arrays["intensity"].reshape(h, w),
        part=arrays["part"].reshape(h, w),
        face=arrays["face"].reshape(h, w),
        status=status_np,
        pose=pose,
        meta=meta,
        xyz_true=arrays["xyz_true"].reshape(h, w, 3),
    )
