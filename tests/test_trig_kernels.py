"""The compiled arc tangents of the edge detectors against NumPy's (float64, then float32)."""
from __future__ import annotations

import numpy as np

from rangesim.edges._trig import bend_degrees, half_atan2


def _values(seed: int, shape=(256, 256)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    scale = rng.choice([1e-6, 1e-3, 1.0, 10.0, 1e3, 1e6], shape)
    return (rng.standard_normal(shape) * scale).astype(np.float32)


def test_half_atan2_is_numpys_to_the_last_bit_of_float32():
    """Each result is the float64 arc tangent rounded to float32, in every quadrant and at every
    scale, so within NumPy's own float32 arctan2's error of it (the C library's atan2f, 1 ulp;
    NumPy's AVX-512 SIMD path, measured 2 ulp on an Intel Xeon VM; 4 ulp allowed)."""
    y, x = _values(0), _values(1)
    got = half_atan2(y, x)
    exact = (0.5 * np.arctan2(y.astype(np.float64), x.astype(np.float64))).astype(np.float32)
    assert got.dtype == np.float32 and got.shape == y.shape
    assert np.array_equal(got, exact)
    numpy32 = np.float32(0.5) * np.arctan2(y, x)
    ulp = np.spacing(np.abs(numpy32))
    assert np.all(np.abs(got - numpy32) <= 4 * ulp)


def test_half_atan2_zeros_infinities_and_nan_as_c():
    y = np.array([[0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 1.0, -1.0, np.nan, 1.0, 0.0, np.inf, 2.0]], np.float32)
    x = np.array([[0.0, 0.0, -0.0, -0.0, 0.0, 0.0, -0.0, -0.0, 1.0, np.nan, -1.0, 1.0, np.inf]], np.float32)
    got = half_atan2(y, x)
    ref = np.float32(0.5) * np.arctan2(y, x)
    assert np.array_equal(np.isnan(got), np.isnan(ref))
    ok = ~np.isnan(ref)
    assert np.array_equal(got[ok], ref[ok])
    assert np.array_equal(np.signbit(got[ok]), np.signbit(ref[ok]))


def test_bend_degrees_is_the_angle_between_two_slopes():
    """atan(t + h) - atan(t - h) in degrees: a slope change from -1 to 1 is a right angle;
    each arc tangent is the float64 one rounded to float32, so every value is NumPy's float32
    expression but for the last bits of each arc tangent (NumPy's float32 arctan: 1 ulp from
    the C library, a few on its AVX-512 SIMD path; 4 allowed)."""
    t, h = _values(2), np.abs(_values(3))
    got = bend_degrees(t, h)
    a = np.arctan((t + h).astype(np.float64)).astype(np.float32)
    b = np.arctan((t - h).astype(np.float64)).astype(np.float32)
    assert np.array_equal(got, (a - b) * (np.float32(180.0) / np.float32(np.pi)))
    ref = np.degrees(np.arctan(t + h) - np.arctan(t - h))
    # each arc tangent within 4 ulp of pi / 2 (float32), the difference rounded once more
    tol = np.degrees(8 * np.spacing(np.float32(np.pi / 2))) + np.spacing(np.abs(ref))
    assert np.all(np.abs(got - ref) <= tol)
    assert bend_degrees(np.zeros((1, 1), np.float32), np.ones((1, 1), np.float32))[0, 0] == np.float32(90.0)
    assert np.isnan(bend_degrees(np.full((1, 1), np.nan, np.float32), np.ones((1, 1), np.float32))[0, 0])


def test_above_tan_half_orders_as_the_tangent():
    """mag > tan(threshold / 2) decided through the arc tangent: the same answer as NumPy's
    but within a float32 ulp of the tangent, where rounding decides; NaN is never above."""
    from rangesim.edges._trig import above_tan_half
    rng = np.random.default_rng(4)
    thr = rng.uniform(15.0, 89.0, (128, 128)).astype(np.float32)
    tan_half = np.tan(np.radians(thr) / 2)
    mag = (tan_half * rng.uniform(0.5, 1.5, thr.shape)).astype(np.float32)
    mag[:4] = tan_half[:4]                                    # exact ties
    mag[4, :10] = np.nan
    got = above_tan_half(mag, thr)
    ref = mag > tan_half
    close = np.abs(mag - tan_half) <= 2 * np.spacing(tan_half)
    assert np.array_equal(got[~close], ref[~close])
    assert not got[4, :10].any()
    assert ref.mean() > 0.3 and (~ref).mean() > 0.3
