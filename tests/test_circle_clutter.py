"""The circle finder's claim loop with two circles internally tangent: where they meet both
edges run through the same pixels, so a circle holding a smaller one tangent inside it (a
tapped hole's rim around the crest outline seen down the hole) keeps the points it shares
with it, while a duplicate, a ghost across two rims and a smaller circle inside a kept one
still lose theirs."""
from __future__ import annotations

import numpy as np

from rangesim.features._circle_kernels import claim_pairs


def _ring(c, r, a0, a1, n_per_px=2.0):
    """Points on the arc a0..a1 (radians) of the circle (c, r), about n_per_px per px of arc."""
    a = np.linspace(a0, a1, max(int((a1 - a0) * r * n_per_px), 2), endpoint=False)
    return np.column_stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)])


def _claim(circles, members, xy):
    """claim_pairs on candidates (centre, radius) in the given order, each with the points
    ``members[k]`` (indices into ``xy``), no labels, no split siblings, min_support 0.5."""
    starts = np.concatenate([[0], np.cumsum([len(m) for m in members])]).astype(np.int64)
    points = np.concatenate(members).astype(np.int64)
    c = np.array([ci for ci, _ in circles], float)
    r = np.array([ri for _, ri in circles], float)
    return list(claim_pairs(np.arange(len(r), dtype=np.int64), starts, points, np.zeros(0, np.uint8),
                            xy[:, 0].copy(), xy[:, 1].copy(), c[:, 0].copy(), c[:, 1].copy(), r, 0.5, 3, 0,
                            np.full(len(r), -1, np.int64)))


def _coverage(pts, c, r):
    """Fraction of round(2 pi r) angular bins holding a point, as the claim loop counts."""
    n = round(2 * np.pi * r)
    a = np.mod(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]), 2 * np.pi)
    return len(np.unique(np.floor(a / (2 * np.pi) * n))) / n


def _inliers(xy, c, r, band=1.0):
    return np.flatnonzero(np.abs(np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) - r) <= band)


def test_outer_circle_keeps_the_points_where_a_kept_inner_one_meets_it():
    # inner circle r 20 complete; outer r 23, centre 3 px away: tangent at angle 0, apart by
    # 6 px opposite. The outer is drawn only over its wide side (|a| > 0.55 pi): alone that is
    # 0.45 of it; the part within 1 px of the inner (|a| < ~0.27 pi) is the inner's.
    ci, ri = np.array([60.0, 60.0]), 20.0
    co, ro = np.array([57.0, 60.0]), 23.0
    xy = np.vstack([_ring(ci, ri, 0, 2 * np.pi), _ring(co, ro, 0.55 * np.pi, 1.45 * np.pi)])
    inner, outer = _inliers(xy, ci, ri), _inliers(xy, co, ro)
    shared = np.intersect1d(inner, outer)
    assert len(shared) > 10  # they meet
    own = np.setdiff1d(outer, inner)
    # the outer's own points alone cover less than half of it, with the shared ones more
    assert _coverage(xy[own], co, ro) < 0.5 < _coverage(xy[outer], co, ro)
    assert _claim([(ci, ri), (co, ro)], [inner, outer], xy) == [0, 1]


def test_smaller_circle_inside_a_kept_one_still_loses_the_shared_points():
    # the same pair the other way round: a candidate inside a kept circle, meeting it, that
    # keeps too little of its own (a circle averaging a rim and the edge inside it lies so)
    co, ro = np.array([57.0, 60.0]), 23.0
    ci, ri = np.array([60.0, 60.0]), 20.0
    xy = np.vstack([_ring(co, ro, 0, 2 * np.pi), _ring(ci, ri, 0.55 * np.pi, 1.45 * np.pi)])
    outer, inner = _inliers(xy, co, ro), _inliers(xy, ci, ri)
    assert _claim([(co, ro), (ci, ri)], [outer, inner], xy) == [0]


def test_duplicates_and_crossing_circles_still_lose_the_shared_points():
    c, r = np.array([60.0, 60.0]), 20.0
    xy = _ring(c, r, 0, 2 * np.pi)
    # a near-duplicate 0.6 px larger, 0.4 px off: the same edge, not a second circle
    dup = (c + [0.4, 0.0], r + 0.6)
    assert _claim([(c, r), dup], [_inliers(xy, c, r), _inliers(xy, *dup)], xy) == [0]
    # a larger circle crossing the kept one (a ghost through its arc), not inside it
    ghost = (c + [12.0, 0.0], r + 2.0)
    xy2 = np.vstack([xy, _ring(ghost[0], ghost[1], 0.5 * np.pi, 1.5 * np.pi)])
    assert _claim([(c, r), ghost], [_inliers(xy2, c, r), _inliers(xy2, *ghost)], xy2) == [0]


def test_one_ring_is_not_two_tangent_circles():
    # a review's probe: a circle 0.9 px off a one-pixel ring with 1.2 px more radius passes the
    # tangency test (nearest gap 0.3 px, farthest 2.1 px), and every point it covers is the
    # ring's: it has no edge of its own where the two are apart, so it is no second circle
    c = np.array([60.0, 60.0])
    rng = np.random.default_rng(0)     # a ring one pixel wide: radii 19.5-20.5 px
    a, rr = rng.uniform(0, 2 * np.pi, 3000), 20.0 + rng.uniform(-0.5, 0.5, 3000)
    xy = np.column_stack([c[0] + rr * np.cos(a), c[1] + rr * np.sin(a)])
    for d, dr in [(0.9, 1.2), (1.0, 1.5), (0.9, 1.5)]:
        other = (c + [d, 0.0], 20.0 + dr)
        assert _claim([(c, 20.0), other], [_inliers(xy, c, 20.0), _inliers(xy, *other)], xy) == [0]
