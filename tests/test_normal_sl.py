"""The normal detector on block-matched scans: the bend between chord normals one matching
window apart (``rangesim.edges._normal_sl``, issue 14).

A block matcher rounds every crease over its window and its errors are correlated over it;
there the normal detector compares the chord normals ``h = window // 2`` either side of a
pixel, over the share of a rounded crease they see, thresholded at multiples of the bend's
measured noise. The scans are the analytic ones of ``tests/test_structured_light_edges.py``:
disparity box-filtered over the 9 px window, with the matcher's correlated noise, quantised
to 1/8 px.
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.edges._normal_sl import K_HIGH, K_LOW, RAYLEIGH_MEDIAN, axis_bends, bend_noise
from tests.test_edge_detectors import roof_distance, synthetic_roof
from tests.test_structured_light_edges import (
    WINDOW,
    assert_one_line_on_the_roof,
    block_matched,
    inner_mask,
    roof_bend_ratio,
    roof_beside_a_gap,
    xyz_stack,
)

STEP = WINDOW // 2


@pytest.mark.parametrize("edge_deg", [0.0, 30.0, 90.0, 135.0])
@pytest.mark.parametrize("convex", [True, False])
def test_a_block_matched_roof_is_one_line_on_the_crease_of_its_type(edge_deg, convex):
    scan = block_matched(synthetic_roof(40.0, edge_deg, convex, size=91), noise_px=0.05,
                         seed=int(edge_deg) + convex)
    em = rs.edges.normal(scan)
    assert em.params["matching_window"] == WINDOW and em.params["step"] == STEP
    found = em.mask & inner_mask(scan.shape)
    assert_one_line_on_the_roof(found, em.labels, scan, edge_deg, convex)


@pytest.mark.parametrize("bend_deg", [30.0, 60.0, 90.0])
@pytest.mark.parametrize("edge_deg", [0.0, 90.0, 30.0, 135.0])
def test_the_bend_is_the_creases_angle(bend_deg, edge_deg):
    """Noise-free: across an image axis the bend (normals 2h apart over the rounding's gain)
    is the crease's angle within 12 %. Obliquely the farther-reaching diagonal pairs see more
    of the rounding than the gain allows for, and the bend reads 25-40 % high (a known
    anisotropy, as curvature's)."""
    scan = block_matched(synthetic_roof(bend_deg, edge_deg, True, size=91))
    ratio = roof_bend_ratio(scan, axis_bends(xyz_stack(scan), None, WINDOW)["strength"], edge_deg, bend_deg)
    if edge_deg in (0.0, 90.0):
        assert ratio == pytest.approx(1.0, abs=0.12)
    else:
        assert 1.0 <= ratio <= 1.4


@pytest.mark.parametrize("noise_px", [0.1, 0.2])
def test_the_noise_law_holds_on_a_block_matched_plane(noise_px):
    """On a plane each axis's bend is a Rayleigh variable of the measured s: about exp(-k^2/2)
    of it exceeds k s (within a factor 2.5 at 3 and 4 s: the matcher's errors are slightly
    heavy-tailed), and the high threshold is never reached."""
    plane = synthetic_roof(0.0, 0.0, True, size=161)
    scan = block_matched(plane, noise_px=noise_px, seed=1)
    b = axis_bends(xyz_stack(scan), None, WINDOW)
    inner = (slice(12, -12), slice(12, -12))
    s = bend_noise([a[inner] for a in b["angles"]], scan.valid[inner])
    bends = np.concatenate([a[inner].ravel() for a in b["angles"]])
    assert np.median(bends) / s == pytest.approx(RAYLEIGH_MEDIAN, rel=0.05)
    for k in (3.0, K_LOW):
        assert 0.4 * np.exp(-k * k / 2) <= (bends > k * s).mean() <= 2.5 * np.exp(-k * k / 2)
    assert not (b["strength"][inner] > K_HIGH * s).any()


def test_a_block_matched_plane_has_no_creases():
    plane = synthetic_roof(0.0, 0.0, True, size=91)
    for seed, noise_px in [(0, 0.05), (1, 0.1), (2, 0.2), (3, 0.3)]:
        em = rs.edges.normal(block_matched(plane, noise_px=noise_px, seed=seed))
        assert not em.mask[12:-12, 12:-12].any()
        low, high = em.params["threshold_deg"]
        noise = em.params["bend_noise_deg"]
        assert low == pytest.approx(max(15.0, K_LOW * noise))
        assert high == pytest.approx(max(20.0, K_HIGH * noise))


def test_an_explicit_threshold_or_window_and_laser_scans_keep_their_paths():
    matched = block_matched(synthetic_roof(40.0, 30.0, True, size=91))
    em = rs.edges.normal(matched, threshold_deg=25.0)
    assert em.params["threshold_deg"] == pytest.approx([25.0, 25.0])
    stencil = rs.edges.normal(matched, window=5)
    assert "matching_window" not in stencil.params and stencil.params["window"] == 5
    laser = rs.edges.normal(synthetic_roof(40.0, 30.0, True))
    assert "matching_window" not in laser.params


@pytest.mark.parametrize("convex", [True, False])
def test_a_crease_beside_a_gap_is_found_with_the_normal_at_the_pixel_standing_in(convex):
    """A dropout strip 3-5 px beside a 60 degree crease (a ragged shadow): the chords into the
    gap are unusable, the normal at the pixel stands in for that side, and the crease is still
    found along its length with its type (dropping such pairs loses it beside the gap)."""
    scan = roof_beside_a_gap(convex)
    dist = roof_distance(scan, 0.0)
    em = rs.edges.normal(scan)
    inner = inner_mask(scan.shape)
    found = em.mask & inner & (em.labels != EdgeLabel.JUMP) & (em.labels != rs.edges.RIM)
    rows = np.unique(np.nonzero(inner & (dist <= 0.5))[0])
    assert np.unique(np.nonzero(found & (dist <= 1.5))[0]).size >= 0.9 * rows.size
    kind = EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE
    assert (em.labels[found & (dist <= 1.5)] == kind).mean() >= 0.95


def test_window_and_block_planes_are_refused_together():
    with pytest.raises(ValueError, match="window and blocks=True"):
        rs.edges.normal(block_matched(synthetic_roof(40.0, 0.0, True, size=41)), window=5, blocks=True)


def test_thresholds_rise_where_the_noise_model_predicts_a_noisier_face():
    """Half a block-matched plane 8x noisier than the other: the measured noise is the scan's
    typical level, so the noisy half fills with false creases unless the scan's predicted
    ``sigma`` raises the thresholds there (its sigma / z over the median, never below 1)."""
    import dataclasses

    from tests.test_structured_light_edges import FB

    plane = synthetic_roof(0.0, 0.0, True, size=121)
    quiet, noisy = block_matched(plane, noise_px=0.05, seed=1), block_matched(plane, noise_px=0.4, seed=2)
    half = np.zeros(quiet.shape, bool)
    half[:, 60:] = True
    depth = np.where(half, noisy.depth, quiet.depth)
    spliced = dataclasses.replace(quiet, depth=depth, xyz=np.where(half[..., None], noisy.xyz, quiet.xyz))
    sigma = (depth.astype(np.float64) ** 2 * np.where(half, 0.4, 0.05) / FB).astype(np.float32)
    inner_noisy, inner_quiet = (slice(12, -12), slice(70, -12)), (slice(12, -12), slice(12, 50))
    without = rs.edges.normal(spliced).mask
    with_sigma = rs.edges.normal(dataclasses.replace(spliced, sigma=sigma)).mask
    assert without[inner_noisy].sum() > 100
    assert not with_sigma[inner_noisy].any() and not with_sigma[inner_quiet].any()
