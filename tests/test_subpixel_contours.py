"""Occluding contours to a fraction of a pixel: the jump pixels' offsets, and the circles,
ellipses and lines fitted through them, against exact contours drawn into depth images."""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.edges._discontinuities import contour_offsets, find_discontinuities

F_PX = 400.0


def depth_scan(depth: np.ndarray) -> RangeScan:
    """A pinhole scan (f = 400 px) of a given depth image (mm), every pixel valid."""
    h, w = depth.shape
    K = np.array([[F_PX, 0, w / 2], [0, F_PX, h / 2], [0, 0, 1]])
    ii, jj = np.mgrid[0:h, 0:w]
    rays = np.stack([jj + 0.5, ii + 0.5, np.ones_like(depth)], -1) @ np.linalg.inv(K).T
    valid = np.ones((h, w), bool)
    return RangeScan(depth=depth, xyz=rays * depth[..., None], valid=valid, normal=np.full((h, w, 3), np.nan),
                     intensity=np.ones((h, w)), part=np.zeros((h, w), int), face=np.zeros((h, w), int),
                     status=np.zeros((h, w), np.uint8), meta={"K": K.tolist(), "sensor": {"name": "test"}})


def ellipse_inside(shape, center, axes, angle):
    """(H, W) bool: pixel centres (x = column, y = row) inside the ellipse."""
    ii, jj = np.mgrid[0:shape[0], 0:shape[1]]
    dx, dy = jj - center[0], ii - center[1]
    u = dx * np.cos(angle) + dy * np.sin(angle)
    v = -dx * np.sin(angle) + dy * np.cos(angle)
    return (u / axes[0]) ** 2 + (v / axes[1]) ** 2 <= 1.0


@pytest.mark.parametrize("angle_deg", [4.0, 17.0, 45.0, 71.0])
def test_offsets_put_a_straight_contour_where_it_is(angle_deg):
    # a near plane (300 mm) before the line x cos a + y sin a = d and a far one (330 mm)
    # beyond (an angle off the axes, so that the line crosses the pixel grid at every phase);
    # the occluding pixels' centres lie on average m / 2 px before the line
    # (m = max(|cos a|, |sin a|), 4-neighbours); moved by their offsets, on it
    a = np.radians(angle_deg)
    n = np.array([np.cos(a), np.sin(a)])
    ii, jj = np.mgrid[0:120, 0:120]
    d = 60.0 * (n[0] + n[1]) + 0.3141
    signed = jj * n[0] + ii * n[1] - d  # > 0 beyond the line (far)
    z = np.where(signed > 0, 330.0, 300.0).astype(np.float32)
    disc = find_discontinuities(z, threshold=np.full(z.shape, 5.0, np.float32))  # mm
    ei, ej = np.nonzero(disc.occluding)
    inner = (ei > 2) & (ei < 117) & (ej > 2) & (ej < 117)
    ei, ej = ei[inner], ej[inner]
    m = max(abs(n[0]), abs(n[1]))
    before = signed[ei, ej]
    after = before + disc.contour[ei, ej] @ n
    assert np.mean(before) == pytest.approx(-m / 2, abs=0.05)
    assert abs(np.mean(after)) <= 0.05
    # every offset points across the contour, towards the far side
    assert np.all(disc.contour[ei, ej] @ n > 0)
    # the far side's pixels (occluded) point back towards the near side
    oi, oj = np.nonzero(disc.occluded)
    assert np.all(disc.contour[oi, oj] @ n < 0)


def test_contour_offsets_of_rows_columns_and_diagonals():
    across = np.array([[2.0, 0.0], [0.0, -1.0], [1.0, 1.0], [0.0, 0.0]])
    np.testing.assert_allclose(contour_offsets(across), [[0.5, 0.0], [0.0, -0.5], [0.25, 0.25], [0.0, 0.0]],
                               atol=1e-6)
    # 8-neighbours reach |ux| + |uy| px across a diagonal: twice as far
    np.testing.assert_allclose(contour_offsets(across[2:3], connectivity=8), [[0.5, 0.5]], atol=1e-6)


@pytest.mark.parametrize("hole", [True, False])
def test_circle_through_jump_pixels_has_no_half_pixel_bias(hole):
    # a hole (far floor inside) or a boss (near top inside) whose rim is an exact circle
    center, r = (60.37, 57.81), 21.3
    inside = ellipse_inside((120, 124), center, (r, r), 0.0)
    near_inside = not hole
    z = np.where(inside == near_inside, 300.0, 330.0)
    scan = depth_scan(z)
    em = rs.edges.gradient(scan)
    jumps = em.label_mask(EdgeLabel.JUMP)
    assert jumps.sum() > 100 and jumps.sum() == em.mask.sum()  # a jump all round
    fits = {}
    for label, offset in (("centres", None), ("offsets", em.offset)):
        em.offset = offset
        found = rs.features.circles(em, radii=(10, 40))
        assert len(found) == 1
        fits[label] = found[0]
    # the jump pixels are the near side's: outside a hole's rim, inside a boss's
    bias = fits["centres"].radius - r
    assert abs(bias) >= 0.25 and np.sign(bias) == (1 if hole else -1)
    assert fits["offsets"].radius == pytest.approx(r, abs=0.1)
    # the centre: the same either way (the bias is radial), to the sampling of the rim
    assert np.hypot(*np.subtract(fits["offsets"].center, center)) <= 0.1


def test_ellipse_through_jump_pixels_has_no_half_pixel_bias():
    center, axes, angle = (70.6, 55.2), (31.4, 17.7), 0.4
    z = np.where(ellipse_inside((110, 140), center, axes, angle), 330.0, 300.0)
    em = rs.edges.gradient(depth_scan(z))
    found = rs.features.ellipses(em, remove_explained=False)
    assert len(found) == 1
    e = found[0]
    assert np.hypot(*np.subtract(e.center, center)) <= 0.1
    assert np.allclose(e.axes, axes, atol=0.1)
    em.offset = None
    e0 = rs.features.ellipses(em, remove_explained=False)[0]
    assert np.all(np.asarray(e0.axes) - axes >= 0.2)  # the pixel centres: half a pixel out


def test_line_fitted_through_jump_pixels_lies_on_the_contour():
    # the edge of a near plate over a far table, at 12 degrees to the rows
    a = np.radians(102.0)
    n = np.array([np.cos(a), np.sin(a)])  # normal of the edge, towards the far table
    ii, jj = np.mgrid[0:100, 0:160]
    d = 50.0 * n[1] + 80.0 * n[0] + 0.27
    z = np.where(jj * n[0] + ii * n[1] > d, 330.0, 300.0)
    segs = rs.features.lines(rs.edges.gradient(depth_scan(z)))
    longest = max(segs, key=lambda s: s.length)
    ends = np.array([longest.start, longest.end])
    assert longest.length > 120
    assert np.all(np.abs(ends @ n - d) <= 0.1)
