"""The gradient detector's compiled kernels give the same bits as the array forms they replace
(issue 14 item 8: speed without changing any output)."""
from __future__ import annotations

import numpy as np
import pytest

from rangesim.edges._gradient import (
    _exact_at,
    _hessian_direction,
    _pairs_arg,
    _plain_dense,
    _plain_strided,
    _scale_and_magnitude,
    _smooth5_at,
    _streamed_responses,
    _taps5,
    _validity5_at,
    second_differences,
)
from rangesim.edges._noise import local_noise_scale, raised_noise_threshold, raised_threshold
from rangesim.edges._pair_kernels import search_gaps
from rangesim.edges._trig import half_atan2
from tests.gradient_reference import _hessian, _second_differences_at, _to_direction


def _random_depth(rng: np.random.Generator, shape: tuple[int, int], holes: float) -> np.ndarray:
    """Float32 depth with NaN holes and some +-0 (their signs must survive the sums)."""
    z = (rng.normal(size=shape) * rng.choice([1e-3, 1.0, 100.0])).astype(np.float32)
    z[rng.random(shape) < 0.1] = 0.0
    z[rng.random(shape) < 0.1] = -0.0
    z[rng.random(shape) < holes] = np.nan
    return z


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float32).view(np.int32)


@pytest.mark.parametrize("seed", range(6))
def test_exact_rule_kernel_matches_its_array_form(seed):
    rng = np.random.default_rng(seed)
    for _ in range(20):
        h, w = (int(v) for v in rng.integers(3, 30, 2))
        z = _random_depth(rng, (h, w), float(rng.choice([0.0, 0.1, 0.4])))
        pairs = rng.random((4, h, w)) < rng.choice([0.0, 0.05, 0.3])
        idx = np.flatnonzero(~np.isnan(z))
        for pp in (pairs, None):
            ref = _second_differences_at(np.pad(z, 1, constant_values=np.nan), pp, idx, w)
            out = [np.full((h, w), 7.0, np.float32) for _ in range(4)]
            _exact_at(z, *_pairs_arg(pp), *np.divmod(idx, w), 1, *out)
            for r, o in zip(ref, out):
                assert np.array_equal(_bits(r), _bits(o.ravel()[idx]))


@pytest.mark.parametrize("shape", [(3, 3), (5, 17), (31, 8), (64, 65)])
def test_dense_plain_operators_match_the_strided_loop(shape):
    z = _random_depth(np.random.default_rng(1), shape, 0.1)
    for d, r in zip(_plain_dense(z), _plain_strided(z, 1)):
        assert np.array_equal(_bits(d), _bits(r))


@pytest.mark.parametrize("seed", range(4))
def test_fused_hessian_direction_matches_its_three_steps(seed):
    rng = np.random.default_rng(seed)
    r = (rng.normal(size=(4, 37, 41)) * rng.choice([1e-3, 1.0, 50.0])).astype(np.float32)
    r[rng.random(r.shape) < 0.05] = np.nan
    r[rng.random(r.shape) < 0.05] = 0.0
    mag = np.abs(r[0])
    mag[rng.random(mag.shape) < 0.1] = np.nan
    direction, positive = _hessian_direction(*r, mag)
    mean, rad, minor, two_dxy, dxx_dyy = _hessian(*r)
    theta = half_atan2(two_dxy, dxx_dyy)
    _to_direction(theta, minor, mag)
    assert np.array_equal(_bits(direction), _bits(theta))
    assert np.array_equal(positive, np.where(minor, mean - rad, mean + rad) > 0)


def _second_differences_reference(z, pairs, skip):
    """second_differences as its array form had it: plain everywhere, the exact rule where the
    plain one is NaN or a pair lies in the 3 x 3 window, on valid pixels not skipped."""
    out = list(_plain_strided(z, 1))
    redo = np.isnan(out[0])
    if pairs is not None:
        any_pair = pairs.any(axis=0)
        pad = np.pad(any_pair, 1)
        for dr in range(3):
            for dc in range(3):
                redo |= pad[dr:dr + z.shape[0], dc:dc + z.shape[1]]
    redo &= ~np.isnan(z)
    if skip is not None:
        redo &= ~skip
    idx = np.flatnonzero(redo)
    p = np.pad(z, 1, constant_values=np.nan)
    for r, exact in zip(out, _second_differences_at(p, pairs, idx, z.shape[1])):
        r.ravel()[idx] = exact
    return out


@pytest.mark.parametrize("seed", range(6))
def test_second_differences_redo_pass_matches_its_array_form(seed):
    rng = np.random.default_rng(seed)
    for _ in range(10):
        h, w = (int(v) for v in rng.integers(1, 80, 2))
        z = _random_depth(rng, (h, w), float(rng.choice([0.0, 0.02, 0.3])))
        pairs = rng.random((4, h, w)) < rng.choice([0.0, 0.01, 0.2])
        skip = rng.random((h, w)) < 0.3
        for pp in (pairs, None):
            for sk in (skip, None):
                got = second_differences(z, pp, sk)
                ref = _second_differences_reference(z, pp, sk)
                keep = ~sk if sk is not None else np.ones((h, w), bool)   # skipped: undefined
                for g, r in zip(got, ref):
                    assert np.array_equal(_bits(g)[keep], _bits(r)[keep])


@pytest.mark.parametrize("seed", range(4))
def test_raised_noise_threshold_matches_scale_then_raise(seed):
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(10, 90, 2))
    sigma = (rng.random((h, w)) * rng.choice([0.01, 1.0])).astype(np.float32)
    sigma[rng.random((h, w)) < 0.1] = np.nan
    sigma[rng.random((h, w)) < 0.05] = 0.0
    footprint = (0.2 + rng.random((h, w))).astype(np.float32)
    valid = rng.random((h, w)) < 0.9
    for cap in (89.0, None, 1.0):
        ref = raised_threshold(20.0, local_noise_scale(None, valid, footprint, sigma), cap)
        got = raised_noise_threshold(None, valid, footprint, 20.0, cap, sigma)
        assert np.array_equal(_bits(np.broadcast_to(got, (h, w))), _bits(np.broadcast_to(ref, (h, w))))
    # too few usable pixels: the scalar threshold, as the scale's None
    assert raised_noise_threshold(None, np.zeros((h, w), bool), footprint, 20.0, 89.0, sigma) == 20.0


@pytest.mark.parametrize("sigma", [1.0, 0.8, 1.2])
def test_validity_smoothing_kernel_matches_smooth5_at(sigma):
    rng = np.random.default_rng(3)
    bad = rng.random((23, 31)) < 0.3
    idx = np.flatnonzero(rng.random(bad.shape) < 0.5)
    ref = _smooth5_at((~bad).astype(np.float32), sigma, idx)
    assert np.array_equal(_bits(_validity5_at(bad, idx, *_taps5(sigma))), _bits(ref))


def _search_reference(z, thr, shade, si, sj, sx, sy, max_search):
    """The array form of search_gaps: every active pixel one step further per round."""
    h, w = z.shape
    found_z, found_t = np.full(si.size, np.nan), np.full(si.size, np.nan)
    found_s, unlit_s = np.zeros(si.size), np.zeros(si.size, np.intp)
    active = np.arange(si.size)
    for s in range(1, max_search + 1):
        ri = si[active] + np.rint(sy[active] * s).astype(np.intp)
        rj = sj[active] + np.rint(sx[active] * s).astype(np.intp)
        inside = (ri >= 0) & (ri < h) & (rj >= 0) & (rj < w)
        active, ri, rj = active[inside], ri[inside], rj[inside]
        zq = z[ri, rj]
        hit = np.isfinite(zq)
        found_z[active[hit]] = zq[hit]
        found_t[active[hit]] = thr[ri[hit], rj[hit]]
        found_s[active[hit]] = s
        if shade is not None:
            first = ~hit & shade[ri, rj] & (unlit_s[active] == 0)
            unlit_s[active[first]] = s
        active = active[~hit]
    return found_z, found_t, found_s, unlit_s


@pytest.mark.parametrize("seed", range(4))
def test_gap_search_kernel_matches_its_array_form(seed):
    rng = np.random.default_rng(seed)
    h, w = 40, 50
    z = _random_depth(rng, (h, w), 0.6)
    thr = rng.random((h, w)).astype(np.float32)
    shade = rng.random((h, w)) < 0.5
    n = 300
    si, sj = rng.integers(0, h, n), rng.integers(0, w, n)
    # directions as the search makes them: the larger component +-1 (float32)
    v = rng.normal(size=(2, n)).astype(np.float32)
    scale = np.maximum(np.abs(v[0]), np.abs(v[1]))
    sx, sy = v[0] / scale, v[1] / scale
    sx[:20], sy[:20] = np.float32(0.5), np.float32(1.0)       # halves: rounded to even
    for sh in (shade, None):
        got = search_gaps(z, thr, shade if sh is not None else np.zeros((1, 1), bool), sh is not None,
                          si, sj, sx, sy, 30)
        ref = _search_reference(z, thr, sh, si, sj, sx, sy, 30)
        for g, r in zip(got, ref):
            assert np.array_equal(g, r, equal_nan=True)


@pytest.mark.parametrize("seed", range(4))
def test_streamed_responses_match_the_three_passes(seed):
    rng = np.random.default_rng(seed)
    for _ in range(5):
        h, w = (int(v) for v in rng.integers(3, 70, 2))
        z = _random_depth(rng, (h, w), float(rng.choice([0.0, 0.05, 0.3])))
        pairs = rng.random((4, h, w)) < rng.choice([0.0, 0.01, 0.2])
        scale = (0.5 + rng.random((h, w))).astype(np.float32)
        for pp in (pairs, None):
            mag, direction, positive = _streamed_responses(z, *_pairs_arg(pp), scale)
            resp = second_differences(z, pp)
            ref_mag = _scale_and_magnitude(*resp, scale)
            ref_dir, ref_pos = _hessian_direction(*resp, ref_mag)
            assert np.array_equal(_bits(mag), _bits(ref_mag))
            assert np.array_equal(_bits(direction), _bits(ref_dir))
            assert np.array_equal(positive, ref_pos)
