"""The sparse, banded circle finder on small synthetic edge maps: centres to a fraction of a pixel,
no circles on clutter, concentric rims, mask-only input (normals from the mask), the batched fits,
and work that follows the edge pixels (no timing assertions)."""
from __future__ import annotations

import numpy as np
import pytest

import rangesim.features as F
from rangesim.core.conics import fit_circle, fit_circles_batched
from rangesim.features._circle_votes import cast_votes, radius_bands, vote_table
from rangesim.features._edge_points import mask_normals


def _ring(mask, c, r, rng, cover=1.0, sigma=0.25):
    a = np.linspace(0, 2 * np.pi * cover, int(6 * np.pi * r), endpoint=False)
    x = np.rint(c[0] + r * np.cos(a) + rng.normal(0, sigma, len(a))).astype(int)
    y = np.rint(c[1] + r * np.sin(a) + rng.normal(0, sigma, len(a))).astype(int)
    ok = (x >= 0) & (x < mask.shape[1]) & (y >= 0) & (y < mask.shape[0])
    mask[y[ok], x[ok]] = True


def _segment(mask, p, q):
    s = np.linspace(0, 1, int(np.hypot(*(np.subtract(q, p)))) * 2)
    mask[np.rint(p[1] + s * (q[1] - p[1])).astype(int), np.rint(p[0] + s * (q[0] - p[0])).astype(int)] = True


@pytest.fixture(scope="module")
def scene():
    """160 x 160: three circles (one with a 25 % gap), two crossing segments, noise pixels."""
    rng = np.random.default_rng(7)
    m = np.zeros((160, 160), bool)
    truth = [((40.3, 45.7), 18.4, 1.0), ((110.6, 52.2), 30.2, 0.75), ((70.1, 120.4), 9.3, 1.0)]
    for c, r, cover in truth:
        _ring(m, c, r, rng, cover)
    _segment(m, (5, 150), (150, 95))
    _segment(m, (20, 85), (150, 150))
    m[rng.integers(0, 160, 15), rng.integers(0, 160, 15)] = True
    return m, truth


def test_circles_found_to_a_fraction_of_a_pixel(scene):
    mask, truth = scene
    found = F.circles(mask, radii=(5, 40))
    assert len(found) == len(truth)
    for c, r, _ in truth:
        d = min(np.hypot(*(np.array(f.center) - c)) for f in found)
        best = min(found, key=lambda f: np.hypot(*(np.array(f.center) - c)))
        assert d <= 0.3, (c, d)
        assert abs(best.radius - r) <= 0.3
        assert best.support >= 0.5 and best.residual <= 0.8


def test_no_circles_on_clutter():
    rng = np.random.default_rng(3)
    m = np.zeros((200, 200), bool)
    for _ in range(12):
        p, q = rng.uniform(0, 199, 2), rng.uniform(0, 199, 2)
        _segment(m, p, q)
    m[rng.integers(0, 200, 200), rng.integers(0, 200, 200)] = True
    # an arc of a fifth of a circle is an arc, not a circle
    _ring(m, (100, 100), 25, rng, cover=0.2)
    assert F.circles(m, radii=(5, 60)) == []


def test_concentric_rims_each_found():
    rng = np.random.default_rng(1)
    m = np.zeros((120, 120), bool)
    for r in (12.0, 24.0):
        _ring(m, (60.4, 59.6), r, rng)
    found = sorted(F.circles(m, radii=(5, 40)), key=lambda f: f.radius)
    assert [round(f.radius) for f in found] == [12, 24]
    assert all(np.hypot(f.center[0] - 60.4, f.center[1] - 59.6) <= 0.3 for f in found)


def test_mask_normals_are_radial_on_a_circle():
    rng = np.random.default_rng(0)
    m = np.zeros((80, 80), bool)
    _ring(m, (40, 40), 20, rng, sigma=0.0)
    rows, cols = np.nonzero(m)
    n = mask_normals(m, rows, cols)
    radial = np.arctan2(rows - 40, cols - 40)
    dev = np.degrees(np.arccos(np.abs(np.cos(n - radial))))
    assert np.median(dev) <= 5 and np.percentile(dev, 95) <= 15


def test_fit_circles_batched_matches_fit_circle():
    rng = np.random.default_rng(2)
    groups, pts = [], []
    for g, (c, r) in enumerate((((10.0, -3.0), 7.0), ((50.0, 40.0), 25.0))):
        a = rng.uniform(0, 1.5 * np.pi, 60)
        pts.append(np.column_stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)]) + rng.normal(0, 0.2, (60, 2)))
        groups.append(np.full(60, g))
    xy, grp = np.concatenate(pts), np.concatenate(groups)
    c, r, rms = fit_circles_batched(xy, grp, 2, np.array([[11.0, -2.0], [49.0, 41.0]]), np.array([6.0, 24.0]),
                                    iterations=8)
    for g in range(2):
        c1, r1, rms1 = fit_circle(xy[grp == g])
        assert np.allclose(c[g], c1, atol=1e-6) and abs(r[g] - r1) < 1e-6 and abs(rms[g] - rms1) < 1e-6


def test_votes_follow_edge_pixels_and_angular_step_is_prop_to_one_over_r():
    bands = radius_bands((512, 512), (5, 80), 1.0, 0.25)
    assert [b.lo for b in bands] == [5, 10, 20, 40] and bands[-1].hi == 80
    assert all(b.cell >= 0.25 * b.lo for b in bands)
    # wider angle window: offsets k * cell / r, so a sample at radius r gets about 2 tol r / cell + 1
    rc, rs, *_, r = vote_table(bands, np.deg2rad(20))
    a = np.arctan2(rs, rc)
    for rr in np.unique(r):
        step = np.diff(np.sort(a[r == rr]))
        if len(step):
            cell = next(b.cell for b in bands if b.lo <= rr < b.hi + 1e-9)
            assert np.allclose(step, cell / rr, rtol=1e-4)
    # the accumulator holds 2 votes per point and column, whatever the image size
    xy = np.array([[100.0, 100.0], [300.0, 200.0]])
    m = len(vote_table(bands, np.deg2rad(4))[0])
    acc, _ = cast_votes(xy, np.zeros(2), bands, np.deg2rad(4))
    assert acc.sum() == 2 * 2 * m


def test_arcs_still_found():
    rng = np.random.default_rng(5)
    m = np.zeros((120, 120), bool)
    _ring(m, (60.0, 62.0), 20.0, rng, cover=0.35)
    _ring(m, (30.0, 30.0), 10.0, rng)
    _segment(m, (5, 110), (110, 100))
    arcs = F.arcs(m, radii=(5, 40))
    assert any(np.hypot(a.center[0] - 60, a.center[1] - 62) <= 1.0 and abs(a.radius - 20) <= 1.0 for a in arcs)
    assert all(a.coverage < 0.5 for a in arcs)


def test_ring_lookup_matches_brute_force():
    # the compiled ring gather returns exactly the edge pixels whose integer offset from the
    # rounded centre has a length within width + 1.25 of r (row by row, clipped to the image)
    from rangesim.features._circle_kernels import _gather
    rng = np.random.default_rng(11)
    H, W = 60, 80
    mask = rng.random((H, W)) < 0.3
    index = np.full(H * W, -1, np.int32)
    flat = np.flatnonzero(mask)
    index[flat] = np.arange(flat.size, dtype=np.int32)
    rows, cols = np.divmod(flat, W)
    out = np.empty(flat.size, np.int64)
    for cx, cy, r, width in ((40.3, 30.6, 12.2, 1.5), (2.0, 57.4, 9.0, 3.0), (70.5, 5.5, 30.0, 0.5), (10, 10, 0.4, 1.0)):
        n = _gather(cx, cy, r, width, index, H, W, out)
        d = np.hypot(cols - round(cx), rows - round(cy))
        expected = np.flatnonzero((d >= max(r - width - 1.25, 0)) & (d <= r + width + 1.25))
        assert sorted(out[:n].tolist()) == expected.tolist()


def test_line_peak_kernels_match_the_array_rule():
    # the accumulator's window maxima over the threshold (as maximum_filter with a constant 0
    # border finds them) and the greedy suppression, against the NumPy they replace
    from scipy import ndimage

    from rangesim.features._line_kernels import suppress_near, window_maxima

    rng = np.random.default_rng(4)
    acc = rng.poisson(2.0, (300, 180)).astype(np.uint64)
    acc[rng.integers(0, 300, 40), rng.integers(0, 180, 40)] += rng.integers(5, 40, 40).astype(np.uint64)
    for rd, ra, thr in ((3, 3, 6.0), (1, 2, 10.0), (0, 0, 4.0)):
        mx = ndimage.maximum_filter(acc, size=(2 * rd + 1, 2 * ra + 1), mode="constant")
        di, ai = np.nonzero((acc == mx) & (acc >= thr))
        got = window_maxima(acc, thr, rd, ra)
        assert np.array_equal(got[0], di) and np.array_equal(got[1], ai)
        order = np.argsort(-acc[di, ai], kind="stable")
        di, ai = di[order], ai[order]
        kept = []
        for j in range(len(di)):
            if len(kept) == 25:
                break
            if not any(abs(di[k] - di[j]) <= rd and abs(ai[k] - ai[j]) <= ra for k in kept):
                kept.append(j)
        assert suppress_near(di, ai, rd, ra, 25).tolist() == kept


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_growth_of_few_conics_is_the_batched_one(seed):
    # the circle finder's ellipse-end check grows its few circles with one compiled call
    # (grow_few); it must give the batched grow's conics (up to sign) and inliers
    from rangesim.features._arc_ellipses import DIRECTION_TOL_DEG, GROW_MARGIN_PX, grow
    from rangesim.features._conic_kernels import grow_few

    rng = np.random.default_rng(seed)
    a, b, c = 30.0, 18.0, np.array([60.0, 55.0])
    t = rng.uniform(0, 2 * np.pi, 400)
    xy = np.column_stack([c[0] + a * np.cos(t), c[1] + b * np.sin(t)]) + rng.normal(0, 0.2, (400, 2))
    theta = np.arctan2(a * np.sin(t), b * np.cos(t))  # the ellipse's normal direction
    xy = np.vstack([xy, rng.uniform(0, 120, (300, 2))])
    theta = np.concatenate([theta, rng.uniform(-np.pi, np.pi, 300)])
    # seeds: the osculating circle at the major axis's end, one at the minor's, one off anywhere
    centres = np.array([[c[0] + a - b * b / a, c[1]], [c[0], c[1] - b + a * a / b], [20.0, 100.0]])
    radii = np.array([b * b / a, a * a / b, 6.0])
    one = np.ones(3)
    conics = np.column_stack([one, 0 * one, one, -2 * centres[:, 0], -2 * centres[:, 1], (centres ** 2).sum(1) - radii ** 2])
    conics /= np.linalg.norm(conics, axis=1, keepdims=True)
    bands = (3.0, 1.5, 1.0)
    g0, ok0, h0, p0 = grow(conics, xy, theta, bands=bands)
    g1, ok1, h1, p1 = grow_few(conics, xy, np.cos(theta), np.sin(theta), np.array(bands),
                               float(np.cos(np.deg2rad(DIRECTION_TOL_DEG))), GROW_MARGIN_PX)
    assert np.array_equal(ok0, ok1) and ok0[0]
    sign = np.sign(np.sum(g0 * g1, axis=1))
    assert np.allclose(g0, sign[:, None] * g1, atol=1e-9)
    assert set(zip(h0.tolist(), p0.tolist())) == set(zip(h1.tolist(), p1.tolist()))
