"""Arc tangents of whole images, compiled (Numba) without calls into libm.

NumPy's float32 ``arctan`` and ``arctan2`` are SIMD only where the CPU has AVX-512; on
AVX2 machines they call the scalar C library per element, 13 and 27 ns each, so the
gradient detector's three full-image arc tangents cost more than its four operators
together there. Cephes' ``atan`` (range reduction to ``|x| <= 0.66`` and a 4/5 rational
function, double precision, relative error about 2e-16) has no calls or tables, so the
loops vectorise: the results, rounded to float32, are the correctly rounded arc tangents,
as glibc's ``atanf`` gives them but for rare last-bit differences.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["atan", "atan2", "half_atan2", "bend_degrees", "above_tan_half"]

_P0, _P1, _P2, _P3, _P4 = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
                           -1.228866684490136173410e2, -6.485021904942025371773e1)
_Q0, _Q1, _Q2, _Q3, _Q4 = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
                           4.853903996359136964868e2, 1.945506571482613964425e2)
_T3P8 = 2.41421356237309504880   # tan(3 pi / 8)
_MOREBITS = 6.123233995736765886130e-17  # pi / 2 - float(pi / 2)
_PIO2 = 1.57079632679489661923
_PIO4 = 0.78539816339744830962
_PI = 3.14159265358979323846


@numba.njit(cache=True, nogil=True, inline="always")
def atan(x):  # pragma: no cover - compiled
    """Arc tangent of a float64 (radians), Cephes' ``atan``: NaN gives NaN, +-inf +-pi / 2.

    Branch-free (selects, one reduction division), so that loops over it vectorise.
    """
    ax = abs(x)
    big = ax > _T3P8
    mid = ax > 0.66
    num = -1.0 if big else (ax - 1.0 if mid else ax)
    den = ax if big else (ax + 1.0 if mid else 1.0)
    r = num / den
    y = _PIO2 if big else (_PIO4 if mid else 0.0)
    extra = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    z = r * r
    p = (((_P0 * z + _P1) * z + _P2) * z + _P3) * z + _P4
    q = ((((z + _Q0) * z + _Q1) * z + _Q2) * z + _Q3) * z + _Q4
    return math.copysign(y + (r * (z * p / q) + extra + r), x)


@numba.njit(cache=True, nogil=True, inline="always")
def atan2(y, x):  # pragma: no cover - compiled
    """``atan2(y, x)`` of float64s (radians, in [-pi, pi]), as C's for finite, zero and NaN
    arguments (not for two infinities). Branch-free: ``y / x`` is +-inf on x = +-0."""
    r = atan(y / x)
    r = y if (y == 0.0 and x == 0.0) else r   # +-0 (then +-pi where x = -0)
    return r + math.copysign(_PI, y) if math.copysign(1.0, x) < 0.0 else r


@numba.njit(cache=True, nogil=True, error_model="numpy")
def half_atan2(y, x):  # pragma: no cover - compiled
    """``np.float32(0.5) * np.arctan2(y, x)`` of two float32 images (H, W), float32 (H, W)."""
    out = np.empty(y.shape, np.float32)
    yf, xf, of = y.ravel(), x.ravel(), out.ravel()
    for k in range(yf.size):
        of[k] = np.float32(0.5) * np.float32(atan2(np.float64(yf[k]), np.float64(xf[k])))
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def bend_degrees(t, half):  # pragma: no cover - compiled
    """``np.degrees(np.arctan(t + half) - np.arctan(t - half))`` of float32 images (H, W):
    the angle between slopes ``t -+ half``, degrees, float32 (H, W)."""
    out = np.empty(t.shape, np.float32)
    tf, hf, of = t.ravel(), half.ravel(), out.ravel()
    deg = np.float32(180.0) / np.float32(np.pi)   # np.degrees' float32 factor
    for k in range(tf.size):
        a = np.float32(atan(np.float64(tf[k] + hf[k])))
        b = np.float32(atan(np.float64(tf[k] - hf[k])))
        of[k] = (a - b) * deg
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def above_tan_half(mag, threshold_deg):  # pragma: no cover - compiled
    """``mag > np.tan(np.radians(threshold_deg) / 2)`` of float32 images (H, W), as
    ``atan(mag) > threshold / 2`` (the same order: tan rises on (-pi / 2, pi / 2)), (H, W) bool."""
    out = np.empty(mag.shape, np.bool_)
    mf, tf, of = mag.ravel(), threshold_deg.ravel(), out.ravel()
    half_rad = np.pi / 360.0
    for k in range(mf.size):
        of[k] = atan(np.float64(mf[k])) > np.float64(tf[k]) * half_rad
    return out
