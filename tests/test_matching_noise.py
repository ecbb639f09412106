"""The block matcher's predicted noise (scan.sigma of structured-light scans) against measured errors."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import rangesim as rs
from rangesim.sensor.matching_noise import disparity_gradient, matching_sigma_px
from tests.conftest import box, plane, top_down_pose

#: the bench preset on a 320 x 240 image (f halves, and so do disparity gradients)
SMALL = {"camera.width": 320, "camera.height": 240}


def _sensor():
    return rs.load_sensor("structured_light_bench").with_params(SMALL)


def _disparity_errors(scan, sensor):
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    v = scan.valid
    return fb / scan.depth[v] - fb / scan.xyz_true[..., 2][v], v


def test_disparity_gradient_of_a_tilted_plane_is_b_tan_over_z():
    # a plane through (0, 0, z0) tilted by t about the camera's y axis: d = f b / z changes by
    # b tan(t) / z0 px per pixel along x at its centre
    z0, t, b = 450.0, math.radians(40), 100.0
    p = np.array([0.0, 0.0, z0])
    n = np.array([math.sin(t), 0.0, -math.cos(t)])
    assert disparity_gradient(p, n, b) == pytest.approx(b * math.tan(t) / z0, rel=1e-12)
    assert disparity_gradient(p, n, -b) == pytest.approx(b * math.tan(t) / z0, rel=1e-12)


@pytest.mark.parametrize("deg", [0, 50, 68])
def test_measured_disparity_error_follows_the_slant_law_on_tilted_planes(deg):
    sensor = _sensor()
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    dist = 0.5 * (near + far)
    p = plane(8 * dist)
    p.apply_transform(trimesh.transformations.rotation_matrix(math.radians(deg), [0, 1, 0]))
    scan = rs.scan([p], sensor, pose=top_down_pose(dist), seed=3)
    err, v = _disparity_errors(scan, sensor)
    err = err[np.abs(err) < 5]
    sl = sensor.params["structured_light"]
    g = disparity_gradient(scan.xyz_true, scan.normal, sensor.params["laser"]["baseline"])
    predicted = matching_sigma_px(np.median(g[v]), sl["window"], sl["match_sigma_px"], sl["slant_linear"],
                                  sl["slant_quadratic"])
    assert err.std() == pytest.approx(predicted, rel=0.3)
    # sigma (mm) is that disparity error carried to depth: z^2 sigma_d / (f b)
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    z = scan.depth[v]
    np.testing.assert_allclose(np.median(scan.sigma[v] * fb / z**2), predicted, rtol=0.05)
    assert np.isnan(scan.sigma[~scan.valid]).all()


def test_the_slant_law_grows_the_error_steeply_from_flat_to_grazing():
    # on planes the measured error grows several-fold from 0 to 68 deg (one scan each)
    sensor = _sensor()
    dist = 450.0
    stds = []
    for deg in (0, 68):
        p = plane(8 * dist)
        p.apply_transform(trimesh.transformations.rotation_matrix(math.radians(deg), [0, 1, 0]))
        err, _ = _disparity_errors(rs.scan([p], sensor, pose=top_down_pose(dist), seed=5), sensor)
        stds.append(err[np.abs(err) < 5].std())
    assert stds[1] > 2.5 * stds[0]


def test_depth_errors_over_predicted_sigma_have_unit_spread_on_a_part():
    # a box on a floor seen obliquely: faces at several slants; away from its edges
    sensor = _sensor()
    scene = [plane(2000), box((-40, -30, 0), (40, 30, 35))]
    eye = np.array([120.0, -260.0, 380.0])
    pose = rs.core.geometry.look_at(eye, (0, 0, 10), up=(0, 0, 1))
    scan = rs.scan(scene, sensor, pose=pose, seed=7)
    inside = ndimage.binary_erosion(scan.valid, iterations=6)
    faces = ndimage.generic_filter(scan.face.astype(float), np.ptp, size=13) == 0
    keep = inside & faces
    z = (scan.depth - scan.xyz_true[..., 2])[keep] / scan.sigma[keep]
    q25, q75 = np.percentile(z, [25, 75])
    assert keep.sum() > 5000
    assert 0.7 < (q75 - q25) / 1.349 < 1.3


def test_every_valid_pixel_has_a_sigma_also_where_the_foreground_fattens_over_nothing():
    # a box with no floor: the matcher's window carries the box's depth past its outline, where
    # the pixel's ray hits nothing; such a pixel gets the fronto-parallel law at its measured depth
    sensor = _sensor()
    scan = rs.scan([box((-40, -30, 0), (40, 30, 35))], sensor, pose=top_down_pose(450.0), seed=7)
    fattened = scan.valid & (scan.part < 0)
    assert fattened.any()
    assert np.isfinite(scan.sigma[scan.valid]).all()
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    s0 = sensor.params["structured_light"]["match_sigma_px"]
    np.testing.assert_allclose(scan.sigma[fattened], scan.depth[fattened] ** 2 * s0 / fb, rtol=1e-5)
