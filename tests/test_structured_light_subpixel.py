"""The block matcher's sub-pixel disparity is unbiased (no pixel locking).

A parabola through the ZNCC scores at d - 1, d, d + 1 pulls the estimate towards whole
pixels: on a slanted plane, whose true disparity runs through every sub-pixel phase, the
error against the true phase is a sinusoid (+-0.05 px) and the 1/8 px levels fill unevenly
(0.07-0.18 of the pixels each; a recorded Kinect frame fills them within 7 %). The dots are
Gaussian spots, so the scores near the peak are a Gaussian of the shift and the parabola
through their logarithms has its vertex at the peak (``subpixel_offset``).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.sensor.block_matching import subpixel_offset
from rangesim.twin.realism import clipped_std
from tests.conftest import plane, top_down_pose


def test_a_gaussian_peak_is_found_exactly_and_a_parabola_too():
    x = np.array([-1.0, 0.0, 1.0])
    for peak in (-0.45, -0.2, 0.0, 0.13, 0.37):
        g = np.exp(-0.5 * ((x - peak) / 0.9) ** 2)
        assert math.isclose(float(subpixel_offset(*g)), peak, abs_tol=1e-12)
    # scores that are not all positive: the parabola's vertex
    p = 1.0 - (x - 0.25) ** 2 - 1.2
    assert math.isclose(float(subpixel_offset(*p)), 0.25, abs_tol=1e-12)


def test_no_pixel_locking_on_a_slanted_plane():
    """With independent dots, whose score peak is the Gaussian the fit assumes. (The preset's
    2 px spaced dots narrow the peak's flanks: their phase error is up to 0.04 px, the levels
    filled 0.098-0.146; recorded frames fill them within 7 %. Left as it is, noted.)"""
    sensor = rs.load_sensor("kinect_v1").with_params({"camera.width": 320, "camera.height": 240,
                                                      "structured_light.depth_unit_mm": 0.0,  # the lattice
                                                      "structured_light.dot_min_spacing_px": 0.0})
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    tilted = plane(30000)
    tilted.apply_transform(trimesh.transformations.rotation_matrix(math.radians(40), [0, 1, 0]))
    occupancy, error, count = np.zeros(8), np.zeros(8), np.zeros(8)
    for seed in (0, 1):
        scan = rs.scan([tilted], sensor, pose=top_down_pose(1500.0), seed=seed)
        d = fb / scan.depth[scan.valid].astype(np.float64)
        d_true = fb / scan.xyz_true[..., 2][scan.valid].astype(np.float64)
        occupancy += np.bincount(np.rint(d * 8).astype(int) % 8, minlength=8)
        phase = np.floor((d_true * 8) % 8).astype(int)  # the true disparity's eighth of a pixel
        error += np.bincount(phase, weights=d - d_true, minlength=8)
        count += np.bincount(phase, minlength=8)
    assert count.min() > 1000
    occupancy /= occupancy.sum()
    # evenly filled levels (the parabola: 0.074 .. 0.176, max / min 2.4)
    assert occupancy.max() / occupancy.min() < 1.3, occupancy
    # and no error that depends on the true sub-pixel phase (the parabola: +-0.05 px)
    assert np.abs(error / count).max() < 0.025, error / count


@pytest.mark.parametrize("distance", [560.0, 2000.0])
def test_depth_in_whole_millimetres_as_a_kinect_writes_it(distance):
    """``structured_light.depth_unit_mm = 1`` (``kinect_v1``'s): every depth a whole millimetre, the point on its
    pixel's ray; the levels f b / d, 1/8 px apart, round to gaps within a unit of their
    spacing z^2 / (8 f b) (here, at 320 px, 1.8 mm at 0.56 m: gaps of 1 and 2 mm, as the
    recorded 640 px frames show at 0.7 m); sigma holds the rounding's 1/12 mm^2."""
    base = rs.load_sensor("kinect_v1").with_params({"camera.width": 320, "camera.height": 240,
                                                    "structured_light.depth_unit_mm": 0.0})
    rounded = base.with_params({"structured_light.depth_unit_mm": 1.0})  # as the preset
    fb = base.focal_px * abs(base.params["laser"]["baseline"])
    tilted = plane(30000)
    tilted.apply_transform(trimesh.transformations.rotation_matrix(math.radians(40), [0, 1, 0]))
    pose = top_down_pose(distance)
    a = rs.scan([tilted], base, pose=pose, seed=0)
    b = rs.scan([tilted], rounded, pose=pose, seed=0)
    z = b.depth[b.valid].astype(np.float64)
    assert np.array_equal(b.valid, a.valid)
    assert np.all(z == np.round(z)) and not np.all(a.depth[a.valid] == np.round(a.depth[a.valid]))
    np.testing.assert_allclose(b.depth[b.valid], np.round(a.depth[a.valid]), atol=1e-3)
    # the points stay on their rays: x / z and y / z as before the rounding
    np.testing.assert_allclose(b.xyz[b.valid][:, :2] / z[:, None], a.xyz[a.valid][:, :2] / a.depth[a.valid][:, None],
                               atol=1e-6)
    near = np.abs(z - distance) < 0.05 * distance
    levels = np.unique(z[near])
    mid = 0.5 * (levels[1:] + levels[:-1])
    spacing = mid**2 / (8 * fb)
    assert np.all(np.abs(np.diff(levels) - spacing) < 1.0 + 0.01 * spacing)
    if distance < 600:
        assert set(np.diff(levels).astype(int).tolist()) == {1, 2}
    np.testing.assert_allclose(b.sigma[b.valid] ** 2, a.sigma[a.valid] ** 2 + 1 / 12, rtol=1e-4)


def test_slanted_plane_noise_follows_nguyen_et_al():
    """Nguyen, Izadi and Lovell (2012) measured a Kinect's axial noise on planes at distance z (m)
    and angle theta: sigma_z = 1.2 + 1.9 (z - 0.4)^2 + 0.1 / sqrt(z) theta^2 / (pi/2 - theta)^2
    mm. kinect_v1 (640 x 480) at 1 m holds it within 15 % at 45, 60 and 70 degrees. With
    independent (Poisson) dots it was 1.26 / 1.55 / 1.82x (the window's dots cluster off its
    centre); the preset's pattern keeps its dots 2 px apart (``dot_min_spacing_px``)."""
    sensor = rs.load_sensor("kinect_v1").with_params({"structured_light.depth_unit_mm": 0.0})
    assert sensor.params["structured_light"]["dot_min_spacing_px"] == 2.0
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    for deg in (45, 60, 70):
        sheet = plane(20000)
        sheet.apply_transform(trimesh.transformations.rotation_matrix(math.radians(deg), [1, 0, 0]))
        scan = rs.scan([sheet], sensor, pose=top_down_pose(1000.0), seed=0)
        h, w = scan.shape
        rows, cols = np.mgrid[:h, :w]
        centre = (np.abs(rows - h / 2) < 100) & (np.abs(cols - w / 2) < 100) & scan.valid
        z_true = scan.xyz_true[..., 2][centre].astype(np.float64)
        error_px = fb / scan.depth[centre].astype(np.float64) - fb / z_true
        sigma_mm = clipped_std(error_px) * 1000.0**2 / fb
        t = math.radians(deg)
        nguyen = 1.2 + 1.9 * 0.6**2 + 0.1 * t * t / (math.pi / 2 - t) ** 2
        assert abs(sigma_mm / nguyen - 1) < 0.15, (deg, sigma_mm, nguyen)


def test_local_plane_noise_is_the_noise_about_each_tiles_plane():
    """``local_plane_std`` on a tilted plane's depths with Gaussian noise of 1.5 mm: every tile
    off the step reads 1.5 mm (to 5 %), the tiles a 30 mm step crosses are left out, and a
    plane's depth image (not linear in the pixel, its inverse is) leaves no residual."""
    from rangesim.twin.kinect import local_plane_std

    h, w = 96, 144
    v, u = np.mgrid[:h, :w].astype(np.float64)
    z_true = 1.0 / (1 / 1000.0 + 2e-7 * u + 1e-7 * v)  # a plane seen obliquely: 1/z linear in the pixel
    stepped = z_true.copy()
    stepped[:, 60:] += 30.0  # a step inside the third column of tiles
    noisy = stepped + np.random.default_rng(0).normal(0, 1.5, stepped.shape)
    usable = np.ones((h, w), bool)
    stds, depths = local_plane_std(noisy, stepped, usable)
    assert len(stds) == 4 * 6 - 4  # the four tiles of columns 48-71 hold the step
    np.testing.assert_allclose(stds, 1.5, rtol=0.1)
    assert abs(np.median(stds) / 1.5 - 1) < 0.05
    clean, _ = local_plane_std(z_true, z_true, usable)
    assert len(clean) == 24 and clean.max() < 1e-6
