"""The normal detector at the scale of a block matcher: the bend between chord normals one
matching window apart.

Analysis layer: pure NumPy / scipy.ndimage over arrays.

A block matcher (structured light, :mod:`rangesim.edges._matching_scale`) measures about the
true surface smoothed by a ``window`` x ``window`` box: a crease comes out rounded over the
window, under errors correlated over it and heavy-tailed (depth quantised in disparity
steps). Adjacent 3 x 3 stencil normals see about a ninth of such a crease's bend under that
noise. Here the normal detector's own quantity, the angle between the normals either side
of a pixel, is taken at the matcher's scale ``h = window // 2``:

* normals from the chords ``P(p + h d) - P(p - h d)`` along image x and y
  (:func:`~rangesim.edges._pcl_scale.chord_normals`, one-sided where a chord would cross a
  gap or a depth jump);
* for each of the four axes ``d`` (0, 45, 90, 135 degrees) the angle between the normals at
  ``p - h d`` and ``p + h d`` (:func:`axis_bends`); where one side is unusable (invalid, or a
  jump between) the normal at ``p`` stands in for it, and the angle is not doubled (beside a
  gap a crease then reads about half its angle; doubling scored 0.719 against 0.758 on the
  tuning seeds: it doubled the noise there too);
* divided by :func:`~rangesim.edges._matching_scale.rounding_gain` ``(window, 2h)`` (0.72
  for the presets' 9 px window): normals ``2h`` apart see that share of a box-rounded
  crease's bend, so the strength estimates the crease's angle.

Noise law (:func:`bend_noise`): on a plane each axis's bend is the length of the difference
of two unit normals, whose two tangential components are (about) Gaussian of one standard
deviation ``s``: a Rayleigh variable, median ``sqrt(2 ln 2) s`` = 1.177 s, exceeding
``k s`` with probability ``exp(-k^2 / 2)``. The matcher's errors follow no independent-error
law, so ``s`` is *measured*: the median of the four axes' bends over the scan's valid pixels
over 1.177 (creases are a few per cent of the pixels). The strength (largest of the four
axes) exceeds ``k s`` on a plane with probability at most ``4 exp(-k^2 / 2)``. Where the scan
carries the noise model's prediction (``RangeScan.sigma``,
:mod:`rangesim.sensor.matching_noise`: the error grows steeply with the surface's slant),
``s`` is that typical level and each pixel's thresholds rise with its predicted angular
noise ``sigma / footprint`` over the scan's median (never below the typical level:
:func:`~rangesim.edges._noise.local_noise_scale`, as ``noise_scale`` of
:func:`sl_creases`): tuning seeds 0-7 mean F1 +0.006 (lowering them on quiet faces too:
-0.002), check seeds 8-15 +0.003.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.edges._differences import dot3, side_samples
from rangesim.edges._matching_scale import ridge_sigma, rounding_gain
from rangesim.edges._pcl_scale import chord_normals, crease_step, nan_gaussian
from rangesim.edges._thinning import hysteresis, nonmax_suppress
from rangesim.edges._trig import half_atan2

__all__ = ["axis_bends", "bend_noise", "sl_creases", "RAYLEIGH_MEDIAN", "K_LOW", "K_HIGH",
           "LOW_FLOOR_DEG", "HIGH_FLOOR_DEG"]

#: median of a Rayleigh variable in units of its components' standard deviation
RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))
#: hysteresis on the strength in measured noise sigmas (:func:`bend_noise`): on a plane one
#: axis exceeds 4 s with probability exp(-8) = 3e-4 and the largest of four at most 1.3e-3,
#: 5.5 s 1e-6 (block-matched planes of 0.1-0.2 px correlated noise: 0.0013-0.0028 and 0).
#: Chosen on the machined parts' tuning seeds 0-7 (kinect_v1, structured_light_bench,
#: noise-free and noisy), mean F1: (3, 4) 0.670, (3.5, 5) 0.749, (4, 5.5) 0.758, (4.5, 6) 0.758,
#: (4, 6.5) 0.755, (5, 6.5) 0.719 (with doubled one-sided pairs), (6, 8) 0.663
K_LOW, K_HIGH = 4.0, 5.5
#: least thresholds, degrees: 15 to continue a crease, 20 (the truth's least crease) to start one
LOW_FLOOR_DEG, HIGH_FLOOR_DEG = 15.0, 20.0


def axis_bends(xyz: np.ndarray, pairs: np.ndarray | None, window: int) -> dict[str, Any]:
    """The bend (radians, over the rounding gain) between chord normals ``+-h`` along each axis.

    Parameters
    ----------
    xyz : (3, H, W) float32
        Points, component-major, NaN where invalid.
    pairs : (4, H, W) bool or None
        Broken neighbour pairs (depth discontinuities).
    window : int
        The matcher's window, pixels (``h = window // 2``).

    Returns
    -------
    dict
        ``angles``: list of 4 (H, W) float32 (NaN where undefined); ``strength``: their
        largest (NaN where none); ``concave``: (H, W) bool, the largest axis's sign; ``step``.
    """
    h = crease_step(window, None)
    n = chord_normals(xyz, pairs, h)
    ok = np.isfinite(n[0])
    inv_gain = np.float32(1.0 / rounding_gain(window, 2 * h))
    shape = ok.shape
    strength = np.full(shape, -1.0, np.float32)
    concave = np.zeros(shape, bool)
    angles = []
    for a in range(4):
        nf, nb, fok, bok = side_samples(n, ok, pairs, a, h)
        pf, pb, _, _ = side_samples(xyz, ok, pairs, a, h)
        nf = np.where(fok, nf, n)
        nb = np.where(bok, nb, n)
        pf = np.where(fok, pf, xyz)
        pb = np.where(bok, pb, xyz)
        count = fok.view(np.int8) + bok.view(np.int8)
        c = dot3(nf, nb)
        np.clip(c, -1, 1, out=c)
        with np.errstate(invalid="ignore", divide="ignore"):
            ang = (np.arccos(c) * inv_gain).astype(np.float32)
        np.copyto(ang, np.nan, where=count == 0)
        # (P_f - P_b) . (n_b - n_f) > 0: the faces turn towards the camera (a valley)
        side = dot3(pf - pb, nb - nf)
        better = ang > strength
        np.copyto(strength, ang, where=better)
        np.copyto(concave, side > 0, where=better)
        angles.append(ang)
    np.copyto(strength, np.nan, where=strength < 0)
    return {"angles": angles, "strength": strength, "concave": concave, "step": h}


def bend_noise(angles: list[np.ndarray], valid: np.ndarray) -> float:
    """Measured noise ``s`` (radians) of one axis's bend: the median of the four axes' bends
    over valid pixels (every 4th row and column) over :data:`RAYLEIGH_MEDIAN`."""
    sub = (slice(None, None, 4), slice(None, None, 4))
    vals = np.concatenate([a[sub][valid[sub]] for a in angles])
    vals = vals[np.isfinite(vals)]
    return float(np.median(vals)) / RAYLEIGH_MEDIAN if vals.size else 0.0


def sl_creases(xyz: np.ndarray, valid: np.ndarray, pairs: np.ndarray | None, window: int,
               threshold_deg: float | None = None, nms: bool = True,
               noise_scale: np.ndarray | None = None) -> dict[str, Any]:
    """Crease pixels of :func:`~rangesim.edges.normal` on a block-matched scan.

    :func:`axis_bends`; the direction across the crease from the second harmonic of the four
    axes' bends; non-maximum suppression across it on the summed bend smoothed over the
    matcher's support (:func:`~rangesim.edges._matching_scale.ridge_sigma`); hysteresis on
    the strength between :data:`K_LOW` and :data:`K_HIGH` times :func:`bend_noise` (floors
    :data:`LOW_FLOOR_DEG`, :data:`HIGH_FLOOR_DEG`), or above ``threshold_deg`` where given.
    ``noise_scale`` (H, W), optional, multiplies the noise thresholds per pixel
    (``threshold_deg`` then reports the unscaled pair and ``threshold_scale_max`` the largest factor).

    Returns
    -------
    dict
        ``crease`` (H, W) bool, ``strength`` (degrees), ``concave``, ``theta``, ``ridge``,
        ``threshold_deg`` ([low, high] before the per-pixel scale), ``threshold_scale_max``,
        ``bend_noise_deg``, ``step``, ``ridge_sigma``.
    """
    b = axis_bends(xyz, pairs, window)
    angles = [np.where(np.isnan(a), np.float32(0), a) for a in b["angles"]]
    strength = b["strength"]
    theta = half_atan2(angles[1] - angles[3], angles[0] - angles[2])
    rank = angles[0] + angles[1] + angles[2] + angles[3]
    np.copyto(rank, np.nan, where=np.isnan(strength))
    rsig = ridge_sigma(window, 2 * b["step"])
    ridge = nan_gaussian(rank, rsig)
    noise = bend_noise(b["angles"], valid)
    scale_max = 1.0
    if threshold_deg is None:
        base_low = max(np.radians(LOW_FLOOR_DEG), K_LOW * noise)
        base_high = max(np.radians(HIGH_FLOOR_DEG), K_HIGH * noise)
        low, high = base_low, base_high
        if noise_scale is not None:
            low = np.maximum(np.radians(LOW_FLOOR_DEG), K_LOW * noise * noise_scale)
            high = np.maximum(np.radians(HIGH_FLOOR_DEG), K_HIGH * noise * noise_scale)
            scale_max = float(np.max(noise_scale[valid])) if valid.any() else 1.0
    else:
        base_low = base_high = low = high = float(np.radians(threshold_deg))
    with np.errstate(invalid="ignore"):
        above = (strength > low) & valid
    crease = nonmax_suppress(ridge, theta, above) if nms else above
    crease = hysteresis(np.where(crease, strength, 0), low, high) & crease
    return {
        "crease": crease, "strength": np.degrees(strength).astype(np.float32), "concave": b["concave"],
        "theta": theta, "ridge": ridge, "threshold_deg": [float(np.degrees(base_low)), float(np.degrees(base_high))],
        "threshold_scale_max": scale_max,
        "bend_noise_deg": float(np.degrees(noise)), "step": b["step"], "ridge_sigma": rsig,
    }
