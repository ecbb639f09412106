"""The structured-light scanner (PrimeSense / Kinect v1 type): a dot pattern, an IR image, block matching.

Physical model, step by step (camera frame, mm; the projector is a pinhole with the camera's
intrinsics K at L = (b, 0, 0), b = ``laser.baseline`` (either sign; ``kinect_v1`` takes +75 mm,
the sign its twin matches the mOSD frames best with), looking along +z: a rectified pair; the
pattern is drawn over every projector column the matcher searches, :func:`matching_layout`,
so the projector's field is that much wider than the camera's):

1. ``rays``: one ``ray_intersect`` of all camera rays -> the surface point P of each pixel
   (camera occlusion is the primary hit itself).
2. Projector shadows: one ``ray_test`` from P towards L (``shadows.laser_reach``); a point
   the projector cannot reach receives no pattern.
3. Pattern irradiance: P projects into the projector at x_p = f (P_x - b) / P_z + c_x,
   y_p = f P_y / P_z + c_y, i.e. the pixel's column shifted by the disparity d = f b / z;
   the pattern (:class:`rangesim.sensor.dot_pattern.DotPattern`) there is scaled by the
   irradiance law albedo cos(i) (z_ref / d_L)^2 (i the incidence of the projector's ray, d_L
   the distance to the projector, z_ref mid-range). Ambient IR adds albedo x ``ambient``.
   A pixel's value is the radiance it sees, so it does not depend on the camera distance.
4. Image noise (electrons, ``exposure_e`` at a dot's peak on a white facing target at
   z_ref): laser speckle multiplies the pattern term by a unit-mean Gamma of contrast
   ``noise.speckle_contrast``; then Poisson shot noise, Gaussian read noise
   (``camera.read_noise_e``) and full-well saturation (``camera.full_well_e``).
5. Depth: :func:`rangesim.sensor.block_matching.block_match` of the IR image against the
   reference (the pattern on a fronto-parallel plane at disparity d0 = round(f b / z_ref), as
   a device stores it from its factory calibration) along the rows over the disparities of
   the working range; sub-pixel disparity quantised to 1 / ``subpixel_steps`` px;
   z = f b / d, the point on the pixel's ray.
6. Speckle filter (:func:`rangesim.sensor.speckle_filter.filter_speckles`): regions of the
   disparity image smaller than ``speckle_window`` px, whose 4-neighbours differ by at most
   ``speckle_range`` px, are chance matches and rejected, as a device's pipeline does.
7. Depth units: with ``depth_unit_mm`` u > 0 the depth is rounded to whole u (a Kinect's
   OpenNI frames hold uint16 millimetres), the point kept on its pixel's ray; ``sigma`` then
   holds the rounding's u^2 / 12 in quadrature. Near range, where a 1/8 px step is under 2 u
   (kinect_v1 at 1 mm: nearer than 0.83 m), the levels then lie 1 or 2 units apart. The
   rounding comes after the range test, so a depth may lie half a unit more beyond the range.

So depth noise follows sigma_z = z^2 sigma_d / (f b), with sigma_d (px) growing with the
surface's slant and holding the rounding to 1 / ``subpixel_steps`` px
(:mod:`rangesim.sensor.matching_noise`: the scan's ``sigma``), depth comes in steps of
f b / d - f b / (d + 1/8) (a fronto-parallel plane within 1.5 steps of the truth at the 99th
percentile with speckle and read noise off; with the presets' image noise up to about 2.2
steps), and a projector shadow behind an edge at depth D - h in front of a surface at D shows
in the image as a band f b (1 / (D - h) - 1 / D) px wide beside the edge, wherever the edge
lies (the edge and the shadow's far end lie on one projector column; on the surface that is
b h / (D - h) mm where the edge is not offset towards the projector, while an edge offset by
x_e towards it hides part of its shadow behind the part's own side, and at x_e >= b casts none
the camera sees). Depth edges may move outwards where the window straddles them, by up to
half the window, when the foreground's texture dominates it (0.2-1.5 px measured at a box's
outline over a plane with ``kinect_v1``).

Status: valid where a disparity was accepted and lies within half a 1/``subpixel_steps`` px
step of the range's disparities f |b| / far .. f |b| / near (a surface inside [near, far] is
measured; its rounded depth may lie up to half a depth step beyond the range); otherwise no
surface (1), projector shadow (2), true surface outside the range (4) or dropout (3: rejected
match, speckle, or a match whose disparity lies further outside the range).
A valid pixel may lie in a true shadow (fattening): its ``xyz_true`` is the true surface.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from rangesim.core.backend import aligned, mitsuba
from rangesim.core.constants import Status
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.block_matching import block_match
from rangesim.sensor.config import Sensor
from rangesim.sensor.dot_pattern import DotPattern
from rangesim.sensor.matching_noise import matching_sigma_mm, matching_sigma_px
from rangesim.sensor.metadata import scan_meta
from rangesim.sensor.rays import camera_hits
from rangesim.sensor.shadows import laser_reach
from rangesim.sensor.speckle_filter import filter_speckles

__all__ = ["scan_structured_light", "ir_image", "disparity_range", "reference_disparity", "matching_setup",
           "matching_layout", "MatchingSetup"]

#: largest mean (electrons) of a pixel's Poisson draw: NumPy refuses means above about 9e18;
#: a pixel beyond it is saturated whatever its full well (a surface touching the projector,
#: whose irradiance (z_ref / d_L)^2 has no bound)
POISSON_MAX_E = 1e18


def reference_disparity(sensor: Sensor) -> int:
    """Disparity (whole pixels) of the reference plane: f b / z_ref rounded, so z0 = f b / d0 near mid-range."""
    d0 = int(round(sensor.focal_px * sensor.params["laser"]["baseline"] / sensor.reference_distance))
    return d0 if d0 != 0 else (1 if sensor.params["laser"]["baseline"] > 0 else -1)


def disparity_range(sensor: Sensor) -> tuple[int, int]:
    """Disparities (whole pixels, lowest first) that cover the working range: f b / z for z in [near, far].

    Negative for a projector on the camera's -x side (b < 0).
    """
    fb = sensor.focal_px * sensor.params["laser"]["baseline"]
    r = sensor.params["range"]
    lo, hi = sorted((fb / r["far"], fb / r["near"]))
    return int(np.floor(lo)) - 1, int(np.ceil(hi)) + 1


@dataclass(frozen=True)
class MatchingSetup:
    """The device's fixed pattern and the matcher's reference and disparity range (pixels)."""

    pattern: DotPattern
    d_min: int
    d_max: int
    d0: int
    margin: int

    def reference(self, width: int, height: int) -> np.ndarray:
        """The stored reference image: the pattern on the plane of disparity d0, ``margin`` columns wider each side."""
        return self.pattern.reference(width, height, self.d0, self.margin)


def matching_layout(sensor: Sensor) -> tuple[int, int, int, int, int, int]:
    """(d_min, d_max, d0, margin, x_lo, x_hi), pixels: the disparity search range, the reference's
    disparity and extra columns each side, and the projector columns [x_lo, x_hi) the pattern covers.

    What :func:`matching_setup` allocates, known before it runs (the scan's memory estimate).
    """
    w = sensor.width
    d_min, d_max = disparity_range(sensor)
    d0 = reference_disparity(sensor)
    margin = max(abs(d_min - d0), abs(d_max - d0)) + 2
    # projector columns seen anywhere: x_p = u - d for the image's and the reference's columns
    x_lo = -max(d_max, d0 + margin, 0) - margin - 4
    x_hi = w + max(-d_min, -(d0 - margin), 0) + margin + 4
    return d_min, d_max, d0, margin, x_lo, x_hi


def matching_setup(sensor: Sensor) -> MatchingSetup:
    """The pattern (covering every projector column the camera sees in the working range) and the reference."""
    sl = sensor.params["structured_light"]
    d_min, d_max, d0, margin, x_lo, x_hi = matching_layout(sensor)
    pattern = DotPattern.generate(x_hi - x_lo, sensor.height, sl["dot_density"], sl["dot_sigma_px"],
                                  sl["pattern_seed"], x_min=x_lo, min_spacing_px=sl["dot_min_spacing_px"])
    return MatchingSetup(pattern, d_min, d_max, d0, margin)


def ir_image(rng: np.random.Generator, pattern_term: np.ndarray, ambient_term: np.ndarray, sensor: Sensor
             ) -> np.ndarray:
    """Electrons of the IR image from the relative pattern and ambient irradiance (flat arrays).

    Speckle (unit-mean Gamma of contrast C on the pattern term), Poisson shot noise, read
    noise and full-well saturation, in that order; the draws come from ``rng``.
    """
    sl, cam = sensor.params["structured_light"], sensor.params["camera"]
    c = float(sensor.params["noise"]["speckle_contrast"])
    expected = np.asarray(pattern_term, np.float64)
    if c > 0:
        expected = expected * rng.gamma(1.0 / c**2, c**2, size=expected.shape)
    electrons = sl["exposure_e"] * (expected + np.asarray(ambient_term, np.float64))
    electrons = rng.poisson(np.clip(electrons, 0.0, POISSON_MAX_E)).astype(np.float64)
    electrons += rng.normal(0.0, float(cam["read_noise_e"]), size=electrons.shape)
    return np.clip(electrons, 0.0, float(cam["full_well_e"]))


def scan_structured_light(scene, sensor: Sensor, pose: np.ndarray, seed: int) -> RangeScan:
    """Scan ``scene`` from camera-to-world ``pose``; see the module docstring."""
    mi = mitsuba()
    p = sensor.params
    sl = p["structured_light"]
    h, w = sensor.height, sensor.width
    K = sensor.K
    f = float(K[0, 0])
    b = float(p["laser"]["baseline"])
    near, far = p["range"]["near"], p["range"]["far"]
    z_ref = sensor.reference_distance

    # 1-2. primary hits and projector shadows
    view = camera_hits(scene, sensor, pose)
    hits, points, normals = view.hits, view.points, view.normals
    zero = dr.zeros(mi.Float, h * w)
    sources = mi.Vector3f(b + zero, zero, zero)
    in_range, lit = laser_reach(scene.mitsuba_scene(), view, sources, pose, near, far)
    albedo = dr.gather(mi.Float, mi.Float(aligned(np.array([o.albedo for o in scene.objects], np.float32))), hits.part,
                       hits.hit)
    dr.eval(points, normals, in_range, lit, albedo)
    P = np.asarray(dr.ravel(points), np.float64).reshape(-1, 3)
    n = np.asarray(dr.ravel(normals), np.float64).reshape(-1, 3)
    hit = np.asarray(hits.hit, bool)
    lit_np, in_range_np = np.asarray(lit, bool), np.asarray(in_range, bool)
    albedo_np = np.asarray(albedo, np.float64)
    P[~hit] = np.nan
    n[~hit] = np.nan

    # 3. pattern irradiance on each surface point, seen by its pixel
    pair = matching_setup(sensor)
    pattern, d_min, d_max, d0 = pair.pattern, pair.d_min, pair.d_max, pair.d0
    with np.errstate(invalid="ignore", divide="ignore"):
        to_proj = np.array([b, 0.0, 0.0]) - P
        d_proj = np.linalg.norm(to_proj, axis=1)
        cos_i = np.einsum("ij,ij->i", n, to_proj) / d_proj
        x_p = f * (P[:, 0] - b) / P[:, 2] + K[0, 2]
        y_p = f * P[:, 1] / P[:, 2] + K[1, 2]
    irradiance = np.where(hit & lit_np, albedo_np * np.clip(np.nan_to_num(cos_i), 0, None) * (z_ref / d_proj) ** 2, 0.0)
    irradiance = np.nan_to_num(irradiance)
    pattern_term = irradiance * pattern.sample(np.where(hit, x_p, np.nan), np.where(hit, y_p, np.nan))
    ambient_term = np.where(hit, albedo_np * sl["ambient"], 0.0)

    # 4. the IR image
    rng = np.random.default_rng(seed)
    electrons = ir_image(rng, pattern_term, np.nan_to_num(ambient_term), sensor).reshape(h, w)

    # 5. block matching against the reference plane at disparity d0, and triangulation
    relative, score = block_match(electrons, pair.reference(w, h), d_min - d0, d_max - d0,
                                  window=sl["window"], subpixel_steps=sl["subpixel_steps"],
                                  min_score=sl["min_score"], uniqueness=sl["uniqueness"], lr_check=sl["lr_check"])
    disparity = relative + d0
    # the working range on the disparity lattice: a level within half a step of f |b| / far ..
    # f |b| / near holds surfaces inside [near, far] (rounding moves a match by up to half a
    # step), so a plane just inside the range is measured, at a depth up to half a step beyond it
    half_step = 0.5 / sl["subpixel_steps"]
    with np.errstate(invalid="ignore"):
        towards = disparity * np.sign(b)  # positive for a point in front of the pair
        in_window = (towards > 0) & (towards >= f * abs(b) / far - half_step) & (
            towards <= f * abs(b) / near + half_step)
    disparity[~in_window] = np.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        z = f * b / disparity
    # 6. chance matches come as small islands of the disparity image (of the working range)
    z[filter_speckles(disparity, sl["speckle_window"], sl["speckle_range"])] = np.nan
    # 7. the depth as the device writes it: whole units (a Kinect's OpenNI frames hold uint16 mm)
    unit = float(sl["depth_unit_mm"])
    if unit > 0:
        z = np.round(z / unit) * unit
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rays = np.stack([(jj - K[0, 2]) / f, (ii - K[1, 2]) / K[1, 1], np.ones_like(jj)], axis=-1)
    matched = np.isfinite(z)
    xyz = np.where(matched[..., None], rays * z[..., None], np.nan)

    status = np.full(h * w, np.uint8(Status.DROPOUT))
    status[~in_range_np] = Status.OUT_OF_RANGE
    status[hit & ~lit_np & in_range_np] = Status.SHADOW
    status[~hit] = Status.MISS
    status = status.reshape(h, w)
    status[matched] = Status.VALID

    # the predicted std of each valid depth (mm), from the true surface's slant; a valid pixel
    # whose ray hits nothing (the foreground fattened over empty space) gets the law on a
    # fronto-parallel face at its measured depth (its error is the fattening, which no noise
    # law describes; neither does sigma where the fattened foreground covers a farther surface)
    noise = (sl["window"], sl["match_sigma_px"], sl["slant_linear"], sl["slant_quadratic"], sl["subpixel_steps"])
    with np.errstate(invalid="ignore"):
        sigma = matching_sigma_mm(P, n, f, b, *noise).reshape(h, w)
        flat = z * z * float(matching_sigma_px(0.0, *noise)) / (f * abs(b))
    sigma = np.where(np.isfinite(sigma), sigma, flat)
    if unit > 0:  # the rounding's uniform error, independent of the match
        sigma = np.sqrt(sigma * sigma + unit * unit / 12.0)
    sigma = np.where(status == Status.VALID, sigma, np.nan).astype(np.float32)

    part = np.asarray(hits.part, np.int32).reshape(h, w)
    face = np.asarray(hits.face, np.int32).reshape(h, w)
    meta = scan_meta(scene, sensor, seed, "structured_light", disparity_range_px=[d_min, d_max],
                     reference_disparity_px=d0)
    meta["projector_origin"] = [b, 0.0, 0.0]
    return RangeScan(
        depth=xyz[..., 2].astype(np.float32), xyz=xyz.astype(np.float32), valid=status == Status.VALID,
        normal=n.reshape(h, w, 3).astype(np.float32),
        intensity=(electrons / sl["exposure_e"]).astype(np.float32),
        part=np.where(hit.reshape(h, w), part, -1), face=np.where(hit.reshape(h, w), face, -1), status=status,
        pose=pose, meta=meta, xyz_true=P.reshape(h, w, 3).astype(np.float32), sigma=sigma,
    )
