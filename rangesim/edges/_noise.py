"""Noise-adaptive defaults of the edge detectors: the scan's own depth noise, and thresholds
raised above the noise level of a detector's strength.

Analysis layer: pure NumPy over arrays. Noise-adaptive defaults (every detector, same
estimator): :func:`estimate_depth_noise` measures the depth noise of the scan itself, in
pixel footprints: the median absolute deviation of the second difference
``z(i-1) - 2 z(i) + z(i+1)`` along rows and columns (valid triples only, each divided by
the centre's footprint), times 1.4826 (MAD to sigma of a Gaussian) over sqrt(6) (a second
difference of i.i.d. noise has variance 6 sigma^2).
Planes, smooth surfaces and the few percent of pixels on edges barely move the median, so
a noise-free scan measures ~0 and the White Scanner preset (0.25 footprints) its true
noise within a few percent. Below :data:`NOISE_FLOOR` a scan counts as noise-free and the
detectors use their noise-free defaults unchanged; above it they smooth / widen their
stencils (each documents how) and raise their threshold to
``max(noise-free default, k * median of the strength over valid pixels)``
(:func:`noise_threshold`): edges cover a few percent of the pixels, so the median is the
strength's noise level, and ``k`` (per detector, :data:`NOISE_K_GRADIENT` etc.) puts the
threshold ~4 noise standard deviations above it.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.edges._scan_access import pixel_geometry, scan_depth

__all__ = [
    "estimate_depth_noise", "noise_threshold", "NOISE_FLOOR", "NOISE_K_GRADIENT",
    "NOISE_K_NORMAL", "NOISE_K_PCL",
]

#: depth noise (pixel footprints) below which a scan counts as noise-free: the detectors'
#: noise-free defaults hold unchanged (a noise-free scan measures < 0.001)
NOISE_FLOOR = 0.05
#: threshold multiples of the median strength on noisy scans (see the module docstring):
#: the gradient's noise bend ``2 atan(max response)`` (an upper estimate, as if the
#: neighbour across responded as much; 3 medians ~ 4 sigma of the bend estimate), the
#: normal detector's pair angle (Rayleigh-like: median 1.18 scale, 4.5 medians ~ 5.3 scale,
#: ~1e-6 tail per pair) and PCL's Sobel
#: magnitude of the normal field (low hysteresis threshold; high scales with it)
NOISE_K_GRADIENT = 3.0
NOISE_K_NORMAL = 4.5
NOISE_K_PCL = 4.0


def estimate_depth_noise(scan: Any = None, z: np.ndarray | None = None,
                         fp: np.ndarray | None = None) -> float:
    """Depth noise of a scan, in pixel footprints (sigma_z / (z / f)).

    A scan that carries its noise model's prediction (``scan.sigma``, mm, as simulated
    laser-stripe scans do) gives the median of ``sigma / footprint`` over its valid pixels:
    the model knows its noise, correlated or not, which the data's second differences
    underestimate when neighbouring errors are correlated. Otherwise, from the data itself:
    the robust estimator of the module docstring: ``1.4826 * MAD / sqrt(6)`` of the second
    differences of depth along rows and columns over valid triples, each divided by the
    pixel footprint at its centre (median taken about 0: on a noise-free piecewise-smooth
    surface almost every second difference is ~0). Works on recorded scans too (footprint
    from :func:`~rangesim.edges._scan_access.pixel_geometry`); quantised depth (Kinect)
    counts as noise.

    Parameters
    ----------
    scan : RangeScan, optional
        Used for the depth and footprint unless ``z`` and ``fp`` are given.
    z : (H, W) float array, optional
        Depth, NaN where invalid.
    fp : (H, W) float array, optional
        Pixel footprint, mm.

    Returns
    -------
    float
        sigma in footprints (0.0 if fewer than 100 valid triples).

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> quiet = rs.datasets.plate_scan({"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": 0})
    >>> bool(rs.edges.estimate_depth_noise(quiet) < rs.edges.estimate_depth_noise(scan))
    True
    """
    if z is None:
        z, _ = scan_depth(scan)
    if fp is None:
        fp = pixel_geometry(scan, z).footprint
    predicted = getattr(scan, "sigma", None) if scan is not None else None
    if predicted is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.asarray(predicted, np.float64) / fp
        ratio = ratio[np.isfinite(ratio) & np.isfinite(z)]
        if ratio.size >= 100:
            return float(np.median(ratio))
    z = np.asarray(z, np.float32)
    # every 4th column / row is plenty for a median (and 4x cheaper)
    zc, fc = z[:, ::4], fp[:, ::4]
    zr, fr = z[::4], fp[::4]
    with np.errstate(invalid="ignore", divide="ignore"):
        d0 = (zc[:-2] - 2 * zc[1:-1] + zc[2:]) / fc[1:-1]
        d1 = (zr[:, :-2] - 2 * zr[:, 1:-1] + zr[:, 2:]) / fr[:, 1:-1]
    d = np.concatenate([d0[np.isfinite(d0)], d1[np.isfinite(d1)]])
    if d.size < 100:
        return 0.0
    return float(1.4826 * np.median(np.abs(d)) / np.sqrt(6.0))


def noise_threshold(strength: np.ndarray, valid: np.ndarray, default: float, k: float) -> float:
    """``max(default, k * median(strength))`` over valid pixels with a finite strength.

    The median is taken on every 4th row and column (1/16 of the pixels): plenty for a
    robust noise level, and 16 times cheaper than over a megapixel.
    """
    sub = (slice(None, None, 4), slice(None, None, 4))
    st = strength[sub][valid[sub] & np.isfinite(strength[sub])]
    if st.size == 0:
        return float(default)
    return float(max(default, k * float(np.median(st))))
