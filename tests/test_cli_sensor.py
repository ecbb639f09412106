"""``--sensor`` on the commands that read recordings: ``rangesim detect SCAN --sensor NAME|TOML|auto``
and ``rangesim compare RECORDED --recorded-sensor ...`` (``compare``'s ``--sensor`` is its twin's),
through :func:`rangesim.evaluate.runs.load_scan_with_labels` to the readers that take ``sensor=``
(``.pcd``). Called in-process through :func:`rangesim.cli.main.main`; the Kinect frame comes from
the shared mOSD data and skips when it is absent.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli.main import main
from rangesim.core.errors import RangesimError
from rangesim.edges import DETECTORS
from rangesim.evaluate.runs import load_scan_with_labels
from rangesim.recorded import load_pcd
from rangesim.sensor.config import PRESET_DIR
from tests.conftest import box, plane, top_down_pose


def _cli(capsys, *args) -> tuple[int, str, str]:
    code = main([*map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope="module")
def laser(tmp_path_factory) -> dict[str, Path]:
    """One small noisy laser-stripe scan (white_scanner, 320 x 240) of a box on a tilted plane,
    saved as .pcd (labels from its parts, no sensor metadata), .exr, .npz and .ply."""
    d = tmp_path_factory.mktemp("sensor_inputs")
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 320, "camera.height": 240})
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    tilted = plane(4000)
    tilted.apply_transform(trimesh.transformations.rotation_matrix(math.radians(35.0), [1, 0, 0]))
    dist = 0.5 * (near + far)
    scene = [tilted, box([-0.05 * dist, -0.05 * dist, 0], [0.05 * dist, 0.05 * dist, 0.08 * dist])]
    scan = rs.scan(scene, sensor, pose=top_down_pose(dist), seed=0)
    assert scan.valid.mean() > 0.3
    return {ext: Path(rs.save_scan(scan, d / f"laser.{ext}")) for ext in ("pcd", "exr", "npz", "ply")}


@pytest.fixture
def kinect_frame(data_dir) -> Path:
    path = data_dir / "mosd-kinect" / "test0.pcd"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    return path


def test_detect_kinect_v1_runs_the_block_matched_path(kinect_frame, tmp_path, capsys):
    out = tmp_path / "out"
    code, stdout, err = _cli(capsys, "detect", kinect_frame, "--sensor", "kinect_v1", "--method", "curvature",
                             "--out", out)
    assert code == 0, err
    assert "structured_light, matching window 9 px" in stdout
    report = json.loads((out / "scores.json").read_text())
    assert report["sensor"] == {"given": "kinect_v1", "name": "kinect_v1", "mode": "structured_light",
                                "matching_window": 9}
    assert report["truth"] == "regions" and 0 < report["methods"]["curvature"]["f1"] <= 1
    # the maps written are the block-matched ones the Python API gives, not the default path's
    tagged = DETECTORS["curvature"](load_pcd(kinect_frame, sensor="kinect_v1"))
    assert tagged.params["scale"] == "sensor" and tagged.params["matching_window"] == 9
    default = DETECTORS["curvature"](load_pcd(kinect_frame))
    assert default.params["matching_window"] is None
    with np.load(out / "curvature_edges.npz") as npz:
        np.testing.assert_array_equal(npz["mask"], tagged.mask)
        assert not np.array_equal(npz["mask"], default.mask)
    assert (out / "curvature.png").is_file()


def test_detect_auto_finds_the_lattice_on_a_kinect_frame(kinect_frame, tmp_path, capsys):
    out = tmp_path / "out"
    code, stdout, err = _cli(capsys, "detect", kinect_frame, "--sensor", "auto", "--method", "gradient", "--out", out)
    assert code == 0, err
    assert "from the disparity lattice" in stdout
    sensor = json.loads((out / "scores.json").read_text())["sensor"]
    assert sensor["mode"] == "structured_light" and sensor["matching_window"] == 9
    assert sensor["evidence"]["rule"] == "disparity lattice"


def test_detect_auto_on_a_laser_scan_leaves_the_metadata_unset(laser, tmp_path, capsys):
    scan, labels = load_scan_with_labels(laser["pcd"], sensor="auto")
    assert "sensor" not in scan.meta and "sensor_evidence" not in scan.meta and labels is not None
    out = tmp_path / "out"
    code, stdout, err = _cli(capsys, "detect", laser["pcd"], "--sensor", "auto", "--method", "gradient",
                             "--out", out)
    assert code == 0, err
    assert "no sensor metadata" in stdout
    sensor = json.loads((out / "scores.json").read_text())["sensor"]
    assert sensor == {"given": "auto", "name": None, "mode": None, "matching_window": None}
    # the same maps as without --sensor
    plain = tmp_path / "plain"
    assert _cli(capsys, "detect", laser["pcd"], "--method", "gradient", "--out", plain)[0] == 0
    with np.load(out / "gradient_edges.npz") as a, np.load(plain / "gradient_edges.npz") as b:
        np.testing.assert_array_equal(a["mask"], b["mask"])


def test_detect_sensor_toml(laser, tmp_path, capsys):
    toml = tmp_path / "bench.toml"
    text = (PRESET_DIR / "kinect_v1.toml").read_text()
    assert text.count("window = 9") == 1
    toml.write_text(text.replace("window = 9", "window = 7"))
    out = tmp_path / "out"
    code, stdout, err = _cli(capsys, "detect", laser["pcd"], "--sensor", toml, "--method", "gradient", "--out", out)
    assert code == 0, err
    assert json.loads((out / "scores.json").read_text())["sensor"]["matching_window"] == 7


def test_compare_recorded_sensor(laser, tmp_path, capsys):
    out = tmp_path / "out"
    code, stdout, err = _cli(capsys, "compare", laser["pcd"], "--recorded-sensor", "kinect_v1", "--out", out)
    assert code == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["recorded_sensor"]["mode"] == "structured_light"
    assert set(metrics["edges"]) == set(DETECTORS)
    # without it, metrics.json is as it was
    plain = tmp_path / "plain"
    assert _cli(capsys, "compare", laser["pcd"], "--out", plain)[0] == 0
    assert "recorded_sensor" not in json.loads((plain / "metrics.json").read_text())


@pytest.mark.parametrize(("command", "file", "value", "words"), [
    ("detect", "pcd", "kinectv1", ["laser.pcd", "unknown sensor preset"]),
    ("detect", "pcd", "{tmp}/missing.toml", ["laser.pcd", "missing.toml"]),
    ("detect", "exr", "kinect_v1", ["laser.exr", ".pcd frames only", "'.exr' files take none"]),
    ("detect", "npz", "auto", ["laser.npz", ".pcd frames only"]),
    ("detect", "ply", "kinect_v1", ["laser.ply", ".pcd frames only"]),
    ("detect", "missing", "kinect_v1", ["no such file"]),
    ("compare", "ply", "kinect_v1", ["laser.ply", ".pcd frames only"]),
    ("compare", "pcd", "kinectv1", ["laser.pcd", "unknown sensor preset"]),
])
def test_bad_sensor_is_one_line_exit_2_no_outputs(laser, tmp_path, capsys, command, file, value, words):
    path = laser[file] if file in laser else tmp_path / "missing.pcd"
    option = "--sensor" if command == "detect" else "--recorded-sensor"
    out = tmp_path / "out"
    code, stdout, err = _cli(capsys, command, path, option, value.replace("{tmp}", str(tmp_path)), "--out", out)
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rangesim: error: "), err
    assert "Traceback" not in err and lines[0].isprintable()
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists()


def test_load_scan_with_labels_sensor_keyword(laser):
    scan, labels = load_scan_with_labels(laser["pcd"], sensor={**rs.load_sensor("kinect_v1").to_dict()})
    assert scan.meta["sensor"]["name"] == "kinect_v1" and labels is not None
    scan, labels = load_scan_with_labels(laser["exr"])  # unchanged without it: the scan's own sensor
    assert scan.meta["sensor"]["name"] == "white_scanner" and labels is None
    with pytest.raises(RangesimError, match=r"laser\.exr.*\.pcd frames only"):
        load_scan_with_labels(laser["exr"], sensor="white_scanner")
