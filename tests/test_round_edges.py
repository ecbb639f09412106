"""A rim is one edge all round: the circle and ellipse finders keep only the supporting points
of a candidate's own edge kind (concave, or convex and occluding), so two rims' arcs seen as
one curve are no circle, and a rim with another edge a pixel away keeps its support."""
from __future__ import annotations

import numpy as np
import pytest

import rangesim.features as F
from rangesim.core.constants import EdgeLabel
from rangesim.edges import EdgeMap
from rangesim.features._edge_points import one_edge


def labelled_arcs(shape, arcs):
    """An EdgeMap of 1 px arcs: (centre, radius, start, stop (radians), label) each."""
    mask = np.zeros(shape, bool)
    labels = np.zeros(shape, np.uint8)
    for (cx, cy), r, a0, a1, label in arcs:
        a = np.linspace(a0, a1, int(8 * r * (a1 - a0)))
        x, y = np.rint(cx + r * np.cos(a)).astype(int), np.rint(cy + r * np.sin(a)).astype(int)
        mask[y, x] = True
        labels[y, x] = label
    return EdgeMap(mask=mask, labels=labels, strength=mask.astype(np.float32), method="test")


def test_one_edge_keeps_the_majority_kind_and_untyped_points():
    labels = np.array([EdgeLabel.JUMP, EdgeLabel.CONVEX, EdgeLabel.CONCAVE, EdgeLabel.NONE, EdgeLabel.JUMP])
    assert one_edge(labels, np.arange(5)).tolist() == [0, 1, 3, 4]
    assert one_edge(labels, np.array([2, 3, 4, 2])).tolist() == [2, 3, 2]  # concave the majority
    assert one_edge(labels, np.array([0, 1, 3])).tolist() == [0, 1, 3]     # one kind: all kept
    assert one_edge(None, np.array([2, 0])).tolist() == [2, 0]               # no labels


def test_two_rims_arcs_make_no_circle():
    # 40 % of a circle as a boss top's far arc (jump), 35 % as its foot's near arc (concave):
    # a bare mask holds a circle over 75 % of it; labelled, neither arc alone covers half
    c, r = (70.0, 60.0), 25.0
    em = labelled_arcs((130, 140), [(c, r, np.pi, np.pi + 0.40 * 2 * np.pi, EdgeLabel.JUMP),
                                    (c, r, 0.05, 0.05 + 0.35 * 2 * np.pi, EdgeLabel.CONCAVE)])
    assert [round(f.radius) for f in F.circles(em.mask, radii=(10, 40))] == [25]
    assert F.circles(em, radii=(10, 40)) == []
    ellipses = F.ellipses(em, remove_explained=False)
    assert all(np.hypot(*np.subtract(e.center, c)) > 2 for e in ellipses)


def test_rim_with_a_concave_edge_beside_it_is_found():
    # a hole's top rim (jump on the near half, convex on the far half) and, 0.8 px inside it,
    # where its wall meets the floor, a concave edge: the rim keeps its own points
    c, r = (70.0, 60.0), 25.0
    em = labelled_arcs((130, 140), [(c, r, 0.0, np.pi, EdgeLabel.JUMP), (c, r, np.pi, 2 * np.pi, EdgeLabel.CONVEX),
                                    (c, r - 0.8, 0.3, np.pi - 0.3, EdgeLabel.CONCAVE)])
    found = F.circles(em, radii=(10, 40))
    assert len(found) >= 1 and abs(found[0].radius - r) <= 0.5
    assert np.hypot(*np.subtract(found[0].center, c)) <= 0.5
    ellipses = F.ellipses(em, remove_explained=False)
    assert any(np.hypot(*np.subtract(e.center, c)) <= 0.5 and abs(np.mean(e.axes) - r) <= 0.5 for e in ellipses)


@pytest.mark.parametrize("seed", range(4))
def test_compiled_claim_loop_is_one_edge_and_the_free_coverage(seed):
    # the circles' claim loop (compiled) against its definition in NumPy: one_edge, then the
    # free points' angular coverage when any point was dropped or taken
    from rangesim.features._circle_kernels import claim
    from rangesim.features._edge_points import angular_coverage

    rng = np.random.default_rng(seed)
    n, K = 600, 12
    xy = rng.uniform(0, 100, (n, 2))
    labels = rng.choice(np.array([0, 1, 2, 3, 4], np.uint8), n, p=[0.1, 0.3, 0.2, 0.3, 0.1])
    c, r = rng.uniform(30, 70, (K, 2)), rng.uniform(5, 25, K)
    members = [np.sort(rng.choice(n, rng.integers(20, 120), replace=False)) for _ in range(K)]
    order = rng.permutation(K)
    used = np.zeros(n, bool)
    expected = []
    for j in order:
        pts = one_edge(labels, members[j])
        free = pts[~used[pts]]
        if len(free) < len(members[j]):
            d = xy[free] - c[j]
            if angular_coverage(np.arctan2(d[:, 1], d[:, 0]), round(2 * np.pi * r[j]))[0] < 0.3:
                continue
        used[pts] = True
        expected.append(j)
    starts = np.concatenate([[0], np.cumsum([len(m) for m in members])])
    got = claim(order.astype(np.int64), starts, np.concatenate(members).astype(np.int64), labels, xy[:, 0].copy(),
                xy[:, 1].copy(), c[:, 0].copy(), c[:, 1].copy(), r, 0.3, int(EdgeLabel.CONCAVE), int(EdgeLabel.NONE))
    assert got.tolist() == expected and 0 < len(expected) < K
