"""Recordings of a block matcher (structured light): ``sensor=`` on the PCD reader, and the
disparity-lattice rule (``rangesim.edges._matching_scale.disparity_lattice``) that tells one
from its depths alone: Kinect-type depth is ``f b / d`` with ``d`` on 1/8 px steps, so the gaps
between its depth levels grow as z^2; laser scans' depths are continuous, and depths rounded
to a fixed unit have constant gaps.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import look_at
from rangesim.edges._matching_scale import disparity_lattice, matching_window
from rangesim.recorded import load_pcd, read_pcd
from tests.conftest import box, plane, top_down_pose

#: the kinect_v1 optics and matcher on a 320 x 240 image (f and the disparities halve)
SMALL_KINECT = {"camera.width": 320, "camera.height": 240}


def _table_top(sensor, eye, seed=2):
    """A table with a box on it, seen obliquely from ``eye`` (depths over a wide span)."""
    table = trimesh.creation.box(extents=(3000, 4000, 20))
    table.apply_translation((0, 0, -10))
    obj = trimesh.creation.box(extents=(300, 200, 250))
    obj.apply_translation((0, 0, 125))
    return rs.scan([table, obj], sensor, pose=look_at(eye, (0, 0, 0), up=(0, 0, 1)), seed=seed)


@pytest.fixture(scope="module")
def kinect_recording():
    """A simulated kinect_v1 scan made to look recorded: no ``meta["sensor"]``."""
    scan = _table_top(rs.load_sensor("kinect_v1").with_params(SMALL_KINECT), (0, -1500, 900))
    scan.meta.pop("sensor")
    scan.xyz_true = None
    return scan


def _laser_scan(name, noise=True):
    sensor = rs.load_sensor(name)
    if not noise:
        sensor = sensor.with_params({"noise.sigma_px": 0.0})
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    tilted = plane(4000)
    tilted.apply_transform(trimesh.transformations.rotation_matrix(math.radians(35.0), [1, 0, 0]))
    d = 0.5 * (near + far)
    scene = [tilted, box([-0.05 * d, -0.05 * d, 0], [0.05 * d, 0.05 * d, 0.08 * d])]
    return rs.scan(scene, sensor, pose=top_down_pose(d), seed=0)


def test_a_block_matched_scan_without_metadata_is_detected(kinect_recording):
    z = kinect_recording.depth
    found = disparity_lattice(z)
    assert found is not None
    assert 1.9 <= found["slope"] <= 2.1
    # its lattice is the small Kinect's: 8 steps x f b (f = 277 px at 320 px wide, b = 75 mm)
    f = 160.0 / math.tan(math.radians(29.0))
    assert found["fb_steps"] == pytest.approx(8 * f * 75.0, rel=0.03)
    # rounded to whole millimetres, as OpenNI stores depth: still found, rounding seen
    rounded = disparity_lattice(np.round(z))
    assert rounded is not None and rounded["rounding_mm"] == 1.0
    assert rounded["fb_steps"] == pytest.approx(found["fb_steps"], rel=0.03)
    # the detectors do not detect by themselves; asked to, the kinect_v1 preset's window
    assert matching_window(kinect_recording) is None
    assert matching_window(kinect_recording, detect=True) == 9


@pytest.mark.parametrize("name", ["white_scanner", "inria_laser", "cyberware_3030"])
@pytest.mark.parametrize("noise", [True, False])
def test_laser_and_noise_free_scans_are_not_block_matched(name, noise):
    scan = _laser_scan(name, noise)
    assert scan.valid.mean() > 0.3
    assert disparity_lattice(scan.depth) is None
    # depth rounded to a fixed unit has constant gaps between levels, not z^2 ones
    assert disparity_lattice(np.round(scan.depth)) is None
    assert disparity_lattice(np.round(scan.depth * 10.0) / 10.0) is None
    assert matching_window(scan, detect=True) is None          # its metadata says laser anyway
    scan.meta.pop("sensor")
    assert matching_window(scan, detect=True) is None


def test_ambiguous_depth_spans_are_refused():
    """A frontal plane: quantised, but its levels span too little depth to tell z^2 gaps from
    constant ones; and too few levels."""
    sensor = rs.load_sensor("kinect_v1").with_params(SMALL_KINECT)
    scan = rs.scan([plane(4000), box([-100, -100, 0], [100, 100, 150])], sensor, pose=top_down_pose(1500.0), seed=0)
    assert disparity_lattice(scan.depth) is None
    assert disparity_lattice(np.full((40, 40), 1000.0)) is None
    assert disparity_lattice(np.full((40, 40), np.nan)) is None


def test_reader_sensor_keyword(kinect_recording, tmp_path):
    path = tmp_path / "frame.pcd"
    kinect_recording.save(path)
    plain = load_pcd(path)
    assert "sensor" not in plain.meta and matching_window(plain) is None
    named, extras = read_pcd(path, sensor="kinect_v1")
    assert named.meta["sensor"]["mode"] == "structured_light" and matching_window(named) == 9
    assert "label" in extras
    custom = rs.load_scan(path, sensor=rs.load_sensor("kinect_v1").with_params({"structured_light.window": 7}))
    assert matching_window(custom) == 7
    auto = rs.load_scan(path, sensor="auto")
    assert matching_window(auto) == 9 and auto.meta["sensor_evidence"]["rule"] == "disparity lattice"
    np.testing.assert_array_equal(auto.depth, plain.depth)
    laser = tmp_path / "laser.pcd"
    _laser_scan("white_scanner").save(laser)
    assert "sensor" not in load_pcd(laser, sensor="auto").meta


def test_a_sensor_of_another_image_size_is_named(kinect_recording, tmp_path):
    """A preset whose camera is not the frame's size (a 2x-binned Kinect frame read with
    kinect_v1's 640 x 480) is attached, as asked, with a one-line warning naming both sizes:
    its matching window and noise law are in its own pixels. The frame's own size is quiet."""
    path = tmp_path / "frame.pcd"
    kinect_recording.save(path)
    h, w = kinect_recording.shape
    with pytest.warns(UserWarning, match=rf"frame.pcd: the file is {w} x {h} px, sensor kinect_v1 640 x 480"):
        scan = load_pcd(path, sensor="kinect_v1")
    assert matching_window(scan) == 9
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_pcd(path, sensor=rs.load_sensor("kinect_v1").with_params(SMALL_KINECT))


@pytest.mark.parametrize("bad, words", [("kinectv1", "unknown sensor preset"), (3, "sensor= must be")])
def test_reader_bad_sensor_is_a_one_line_error(kinect_recording, tmp_path, bad, words):
    path = tmp_path / "frame.pcd"
    kinect_recording.save(path)
    with pytest.raises(RangesimError) as err:
        load_pcd(path, sensor=bad)
    text = str(err.value)
    assert words in text and "frame.pcd" in text and "\n" not in text


def test_recorded_kinect_frames_are_detected(data_dir):
    frames = sorted((data_dir / "mosd-kinect").glob("test*.pcd")) + sorted((data_dir / "pcl-organized").glob("*.pcd"))
    if not frames:
        pytest.skip("no recorded Kinect frames in the shared data")
    for path in frames:
        found = disparity_lattice(load_pcd(path).depth)
        assert found is not None, path.name
        # 8 steps x f b: 525 px x 75 mm nominal; the devices' about 5-10 % more
        assert 8 * 525 * 75 * 0.95 <= found["fb_steps"] <= 8 * 525 * 75 * 1.2, path.name
        assert found["rounding_mm"] == 1.0


def test_the_default_matcher_is_the_kinect_presets():
    """The core's stand-in for a block matcher of unknown make is the kinect_v1 preset's
    matcher (the analysis layer reads no sensor files, so the window is a constant there)."""
    from rangesim.core.quantisation import DEFAULT_MATCHER_PRESET, DEFAULT_MATCHER_WINDOW

    sensor = rs.load_sensor(DEFAULT_MATCHER_PRESET)
    assert sensor.mode == "structured_light"
    assert sensor.params["structured_light"]["window"] == DEFAULT_MATCHER_WINDOW


def test_features_takes_the_recording_sensor_as_detect_does(data_dir, tmp_path, capsys):
    """``rangesim features`` read a .pcd frame with no sensor, so its detectors never took their
    block-matched paths (``detect`` has had ``--sensor``): on mOSD test31 no cylinder top was
    found. With ``--sensor auto`` (kinect_v1, from the disparity lattice) the tall cylinder's
    top, an ellipse centred near (349, 186) px with semi-axes about 33 x 17 px (fitted to the
    top face's labelled pixels), is."""
    import json

    from rangesim.cli.main import main

    frame = data_dir / "mosd-kinect" / "test31.pcd"
    out = tmp_path / "f"
    assert main(["features", str(frame), "--out", str(out), "--sensor", "auto"]) == 0
    assert "sensor auto: kinect_v1" in capsys.readouterr().out
    found = json.loads((out / "features.json").read_text())["ellipses"]
    tops = [e for e in found if math.dist(e["center"], (349, 186)) < 4]
    assert len(tops) == 1
    assert 28 < max(tops[0]["axes"]) < 38 and 12 < min(tops[0]["axes"]) < 20
