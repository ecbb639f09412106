"""The geometric laser-stripe scanner: visibility, signal and noise decided by physical rules.

Steps (each in its own module; all per-pixel work runs as fused Dr.Jit kernels on the
Mitsuba variant's backend, LLVM on the CPU or CUDA on a GPU):

1. ``rays``: one ``ray_intersect`` of all camera rays (pinhole, OpenCV axes).
2. ``laser``: the sheet that lights each hit and where its light comes from.
3. ``shadows``: one ``ray_test`` towards the laser -> status 2 where blocked, or where the
   laser is behind the visible surface.
4. ``signal``: Lambertian return with inverse-square falloff.
5. working range on the true depth -> status 4 outside [near, far].
6. ``mixed_pixels`` (Dr.Jit, near depth steps and lit/unlit boundaries only): centroid
   shift where a finite-width stripe straddles a depth step.
7. ``stripe_noise`` (one mechanism with the twin of a recording; here in Dr.Jit, with a
   PCG32 stream per pixel): status 3 where the
   return, dimmed where the stripe is cut by an outline or shadow border, is below
   ``min_signal`` (a hard threshold, or a speckle probability with ``signal_contrast``);
   the peak error (floor, signal-limited term, correlated speckle, partial stripes,
   quantisation) and its predicted std ``sigma``; ``triangulation`` moves the point inside
   the laser sheet along the camera-ray/sheet intersection.

Precedence of status codes: miss (1) > out of range (4) > laser shadow (2) > dropout (3).
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from rangesim.core.backend import aligned, mitsuba, opaque_scalar
from rangesim.core.constants import Status
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.config import Sensor
from rangesim.sensor.laser import sheet_through
from rangesim.sensor.metadata import scan_meta
from rangesim.sensor.mixed_pixels import peak_window_px, row_steps, stripe_mixing_shift
from rangesim.sensor.rays import camera_hits
from rangesim.sensor.shadows import laser_reach
from rangesim.sensor.signal import return_signal
from rangesim.sensor.stripe_noise import PixelDraws, StripeNoise, border_distance_at, dorsch_sigma_mm, simulate
from rangesim.sensor.triangulation import triangulate

#: below this |n . r| (sheet nearly containing the camera ray) triangulation is undefined
MIN_SHEET_ANGLE = 1e-3


def scan_geometric(scene, sensor: Sensor, pose: np.ndarray, seed: int, rows: tuple[int, int] | None = None,
                   fields: dict | None = None) -> RangeScan:
    """Scan ``scene`` from camera-to-world ``pose``; see the module docstring.

    ``rows`` (first, stop): scan only that band of image rows (:mod:`rangesim.sensor.bands`);
    its pixels get the rays and the white noise draws they get in the whole image, and
    ``fields`` (a dict shared by the bands) holds any correlated noise field of the whole image.
    """
    mi = mitsuba()
    p = sensor.params
    h, w = sensor.height, sensor.width
    first = 0
    if rows is not None:
        first, h = rows[0], rows[1] - rows[0]
    K = sensor.K
    f = float(K[0, 0])
    near, far = p["range"]["near"], p["range"]["far"]
    mscene = scene.mitsuba_scene()

    # 1. primary rays
    view = camera_hits(scene, sensor, pose, rows)
    hits, points, normals = view.hits, view.points, view.normals
    hit = hits.hit
    rays = hits.rays

    # 2-5. laser geometry, shadows, signal, working range
    sources, sheet_n = sheet_through(points, p["laser"]["sweep"], p["laser"]["baseline"], sensor.tilt_rad)
    albedo = dr.gather(mi.Float, mi.Float(aligned(np.array([o.albedo for o in scene.objects], np.float32))), hits.part, hit)
    signal, _ = return_signal(albedo, normals, points, sources, sensor.reference_distance)
    in_range, lit = laser_reach(mscene, view, sources, pose, near, far)
    signal = dr.select(lit, signal, 0.0)
    noise = StripeNoise.from_params(p)
    # the min_signal threshold (hard, or a probability) is applied in step 7a, where truncated stripes are known
    weak = (signal <= 0) | (dr.abs(dr.dot(sheet_n, rays)) < MIN_SHEET_ANGLE)
    status = dr.zeros(mi.UInt32, h * w)  # Status.VALID
    for code, condition in ((Status.DROPOUT, weak), (Status.SHADOW, ~lit), (Status.OUT_OF_RANGE, ~in_range),
                            (Status.MISS, ~hit)):  # lowest precedence first
        status = dr.select(condition, int(code), status)
    dr.eval(points, normals, sources, sheet_n, signal, status, lit, albedo)

    # 7a. dropouts, predicted std and peak errors: the stripe noise model (lazy Dr.Jit)
    candidate = status == int(Status.VALID)
    draws = PixelDraws(np.random.default_rng(seed), h * w, first_index=first * w, rows=rows,
                       image_shape=(sensor.height, w), fields=fields)
    window = peak_window_px(p["laser"]["stripe_width"], f, near)  # the peak detector's, +-px
    draw, dz_du = _stripe_draw(noise, draws, (h, w), f, sensor.reference_distance, status, points, normals, sources,
                               sheet_n, rays, signal, albedo, window)
    status = dr.select(candidate & ~draw.detected, int(Status.DROPOUT), status)
    valid = status == int(Status.VALID)

    # 6. mixed pixels at depth edges
    shift = stripe_mixing_shift(points, sheet_n, lit, signal, valid, w, p["laser"]["stripe_width"], window)

    # 7b. the peak error triangulated against the sheet; the predicted std (mm): the model's
    # peak std with the mixed pixels' centroid shift, through dz/du
    measured = dr.select(valid, triangulate(points, sheet_n, rays, shift + draw.error_px, opaque_scalar(f)), dr.nan)
    # the camera reads the stripe's peak within the window its sensor sees, which is the working
    # range: a peak error that carries the measured depth past near or far puts the peak off
    # the sensor, so the pixel has no measurement (the true surface was in range)
    off_window = valid & ((measured.z < opaque_scalar(near)) | (measured.z > opaque_scalar(far)))
    status = dr.select(off_window, int(Status.OUT_OF_RANGE), status)
    valid = valid & ~off_window
    measured = dr.select(valid, measured, dr.nan)
    shift_px = dr.select(dr.isfinite(shift), shift, 0.0)
    sigma = dr.select(valid, dr.sqrt(dr.square(draw.sigma_px) + dr.square(shift_px)) * dz_du, dr.nan)
    points = dr.select(hit, points, dr.nan)
    normals = dr.select(hit, normals, dr.nan)
    outputs = {
        "xyz": dr.ravel(measured), "xyz_true": dr.ravel(points), "normal": dr.ravel(normals),
        "intensity": signal, "part": hits.part, "face": hits.face, "status": status, "sigma": sigma,
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
        sigma=arrays["sigma"].reshape(h, w),
    )


def _stripe_draw(noise: StripeNoise, draws: PixelDraws, shape: tuple[int, int], f: float, z_ref: float,
                 status, points, normals, sources, sheet_n, rays, signal, albedo, window: int):
    """:func:`rangesim.sensor.stripe_noise.simulate` on the camera-frame geometry, in Dr.Jit.

    The per-pixel inputs, the model's arithmetic and its white draws (a PCG32 stream per
    pixel) stay lazy Dr.Jit expressions, so they fuse into the scan's last kernel; only the
    border distance of the few cells that need it and any correlated field are made in
    NumPy. ``window``: the peak detector's half-width W (px; a depth step whose image jump
    exceeds it cuts the stripe). Returns the draw (Dr.Jit arrays) and dz/du (mm of depth per
    pixel of peak shift), which turns its std into mm.
    """
    mi = mitsuba()
    to_laser = sources - points
    d_laser = dr.norm(to_laser)
    d_camera = dr.norm(points)
    cos_i = dr.dot(normals, to_laser) / d_laser
    amplitude = albedo * cos_i * dr.square(z_ref / d_laser)
    sin_theta = dr.norm(dr.cross(points / d_camera, to_laser / d_laser))
    f_op = opaque_scalar(f)
    dzdu = dr.abs(points.z * sheet_n.x / (f_op * dr.dot(sheet_n, rays)))
    # a peak shift moves the point along the laser ray (the row's plane of camera rays holds
    # the laser's origin, so it meets the sheet in that ray): dz/du / cos(alpha) mm along it
    # per pixel, alpha the ray's angle from the optical axis. Dorsch's limit is a displacement
    # along the illumination, so in pixels it is sigma_D cos(alpha) / (dz/du).
    cos_alpha = dr.abs(to_laser.z) / d_laser
    speckle_px = dorsch_sigma_mm(d_camera, sin_theta, noise.speckle_contrast, noise.wavelength_nm,
                                 noise.aperture_mm) * cos_alpha / dzdu
    # pixels per mm on the surface along the row, foreshortened by the view: one pixel along
    # the row moves the seen point by dP/du = (z / f) (e_x - n_x P / (n . P)) on the surface
    # (normal n), which crosses a = |n_s . dP/du| mm of the sheet's thickness; the stripe's
    # image is s / a px wide, i.e. (cos i / a) s / cos i: f / d cos(e) on a plane seen at
    # viewing angle e in the sheet's plane of incidence
    across = dr.abs(points.z / f_op * (sheet_n.x - normals.x * dr.dot(sheet_n, points) / dr.dot(normals, points)))
    magnification = dr.abs(cos_i) / across
    cos_i, amplitude, magnification, speckle_px, dzdu = (
        dr.select(dr.isfinite(v), v, 0.0) for v in (cos_i, amplitude, magnification, speckle_px, dzdu))
    candidate = status == int(Status.VALID)

    def border_mm(where) -> "mi.Float":
        # the stripe is truncated where the surface ends, the laser cannot reach it, or a depth
        # step sends the rest of its light onto another surface outside the peak detector's
        # window (an occluding edge over a measured background: the step's image jump
        # delta / a over the window's W px; a smaller step's light stays in the window, where
        # the mixed pixels' centroid takes it) (px on the image over magnification px/mm), only
        # at the cells asked: the others +inf
        status_np = np.asarray(status)
        reached = (status_np == Status.VALID) | (status_np == Status.DROPOUT)
        ask = np.flatnonzero(np.asarray(where) & reached)
        m = np.asarray(magnification)[ask]
        d = np.full(status_np.size, np.inf, np.float32)
        cuts = np.asarray(row_steps(points, sheet_n, mi.Bool(aligned(reached)), shape[1],
                                    min_shift_px=0.5 * max(window, 1))).reshape(shape)
        d[ask] = border_distance_at(reached.reshape(shape), ask, cuts=cuts) / np.where(
            (status_np[ask] == Status.VALID) & (m > 0), m, 1.0)
        return mi.Float(aligned(d))

    corr = noise.correlation_mm * f / z_ref
    draw = simulate(noise, draws, shape, candidate=candidate, signal=signal, cos_incidence=cos_i,
                    amplitude=amplitude, magnification=magnification, reference_magnification=f / z_ref,
                    speckle_px=speckle_px, border_mm=border_mm, corr_px=(corr, corr))
    return draw, dzdu
