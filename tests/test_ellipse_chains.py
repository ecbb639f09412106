"""Chain hypotheses of the model-free ellipse finder (rangesim.features._ellipse_chains): edge
pixels traced into ordered chains, cut into arc pieces, fitted and grown over whole pieces.

Small synthetic masks whose shapes are known exactly: a circle with a tangent line, two arcs
meeting at a corner, a partial ellipse, a closed loop.
"""
from __future__ import annotations

import numpy as np
import pytest

from rangesim.core.conics import ellipse_from_conic
from rangesim.features._arc_ellipses import free_ellipses
from rangesim.features._edge_points import edge_points
from rangesim.features._ellipse_chains import chain_hypotheses, chains, pieces


def _mask_points(mask):
    xy, theta, pix = edge_points(mask, return_pixels=True)
    return xy, theta, pix


def _draw(mask, x, y):
    mask[np.rint(y).astype(int), np.rint(x).astype(int)] = True


def _piece_sets(mask):
    xy, theta, pix = _mask_points(mask)
    order, start = chains(pix, theta)
    p_start, p_cnt, _ = pieces(xy, order, start)
    return xy, [order[s:s + n] for s, n in zip(p_start, p_cnt)], order, start


def test_chains_are_ordered_walks():
    """Every chain steps between 8-neighbours only, and each point is in one chain at most."""
    mask = np.zeros((80, 80), bool)
    t = np.linspace(0, 2 * np.pi, 800)
    _draw(mask, 40 + 25 * np.cos(t), 40 + 18 * np.sin(t))
    xy, theta, pix = _mask_points(mask)
    order, start = chains(pix, theta)
    assert len(np.unique(order)) == len(order)
    # a closed loop: mostly one chain (a staircase pixel whose step to its neighbour runs along
    # the normal is not linked, and a walk passes it by: 21 of 168 here)
    assert len(order) >= 0.85 * len(xy)
    for c in range(len(start) - 1):
        p = pix[order[start[c]:start[c + 1]]]
        assert np.all(np.abs(np.diff(p, axis=0)).max(1) == 1)


def test_tangent_line_cuts_the_chain():
    """A circle with a line tangent to it: no piece runs from the circle's far side onto the
    line beyond the tangent point."""
    mask = np.zeros((90, 130), bool)
    t = np.linspace(0, 2 * np.pi, 1000)
    _draw(mask, 40 + 20 * np.cos(t), 40 + 20 * np.sin(t))
    x = np.linspace(40, 120, 400)
    _draw(mask, x, np.full_like(x, 60.0))
    xy, sets, _, _ = _piece_sets(mask)
    assert sets
    for s in sets:
        p = xy[s]
        on_line = (np.abs(p[:, 1] - 60) <= 0.6) & (p[:, 0] >= 52)  # 2.5 px or more off the circle
        on_circle = p[:, 1] <= 52  # the circle's upper part, far from the tangent point (40, 60)
        assert not (on_line.any() and on_circle.any())


def test_corner_splits_a_chain():
    """Two arcs meeting at a right-angled corner end up in different pieces."""
    mask = np.zeros((100, 100), bool)
    t = np.linspace(np.pi, 1.5 * np.pi, 400)  # the arc from (20, 50) up to (50, 20)
    _draw(mask, 50 + 30 * np.cos(t), 50 + 30 * np.sin(t))
    t = np.linspace(0.5 * np.pi, np.pi, 400)  # from (50, 20) on to (80, 50) bending the other way
    _draw(mask, 80 + 30 * np.cos(t), 20 + 30 * np.sin(t))
    xy, sets, _, _ = _piece_sets(mask)
    assert sets
    for s in sets:
        p = xy[s]
        assert not ((p[:, 0] <= 45).any() and (p[:, 0] >= 55).any())


@pytest.mark.parametrize("angle", [0.3, -1.1])
def test_partial_ellipse_recovered(angle):
    """40 % of an ellipse, on its own: a chain hypothesis and the finder recover its centre
    within 0.3 px (the points at their true positions, traced on their pixels)."""
    c, (a, b) = np.array([60.0, 55.0]), (30.0, 18.0)
    t = np.arange(0.4, 0.4 + 0.4 * 2 * np.pi, 0.05)
    ca, sa = np.cos(angle), np.sin(angle)
    x = c[0] + a * np.cos(t) * ca - b * np.sin(t) * sa
    y = c[1] + a * np.cos(t) * sa + b * np.sin(t) * ca
    pix = np.column_stack([np.rint(x), np.rint(y)]).astype(np.int64)
    _, first = np.unique(pix[:, 1] * 1000 + pix[:, 0], return_index=True)
    first = np.sort(first)
    pix, xy = pix[first], np.column_stack([x, y])[first]
    # the normals of the true ellipse at the points
    tx, ty = -a * np.sin(t) * ca - b * np.cos(t) * sa, -a * np.sin(t) * sa + b * np.cos(t) * ca
    theta = (np.arctan2(ty, tx) + np.pi / 2)[first]
    conics, n = chain_hypotheses(xy, theta, pix)
    assert len(conics) > 0
    centres = np.array([ellipse_from_conic(q)[0] for q in conics])
    assert np.hypot(*(centres - c).T).min() <= 0.3
    found = free_ellipses(xy, theta, pixels=pix, min_support=0.3, hypotheses="chains")
    assert len(found) == 1
    (cx, cy), (fa, fb), _ = ellipse_from_conic(found[0][0])
    assert np.hypot(cx - c[0], cy - c[1]) <= 0.3
    assert abs(fa - a) <= 0.5 and abs(fb - b) <= 0.5


def test_empty_and_unknown():
    order, start = chains(np.zeros((0, 2), np.int64), np.zeros(0))
    assert len(order) == 0 and list(start) == [0]
    with pytest.raises(ValueError, match="hypotheses"):
        free_ellipses(np.zeros((30, 2)), np.zeros(30), hypotheses="nope")
    with pytest.raises(ValueError, match="outlines=False"):  # the outlines are all that generator fits
        free_ellipses(np.zeros((30, 2)), np.zeros(30), hypotheses="outlines", outlines=False)


def test_links_join_the_arcs_of_one_ellipse_across_gaps():
    """An ellipse drawn with four 3 px gaps (four chains) and a line beside it: the pieces
    linked end to end make one path holding the four arcs and not the line, and its fit
    is the ellipse."""
    from rangesim.features._ellipse_chains_kernels import link_groups

    mask = np.zeros((200, 200), bool)
    t = np.linspace(0, 2 * np.pi, 4000)
    keep = np.ones(len(t), bool)
    for a in (0.3, 1.9, 3.5, 5.1):
        keep &= ~((t > a) & (t < a + 0.05))
    _draw(mask, 100 + 60 * np.cos(t[keep]), 100 + 45 * np.sin(t[keep]))
    x = np.linspace(150, 190, 200)
    _draw(mask, x, np.full_like(x, 150.0))
    xy, theta, pix = _mask_points(mask)
    order, start = chains(pix, theta)
    p_start, p_cnt, _ = pieces(xy, order, start)
    pts, lo, n, _ = link_groups(xy, order, p_start, p_cnt, 0.5, 12.0, np.cos(np.deg2rad(30)), 8, np.array([3]))
    on_ellipse = np.abs(np.hypot((xy[:, 0] - 100) / 60, (xy[:, 1] - 100) / 45) - 1) < 0.05
    whole = [pts[a:a + m] for a, m in zip(lo, n)]
    best = max(whole, key=len)
    arcs = [order[a:a + m] for a, m in zip(p_start, p_cnt) if on_ellipse[order[a:a + m]].all()]
    assert len(arcs) >= 4 and set(best) == set(np.concatenate(arcs))  # the four arcs, not the line
    conics, _ = chain_hypotheses(xy, theta, pix)
    centres = np.array([ellipse_from_conic(q)[0] for q in conics])
    assert np.hypot(*(centres - 100.0).T).min() <= 0.3
