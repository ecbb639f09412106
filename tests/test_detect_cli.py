"""``rangesim detect``: edge maps, overlays and scores from the command line.

Called in-process through :func:`rangesim.cli.main.main`. The synthetic scan is a box on a
plane seen obliquely by the quiet 160 x 120 test sensor, saved as .exr beside the scene TOML
it came from; the recorded scans come from the shared data and skip when it is absent.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import rangesim as rs
from rangesim.cli.main import main
from rangesim.core.geometry import look_at
from rangesim.edges import DETECTORS
from tests.conftest import BOX_SCENE_TOML, grid_recording, make_sensor

SCENE_TOML = BOX_SCENE_TOML

ARRAYS = {"mask", "labels", "strength"}
SCORES = ("precision", "recall", "f1", "fom")


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> tuple[Path, Path]:
    """(scan .exr, scene .toml): the box on a plane, camera tilted about 35 degrees."""
    d = tmp_path_factory.mktemp("detect_inputs")
    scene = d / "scene.toml"
    scene.write_text(SCENE_TOML)
    pose = look_at((0.0, -250.0, 380.0), (0.0, 0.0, 20.0), up=(0, 0, 1))
    scan = rs.scan(scene, make_sensor(), pose=pose, seed=0)
    assert 0 < scan.valid.sum() < scan.valid.size  # the box casts a laser shadow
    path = rs.save_scan(scan, d / "scan.exr")
    return Path(path), scene


def _detect(capsys, *args) -> tuple[int, str, str]:
    """``main(["detect", *args])``: exit code, stdout, stderr."""
    code = main(["detect", *map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _check_edge_files(out: Path, shape: tuple[int, int]) -> None:
    """One NPZ (mask, labels, strength of the scan's shape) and one PNG per detector."""
    for method in DETECTORS:
        with np.load(out / f"{method}_edges.npz") as npz:
            assert ARRAYS <= set(npz.files), (method, npz.files)
            assert npz["mask"].shape == shape and npz["mask"].dtype == bool
            assert npz["labels"].shape == shape and int(npz["labels"].max(initial=0)) <= 4  # EdgeLabel 0-3 or edges.RIM
            assert npz["strength"].shape == shape
            assert not npz["labels"][~npz["mask"]].any()  # labels only on edge pixels
        assert (out / f"{method}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _check_scores(out: Path, truth: str) -> dict:
    """scores.json with every detector's scores in [0, 1]; returns the report."""
    report = json.loads((out / "scores.json").read_text())
    assert report["truth"] == truth
    assert set(report["methods"]) == set(DETECTORS)
    for method, s in report["methods"].items():
        for key in SCORES:
            assert 0.0 <= s[key] <= 1.0, (method, key, s[key])
    return report


def test_all_methods_on_synthetic_scan_with_scene(synthetic, tmp_path, capsys):
    scan_path, scene = synthetic
    out = tmp_path / "edges"
    code, stdout, err = _detect(capsys, scan_path, "--method", "all", "--scene", scene, "--out", out)
    assert code == 0, err
    shape = rs.load_scan(scan_path).shape
    _check_edge_files(out, shape)
    assert (out / "ground_truth.png").is_file()
    report = _check_scores(out, "geometry")
    # a noise-free box: the best detector finds most of its edges
    assert max(s["f1"] for s in report["methods"].values()) > 0.5
    assert "truth: geometry" in stdout and all(m in stdout for m in DETECTORS)


def test_single_method(synthetic, tmp_path, capsys):
    scan_path, scene = synthetic
    out = tmp_path / "edges"
    code, _, err = _detect(capsys, scan_path, "--method", "gradient", "--scene", scene, "--out", out)
    assert code == 0, err
    names = sorted(p.name for p in out.iterdir())
    assert names == ["gradient.png", "gradient_edges.npz", "ground_truth.png", "scores.json"]
    with np.load(out / "gradient_edges.npz") as npz:
        assert "direction" in npz.files  # the gradient detector also gives edge directions


def test_a_scan_without_truth_leaves_no_old_scores_in_a_reused_folder(synthetic, tmp_path, capsys):
    scan_path, scene = synthetic
    out = tmp_path / "edges"
    assert _detect(capsys, scan_path, "--method", "gradient", "--scene", scene, "--out", out)[0] == 0
    json.loads((out / "scores.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in scores.json"))
    recording = tmp_path / "rec.npz"
    grid_recording(40, 50).save(recording)  # no truth: scores.json and ground_truth.png were the first scan's
    assert _detect(capsys, recording, "--method", "gradient", "--out", out)[0] == 0
    assert sorted(p.name for p in out.iterdir()) == ["gradient.png", "gradient_edges.npz"]


def test_recorded_range_grid_without_truth(data_dir, tmp_path, capsys):
    ply = data_dir / "stanford-bunny" / "bun000.ply"
    if not ply.is_file():
        pytest.skip(f"{ply} not found")
    out = tmp_path / "bunny"
    code, stdout, err = _detect(capsys, ply, "--method", "all", "--out", out)
    assert code == 0, err
    _check_edge_files(out, (400, 512))
    assert not (out / "scores.json").exists()
    assert not (out / "ground_truth.png").exists()
    assert "truth: none" in stdout


def test_mosd_pcd_scores_against_regions(data_dir, tmp_path, capsys):
    pcd = data_dir / "mosd-kinect" / "test0.pcd"
    if not pcd.is_file():
        pytest.skip(f"{pcd} not found")
    out = tmp_path / "mosd"
    code, stdout, err = _detect(capsys, pcd, "--method", "all", "--out", out)
    assert code == 0, err
    _check_edge_files(out, (480, 640))
    _check_scores(out, "regions")
    assert (out / "ground_truth.png").is_file()
    assert "truth: regions (the boundaries of the file's label regions: object outlines, no creases)" in stdout


def test_missing_scan_is_a_one_line_error(tmp_path, capsys):
    missing = tmp_path / "no_such_scan.exr"
    code, stdout, err = _detect(capsys, missing, "--out", tmp_path / "edges")
    assert code == 2
    assert err.strip() and err.strip().count("\n") == 0, err
    assert "no_such_scan.exr" in err and "Traceback" not in err
    assert not (tmp_path / "edges").exists()


def test_out_pointing_at_a_file_is_an_error(synthetic, tmp_path, capsys):
    scan_path, scene = synthetic
    target = tmp_path / "a_file"
    target.write_text("not a directory")
    code, _, err = _detect(capsys, scan_path, "--scene", scene, "--out", target)
    assert code == 2
    assert err.strip().count("\n") == 0 and "Traceback" not in err
    assert target.read_text() == "not a directory"


def test_detect_refuses_what_it_cannot_score(synthetic, tmp_path, capsys):
    """From a new user's probe: a scan with no valid pixel went through with every score 1.0;
    a scene file edited since the scan was scored against silently (F1 0); scores.json now says
    which convention it counts by."""
    import dataclasses

    scan_path, scene_path = synthetic
    scan = rs.load_scan(scan_path)
    empty = dataclasses.replace(scan, valid=np.zeros(scan.shape, bool))
    empty_path = rs.save_scan(empty, tmp_path / "empty.exr")
    code, _, err = _detect(capsys, empty_path, "--method", "gradient", "--out", tmp_path / "e")
    assert code == 2 and "no valid pixel" in err and "Traceback" not in err and not (tmp_path / "e").exists()
    assert main(["features", str(empty_path), "--out", str(tmp_path / "f")]) == 2
    # the scene the scan names, edited since: refused, not scored
    edited = tmp_path / "scene.toml"
    edited.write_text(SCENE_TOML.replace("translate = [0, 0, 25]", "translate = [150, 120, 25]"))
    moved = dataclasses.replace(scan, meta={**scan.meta, "scene": str(edited)})
    moved_path = rs.save_scan(moved, tmp_path / "moved.exr")
    code, _, err = _detect(capsys, moved_path, "--method", "gradient", "--out", tmp_path / "m")
    assert code == 2 and "no longer matches" in err
    # the scene as it was: scored, and the report names its convention
    code, _, _ = _detect(capsys, scan_path, "--method", "gradient", "--out", tmp_path / "ok")
    report = json.loads((tmp_path / "ok" / "scores.json").read_text())
    assert code == 0 and report["ignore_data_boundary"] is False


def test_scene_check_is_per_object(tmp_path, capsys):
    """A small box on a large table, seen from above: the table filled most pixels, so the same
    scene with the box turned 30 degrees matched 92 % of the pixels and passed the 90 % check."""
    body = ('units = "mm"\n[[object]]\nname = "box"\nprimitive = "box"\nsize = [60, 60, 30]\ntranslate = [0, 0, 15]\n'
            '{turn}[[object]]\nname = "table"\nprimitive = "plane"\nsize = [1200, 1200]\n')
    made = tmp_path / "made.toml"
    made.write_text(body.format(turn=""))
    turned = tmp_path / "turned.toml"
    turned.write_text(body.format(turn="rotate_deg = [0, 0, 30]\n"))
    sensor = make_sensor(**{"noise.sigma_px": 0.0})
    scan = rs.scan(made, sensor, pose=look_at((0.0, 0.0, 420.0), (0.0, 0.0, 0.0), up=(0, 1, 0)), seed=0)
    path = rs.save_scan(scan, tmp_path / "scan.exr")
    from rangesim.cli.scene_match import scene_match_share

    assert scene_match_share(scan, rs.load_scene(made)) > 0.99
    code, _, err = _detect(capsys, path, "--method", "gradient", "--scene", turned, "--out", tmp_path / "d")
    assert code == 2 and "does not match this scan" in err


def test_detect_and_diff_details_from_a_users_probe(synthetic, tmp_path, capsys):
    import dataclasses

    scan_path, scene_path = synthetic
    scan = rs.load_scan(scan_path)
    # a detector's refusal names the file (it named only "scan.depth")
    bad = scan.depth.copy()
    bad[scan.valid] = -bad[scan.valid]
    neg = rs.save_scan(dataclasses.replace(scan, depth=bad, xyz=scan.xyz * np.array([1, 1, -1], np.float32)),
                       tmp_path / "neg.npz")
    code, _, err = _detect(capsys, neg, "--method", "gradient", "--out", tmp_path / "n")
    assert code == 2 and err.startswith(f"rangesim: error: {neg}") and "Traceback" not in err
    # truth is kept only where the detectors can read a depth (valid without a depth: a hole)
    holed = dataclasses.replace(scan, depth=np.where(np.arange(scan.shape[1]) < 20, np.nan, scan.depth).astype(np.float32))
    truth = rs.evaluate.visible_truth(holed, rs.load_scene(scene_path))
    assert not truth[:, :20].any()
    # diff of two views warns that it compares different surface points
    other = rs.save_scan(dataclasses.replace(scan, pose=scan.pose @ np.diag([1.0, 1.0, 1.0, 1.0])
                                             + np.array([[0, 0, 0, 50.0], [0] * 4, [0] * 4, [0] * 4])),
                         tmp_path / "other.exr")
    assert main(["diff", str(scan_path), str(other), "--out", str(tmp_path / "d.png")]) == 0
    assert "another pose" in capsys.readouterr().err


def test_feature_precision_needs_feature_truth():
    """A scene without analytic features (primitives) judged 5 correct box edges precision 0."""
    from rangesim.features._lines import Segment

    found = {"segments": [Segment((0.0, 0.0), (30.0, 0.0), 30.0, None, 30, 0.1)]}
    s = rs.evaluate.feature_scores(found, {"circles": [], "segments": []})
    assert np.isnan(s["segments"]["precision"]) and np.isnan(s["round"]["precision"])


def test_edge_files_describe_themselves_and_another_scans_leave(synthetic, tmp_path, capsys):
    """A reused folder kept another scan's maps of the methods not run now beside the new ones;
    the NPZ files now say which scan and method made them, with the parameters used."""
    import dataclasses

    scan_path, _ = synthetic
    out = tmp_path / "d"
    assert _detect(capsys, scan_path, "--method", "all", "--out", out)[0] == 0
    with np.load(out / "normal_edges.npz") as npz:
        assert str(npz["method"]) == "normal" and str(npz["scan"]) == str(Path(scan_path).resolve())
        assert "threshold_deg" in json.loads(str(npz["params"]))
    # the same scan, one method: the others' files stay (they are this scan's)
    assert _detect(capsys, scan_path, "--method", "gradient", "--out", out)[0] == 0
    assert (out / "normal_edges.npz").is_file()
    # another scan, one method: the first scan's other maps go
    other = rs.save_scan(dataclasses.replace(rs.load_scan(scan_path)), tmp_path / "other.exr")
    assert _detect(capsys, other, "--method", "gradient", "--out", out)[0] == 0
    assert not (out / "normal_edges.npz").exists() and not (out / "normal.png").exists()
    assert (out / "gradient_edges.npz").is_file()


def test_a_bare_mesh_in_cm_keeps_its_units_for_the_truth(tmp_path, capsys):
    """``rangesim scan part.stl --units cm``: the scan named the .stl, and detect rebuilt its
    truth from it in millimetres, 10x too small (now refused by the scene check, before
    silently scored against it): the scan records the mesh's units and the truth uses them."""
    import trimesh

    trimesh.creation.box((4.0, 3.0, 2.0)).export(tmp_path / "part.stl")
    scan_path = tmp_path / "p.exr"
    assert main(["scan", str(tmp_path / "part.stl"), "--units", "cm", "--sensor", "white_scanner", "--set",
                 "camera.width=96", "--set", "camera.height=90", "--out", str(scan_path), "--quiet"]) == 0
    assert rs.load_scan(scan_path).meta["scene_units"] == "cm"
    code, out, _ = _detect(capsys, scan_path, "--method", "gradient", "--out", tmp_path / "d")
    report = json.loads((tmp_path / "d" / "scores.json").read_text())
    assert code == 0 and report["truth"] == "geometry" and report["methods"]["gradient"]["f1"] > 0.9
    assert main(["features", str(scan_path), "--out", str(tmp_path / "f"), "--quiet"]) == 0


def test_nothing_to_find_prints_and_writes_no_score(tmp_path, capsys):
    """A plane seen from above holds no true edge pixel: scores.json has null, not 1.0, and the
    printed table a dash."""
    (tmp_path / "plane.toml").write_text('units = "mm"\n[[object]]\nname = "table"\nprimitive = "plane"\n'
                                         'size = [2000, 2000]\n[view]\nposition = [0, 0, 400]\n'
                                         'look_at = [0, 0, 0]\nup = [0, 1, 0]\n')
    scan = rs.scan(tmp_path / "plane.toml", make_sensor(**{"noise.sigma_px": 0.0}), seed=0)
    path = rs.save_scan(scan, tmp_path / "plane.exr")
    code, out, _ = _detect(capsys, path, "--method", "gradient", "--out", tmp_path / "d")
    report = json.loads((tmp_path / "d" / "scores.json").read_text())
    assert code == 0 and report["methods"]["gradient"]["n_gt"] == 0
    assert report["methods"]["gradient"]["recall"] is None and report["methods"]["gradient"]["f1"] is None
    assert "      -" in out.splitlines()[-2]
