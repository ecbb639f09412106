"""line_fit on block-matched scans: the line test one matching window out (issue 14).

A block matcher rounds a crease over its window and its errors are correlated over it
(``rangesim.edges._line_fit_sl``): the lines through a pixel are drawn ``window`` px out,
skipping gaps and stopping at jumps, their bends are divided by the rounding's gain, the
tolerance is a multiple of the bend noise measured at that stride, and the bands are thinned
on the smoothed strength. These tests check the crease found and its label, the silence on
noisy planes, gaps skipped, and the tolerance law against the measured noise.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.edges._line_fit_sl import K_SL, bend_noise, min_reach, sl_tolerance
from rangesim.edges._matching_scale import rounding_gain
from rangesim.edges._noise import stride_gain
from tests.test_edge_detectors import grid_scan, pinhole_rays, roof_distance, synthetic_roof
from tests.test_structured_light_edges import (
    WINDOW,
    assert_one_line_on_the_roof,
    block_matched,
    inner_mask,
)

F, Z0 = 400.0, 500.0


def _creases(em):
    return em.mask & ((em.labels == EdgeLabel.CONVEX) | (em.labels == EdgeLabel.CONCAVE))




@pytest.mark.parametrize(("bend_deg", "edge_deg"), [
    (90.0, 0.0), (90.0, 30.0), (90.0, 90.0), (90.0, 135.0), (40.0, 0.0), (40.0, 90.0), (40.0, 135.0),
])
@pytest.mark.parametrize("convex", [True, False])
def test_a_block_matched_crease_is_found_on_the_crease_with_its_label(bend_deg, edge_deg, convex):
    """A crease rounded over the 9 px window, with the matcher's correlated noise: one line
    within 1.5 px of it (90 % of its length or more, no more than 130 %: non-maximum
    suppression along the compass axes leaves a few doubled pixels on oblique creases), of
    its type. (A crease between the compass axes is seen by its second least bent line at a
    shallow crossing, about a third of its bend at 22.5-30 degrees off an axis: 40 degrees
    is found on the axes and diagonals, 90 at any angle.)"""
    scan = block_matched(synthetic_roof(bend_deg, edge_deg, convex, size=91), noise_px=0.05,
                         seed=int(edge_deg) + convex)
    em = rs.edges.line_fit(scan)
    assert em.params["matching_window"] == WINDOW and em.params["median_stride"] == WINDOW
    found = _creases(em) & inner_mask(scan.shape)
    assert_one_line_on_the_roof(found, em.labels, scan, edge_deg, convex, most=1.3)
    # nothing but the crease (and the image border's jump-free frame) is marked
    assert not (em.mask & inner_mask(scan.shape) & (roof_distance(scan, edge_deg) > 1.5)).any()


def test_the_lines_skip_a_dropout_strand_beside_the_crease():
    """Invalid pixels on a strand 3 px from the crease (a steep face's dropouts) are skipped
    over: the crease is found as without them. (The pixels beside the strand, whose lines
    reach across it to the crease, are thinned against the gap, which does not suppress:
    they may be marked too, nothing else is.)"""
    scan = block_matched(synthetic_roof(40.0, 0.0, True, size=91), noise_px=0.05, seed=3)
    dist = roof_distance(scan, 0.0)
    jj = np.arange(scan.shape[1]) + 0.5 - scan.shape[1] / 2 - 0.3
    strand = np.zeros(scan.shape, bool)
    strand[:, np.argmin(np.abs(jj - 3.5))] = True
    for name in ("depth", "xyz"):
        arr = getattr(scan, name)
        arr[strand] = np.nan
    scan.valid[strand] = False
    em = rs.edges.line_fit(scan)
    inner = inner_mask(dist.shape)
    found = _creases(em) & inner
    length = int((inner & (dist <= 0.5)).any(axis=1).sum())
    on_crease = found & (dist <= 1.5)
    assert on_crease.sum() >= 0.9 * length
    beside = ndimage.binary_dilation(strand, np.ones((3, 3), bool)) & ~strand
    assert not (found & (dist > 1.5) & ~beside).any()


@pytest.mark.parametrize("noise_px", [0.05, 0.1, 0.2])
@pytest.mark.parametrize("tilt", [0.0, 0.5])
def test_no_creases_on_a_block_matched_noisy_plane(noise_px, tilt):
    """A plane (head-on, or tilted by atan 0.5) under the matcher's correlated, quantised noise:
    no crease pixel, whatever the noise, since the tolerance follows the measured bend noise."""
    K, rays = pinhole_rays(120, F)
    z = Z0 * (1 + tilt * rays[..., 0]) ** -1 if tilt else np.full(rays.shape[:2], Z0)
    scan = block_matched(grid_scan(rays * z[..., None], K), noise_px=noise_px, seed=int(noise_px * 100))
    em = rs.edges.line_fit(scan)
    assert em.params["matching_window"] == WINDOW
    assert _creases(em).sum() == 0
    assert not (em.labels == EdgeLabel.JUMP).any()


def test_the_bend_noise_is_the_stride_gains_and_falls_as_one_over_s_for_independent_errors():
    """bend_noise(s) is stride_gain's estimator at one lag: bend_noise(1) * stride_gain(s); for
    independent errors of sigma footprints it is sqrt(6) sigma / s."""
    rng = np.random.default_rng(7)
    sigma = 0.3
    fp = np.full((200, 200), 0.5, np.float32)
    z = (100.0 + sigma * fp * rng.standard_normal(fp.shape)).astype(np.float32)
    gain = stride_gain(z, fp, 9)
    for s in (1, 3, 5, 9):
        assert bend_noise(z, fp, s) == pytest.approx(bend_noise(z, fp, 1) * gain[s], rel=1e-6)
        assert bend_noise(z, fp, s) == pytest.approx(np.sqrt(6) * sigma / s, rel=0.06)


@pytest.mark.parametrize("noise_px", [0.1, 0.2])
def test_the_tolerance_is_k_measured_bend_noises_over_the_rounding_gain(noise_px):
    """The tolerance line_fit uses is K_SL bend noises at the stride (the window) over the
    rounding gain, the noise measured on the scan's own depth; it rises with the matcher's
    noise and stays above the plane's strongest bends."""
    K, rays = pinhole_rays(120, F)
    scan = block_matched(grid_scan(rays * Z0, K), noise_px=noise_px, seed=11)
    em = rs.edges.line_fit(scan)
    z = np.where(scan.valid, scan.depth, np.nan).astype(np.float32)
    fp = (z / F).astype(np.float32)
    noise = bend_noise(z, fp, WINDOW)
    assert em.params["bend_noise"] == pytest.approx(noise, rel=1e-3)
    want = max(15.0, np.degrees(K_SL * noise / rounding_gain(WINDOW, WINDOW)))
    assert em.params["angle_tol_deg"] == pytest.approx(want, rel=1e-3)
    assert np.degrees(sl_tolerance(noise, WINDOW, WINDOW)) == pytest.approx(want, rel=1e-6)


def test_the_shortest_chord_reaches_past_the_rounding():
    assert min_reach(WINDOW) == 5 and min_reach(WINDOW) > WINDOW / 2


@pytest.mark.parametrize("k", [1.5, 2.0])
def test_the_two_line_tolerance_keeps_a_planes_false_crease_rate_of_three_lines(k):
    """The least of n tested lines with independent half-normal bends (RMS 1) exceeds t with
    P1(t) ** n, P1(t) = erfc(t / sqrt 2): lines_k equates the rates for two and three lines,
    and is k itself for three; on a simulated plane the rates agree."""
    from scipy.special import erfc

    from rangesim.edges._line_fit_sl import lines_k

    k2, k3 = float(lines_k(k, 2)), float(lines_k(k, 3))
    assert k3 == pytest.approx(k)
    assert k2 > k3
    assert erfc(k2 / np.sqrt(2)) ** 2 == pytest.approx(erfc(k3 / np.sqrt(2)) ** 3, rel=1e-9)
    b = np.abs(np.random.default_rng(0).standard_normal((3, 2_000_000)))
    r2, r3 = (b[:2].min(axis=0) > k2).mean(), (b.min(axis=0) > k3).mean()
    assert r2 == pytest.approx(r3, rel=0.2)


def test_lines_the_image_frame_cuts_are_not_tested():
    """A line the frame would cut within the stride (the matcher's window clipped there: the
    pixels along a tilted plane's border bend its lines) is left out of the test."""
    from rangesim.edges._line_fit_sl import _frame_cut

    cut = _frame_cut((30, 40), WINDOW)
    assert not cut[:, WINDOW:-WINDOW, WINDOW:-WINDOW].any()
    assert cut[0, :, :WINDOW].all() and not cut[0, :, WINDOW:-WINDOW].any()
    assert cut[2, 3, 20] and cut[1, 3, 20] and cut[3, 3, 20] and not cut[0, 3, 20]
