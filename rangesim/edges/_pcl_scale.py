"""pcl_organized's high-curvature edges at the scale the sensor resolves.

Analysis layer: pure NumPy / scipy.ndimage over arrays.

PCL's detector runs Canny (3 x 3 Gaussian, Sobel, non-maximum suppression, hysteresis) on
the normal images. At 3 x 3 that works on clean scans; on the scans of a block matcher
(structured light: depth is about the true surface smoothed by a ``window`` x ``window``
box, :mod:`rangesim.edges._matching_scale`) a crease is rounded over the window and a 3 x 3
difference of normals sees about a ninth of its bend, and on noisy laser scans the normals'
noise swamps the creases. Here the same pipeline runs at a step ``h`` (pixels):

* normals from central chords ``P(p + h d) - P(p - h d)`` along image x and y
  (:func:`chord_normals`; one-sided where a chord would cross a gap or a depth jump), PCL's
  ``AVERAGE_3D_GRADIENT`` integral-image normals at a smoothing size of ``2h + 1``;
* Sobel at stride ``h`` (:func:`strided_sobel`): the normal difference ``n(p + h d) -
  n(p - h d)`` averaged ``[1 2 1] / 4`` along the edge at stride ``h``, times 4 (PCL's raw
  Sobel units), divided by the share of a box-rounded crease those normals see
  (:func:`~rangesim.edges._matching_scale.rounding_gain` at lag ``2h``: 0.72 for the presets'
  9 px window and ``h = 4``). A crease bending the surface by ``beta`` radians then responds
  with about ``8 sin(beta / 2)`` (~4 beta);
* thresholds from the noise of that strength (:func:`strength_noise`).

The step (:func:`crease_step`): on block-matched scans ``window // 2``, so the chords of
the normals either side of a crease reach the rounding's edge (a matcher's rounding spans
``+-window / 2``); on noisy laser scans the smallest step at which the predicted noise of
the normal difference (below) is at most :data:`NOISE_TARGET_RAD`.

The noise law (per component of the normal difference, radians, a face seen head-on, depth
errors independent from pixel to pixel with standard deviation ``sigma`` pixel
footprints): a tangent of chord ``2h`` has slope noise ``sigma / (sqrt 2 h)``, the two normals
``h`` either side share the centre point, so their difference is the second difference of
depth at lag ``2h`` over ``2h``, of std ``sqrt 6 sigma / (2 h)``; the Sobel's ``[1 2 1] / 4``
along the edge leaves ``sqrt 6 / 4`` of it. In raw Sobel units (times 4) that is
``3 sigma / h`` (:func:`predicted_noise_law`). Faces seen obliquely have quieter normals (the
law is their upper bound). Scans that carry the noise model's prediction
(``RangeScan.sigma``, laser stripes) get this law per pixel, with the least sigma over 5 x 5
(:func:`~rangesim.edges._noise.predicted_noise`); scans without it, and block-matched ones
(which carry it too, but whose errors are correlated over the window, so no
independent-error law holds), get the noise measured on the strength itself: its magnitude over the four tangential components
is chi-distributed with 4 degrees of freedom, of median :data:`CHI4_MEDIAN` sigmas.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from rangesim.edges._differences import central_difference, normals_from_tangents
from rangesim.edges._grid import pad_last2, padded_view
from rangesim.edges._matching_scale import rounding_gain
from rangesim.edges._noise import predicted_noise

__all__ = [
    "crease_step", "chord_normals", "strided_sobel", "predicted_noise_law", "strength_noise",
    "nan_gaussian", "NOISE_TARGET_RAD", "MAX_STEP", "CHI4_MEDIAN", "K_LOW", "K_HIGH",
]

#: the noise on the normal difference (radians, per component, head-on face) that a noisy
#: laser scan's step brings its normals under: a 45-degree crease (the machined parts'
#: chamfers) then stands 3.5 noise sigmas above it. At the White Scanner preset's noise
#: (0.25 footprints) the step is 1 px, at the INRIA preset's (0.8) 3 px; on the machined
#: parts' tuning seeds 20-29 (inria_laser, noisy) steps 2 / 3 / 4 gave F1 0.59 / 0.68 / 0.60
#: and on seeds 0-7 of white_scanner and cyberware_3030 step 1 was best
NOISE_TARGET_RAD = float(np.pi / 4 / 3.5)
#: largest step on laser scans (a 9 px stencil, as the normal detector's widest)
MAX_STEP = 4
#: median of a chi distribution with 4 degrees of freedom (the strength's magnitude under
#: noise: two tangential components of each of the two normal differences)
CHI4_MEDIAN = 1.8324
#: hysteresis thresholds in noise sigmas of the strength: a chi-4 magnitude exceeds 4 sigma
#: with probability 3e-3 and 6 sigma with 3e-7 per pixel; PCL's noise-free (0.4, 1.1) stay
#: as floors. Chosen on tuning seeds 0-7 (kinect_v1, structured_light_bench) and 20-29
#: (inria_laser): (3.5, 5), (3, 4.5), (3, 5.5) and (4, 5.5) were within 0.01-0.04 F1
K_LOW, K_HIGH = 4.0, 6.0


def crease_step(window: int | None, noise: float | None) -> int:
    """The step ``h`` (pixels) of :func:`chord_normals` and :func:`strided_sobel`.

    ``window // 2`` for a block matcher's ``window``; otherwise the smallest ``h`` whose
    predicted noise ``sqrt 6 (sqrt 6 / 4) noise / (2 h)`` is at most
    :data:`NOISE_TARGET_RAD` (``noise`` in pixel footprints), 1 to :data:`MAX_STEP`.

    Examples
    --------
    >>> crease_step(9, 0.5), crease_step(None, 0.25), crease_step(None, 0.8), crease_step(None, 0.0)
    (4, 1, 3, 1)
    """
    if window is not None:
        return max(1, int(window) // 2)
    if not noise or noise <= 0:
        return 1
    need = 1.5 * float(noise) / (2.0 * NOISE_TARGET_RAD)
    return int(np.clip(np.ceil(need), 1, MAX_STEP))


def chord_normals(xyz: np.ndarray, pairs: np.ndarray | None, step: int) -> np.ndarray:
    """Unit normals from the central chords ``P(p + h d) - P(p - h d)`` along image x and y.

    One-sided where a side is invalid or across a depth discontinuity
    (:func:`~rangesim.edges._differences.central_difference`); turned towards the camera
    (``n . p <= 0``); NaN where a tangent is missing.

    Parameters
    ----------
    xyz : (3, H, W) float array
        Points, component-major, NaN where invalid.
    pairs : (4, H, W) bool or None
        Broken neighbour pairs (depth discontinuities).
    step : int
        ``h``, pixels.

    Returns
    -------
    (3, H, W) array of xyz's dtype
    """
    return normals_from_tangents(central_difference(xyz, 0, pairs, step), central_difference(xyz, 2, pairs, step),
                                 xyz)


def _smooth_along(a: np.ndarray, axis: int, s: int) -> np.ndarray:
    """NaN-aware ``[1 2 1]`` at stride ``s`` along image axis 0 (y) or 1 (x) of a (C, H, W) stack."""
    ok = ~np.isnan(a[0])
    filled = np.where(ok, a, np.float32(0))
    wgt = ok.astype(np.float32)
    dr, dc = (s, 0) if axis == 0 else (0, s)
    shape = ok.shape
    fp, wp = pad_last2(filled, s, 0.0), pad_last2(wgt, s, 0.0)
    two = np.float32(2)
    num = two * filled + padded_view(fp, s, dr, dc, shape) + padded_view(fp, s, -dr, -dc, shape)
    den = two * wgt + padded_view(wp, s, dr, dc, shape) + padded_view(wp, s, -dr, -dc, shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[:, ~ok] = np.nan
    return out


def strided_sobel(n: np.ndarray, pairs: np.ndarray | None, step: int,
                  window: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Sobel of a normal field at stride ``h``, raw units, divided by the rounding's gain.

    Along x: ``n(p + h x) - n(p - h x)`` (twice the one-sided difference where a side is
    unusable, as :func:`~rangesim.edges._differences.central_difference`), averaged
    ``[1 2 1] / 4`` along y at stride ``h``, times 4; along y likewise. Divided by
    :func:`~rangesim.edges._matching_scale.rounding_gain` ``(window, 2 h)`` (1 without a
    matcher), the share of a box-rounded crease's bend these normals see.

    Returns
    -------
    gx, gy : (3, H, W) float32
    """
    h = int(step)
    scale = np.float32(4 * 2 * h / rounding_gain(window or 1, 2 * h))
    gx = _smooth_along(central_difference(n, 0, pairs, h), 0, h)
    gy = _smooth_along(central_difference(n, 2, pairs, h), 1, h)
    gx *= scale
    gy *= scale
    return gx, gy


def predicted_noise_law(sigma_fp: np.ndarray | float, step: int, window: int | None = None) -> np.ndarray | float:
    """Std of one component of :func:`strided_sobel`'s strength under independent depth errors.

    ``3 sigma_fp / h`` raw Sobel units (module docstring), over the rounding gain.

    Examples
    --------
    >>> predicted_noise_law(0.25, 1), predicted_noise_law(0.5, 3)
    (0.75, 0.5)
    """
    return 3.0 * sigma_fp / float(step) / rounding_gain(window or 1, 2 * int(step))


def strength_noise(scan: Any, magnitude: np.ndarray, valid: np.ndarray, footprint: np.ndarray,
                   step: int, window: int | None) -> tuple[np.ndarray | float, str]:
    """The strength's noise sigma (raw Sobel units): per pixel from the noise model, or measured.

    ``scan.sigma`` (the noise model's prediction, least over 5 x 5) gives
    :func:`predicted_noise_law` per pixel (0 where nothing is predicted); a scan without it,
    or a block-matched one (``window``), the median of ``magnitude`` over valid pixels (every 4th row and column) over
    :data:`CHI4_MEDIAN`.

    Returns
    -------
    (sigma, source)
        ``source`` is ``"sigma"`` or ``"measured"``.
    """
    sig = predicted_noise(scan) if window is None else None
    if sig is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            sfp = sig / footprint
        sfp = np.where(np.isfinite(sfp), sfp, np.float32(0)).astype(np.float32)
        return (predicted_noise_law(sfp, step, window)).astype(np.float32), "sigma"
    sub = (slice(None, None, 4), slice(None, None, 4))
    m = magnitude[sub][valid[sub] & np.isfinite(magnitude[sub])]
    return (float(np.median(m)) / CHI4_MEDIAN if m.size else 0.0), "measured"


def nan_gaussian(a: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing of an (H, W) image by normalised convolution (truncated at 2.5
    sigma); NaN stays NaN and never leaks."""
    if sigma <= 0:
        return a
    ok = np.isfinite(a)
    wgt = ndimage.gaussian_filter(ok.astype(np.float32), sigma, truncate=2.5)
    out = ndimage.gaussian_filter(np.where(ok, a, np.float32(0)).astype(np.float32), sigma, truncate=2.5)
    with np.errstate(invalid="ignore", divide="ignore"):
        out /= wgt
    out[~ok] = np.nan
    return out
