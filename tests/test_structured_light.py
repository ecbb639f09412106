"""The structured-light mode (Kinect type) against its laws: disparity, noise, steps, shadows, edges."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.sensor.block_matching import block_match
from rangesim.sensor.dot_pattern import DotPattern
from tests.conftest import box, plane, top_down_pose

#: a small Kinect: the kinect_v1 optics and matcher on a 320 x 240 image (f halves, so do disparities)
SMALL = {"camera.width": 320, "camera.height": 240}


def small_kinect(**changes):
    return rs.load_sensor("kinect_v1").with_params({**SMALL, **changes})


def _tilted_plane(deg):
    p = plane(4000)
    p.apply_transform(trimesh.transformations.rotation_matrix(math.radians(deg), [0, 1, 0]))
    return p


def test_block_matching_recovers_a_known_shift_to_an_eighth_pixel():
    pattern = DotPattern.generate(200, 60, 0.1, 0.6, seed=3, x_min=-30)
    ref = pattern.reference(120, 60, 0.0, margin=40)
    for shift in (7.0, 7.375, 12.625):
        img = pattern.reference(120, 60, shift, margin=0)  # image[:, j] = pattern at j - shift
        d, score = block_match(img, ref, 0, 20, window=9, subpixel_steps=8)
        inner = d[10:-10, 30:-10]
        assert np.isfinite(inner).mean() > 0.95
        assert np.nanmedian(inner) == pytest.approx(shift, abs=0.13)
        assert np.all(np.abs(inner[np.isfinite(inner)] * 8 - np.round(inner[np.isfinite(inner)] * 8)) < 1e-9)


def test_depth_is_f_b_over_disparity_on_a_plane():
    # the lattice itself: without the device's rounding to whole millimetres (depth_unit_mm)
    sensor = small_kinect(**{"noise.speckle_contrast": 0.0, "camera.read_noise_e": 0.0,
                             "structured_light.depth_unit_mm": 0.0})
    scan = rs.scan([plane(4000)], sensor, pose=top_down_pose(1200.0), seed=0)
    assert scan.valid.mean() > 0.9 and scan.meta["mode"] == "structured_light"
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    d = fb / scan.depth[scan.valid]
    # one disparity for a fronto-parallel plane: the depth is one 1/8 px step of f b / d from the truth
    step = 1200.0**2 / (8 * fb)
    assert np.percentile(np.abs(scan.depth[scan.valid] - 1200.0), 99) < 1.5 * step
    assert np.allclose(d * 8, np.round(d * 8), atol=1e-3)
    # points lie on their pixels' rays
    K = sensor.K
    jj, ii = np.meshgrid(np.arange(scan.shape[1]) + 0.5, np.arange(scan.shape[0]) + 0.5)
    np.testing.assert_allclose(scan.xyz[..., 0][scan.valid], ((jj - K[0, 2]) / K[0, 0] * scan.depth)[scan.valid],
                               rtol=1e-5, atol=1e-3)


def test_disparity_steps_of_an_eighth_pixel_are_depth_steps():
    sensor = small_kinect(**{"structured_light.depth_unit_mm": 0.0})  # the lattice, not rounded to mm
    scan = rs.scan([_tilted_plane(30.0)], sensor, pose=top_down_pose(2000.0), seed=0)
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    d = fb / scan.depth[scan.valid].astype(np.float64)
    assert np.allclose(d * 8, np.round(d * 8), atol=5e-3)
    levels = np.unique(np.round(d * 8))
    assert levels.size > 20  # the tilted plane spans many steps
    z_levels = np.sort(fb / (levels / 8))
    # adjacent depth levels differ by z^2 / (8 f b)
    gaps = np.diff(z_levels)
    mid = 0.5 * (z_levels[1:] + z_levels[:-1])
    np.testing.assert_allclose(gaps, mid**2 / (8 * fb), rtol=0.02)


def test_depth_noise_follows_z_squared_sigma_d_over_f_b():
    sensor = small_kinect()
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    sigma = {}
    for z in (1000.0, 2000.0):
        scan = rs.scan([_tilted_plane(20.0)], sensor, pose=top_down_pose(z), seed=1)
        ok = scan.valid & np.isfinite(scan.xyz_true[..., 2])
        z_true = scan.xyz_true[..., 2][ok].astype(np.float64)
        e_d = fb / scan.depth[ok].astype(np.float64) - fb / z_true
        e_z = scan.depth[ok] - z_true
        s_d = 1.4826 * np.median(np.abs(e_d - np.median(e_d)))
        s_z = 1.4826 * np.median(np.abs(e_z - np.median(e_z)))
        assert s_z == pytest.approx(np.median(z_true) ** 2 * s_d / fb, rel=0.2)
        sigma[z] = (s_z, s_d)
    # the disparity error holds at about a step's size, so the depth error grows about as z^2
    assert 2.5 < sigma[2000.0][0] / sigma[1000.0][0] < 6.5


@pytest.mark.parametrize("baseline", [-75.0, 75.0])
def test_projector_shadow_width_follows_the_baseline(baseline):
    D, h, x_left, x_right = 1000.0, 100.0, -40.0, 20.0
    sensor = small_kinect(**{"laser.baseline": baseline})
    scan = rs.scan([plane(4000), box([x_left, -60, 0], [x_right, 60, h])], sensor, pose=top_down_pose(D), seed=0)
    rows = np.abs(scan.xyz_true[..., 1]) < 40
    shadow = (scan.status == Status.SHADOW) & (scan.part == 0) & rows
    x = scan.xyz_true[..., 0][shadow]
    # behind the top edge away from the projector at (b, 0, 0): |b - x_edge| h / (D - h) wide
    if baseline > 0:
        width, expected = x_left - x.min(), (baseline - x_left) * h / (D - h)
    else:
        width, expected = x.max() - x_right, (x_right - baseline) * h / (D - h)
    footprint = D / sensor.focal_px
    assert abs(width - expected) < 1.5 * footprint
    assert not np.any(scan.valid & (scan.status == Status.SHADOW))


def test_edge_fattening_stays_within_half_the_window():
    # a straddling window takes the brighter foreground's disparity, up to half a window out
    rng = np.random.default_rng(0)
    ref = rng.random((30, 200))
    fg, bg = ref[:, 40 - 20:40 - 20 + 120] * 4.0, ref[:, 40 - 5:40 - 5 + 120]  # d = 20 (bright), d = 5
    img = np.concatenate([fg[:, :60], bg[:, 60:]], axis=1)
    d, _ = block_match(img, ref, -10, 30, window=9, min_score=0.0, uniqueness=0.0, lr_check=False)
    fattened = np.sum(np.abs(d[5:25, 60:] - 20) < 0.5, axis=1)
    assert np.median(fattened) >= 1 and fattened.max() <= 4
    # in a scan: wrong-surface depths only within half a window of a true depth edge
    sensor = small_kinect()
    scan = rs.scan([plane(4000), box([-100, -150, 0], [20, 150, 1000])], sensor, pose=top_down_pose(2000.0),
                   seed=0)
    zt = scan.xyz_true[..., 2]
    wrong = scan.valid & ~(np.abs(scan.depth - zt) < 0.03 * zt)
    jump = np.zeros(scan.shape, bool)
    jump[:, 1:] |= np.abs(np.diff(np.nan_to_num(zt, nan=1e5), axis=1)) > 100
    near_edge = ndimage.binary_dilation(jump, iterations=sensor.params["structured_light"]["window"] // 2 + 1)
    assert wrong.sum() > 0 and (wrong & ~near_edge).sum() <= 0.01 * scan.valid.sum()


def test_same_seed_same_scan_and_the_ir_image_is_the_intensity():
    sensor = small_kinect()
    scene = [plane(4000), box([-40, -60, 0], [20, 60, 100])]
    a = rs.scan(scene, sensor, pose=top_down_pose(1000.0), seed=4)
    b = rs.scan(scene, sensor, pose=top_down_pose(1000.0), seed=4)
    c = rs.scan(scene, sensor, pose=top_down_pose(1000.0), seed=5)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert not np.array_equal(a.intensity, c.intensity)
    # the IR image shows the dots: a bright, sparse, textured image, dark in the projector's shadow
    lit = a.status != Status.SHADOW
    assert a.intensity[lit].std() > 0.1 and a.intensity[a.status == Status.SHADOW].mean() < 0.2 * a.intensity[lit].mean()


def test_structured_light_presets_load_and_validate():
    for name in ("kinect_v1", "structured_light_bench"):
        s = rs.load_sensor(name)
        assert s.mode == "structured_light"
    with pytest.raises(rs.RangesimError, match="window"):
        small_kinect(**{"structured_light.window": 8})


def test_scan_saves_as_an_organized_pcd_that_reads_back(tmp_path):
    sensor = small_kinect(**{"camera.width": 160, "camera.height": 120})
    scan = rs.scan([plane(4000), box([-40, -60, 0], [20, 60, 100])], sensor, pose=top_down_pose(1000.0))
    path = scan.save(tmp_path / "frame.pcd")
    header = path.read_bytes()[:400].split(b"DATA")[0].decode()
    assert "WIDTH 160" in header and "HEIGHT 120" in header and "label" in header
    back = rs.load_scan(path)
    np.testing.assert_array_equal(back.valid, scan.valid)
    assert np.nanmax(np.abs(back.xyz - scan.xyz)) < 1e-3  # metres in float32
    try:
        import open3d as o3d
    except ImportError:
        return
    cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False)
    assert len(cloud.points) == 160 * 120


# -- twins of the recorded Kinect frames ---------------------------------------------------------------
def _synthetic_frame(shape):
    """A labelled 'recording' made by scanning a known table and object with the small Kinect."""
    from rangesim.core.geometry import look_at

    table = trimesh.creation.box(extents=(1200, 800, 20))
    table.apply_translation((0, 0, -10))
    obj = (trimesh.creation.box(extents=(160, 100, 120)) if shape == "box"
           else trimesh.creation.cylinder(radius=60, height=150, sections=96))
    obj.apply_translation((0, 0, obj.bounds[1, 2] - obj.bounds[0, 2] and (obj.bounds[1, 2] - obj.bounds[0, 2]) / 2))
    pose = look_at((0, -600, 700), (0, 0, 0), up=(0, 0, 1))
    scan = rs.scan([table, obj], small_kinect(), pose=pose, seed=2)
    labels = np.where(scan.valid, np.where(scan.part == 0, 1, np.where(scan.part == 1, 20, 0)), 0).astype(np.uint32)
    scan.xyz_true = None  # a recording has no truth
    return scan, labels, obj


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_scene_fitted_to_labels_recovers_the_shapes(shape):
    from rangesim.twin.kinect import scene_from_labels

    scan, labels, obj = _synthetic_frame(shape)
    shapes = scene_from_labels(scan, labels)
    assert [s.kind for s in shapes] == ["table", shape]
    fitted = shapes[1]
    if shape == "box":
        size = sorted(fitted.params["size_mm"][:2])
        # the frame's own fattening (half a 9 px window, 3.4 mm per px here) may widen the footprint
        assert size == pytest.approx([100, 160], abs=16) and fitted.params["size_mm"][2] == pytest.approx(120, abs=8)
    else:
        assert fitted.params["radius_mm"] == pytest.approx(60, abs=4)
        assert fitted.params["height_mm"] == pytest.approx(150, abs=8)


def test_kinect_twin_of_a_recorded_frame(data_dir):
    from rangesim.evaluate.runs import load_scan_with_labels
    from rangesim.twin.kinect import compare_kinect

    scan, labels = load_scan_with_labels(data_dir / "mosd-kinect" / "test31.pcd", None)
    m = compare_kinect(scan, labels, "kinect_v1", detectors=["gradient"])
    assert [s["kind"] for s in m["shapes"]] == ["table", "cylinder", "cylinder", "cylinder"]
    assert m["focal_px"] == pytest.approx(525.0, abs=0.5)
    assert m["iou"] > 0.9
    k = m["z2_coefficient_mm_per_m2"]
    assert 0.5 < k["twin"] / k["recorded"] < 2.0  # the z^2 law at the recording's size
    # the same spread ratio as a mesh twin reports (the figure's histogram title)
    assert 0.5 < m["noise_std_ratio"] < 2.0
    # the predicted noise: the twin's own errors have unit spread over it on this real geometry,
    # the recording's a little more (it also holds the fitted scene's own error)
    assert 0.85 < m["z_spread"]["twin"] < 1.2
    assert m["z_spread"]["twin"] < m["z_spread"]["recorded"] < 2.0
    # both show depth in disparity steps: the recording's levels are 0.8-1 of the preset's 1/8 px step
    gaps = m["depth_level_gaps_in_steps"]
    assert gaps["twin"]["median"] == pytest.approx(1.0, abs=0.05)
    assert 0.7 < gaps["recorded"]["median"] < 1.1


def test_cli_compare_kinect_frame_without_mesh(data_dir, tmp_path):
    import json

    from rangesim.cli.main import main

    out = tmp_path / "k"
    assert main(["compare", str(data_dir / "mosd-kinect" / "test0.pcd"), "--sensor", "kinect_v1", "--out",
                 str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["iou"] > 0.9 and len(metrics["shapes"]) == 3
    assert (out / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_an_empty_structured_light_scan_blames_the_block_matcher():
    # 16 x 12 px: the 9 px matching window holds too few dots anywhere; the warning used to
    # say the return signal was below noise.min_signal (0 for this preset)
    from rangesim.core.geometry import look_at
    from rangesim.sensor._scan import EmptyScanWarning

    sensor = rs.load_sensor("kinect_v1").with_params({"camera.width": 16, "camera.height": 12})
    with pytest.warns(EmptyScanWarning, match="block matcher found no reliable match") as caught:
        rs.scan(rs.load_scene("scenes/green_piece.toml"), sensor, pose=look_at((0, 0, 800), (0, 0, 0), up=(0, 1, 0)))
    assert not any("min_signal" in str(w.message) for w in caught)
