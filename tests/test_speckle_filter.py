"""The block matcher's speckle filter: small islands of disparity go, surfaces stay whole."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.sensor.speckle_filter import filter_speckles, speckle_regions
from tests.conftest import plane, top_down_pose


def test_regions_join_neighbours_within_the_step_and_count_their_pixels():
    d = np.full((30, 40), 100.0)
    d[10:13, 10:14] = 140.0  # a 12 px island of chance matches
    d[20, 30] = np.nan
    area = speckle_regions(d, 2.0)
    assert area[11, 11] == 12 and area[0, 0] == 30 * 40 - 12 - 1 and area[20, 30] == 0
    speckle = filter_speckles(d, 13, 2.0)
    assert speckle.sum() == 12 and speckle[10:13, 10:14].all()
    assert not filter_speckles(d, 12, 2.0).any()  # regions of exactly max_size stay
    assert not filter_speckles(d, 0, 2.0).any()  # 0: off


def test_a_slanted_surface_stays_one_region_while_its_step_is_within_the_range():
    # a plane at incidence theta steps (b / z) tan(theta) px of disparity per pixel along the baseline:
    # 2 px at atan(2 z / b) = 83.7 deg for b = 100 mm at z = 450 mm
    b, z = 100.0, 450.0
    for theta_deg, whole in ((75.0, True), (83.5, True), (84.0, False)):
        step = b / z * math.tan(math.radians(theta_deg))
        d = 250.0 + step * np.arange(60)[None, :] * np.ones((20, 1))
        area = speckle_regions(d, 2.0)
        assert (area == d.size).all() == whole, theta_deg
        if not whole:  # each column alone: 20 px regions, all speckle at 100 px
            assert (area == 20).all() and filter_speckles(d, 100, 2.0).all()


def test_no_small_region_survives_a_scan_straddling_the_far_limit():
    # a plane tilted 30 deg through the far limit: past it the matcher's windows find chance matches
    sensor = rs.load_sensor("kinect_v1").with_params({"camera.width": 320, "camera.height": 240})
    far = sensor.params["range"]["far"]
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    floor = plane(8000)
    floor.apply_transform(trimesh.transformations.rotation_matrix(math.radians(30), [1, 0, 0]))
    scans = {w: rs.scan([floor], sensor.with_params({"structured_light.speckle_window": w}),
                        pose=top_down_pose(far), seed=0) for w in (0, 100)}
    small = {w: int(((a > 0) & (a < 100)).sum())
             for w, a in ((w, speckle_regions(fb / s.depth, 2.0)) for w, s in scans.items())}
    gross = {w: int((np.abs(s.depth - s.xyz_true[..., 2]) > 0.05 * far)[s.valid].sum()) for w, s in scans.items()}
    assert small[0] > 50 and small[100] == 0
    assert gross[100] < gross[0]
    # the filter only takes pixels away, and those are the small regions' pixels
    assert not (scans[100].valid & ~scans[0].valid).any()
    assert scans[0].valid.sum() - scans[100].valid.sum() == small[0]


def test_speckle_settings_are_validated():
    with pytest.raises(rs.RangesimError, match="speckle_window"):
        rs.load_sensor("kinect_v1").with_params({"structured_light.speckle_window": -1})
    with pytest.raises(rs.RangesimError, match="speckle_window"):
        rs.load_sensor("kinect_v1").with_params({"structured_light.speckle_window": 2.5})
    with pytest.raises(rs.RangesimError, match="speckle_range"):
        rs.load_sensor("kinect_v1").with_params({"structured_light.speckle_range": -0.5})


def test_region_areas_equal_scipys_connected_components_on_random_images():
    # the compiled union-find against the graph form (scipy.sparse.csgraph) it replaced
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    def reference(d, max_diff):
        h, w = d.shape
        valid = np.isfinite(d)
        index = np.arange(h * w).reshape(h, w)
        with np.errstate(invalid="ignore"):
            across = valid[:, :-1] & valid[:, 1:] & (np.abs(d[:, :-1] - d[:, 1:]) <= max_diff)
            down = valid[:-1] & valid[1:] & (np.abs(d[:-1] - d[1:]) <= max_diff)
        rows = np.concatenate([index[:, :-1][across], index[:-1][down]])
        cols = np.concatenate([index[:, 1:][across], index[1:][down]])
        _, label = connected_components(coo_matrix((np.ones(rows.size), (rows, cols)), shape=(h * w, h * w)),
                                        directed=False)
        return np.where(valid, np.bincount(label)[label].reshape(h, w), 0)

    rng = np.random.default_rng(0)
    for shape in [(1, 1), (1, 17), (13, 1), (40, 60), (97, 31)]:
        for holes in (0.0, 0.3, 1.0):
            d = np.round(rng.uniform(0, 6, shape), 1)
            d[rng.random(shape) < holes] = np.nan
            np.testing.assert_array_equal(speckle_regions(d, 2.0), reference(d, 2.0))
