"""pcl_organized's high-curvature edges at the scale the sensor resolves (issue 14).

PCL's Canny on the normal images runs at 3 x 3 on clean laser scans; on block-matched scans
(a crease rounded over the matcher's window) and noisy ones it runs at a step ``h``: normals
from chords ``+-h``, Sobel at stride ``h``, thresholds in sigmas of the strength's predicted
noise (``rangesim.edges._pcl_scale``). These tests check the scale, the noise law against the
normals' measured noise, the false-crease rate on noisy planes and the creases found.
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.edges._differences import dot3
from rangesim.edges._pcl_scale import (
    K_HIGH,
    K_LOW,
    chord_normals,
    crease_step,
    predicted_noise_law,
    strided_sobel,
)
from tests.test_edge_detectors import grid_scan, pinhole_rays, roof_distance, synthetic_roof
from tests.test_structured_light_edges import WINDOW, block_matched

F, Z0 = 400.0, 500.0


def _noisy(scan, sigma_fp: float, seed: int):
    """``scan`` with independent depth noise of ``sigma_fp`` pixel footprints along the rays,
    carrying that as its noise model's prediction (``sigma``, mm), as laser-stripe scans do."""
    K = np.asarray(scan.meta["K"])
    xyz = scan.xyz.astype(np.float64)
    fp = xyz[..., 2] / K[0, 0]
    rng = np.random.default_rng(seed)
    scale = 1 + rng.standard_normal(fp.shape) * sigma_fp * fp / xyz[..., 2]
    return grid_scan(xyz * scale[..., None], K, sigma=(sigma_fp * fp).astype(np.float32))


def _plane(size: int = 120):
    K, rays = pinhole_rays(size, F)
    return grid_scan(rays * Z0, K)


def _crease_stats(em, dist, convex):
    inner = np.zeros(dist.shape, bool)
    inner[15:-15, 15:-15] = True
    rows, cols = np.nonzero(inner & (dist <= 0.5))
    length = max(np.unique(rows).size, np.unique(cols).size)
    found = em.high_curvature & inner
    kind = EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE
    return found, length, (em.labels[found] == kind).mean() if found.any() else 0.0


def test_the_step_is_the_matchers_half_window_or_the_noises():
    assert crease_step(WINDOW, 0.5) == 4 and crease_step(13, None) == 6
    # laser: the smallest step whose normal-difference noise 0.75 sigma / h rad is <= 0.224
    assert [crease_step(None, s) for s in (0.0, 0.1, 0.25, 0.5, 0.8, 5.0)] == [1, 1, 1, 2, 3, 4]


@pytest.mark.parametrize("edge_deg", [0.0, 30.0, 90.0, 135.0])
@pytest.mark.parametrize("convex", [True, False])
def test_a_block_matched_crease_is_one_line_on_the_crease(edge_deg, convex):
    """A 40 degree crease rounded over the 9 px window with the matcher's correlated noise:
    normals 4 px either side (past the rounding) see ~0.72 of it; divided out, the strength is
    8 sin(20 deg) within 20 %, and the crease is one line within 1.5 px, of its type."""
    scan = block_matched(synthetic_roof(40.0, edge_deg, convex, size=91), noise_px=0.05,
                         seed=int(edge_deg) + convex)
    em = rs.edges.pcl_organized(scan)
    assert em.params["scale"] == "sensor" and em.params["normal_window"] == WINDOW
    assert em.params["curvature_noise"] == "measured"
    dist = roof_distance(scan, edge_deg)
    found, length, right_kind = _crease_stats(em, dist, convex)
    assert found.sum() >= 0.9 * length and found.sum() <= 1.1 * length
    assert np.all(dist[found] <= 1.5)
    assert right_kind >= 0.95
    assert np.median(em.strength[found]) == pytest.approx(8 * np.sin(np.radians(20.0)), rel=0.2)


def test_a_block_matched_plane_has_no_creases():
    plane = synthetic_roof(0.0, 0.0, True, size=91)
    for seed in range(3):
        em = rs.edges.pcl_organized(block_matched(plane, noise_px=0.05, seed=seed))
        assert not em.high_curvature[15:-15, 15:-15].any()


@pytest.mark.parametrize("sigma_fp", [0.25, 0.5])
@pytest.mark.parametrize("step", [2, 3, 4])
def test_the_noise_law_is_the_measured_noise_of_the_normal_differences(sigma_fp, step):
    """A frontal plane with independent depth noise: the strength's component across (the
    second difference at lag 2h over 2h, Sobel-averaged) has the law's std, 3 sigma / h raw
    units, within 8 %; the component along the edge (a mixed difference) is quieter."""
    scan = _noisy(_plane(160), sigma_fp, seed=step)
    xyz = np.moveaxis(scan.xyz, -1, 0).copy()
    gx, gy = strided_sobel(chord_normals(xyz, None, step), None, step, None)
    inner = (slice(10, -10), slice(10, -10))
    law = predicted_noise_law(sigma_fp, step)
    assert law == pytest.approx(3 * sigma_fp / step)
    for across in (gx[0][inner], gy[1][inner]):
        assert np.std(across) == pytest.approx(law, rel=0.08)
    for along in (gx[1][inner], gy[0][inner]):
        assert np.std(along) < 0.85 * law
    # the magnitude over the four components: below the chi-4 median of the law
    mag = np.sqrt(dot3(gx, gx) + dot3(gy, gy))[inner]
    assert 0.7 * law < np.median(mag) / 1.8324 < law


@pytest.mark.parametrize("sigma_fp", [0.25, 0.5, 0.8])
def test_noisy_planes_have_no_false_creases(sigma_fp):
    """Thresholds K_LOW = 4 and K_HIGH = 6 law sigmas: a chi-4 magnitude passes 6 sigma with
    ~3e-7 per pixel, so no crease may start on a noisy plane (3 x 12,100 inner pixels)."""
    for seed in range(3):
        em = rs.edges.pcl_organized(_noisy(_plane(), sigma_fp, seed))
        assert em.params["scale"] == "sensor" and em.params["curvature_noise"] == "sigma"
        assert em.params["normal_window"] == 2 * crease_step(None, sigma_fp) + 1
        assert not em.high_curvature[5:-5, 5:-5].any()


@pytest.mark.parametrize("sigma_fp", [0.25, 0.5, 0.8])
@pytest.mark.parametrize("edge_deg", [0.0, 30.0, 135.0])
@pytest.mark.parametrize("convex", [True, False])
def test_noisy_laser_creases_above_the_law_are_found_and_those_below_are_not(sigma_fp, edge_deg, convex):
    """A 90 degree crease (strength 8 sin 45 = 5.7 raw) clears K_HIGH law sigmas at each
    preset-like noise (3 sigma / h = 0.75-0.8 raw at the chosen step, 4.5-4.8 to start): one
    line on the crease, of its type. A 30 degree one (2.1 raw) is under K_LOW sigmas there."""
    seed = int(edge_deg) + convex
    steep = _noisy(synthetic_roof(90.0, edge_deg, convex, size=121), sigma_fp, seed)
    em = rs.edges.pcl_organized(steep)
    h = crease_step(None, sigma_fp)
    assert 8 * np.sin(np.radians(45.0)) > K_HIGH * predicted_noise_law(sigma_fp, h)
    dist = roof_distance(steep, edge_deg)
    found, length, right_kind = _crease_stats(em, dist, convex)
    assert found.sum() >= 0.9 * length
    assert np.mean(dist[found] <= 1.5) >= 0.98
    assert right_kind >= 0.95
    gentle = _noisy(synthetic_roof(30.0, edge_deg, convex, size=121), sigma_fp, seed)
    assert 8 * np.sin(np.radians(15.0)) < K_LOW * predicted_noise_law(sigma_fp, h)
    assert not rs.edges.pcl_organized(gentle).high_curvature[15:-15, 15:-15].any()


def test_clean_laser_scans_keep_pcls_3x3_canny():
    scan = synthetic_roof(30.0, 30.0, True)
    em = rs.edges.pcl_organized(scan)
    assert em.params["scale"] == "3x3" and em.params["normal_window"] == 3
    assert em.params["curvature_threshold"] == [0.4, 1.1]
    assert em.high_curvature.any()


def test_pcls_own_pipeline_on_any_scan_with_scale_3x3():
    """``scale="3x3"`` runs PCL's 3 x 3 pipeline on a noisy scan (to compare with PCL itself):
    at PCL's fixed thresholds 0.8 footprints of noise flood a plane with creases, as PCL's
    own would, while the default measures at the sensor's scale and stays (nearly) silent;
    ``"sensor"`` forces the scaled path on a clean scan; a bad scale is refused."""
    noisy = _noisy(_plane(), 0.8, 0)
    own = rs.edges.pcl_organized(noisy, scale="3x3", normal_window=3, curvature_threshold=(0.4, 1.1))
    assert own.params["scale"] == "3x3" and own.params["normal_window"] == 3
    auto = rs.edges.pcl_organized(noisy)
    assert auto.params["scale"] == "sensor"
    assert own.high_curvature.sum() > 10 * max(auto.high_curvature.sum(), 1)
    forced = rs.edges.pcl_organized(synthetic_roof(30.0, 30.0, True), scale="sensor")
    assert forced.params["scale"] == "sensor"
    with pytest.raises(ValueError, match="scale must be"):
        rs.edges.pcl_organized(noisy, scale="5x5")
