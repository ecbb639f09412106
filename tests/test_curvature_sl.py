"""The curvature detector on block-matched scans: the shape operator from chords at the
matcher's scale (``rangesim.edges._curvature_chords``, issue 14).

A block matcher rounds every crease over its window; the ``extrema`` rule there measures the
change of the chord normals ``h = window // 2`` apart per length of surface instead of fitting
13 px quadrics, one-sided where a chord would cross a gap or a jump. The scans are the
analytic ones of ``tests/test_structured_light_edges.py``: disparity box-filtered over the 9 px
window, with the matcher's correlated noise, quantised to 1/8 px.
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.edges._curvature_chords import HIGH_FLOOR, chord_bend, chord_curvatures, form_sigma
from tests.test_edge_detectors import grid_scan, pinhole_rays, roof_distance, synthetic_roof
from tests.test_structured_light_edges import (
    WINDOW,
    assert_one_line_on_the_roof,
    block_matched,
    inner_mask,
    roof_bend_ratio,
    roof_beside_a_gap,
    xyz_stack,
)

F, Z0 = 400.0, 500.0
STEP = WINDOW // 2


def _cylinder(radius: float, concave: bool, size: int = 91):
    """A pinhole view of a cylinder whose axis runs along image y, its nearest (convex) or
    farthest (concave, seen from inside) line at depth Z0 through the image centre."""
    K, rays = pinhole_rays(size, F)
    c = Z0 - radius if concave else Z0 + radius
    dx, dz = rays[..., 0], rays[..., 2]
    a, b, cc = dx * dx + dz * dz, -2 * c * dz, c * c - radius * radius
    root = np.sqrt(b * b - 4 * a * cc)
    t = (-b + root) / (2 * a) if concave else (-b - root) / (2 * a)
    return grid_scan(rays * t[..., None], K)


@pytest.mark.parametrize("edge_deg", [0.0, 30.0, 90.0, 135.0])
@pytest.mark.parametrize("convex", [True, False])
def test_a_block_matched_crease_is_one_line_on_the_crease_of_its_type(edge_deg, convex):
    scan = block_matched(synthetic_roof(40.0, edge_deg, convex, size=91), noise_px=0.05,
                         seed=int(edge_deg) + convex)
    em = rs.edges.curvature(scan)
    assert em.params["scale"] == "sensor" and em.params["step"] == STEP
    found = em.mask & inner_mask(scan.shape)
    assert_one_line_on_the_roof(found, em.labels, scan, edge_deg, convex)


@pytest.mark.parametrize("bend_deg", [30.0, 60.0, 90.0])
@pytest.mark.parametrize("edge_deg", [0.0, 90.0, 30.0, 135.0])
def test_the_bend_is_the_creases_angle(bend_deg, edge_deg):
    """Noise-free: across an image axis the bend (normals 2h apart over the rounding's gain)
    is the crease's angle within 6 %. Across a diagonal the x and y chords each span less of
    the crease than 2h, and the bend reads up to 25 % high (a known anisotropy)."""
    scan = block_matched(synthetic_roof(bend_deg, edge_deg, True, size=91))
    bend = chord_bend(chord_curvatures(xyz_stack(scan), None, STEP, form_sigma(STEP)), STEP, WINDOW)
    ratio = roof_bend_ratio(scan, bend, edge_deg, bend_deg)
    if edge_deg in (0.0, 90.0):
        assert ratio == pytest.approx(1.0, abs=0.06)
    else:
        assert 1.0 <= ratio <= 1.3


@pytest.mark.parametrize("radius", [100.0, 200.0])
@pytest.mark.parametrize("concave", [False, True])
def test_a_cylinder_has_curvature_one_over_its_radius(radius, concave):
    """A block-matched cylinder (radius 80 / 160 footprints): the larger principal curvature is
    -1/R (convex) or +1/R (concave) within 10 % (median), across the axis (image x); the
    other is 0; it is no crease."""
    scan = block_matched(_cylinder(radius, concave))
    curv = chord_curvatures(xyz_stack(scan), None, STEP, form_sigma(STEP))
    inner = (slice(25, -25), slice(25, -25))
    sign = 1.0 if concave else -1.0
    assert np.median(curv["k"][inner]) * radius == pytest.approx(sign, rel=0.1)
    assert abs(np.median(curv["k_other"][inner])) * radius < 0.05
    assert np.median(curv["H"][inner]) * radius == pytest.approx(sign / 2, rel=0.1)
    direction = np.median(np.minimum(curv["direction"][inner], np.pi - curv["direction"][inner]))
    assert direction < np.radians(3)
    em = rs.edges.curvature(scan)
    assert em.params["scale"] == "sensor"
    assert not (em.mask & (em.labels != EdgeLabel.JUMP))[10:-10, 10:-10].any()


def test_a_block_matched_plane_has_no_creases():
    plane = synthetic_roof(0.0, 0.0, True, size=91)
    for seed in range(3):
        em = rs.edges.curvature(block_matched(plane, noise_px=0.05, seed=seed))
        assert not em.mask[12:-12, 12:-12].any()
        low, high = em.params["bend_threshold"]
        assert high >= HIGH_FLOOR and low < high


@pytest.mark.parametrize("convex", [True, False])
def test_a_crease_beside_a_gap_is_found(convex):
    """A dropout strip 3-5 px beside the crease (a ragged shadow): every 13 px block there holds
    a gap, so the block fits found nothing; the one-sided chords keep the crease."""
    scan = roof_beside_a_gap(convex)
    dist = roof_distance(scan, 0.0)
    em = rs.edges.curvature(scan)
    inner = inner_mask(scan.shape)
    found = em.mask & inner & (em.labels != EdgeLabel.JUMP)
    rows = np.unique(np.nonzero(inner & (dist <= 0.5))[0])
    assert np.unique(np.nonzero(found)[0]).size >= 0.9 * rows.size
    assert np.all(dist[found] <= 1.5)
    kind = EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE
    assert (em.labels[found] == kind).mean() >= 0.95
    blocks = rs.edges.curvature(scan, window=13)
    assert blocks.params["scale"] == "blocks"
    assert (blocks.mask & inner & (dist <= 1.5)).sum() < 0.2 * rows.size


def test_other_scans_and_settings_keep_the_block_fits():
    roof = synthetic_roof(40.0, 30.0, True)
    assert rs.edges.curvature(roof).params["scale"] == "blocks"
    matched = block_matched(synthetic_roof(40.0, 30.0, True, size=91))
    assert rs.edges.curvature(matched, window=13).params["scale"] == "blocks"
    assert rs.edges.curvature(matched, rule="both").params["scale"] == "blocks"
    em = rs.edges.curvature(matched, threshold=1e-3)
    assert em.params["scale"] == "sensor" and em.params["bend_threshold"] is None
