"""Predicted depth noise of a block matcher: the disparity error grows with the surface's slant.

A block matcher compares a fronto-parallel ``w`` x ``w`` window of the image with the
reference. On a surface whose disparity changes by ``g`` px per pixel (its disparity
gradient), the disparity spreads by ``s = w g`` px across the window: the window's texture
no longer sits at one disparity, and the reference stretch it is compared with is
compressed or stretched by ``s`` px over the window. The error of the matched disparity
then has these terms, added in quadrature (px)::

    sigma_d^2 = sigma_m^2 + q^2 / 12 + (a s)^2 + (c s^2)^2,   q = 1 / subpixel_steps

``sigma_m`` the matching error on a fronto-parallel textured plane (the pattern's sampling
by the pixels and the sub-pixel fit; the shot and speckle noise of the dots add about 0.02 px
at the presets' exposures), ``q^2 / 12`` the rounding of the sub-pixel disparity to steps of
``q`` px (a uniform error of variance q^2 / 12 px^2, independent of the match: 0.036 px at
1/8 px, 0.29 px at whole pixels), ``a s`` the bias of weighting the window's texture unevenly
(its centre of texture is not its centre), ``c s^2`` the correlation peak's widening as the
stretch decorrelates the blocks. ``structured_light.match_sigma_px`` (s0) is the measured
fronto-parallel error at the presets' 1/8 px steps (:data:`CALIBRATION_STEPS`), rounding
included: sigma_m^2 = s0^2 - (1/8)^2 / 12, so that another ``subpixel_steps`` swaps that
rounding term for its own. For a plane n . X = p (camera frame, mm) the disparity
d = f b / z is affine in the pixel, with gradient b (n_x, n_y) / p, so
``g = |b| sqrt(n_x^2 + n_y^2) / |n . X|`` at each surface point X with normal n. Depth follows
as sigma_z = z^2 sigma_d / (f |b|).

The constants (``structured_light.match_sigma_px``, ``slant_linear``, ``slant_quadratic``)
were calibrated on scans of tilted planes (0-74 degrees about three axes at two distances per
preset), not on the parts the detectors are benchmarked on; ``tests/test_matching_noise.py``
holds the law on planes and the z-scores of a part.
"""
from __future__ import annotations

import numpy as np

__all__ = ["disparity_gradient", "matching_sigma_px", "matching_sigma_mm", "CALIBRATION_STEPS"]

#: sub-pixel steps per pixel at which the presets' ``match_sigma_px`` was measured (its
#: rounding part is (1 / CALIBRATION_STEPS)^2 / 12 px^2)
CALIBRATION_STEPS = 8


def disparity_gradient(points: np.ndarray, normals: np.ndarray, baseline: float) -> np.ndarray:
    """|grad d| (px per px) of the true surface at each point, from its tangent plane.

    Parameters
    ----------
    points : (..., 3) float
        Surface points, camera frame, mm (NaN where there is none).
    normals : (..., 3) float
        Unit surface normals there.
    baseline : float
        Camera-projector baseline, mm (either sign).

    Returns
    -------
    (...) float64

    Examples
    --------
    >>> p, n = np.array([[0.0, 0.0, 1000.0]]), np.array([[np.sin(0.5), 0.0, -np.cos(0.5)]])
    >>> round(float(disparity_gradient(p, n, 75.0)[0]), 6), round(75 * float(np.tan(0.5)) / 1000, 6)  # b tan(t) / z
    (0.040973, 0.040973)
    """
    p = np.asarray(points, np.float64)
    n = np.asarray(normals, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return abs(baseline) * np.hypot(n[..., 0], n[..., 1]) / np.abs(np.einsum("...k,...k->...", n, p))


def matching_sigma_px(gradient: np.ndarray, window: int, sigma_0: float, linear: float,
                      quadratic: float, subpixel_steps: int = CALIBRATION_STEPS) -> np.ndarray:
    """Disparity error std (px) for disparity gradients ``gradient`` (px per px); see the module docstring.

    Parameters
    ----------
    gradient : array
        Disparity gradient g of the surface, px per px.
    window : int
        Matching window, px (s = window g).
    sigma_0 : float
        Fronto-parallel error at 1/8 px steps, rounding included (``match_sigma_px``), px.
    linear, quadratic : float
        a (dimensionless) and c (per px) of the slant terms.
    subpixel_steps : int
        The disparity is rounded to 1 / subpixel_steps px.

    Examples
    --------
    >>> float(matching_sigma_px(np.array(0.0), 9, 0.08, 0.09, 0.036))
    0.08
    >>> round(float(matching_sigma_px(np.array(0.5), 9, 0.08, 0.09, 0.036)), 3)  # s = 4.5 px
    0.838
    >>> round(float(matching_sigma_px(np.array(0.0), 9, 0.08, 0.09, 0.036, subpixel_steps=1)), 3)  # + 1/12 px^2
    0.297
    """
    s = window * np.asarray(gradient, np.float64)
    # s0 holds the 1/8 px rounding it was measured with: swap that for this step's q^2 / 12
    matching = max(sigma_0**2 - 1.0 / (12.0 * CALIBRATION_STEPS**2), 0.0)
    rounding = 1.0 / (12.0 * float(subpixel_steps) ** 2)
    return np.sqrt(matching + rounding + (linear * s) ** 2 + (quadratic * s * s) ** 2)


def matching_sigma_mm(points: np.ndarray, normals: np.ndarray, focal_px: float, baseline: float,
                      window: int, sigma_0: float, linear: float, quadratic: float,
                      subpixel_steps: int = CALIBRATION_STEPS) -> np.ndarray:
    """Depth error std (mm) of a block matcher at surface ``points`` with ``normals``.

    sigma_z = z^2 sigma_d / (f |b|), with sigma_d (px) from :func:`matching_sigma_px` at the
    surface's :func:`disparity_gradient`. Shapes as :func:`disparity_gradient`; NaN where
    the point is.
    """
    g = disparity_gradient(points, normals, baseline)
    z = np.asarray(points, np.float64)[..., 2]
    sigma_d = matching_sigma_px(g, window, sigma_0, linear, quadratic, subpixel_steps)
    return z * z * sigma_d / (focal_px * abs(baseline))
