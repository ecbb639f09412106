"""Curvature at the scale a block matcher resolves: the shape operator from chords.

Analysis layer: pure NumPy / scipy.ndimage over arrays.

A block matcher (structured light, :mod:`rangesim.edges._matching_scale`) measures about the
true surface smoothed by a ``window`` x ``window`` box: every crease comes out rounded over
the window, under noise correlated over it. A quadric fitted to a block sees a crease only
when the block reaches past the rounding (13 px for the presets' 9), and such blocks touch a
gap or a jump almost everywhere on these scans (ragged shadows, fattened jumps), so few fits
are usable there. Here the curvature is measured as the paper defines it, the change of the
surface normal per length of surface, at the matcher's scale ``h = window // 2``:

* normals from the chords ``P(p + h d) - P(p - h d)`` along image x and y
  (:func:`~rangesim.edges._pcl_scale.chord_normals`, one-sided where a chord would cross a
  gap or a depth jump);
* the tangents ``T_x, T_y`` (chords at ``+-h``) and the normals' derivatives ``N_x, N_y``
  (normals at ``+-h``, so a curvature at ``p`` spans about ``4h`` pixels), both one-sided
  where a side is unusable (:func:`~rangesim.edges._differences.central_difference`);
* the first and second fundamental forms ``I = [[T_x.T_x, T_x.T_y], [., T_y.T_y]]`` and
  ``II = -[[N_x.T_x, (N_x.T_y + N_y.T_x) / 2], [., N_y.T_y]]`` averaged over the matcher's
  support (a Gaussian of ``window / sqrt 12``, NaN-aware), and the principal curvatures and
  directions of the shape operator ``I^-1 II`` (:func:`chord_curvatures`). The principal
  direction of the larger curvature is an image direction directly (the parameters are the
  pixel coordinates): the direction across a crease.

Convention as :mod:`rangesim.curvature`: normals towards the camera, curvature positive where
the surface bends towards it (H < 0 convex, H > 0 concave).

On a surface smooth at the scale ``4h`` (a cylinder of radius well above ``window``
footprints) this is its curvature. A crease of bend ``beta`` rounded by the box is seen by
normals ``+-h`` apart as about ``rounding_gain(window, 2h) beta`` (0.72 of it for the 9 px
window), spread over the ``2h`` pixels between them: the *bend* ``|k| * 2h * |dP/ds|``
(``|dP/ds|`` mm per pixel along the principal direction) over that gain estimates the
crease's angle (:func:`chord_bend`), whatever the face's slant.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.edges._differences import central_difference, dot3
from rangesim.edges._matching_scale import ridge_sigma, rounding_gain
from rangesim.edges._pcl_scale import chord_normals, crease_step, nan_gaussian
from rangesim.edges._scan_access import scan_points
from rangesim.edges._thinning import JUMP_CLEARANCE, hysteresis, near_mask, nonmax_suppress

__all__ = ["chord_curvatures", "chord_bend", "matched_creases", "form_sigma", "K_LOW", "K_HIGH",
           "LOW_FLOOR", "HIGH_FLOOR"]

#: hysteresis thresholds on the bend (:func:`chord_bend`) in multiples of its median over the
#: scan's valid pixels (the measured noise level; creases are a few per cent of the pixels).
#: The matcher's errors are correlated over its window and heavy-tailed (depth quantised in
#: whole disparity steps), so no law predicts them; chosen on the machined parts' tuning seeds
#: 0-7 (kinect_v1, structured_light_bench, noise-free and noisy): (3, 4), (3.5, 4.5), (3, 4.5),
#: (3.5, 5) and (4, 5) gave mean F1 0.751-0.759, (4, 6) 0.70 (noisy kinect_v1 creases fall
#: under it), (2.5, 3.5) 0.63-0.69
K_LOW, K_HIGH = 3.5, 4.5
#: least thresholds, radians of bend: 15 degrees to continue a crease (the gradient
#: detector's noise-free threshold), 20 to start one (the ground truth's least crease);
#: they bind only on quiet scans (a noise-free synthetic matcher), the presets' noise sets
#: 35-60 degrees
LOW_FLOOR, HIGH_FLOOR = float(np.radians(15.0)), float(np.radians(20.0))


def chord_curvatures(xyz: np.ndarray, pairs: np.ndarray | None, step: int, sigma: float = 0.0) -> dict[str, Any]:
    """Principal curvatures and directions of the surface at step ``h`` (module docstring).

    Parameters
    ----------
    xyz : (3, H, W) float32
        Points, component-major, NaN where invalid.
    pairs : (4, H, W) bool or None
        Broken neighbour pairs (depth discontinuities): no chord crosses them.
    step : int
        ``h``, pixels.
    sigma : float
        Gaussian (pixels) over which the fundamental forms are averaged (0: none).

    Returns
    -------
    dict
        ``k`` (H, W) float32, 1/mm: the principal curvature of larger magnitude, signed;
        ``k_other``: the other one; ``H``: the mean curvature; ``direction``: angle in
        [0, pi) of the image vector along ``k``'s principal direction (across a crease);
        ``length``: mm of surface per pixel along that image direction. NaN where a
        tangent or a normal derivative is missing.
    """
    h = int(step)
    n = chord_normals(xyz, pairs, h)
    tx = central_difference(xyz, 0, pairs, h)
    ty = central_difference(xyz, 2, pairs, h)
    nx = central_difference(n, 0, pairs, h)
    ny = central_difference(n, 2, pairs, h)
    forms = [dot3(tx, tx), dot3(tx, ty), dot3(ty, ty),
             -dot3(nx, tx), -0.5 * (dot3(nx, ty) + dot3(ny, tx)), -dot3(ny, ty)]
    if sigma > 0:
        forms = [nan_gaussian(f.astype(np.float32), sigma) for f in forms]
    e, f, g, ll, m, nn = (a.astype(np.float64) for a in forms)
    with np.errstate(invalid="ignore", divide="ignore"):
        det = e * g - f * f
        gauss = (ll * nn - m * m) / det
        mean = (e * nn - 2 * f * m + g * ll) / (2 * det)
        root = np.sqrt(np.maximum(mean * mean - gauss, 0.0))
        k = mean + np.where(mean >= 0, root, -root)
        k_other = mean - np.where(mean >= 0, root, -root)
        # (II - k I) v = 0: either row gives v; take the better conditioned
        a, b, c = ll - k * e, m - k * f, nn - k * g
        u1, v1 = -b, a
        u2, v2 = c, -b
        first = (u1 * u1 + v1 * v1) >= (u2 * u2 + v2 * v2)
        u = np.where(first, u1, u2)
        v = np.where(first, v1, v2)
        norm = np.sqrt(u * u + v * v)
        u, v = u / norm, v / norm
        length = np.sqrt(e * u * u + 2 * f * u * v + g * v * v)
        direction = np.mod(np.arctan2(v, u), np.pi)
    bad = ~(det > 0)
    out = {"k": k, "k_other": k_other, "H": mean, "direction": direction, "length": length}
    for key, val in out.items():
        val = val.astype(np.float32)
        val[bad] = np.nan
        out[key] = val
    return out


def chord_bend(curv: dict[str, Any], step: int, window: int | None) -> np.ndarray:
    """A crease's angle (radians) estimated from :func:`chord_curvatures`' larger curvature:
    ``|k| * 2h * length`` over :func:`~rangesim.edges._matching_scale.rounding_gain`
    ``(window, 2h)`` (the share of a box-rounded crease that normals ``2h`` apart see)."""
    h = int(step)
    scale = np.float32(2 * h / rounding_gain(window or 1, 2 * h))
    return np.abs(curv["k"]) * curv["length"] * scale


def form_sigma(step: int) -> float:
    """Gaussian (pixels) over which :func:`matched_creases` averages the fundamental forms:
    a box of the normals' step ``h`` (``h / sqrt 12``, 1.15 px for ``h = 4``). On the tuning
    seeds 0-7 Gaussians of 1.0 / 1.15 / 1.5 / 2.0 px gave mean F1 0.757 / 0.758 / 0.759 / 0.746,
    none 0.62 (the ridge then thinned on the bend smoothed over the matcher's support)."""
    return float(step) / float(np.sqrt(12.0))


def matched_creases(scan: Any, valid: np.ndarray, disc: Any, window: int,
                    threshold: float | None = None) -> tuple[np.ndarray, dict[str, Any], dict[str, Any]]:
    """Crease points of :func:`~rangesim.edges.curvature`'s ``extrema`` rule on a block-matched scan.

    The paper's rule, local extrema of curvature, at the matcher's scale: the larger principal
    curvature of :func:`chord_curvatures` at ``h = window // 2`` (fundamental forms averaged
    over :func:`form_sigma`), non-maximum suppression along its principal direction on the
    bend smoothed over the matcher's support
    (:func:`~rangesim.edges._matching_scale.ridge_sigma` of the window), hysteresis on the
    bend (:func:`chord_bend`, radians) between :data:`K_LOW` and :data:`K_HIGH` times its
    median over the scan (floors :data:`LOW_FLOOR`, :data:`HIGH_FLOOR`), or ``|k| >
    threshold`` (1/mm) where one is given; then no crease within
    :data:`~rangesim.edges._thinning.JUMP_CLEARANCE` px of a depth discontinuity (the crest
    beside a jump is the jump itself).

    Parameters
    ----------
    scan : RangeScan
    valid : (H, W) bool
    disc : Discontinuities
        The detectors' jump rule (:func:`~rangesim.edges._discontinuities.discontinuities`).
    window : int
        The matcher's window, pixels.
    threshold : float, optional
        Curvature threshold, 1/mm (a single threshold, no hysteresis).

    Returns
    -------
    points : (H, W) bool
    curv : dict
        :func:`chord_curvatures`' arrays.
    info : dict
        ``step``, ``form_sigma``, ``ridge_sigma`` and ``bend_threshold`` ([low, high]
        radians, or None with an explicit ``threshold``), ``bend_noise`` (the median bend).
    """
    h = crease_step(window, None)
    xyz = scan_points(scan, valid, component_major=True)
    fs = form_sigma(h)
    curv = chord_curvatures(xyz, disc.pairs, h, fs)
    bend = chord_bend(curv, h, window)
    rsig = ridge_sigma(window, 2 * h)
    ridge = nan_gaussian(bend, rsig)
    info: dict[str, Any] = {"step": h, "form_sigma": fs, "ridge_sigma": rsig, "bend_threshold": None, "bend_noise": None}
    with np.errstate(invalid="ignore"):
        if threshold is None:
            sub = (slice(None, None, 4), slice(None, None, 4))
            b = bend[sub][valid[sub] & np.isfinite(bend[sub])]
            noise = float(np.median(b)) if b.size else 0.0
            low, high = max(LOW_FLOOR, K_LOW * noise), max(HIGH_FLOOR, K_HIGH * noise)
            thin = nonmax_suppress(ridge, curv["direction"], bend > low)
            points = hysteresis(np.where(thin, bend, 0), low, high)
            info.update(bend_threshold=[low, high], bend_noise=noise)
        else:
            points = nonmax_suppress(ridge, curv["direction"], np.abs(curv["k"]) > float(threshold))
    points &= valid
    points &= ~near_mask(points, disc.touching, JUMP_CLEARANCE)
    return points, curv, info
