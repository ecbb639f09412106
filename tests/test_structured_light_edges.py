"""Edges of block-matched (structured-light) depth: creases rounded over the matcher's window.

A structured-light scanner's depth is about the true surface's disparity averaged over its
matching window (``rangesim.sensor.block_matching``), so a crease comes out rounded over the
window. These tests build that analytically: a pinhole view of a roof, its disparity
box-filtered over the window and quantised to the matcher's 1/8 px steps, with
``meta["sensor"]`` saying what a structured-light scan's does.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from rangesim.core.constants import EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.edges import gradient
from rangesim.edges._gradient import matching_stride, second_differences
from rangesim.edges._matching_scale import matching_window, rounding_gain, strided_pairs, strided_responses
from tests.test_edge_detectors import grid_scan, pinhole_rays, roof_distance, synthetic_roof

WINDOW = 9
#: f b of the synthetic matcher, px mm (the structured_light_bench preset's 1194 px x 100 mm)
FB = 119_400.0
SL_META = {"mode": "structured_light", "structured_light": {"window": WINDOW, "subpixel_steps": 8}}


def inner_mask(shape, margin: int = 15) -> np.ndarray:
    """The image less a ``margin`` px border (where the block-matched roofs' windows are whole)."""
    inner = np.zeros(shape, bool)
    inner[margin:-margin, margin:-margin] = True
    return inner


def xyz_stack(scan: RangeScan) -> np.ndarray:
    """The scan's points component-major, (3, H, W) float32."""
    return np.ascontiguousarray(np.moveaxis(scan.xyz, -1, 0), np.float32)


def assert_one_line_on_the_roof(found: np.ndarray, labels: np.ndarray, scan: RangeScan, edge_deg: float,
                                convex: bool, most: float = 1.1) -> None:
    """``found`` (the crease pixels inside :func:`inner_mask`) is one line along the roof of
    :func:`synthetic_roof`: 0.9 to ``most`` times its length, every pixel within 1.5 px of
    the crease, and at least 95 % of them labelled with its type."""
    dist = roof_distance(scan, edge_deg)
    rows, cols = np.nonzero(inner_mask(dist.shape) & (dist <= 0.5))
    length = max(np.unique(rows).size, np.unique(cols).size)
    assert 0.9 * length <= found.sum() <= most * length
    assert np.all(dist[found] <= 1.5)
    kind = EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE
    assert (labels[found] == kind).mean() >= 0.95


def roof_bend_ratio(scan: RangeScan, bend_rad: np.ndarray, edge_deg: float, bend_deg: float) -> float:
    """The median of a measured bend (radians) on the crease of :func:`synthetic_roof` over
    the roof's true bend."""
    on = inner_mask(scan.shape) & (roof_distance(scan, edge_deg) <= 0.5)
    return float(np.degrees(np.median(bend_rad[on])) / bend_deg)


def roof_beside_a_gap(convex: bool, seed: int = 3) -> RangeScan:
    """A block-matched 60 degree roof (crease along image y through the centre) with a dropout
    strip 3-5 px beside the crease, as a ragged shadow leaves one."""
    scan = block_matched(synthetic_roof(60.0, 0.0, convex, size=91), noise_px=0.05, seed=seed)
    cols = np.arange(scan.shape[1]) + 0.5 - scan.shape[1] / 2 - 0.3
    gap = np.zeros(scan.shape, bool)
    gap[:, (cols > 3) & (cols < 6)] = True
    scan.valid[gap] = False
    scan.depth[gap] = np.nan
    scan.xyz[gap] = np.nan
    return scan


def block_matched(scan: RangeScan, window: int = WINDOW, steps: int = 8, noise_px: float = 0.0,
                  seed: int = 0) -> RangeScan:
    """``scan`` as a block matcher of ``window`` px would measure it: disparity ``FB / z``
    averaged over the window, plus ``noise_px`` of noise correlated over the window,
    quantised to ``1 / steps`` px; points on the pixels' rays; ``meta["sensor"]`` set."""
    d = FB / np.asarray(scan.depth, np.float64)
    d = ndimage.uniform_filter(d, window, mode="nearest")
    if noise_px:
        rng = np.random.default_rng(seed)
        # white noise box-filtered over the window, scaled back to noise_px
        e = ndimage.uniform_filter(rng.standard_normal(d.shape), window, mode="nearest") * window
        d = d + noise_px * e
    d = np.round(d * steps) / steps
    K = np.asarray(scan.meta["K"])
    size = scan.shape[0]
    _, rays = pinhole_rays(size, K[0, 0])
    out = grid_scan(rays * (FB / d)[..., None], K)
    out.meta["sensor"] = dict(SL_META, structured_light=dict(SL_META["structured_light"], window=window))
    return out


def test_matching_window_comes_from_the_scans_sensor():
    roof = synthetic_roof(40.0, 0.0, True)
    assert matching_window(roof) is None                       # no sensor metadata: no matcher
    assert matching_window(block_matched(roof)) == WINDOW
    laser = block_matched(roof)
    laser.meta["sensor"] = {"mode": "geometric"}
    assert matching_window(laser) is None
    assert matching_stride(None) == 1 and matching_stride(WINDOW) == WINDOW


@pytest.mark.parametrize("stride", [2, 4, 9, 13])
def test_rounding_gain_is_what_a_strided_difference_sees_of_a_box_rounded_crease(stride):
    # a roof along the columns whose slope changes by 0.6 per pixel, box-smoothed over 9 px
    yy, xx = np.mgrid[0:40, 0:121].astype(np.float64)
    roof = 100.0 + 0.3 * np.abs(xx - 60)
    rounded = ndimage.uniform_filter(roof, WINDOW, mode="nearest").astype(np.float32)
    r0 = strided_responses(rounded, None, stride, second_differences)[0]
    # continuous box: 1 - w / (4 s) beyond w / 2, s / w within; the discrete box's centre
    # lies 20 / 9 instead of 9 / 4 px of slope off (1 %)
    assert r0[20, 60] / 0.6 == pytest.approx(rounding_gain(WINDOW, stride), rel=0.03)
    # faces beside the rounding: no response once the stencil clears it
    assert abs(r0[20, 60 + stride + WINDOW // 2 + 1]) < 1e-3


def test_strided_pairs_are_cut_by_gaps_and_jumps_between_their_ends():
    valid = np.ones((5, 20), bool)
    valid[2, 8] = False
    pairs = np.zeros((4, 5, 20), bool)
    pairs[0, 2, 14] = True                                    # a jump between columns 14 and 15
    cut = strided_pairs(pairs, valid, 4)[0]                   # steps of 4 along the rows
    assert cut[2, 5] and cut[2, 6] and cut[2, 7]              # 5 -> 9 .. 7 -> 11 pass over the gap
    assert not cut[2, 3] and not cut[2, 9]                    # 3 -> 7 and 9 -> 13 stay clear
    assert not cut[2, 4]                                      # 4 -> 8 ends on it (a NaN end, not a cut)
    assert cut[2, 11] and cut[2, 14] and not cut[2, 10] and not cut[2, 15]   # the jump 14 | 15
    assert not cut[1, :16].any() and cut[1, 17:].all()       # other rows: cut only where leaving the image


def _matched_crease(edge_deg: float, convex: bool):
    """A block-matched 40 degree crease (91 x 91): the scan, each pixel's distance to the
    crease line (px), the inner region away from the border, the crease pixels' rows and
    columns there and the crease's length in pixels of an 8-connected line."""
    roof = synthetic_roof(40.0, edge_deg, convex, size=91)
    scan = block_matched(roof, noise_px=0.05, seed=int(edge_deg) + convex)
    dist = roof_distance(scan, edge_deg)
    inner = np.zeros(scan.shape, bool)
    inner[15:-15, 15:-15] = True
    rows, cols = np.nonzero(inner & (dist <= 0.5))
    return scan, dist, inner, rows, cols, max(np.unique(rows).size, np.unique(cols).size)


@pytest.mark.parametrize("edge_deg", [0.0, 30.0, 90.0, 135.0])
@pytest.mark.parametrize("convex", [True, False])
def test_gradient_finds_a_block_matched_crease_at_the_window_scale(edge_deg, convex):
    """A 40 degree crease rounded over the 9 px window with the matcher's correlated noise: the
    3 x 3 operators (``stride=1``, the detector before) see a bend spread over nine pixels under
    the noise and find almost none of it; at the window's stride the crease is one line on
    the crease, of its type, its strength near the bend."""
    scan, dist, inner, rows, cols, length = _matched_crease(edge_deg, convex)
    em = gradient(scan)
    assert em.params["stride"] == WINDOW
    found = em.mask & inner
    assert found.sum() >= 0.8 * length
    assert np.mean(dist[found] <= 1.5) >= 0.95                # on the crease
    assert (em.labels[found] == (EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE)).mean() >= 0.95
    # the rounding's share divided out: the bend within 30 % (the 3 x 3 bend would be a ninth)
    assert np.median(em.strength[found]) == pytest.approx(40.0, rel=0.3)
    old = gradient(scan, stride=1)
    assert (old.mask & inner).sum() <= 0.2 * length


def test_a_block_matched_plane_has_no_creases():
    plane = synthetic_roof(0.0, 0.0, True, size=91)
    em = gradient(block_matched(plane, noise_px=0.05, seed=3))
    assert not em.mask[15:-15, 15:-15].any()


def test_scans_without_a_matcher_keep_the_3x3_operators():
    scan = synthetic_roof(30.0, 30.0, True)
    em, em1 = gradient(scan), gradient(scan, stride=1)
    assert em.params["stride"] == 1
    assert np.array_equal(em.mask, em1.mask) and np.array_equal(em.labels, em1.labels)
    with pytest.raises(ValueError, match="stride"):
        gradient(scan, stride=0)


@pytest.mark.parametrize("edge_deg", [0.0, 30.0, 135.0])
@pytest.mark.parametrize("convex", [True, False])
def test_curvature_fits_blocks_past_the_matchers_rounding(edge_deg, convex):
    """The same block-matched 40 degree crease: a 5 x 5 quadric (the default before) fits the
    rounding alone and finds nothing; the default block on such a scan (13 px for the 9 px
    window) reaches the faces and marks the crease as one line of its type."""
    from rangesim.edges import curvature
    from rangesim.edges._curvature import matching_block

    assert matching_block(None) == 5 and matching_block(WINDOW) == 13
    scan, dist, inner, rows, cols, length = _matched_crease(edge_deg, convex)
    em = curvature(scan)
    assert em.params["window"] == 13
    found = em.mask & inner
    assert found.sum() >= 0.8 * length
    assert np.mean(dist[found] <= 1.5) >= 0.95
    assert (em.labels[found] == (EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE)).mean() >= 0.95
    assert (curvature(scan, window=5).mask & inner).sum() <= 0.2 * length
    # without a matcher the block stays 5
    assert curvature(synthetic_roof(40.0, edge_deg, convex)).params["window"] == 5
