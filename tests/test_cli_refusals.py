"""Bad input the command line refuses up front: one line naming the file and the problem, exit
code 2, no traceback, and no output file left behind."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli.main import main
from rangesim.core.errors import RangesimError
from tests.conftest import grid_recording

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
GREEN = str(ROOT / "scenes" / "green_piece.toml")


def _refused(capsys, argv, *words):
    """``main(argv)`` exits 2 with one error line that holds every word."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rangesim: error:"), err
    assert "Traceback" not in err
    for word in words:
        assert str(word) in lines[0], (word, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    """The small synthetic plate scan as .exr (and .npz)."""
    folder = tmp_path_factory.mktemp("plate")
    scan = rs.datasets.plate_scan()
    scan.save(folder / "plate.exr")
    return folder / "plate.exr"


# -- 1: calibrate or compare a mesh that does not overlap the recording -------------------------
@pytest.mark.parametrize(("command", "options", "words"), [
    ("calibrate", ["--geometry-only"], ["IoU"]),
    # without a fit nothing checked it: IoU 0, NaN statistics and "hole recall 1.000", exit code 0
    ("compare", ["--no-fit"], ["silhouette"]),
])
def test_a_mesh_that_does_not_overlap_is_refused(tmp_path, capsys, command, options, words):
    rec = tmp_path / "rec.npz"
    grid_recording(60, 70, x0=-17.0, y0=-21.0).save(rec)
    far = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    far.apply_translation((5000.0, 5000.0, 0.0))
    mesh = tmp_path / "far.stl"
    far.export(mesh)
    out = tmp_path / ("c.toml" if command == "calibrate" else "d")
    _refused(capsys, [command, rec, "--mesh", mesh, "--sensor", "cyberware_3030", "--out", out, *options],
             "do not overlap", "far.stl", *words)
    assert not out.exists()


@pytest.mark.parametrize("command", ["compare", "calibrate"])
@pytest.mark.parametrize(("text", "words"), [
    ("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "1 vertices have NaN or infinite coordinates"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "not a triangle mesh"),   # (the words of scan's mesh reader)
])
def test_twin_meshes_with_nan_vertices_or_no_triangles_are_refused_by_name(tmp_path, capsys, command, text, words):
    # compare once wrote IoU 0 and NaN statistics for the NaN mesh, with exit code 0
    rec = tmp_path / "rec.npz"
    grid_recording(60, 70, x0=-17.0, y0=-21.0).save(rec)
    mesh = tmp_path / "bad.obj"
    mesh.write_text(text)
    out = tmp_path / ("c.toml" if command == "calibrate" else "d")
    extra = ["--sensor", "cyberware_3030", "--geometry-only"] if command == "calibrate" else ["--no-fit"]
    _refused(capsys, [command, rec, "--mesh", mesh, "--out", out, *extra], "bad.obj", words)
    assert not out.exists()


@pytest.mark.parametrize("command", ["compare", "calibrate"])
def test_a_structured_light_sensor_is_refused_for_a_mesh_twin(tmp_path, capsys, command):
    # compare once twinned a laser-stripe recording with kinect_v1's numbers in the stripe model, exit 0
    rec = tmp_path / "rec.npz"
    grid_recording(60, 70, x0=-17.0, y0=-21.0).save(rec)
    mesh = tmp_path / "plate.stl"
    trimesh.creation.box(extents=(60.0, 60.0, 2.0)).export(mesh)
    out = tmp_path / ("c.toml" if command == "calibrate" else "d")
    extra = ["--geometry-only"] if command == "calibrate" else ["--no-fit"]
    _refused(capsys, [command, rec, "--mesh", mesh, "--sensor", "kinect_v1", "--out", out, *extra],
             "kinect_v1", "structured-light", "laser-stripe")
    assert not out.exists()


def test_calibrate_views_refuses_no_overlap_in_the_library(tmp_path):
    from rangesim.twin.joint import calibrate_views

    far = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    far.apply_translation((5000.0, 5000.0, 0.0))
    with pytest.raises(RangesimError, match="do not overlap"):
        calibrate_views([grid_recording(60, 70, x0=-17.0, y0=-21.0)], far, "cyberware_3030", fit_noise=False)


# -- 2: calibrate's options ----------------------------------------------------------------------
@pytest.mark.parametrize("extra, words", [
    (["--evaluations", "0"], ["--evaluations", ">= 1"]),
    (["--evaluations", "-5"], ["--evaluations", ">= 1"]),
    (["--name", ""], ["--name"]),
    (["--report", "/proc/rangesim-test/r.json"], ["/proc/rangesim-test/r.json"]),
])
def test_calibrate_checks_options_up_front(tmp_path, capsys, extra, words):
    rec = tmp_path / "rec.npz"
    grid_recording(60, 70, x0=-17.0, y0=-21.0).save(rec)
    mesh = tmp_path / "box.stl"
    trimesh.creation.box(extents=(10.0, 10.0, 10.0)).export(mesh)
    out = tmp_path / "c.toml"
    _refused(capsys, ["calibrate", rec, "--mesh", mesh, "--sensor", "cyberware_3030", "--out", out, *extra], *words)
    assert not out.exists()


# -- 3: a scene that is not the scan's -----------------------------------------------------------
@pytest.mark.parametrize("command", ["detect", "features"])
def test_scoring_against_the_wrong_scene_is_refused(plate, tmp_path, capsys, command):
    out = tmp_path / "o"
    extra = ["--method", "gradient"] if command == "detect" else []
    _refused(capsys, [command, plate, "--scene", GREEN, "--out", out, *extra], "plate.exr", "does not match")
    assert not out.exists()


def test_scene_match_share_is_one_for_the_scans_own_scene():
    from rangesim.cli.scene_match import MIN_SCENE_MATCH, scene_match_share

    scan = rs.datasets.plate_scan(width=64, height=60)
    assert scene_match_share(scan, rs.datasets.plate_scene()) >= MIN_SCENE_MATCH
    assert scene_match_share(scan, rs.load_scene(GREEN)) < MIN_SCENE_MATCH


# -- 4: every output checked before any is written -------------------------------------------------
def test_model_writes_no_mesh_when_the_tree_cannot_be_written(tmp_path, capsys):
    out = tmp_path / "o" / "m.stl"
    tree = tmp_path / "t.json"
    tree.mkdir()
    _refused(capsys, ["model", "green_piece", "--out", out, "--tree", tree], "t.json", "directory")
    assert not out.exists()
    _refused(capsys, ["model", "green_piece", "--out", out, "--tree", "/proc/rangesim-test/t.json"], "/proc")
    assert not out.exists()


def test_volumes_writes_no_json_when_the_picture_cannot_be_written(tmp_path, capsys):
    out = tmp_path / "o" / "v.json"
    _refused(capsys, ["volumes", "green_piece", "--out", out, "--picture", "/proc/rangesim-test/v.png"], "/proc")
    assert not out.exists()


def test_features_writes_nothing_when_one_output_is_a_directory(plate, tmp_path, capsys):
    out = tmp_path / "f"
    (out / "features.png").mkdir(parents=True)
    line = _refused(capsys, ["features", plate, "--out", out], "features.png", "directory")
    assert ".tmp-" not in line
    assert sorted(p.name for p in out.iterdir()) == ["features.png"]


# -- 5: --conf with a scan that is not a Stanford .ply ---------------------------------------------
@pytest.mark.parametrize("command", ["compare", "detect", "calibrate"])
def test_conf_with_an_exr_is_refused(plate, tmp_path, capsys, command):
    conf = tmp_path / "bun.conf"
    conf.write_text("camera 0 0 0 0 0 0 1\nbmesh bun000.ply 0 0 0 0 0 0 1\n")
    mesh = tmp_path / "box.stl"
    trimesh.creation.box(extents=(10.0, 10.0, 10.0)).export(mesh)
    out = tmp_path / ("c.toml" if command == "calibrate" else "d")
    extra = {"compare": ["--mesh", mesh], "detect": [], "calibrate": ["--mesh", mesh, "--sensor", "cyberware_3030"]}
    line = _refused(capsys, [command, plate, "--conf", conf, "--out", out, *extra[command]],
                    "plate.exr", "--conf applies to Stanford .ply range grids only")
    assert "TypeError" not in line
    assert not out.exists()


# -- 6: calibrate on a synthetic scan ----------------------------------------------------------------
def test_calibrate_names_a_synthetic_scan(plate, tmp_path, capsys):
    mesh = tmp_path / "box.stl"
    trimesh.creation.box(extents=(10.0, 10.0, 10.0)).export(mesh)
    out = tmp_path / "a.toml"
    _refused(capsys, ["calibrate", plate, "--mesh", mesh, "--sensor", "cyberware_3030", "--out", out],
             "plate.exr", "synthetic")
    assert not out.exists()


# -- 8: model parameters ------------------------------------------------------------------------
@pytest.mark.parametrize("param, words", [
    ("thickness=nan", ["thickness", "finite"]),
    ("thickness=inf", ["thickness", "finite"]),
    ("thickness=1e9", ["thickness", "out of range"]),
    ("=5", ["parameter name"]),
])
def test_model_params_are_validated(tmp_path, capsys, param, words):
    out = tmp_path / "m.stl"
    line = _refused(capsys, ["model", "green_piece", "--param", param, "--out", out], "green_piece", *words)
    assert "convert" not in line and "incompatible" not in line
    assert not out.exists()


# -- 7: a dataset whose every view would be empty ----------------------------------------------------
def test_dataset_refuses_a_distance_outside_the_working_range(tmp_path, capsys):
    out = tmp_path / "ds"
    _refused(capsys, ["dataset", "--scene", GREEN, "--views", "2", "--out", out, "--distance", "1e6", "2e6",
                      "--set", "camera.width=32", "--set", "camera.height=24", "--workers", "0", "--quiet"],
             "working range", "empty")
    assert not out.exists()


def test_dataset_prints_plain_numbers(tmp_path, capsys):
    line = _refused(capsys, ["dataset", "--scene", GREEN, "--views", "1", "--out", tmp_path / "ds",
                             "--target", "nan", "0", "0", "--workers", "0", "--quiet"], "target", "nan")
    assert "np.float64" not in line


# -- 10: smaller ones --------------------------------------------------------------------------------
def test_diff_names_both_files(plate, tmp_path, capsys):
    other = tmp_path / "small.npz"
    rs.datasets.plate_scan(width=32, height=30).save(other)
    out = tmp_path / "d.png"
    _refused(capsys, ["diff", plate, other, "--out", out], "plate.exr", "small.npz")
    assert not out.exists()


def test_diff_of_empty_scans_is_refused_and_of_disjoint_ones_says_so(plate, tmp_path, capsys):
    scan = rs.load_scan(plate)
    empty = tmp_path / "empty.npz"
    dataclasses.replace(scan, **{k: getattr(scan, k)[:0, :0] for k in ("depth", "xyz", "valid", "normal", "intensity",
                                                                      "part", "face", "status", "xyz_true", "sigma")
                                  if getattr(scan, k) is not None}).save(empty)
    out = tmp_path / "d.png"
    _refused(capsys, ["diff", empty, empty, "--out", out], "empty.npz", "empty scan (0 x 0 px)")  # was ZeroDivisionError
    assert not out.exists()
    blank = tmp_path / "blank.npz"
    dataclasses.replace(scan, valid=np.zeros_like(scan.valid)).save(blank)
    assert main(["diff", str(blank), str(plate), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "no pixel valid in both" in printed and "nan" not in printed


@pytest.mark.parametrize("command", ["detect", "features"])
def test_scene_with_a_recording_is_refused(tmp_path, capsys, command):
    rec = tmp_path / "rec.npz"
    grid_recording(60, 70, x0=-17.0, y0=-21.0).save(rec)
    out = tmp_path / "o"
    _refused(capsys, [command, rec, "--scene", GREEN, "--out", out], "rec.npz", "ground truth")
    assert not out.exists()


def test_truncated_exr_is_one_line(plate, tmp_path, capfd):
    broken = tmp_path / "trunc.exr"
    data = plate.read_bytes()
    broken.write_bytes(data[: len(data) // 2])
    assert main(["detect", str(broken), "--out", str(tmp_path / "d")]) == 2
    captured = capfd.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "trunc.exr" in lines[0] and "truncated or corrupt" in lines[0], captured.err


def test_kinect_twin_refusals_name_the_frame(tmp_path, capsys):
    from rangesim.recorded import write_pcd

    scan = rs.datasets.plate_scan(width=32, height=30)
    frame = tmp_path / "frame.pcd"
    write_pcd(scan, frame, extras={"label": np.zeros(scan.shape, np.uint32)})  # no table label at all
    _refused(capsys, ["compare", frame, "--sensor", "kinect_v1", "--out", tmp_path / "d"], "frame.pcd", "table")


def test_dataset_refuses_a_target_that_keeps_the_part_out_of_view(tmp_path, capsys):
    """A target 2 m beside the part made every view empty (warnings only, exit 0): the cap's
    cameras look at the target, the part outside their field of view or beyond their range."""
    out = tmp_path / "ds"
    _refused(capsys, ["dataset", "--scene", GREEN, "--views", "2", "--out", out, "--target", "2000", "0", "0",
                      "--set", "camera.width=32", "--set", "camera.height=24", "--workers", "0", "--quiet"],
             "field of view", "target [2000, 0, 0]", "empty")
    assert not out.exists()


# -- a review's findings (seventeenth session): a moved scan, a scan without depth or intrinsics -------------
@pytest.fixture(scope="module")
def moved(tmp_path_factory):
    """A small Green Piece scan whose scene file was deleted after the scan (a folder moved)."""
    folder = tmp_path_factory.mktemp("moved")
    scene = folder / "green_piece.toml"
    scene.write_text((ROOT / "scenes" / "green_piece.toml").read_text())
    assert main(["scan", str(scene), "--set", "camera.width=64", "--set", "camera.height=60",
                 "--out", str(folder / "r.npz"), "--quiet"]) == 0
    scene.unlink()
    return folder / "r.npz"


@pytest.mark.parametrize(("command", "lost"), [("detect", "no ground truth, no scores"),
                                               ("features", "ellipses from the edges alone")])
def test_a_scan_whose_scene_is_gone_says_so(tmp_path, capsys, moved, command, lost):
    out = tmp_path / "out"
    assert main([command, str(moved), "--out", str(out)]) == 0   # the detectors still run
    # (progress lines, which a slow run on a loaded machine prints to a non-terminal, aside)
    err = [line for line in capsys.readouterr().err.strip().splitlines() if " %)" not in line]
    assert len(err) == 1 and err[0].startswith("rangesim: warning: "), err
    assert "r.npz" in err[0] and "green_piece.toml" in err[0] and "is not there" in err[0] and lost in err[0]
    assert "--scene" in err[0]


@pytest.mark.parametrize("command", ["detect", "features"])
def test_scans_without_depth_or_intrinsics_are_refused_by_name(tmp_path, capsys, moved, command):
    scan = rs.load_scan(moved)
    no_depth = tmp_path / "no_depth.npz"
    dataclasses.replace(scan, depth=np.full(scan.shape, np.nan, np.float32)).save(no_depth)
    _refused(capsys, [command, no_depth, "--out", tmp_path / "a"], "no_depth.npz", "no valid pixel (with a depth)")
    assert not (tmp_path / "a").exists()
    no_k = tmp_path / "no_k.npz"  # naming a scene that is there (--scene checks the intrinsics itself)
    meta = {**{k: v for k, v in scan.meta.items() if k != "K"}, "scene": GREEN}
    dataclasses.replace(scan, meta=meta).save(no_k)
    _refused(capsys, [command, no_k, "--out", tmp_path / "b"], "no_k.npz", "meta['K']")
    assert not (tmp_path / "b").exists()


def test_compare_reads_its_mesh_as_scan_does(tmp_path, capsys):
    rec = tmp_path / "rec.npz"
    grid_recording(60, 70).save(rec)
    whole = tmp_path / "box.stl"
    trimesh.creation.box(extents=(20.0, 20.0, 20.0)).export(whole)
    cut = tmp_path / "cut.stl"
    cut.write_bytes(whole.read_bytes()[:300])
    _refused(capsys, ["compare", rec, "--mesh", cut, "--sensor", "cyberware_3030", "--out", tmp_path / "c"],
             "cut.stl", "truncated binary STL")
    _refused(capsys, ["compare", rec, "--mesh", tmp_path, "--sensor", "cyberware_3030", "--out", tmp_path / "c"],
             "is a directory")


def test_a_failed_write_leaves_no_empty_output_folder(tmp_path, capsys, monkeypatch, plate):
    import rangesim.viz.edge_overlay as overlay

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(overlay, "save_edge_overlay", full_disk)
    out = tmp_path / "new" / "deeper" / "out"
    assert main(["detect", str(plate), "--method", "gradient", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()                 # (a note that it made the folders)
    assert err[-1].startswith("rangesim: error: ") and "No space left" in err[-1], err
    assert not (tmp_path / "new").exists()                              # made by the run, left empty: removed
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "notes.txt").write_text("mine")
    _refused(capsys, ["detect", plate, "--method", "gradient", "--out", kept / "out"], "No space left")
    assert sorted(p.name for p in kept.iterdir()) == ["notes.txt"]       # a folder that was there stays
    # empty folders that were there stay, whatever the path's spelling (a review's case: `..`)
    (tmp_path / "existing" / "empty").mkdir(parents=True)
    assert main(["detect", str(plate), "--method", "gradient",
                 "--out", str(tmp_path / "new2" / ".." / "existing" / "out")]) == 2
    assert (tmp_path / "existing" / "empty").is_dir() and not (tmp_path / "existing" / "out").exists()
    capsys.readouterr()

    # a folder another process makes meanwhile in a new parent stays
    def other_process_then_full(*args, **kwargs):
        (tmp_path / "shared" / "run_b").mkdir()
        full_disk()

    monkeypatch.setattr(overlay, "save_edge_overlay", other_process_then_full)
    assert main(["detect", str(plate), "--method", "gradient", "--out", str(tmp_path / "shared" / "run_a")]) == 2
    assert (tmp_path / "shared" / "run_b").is_dir() and not (tmp_path / "shared" / "run_a").exists()
    capsys.readouterr()
    # a name too long to look at: the one-line error, not a traceback
    _refused(capsys, ["detect", plate, "--method", "gradient", "--out", tmp_path / ("a" * 300) / "out"],
             "File name too long")


def test_pose_files_that_are_no_pose_file_say_what_they_are(tmp_path, capsys):
    folder = tmp_path / "poses"
    folder.mkdir()
    text = tmp_path / "pose.npy"
    text.write_text("[[1, 0, 0, 0]]")  # a text file named .npy (numpy's words: pickle advice)
    for pose, words in ((folder, "is a directory"), (text, "not a .npy file")):
        _refused(capsys, ["scan", GREEN, "--pose", pose, "--out", tmp_path / "s.exr"], pose.name, words)
    assert not (tmp_path / "s.exr").exists()


def test_a_json_pose_in_the_scenes_view_form(tmp_path, capsys):
    """{"position", "look_at", "up"} (mm), as a scene's [view] table, is the look_at pose; other
    dicts get a message listing the three forms and the keys found (it was 'got shape (0,)')."""
    import json

    from rangesim.cli.main import _load_pose
    from rangesim.core.geometry import look_at

    view = tmp_path / "view.json"
    view.write_text(json.dumps({"position": [0, -200, 300], "look_at": [0, 0, 10]}))
    np.testing.assert_allclose(_load_pose(view), look_at((0, -200, 300), (0, 0, 10)))
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"pos": [0, -200, 300]}))
    _refused(capsys, ["scan", GREEN, "--pose", other, "--out", tmp_path / "s.exr"], "other.json",
             '{"position": [x, y, z]', "got the keys pos")
    assert not (tmp_path / "s.exr").exists()


def test_detect_on_a_tiny_image_says_it_is_too_small(tmp_path, capsys):
    """A 2 x 2 px scan is a grid, just too small for 3 x 3 operators: it was called 'not an
    organized range image'; a point list still is one."""
    tiny = rs.scan(rs.datasets.plate_scene(), rs.load_sensor("white_scanner").with_params(
        {"camera.width": 2, "camera.height": 2}), pose=rs.datasets.plate_scan().pose)
    tiny.save(tmp_path / "tiny.npz")
    _refused(capsys, ["detect", tmp_path / "tiny.npz", "--out", tmp_path / "d"], "tiny.npz",
             "a 2 x 2 px image is too small for the edge detectors (at least 3 x 3)")
    points = tmp_path / "points.xyz"
    np.savetxt(points, np.random.default_rng(0).uniform(0, 50, (30, 3)))
    _refused(capsys, ["detect", points, "--out", tmp_path / "d"], "not an organized range image")
    assert not (tmp_path / "d").exists()


def test_unknown_units_list_the_inch_sign_quoted(tmp_path, capsys):
    line = _refused(capsys, ["points", "green_piece", "--resolution", "3 furlong", "--out", tmp_path / "p.ply"],
                    "furlong")
    assert line.endswith("""the inch sign '"')"""), line


def test_points_takes_the_units_of_a_mesh_file_and_warns_of_a_tiny_one(tmp_path, capsys):
    mesh = tmp_path / "box_m.stl"
    trimesh.creation.box(extents=(0.05, 0.04, 0.03)).export(mesh)   # a 50 mm box in metres
    assert main(["points", str(mesh), "--resolution", "2mm", "--out", str(tmp_path / "a.ply")]) == 0
    err = capsys.readouterr().err
    assert "only 0.05 mm across" in err and "--units" in err
    assert main(["points", str(mesh), "--units", "m", "--resolution", "2mm", "--out", str(tmp_path / "b.ply")]) == 0
    assert "warning" not in capsys.readouterr().err
    a = trimesh.load(tmp_path / "a.ply")
    b = trimesh.load(tmp_path / "b.ply")
    assert len(a.vertices) < 50 < 500 < len(b.vertices)             # a few points per face, against its surface
    _refused(capsys, ["points", "green_piece", "--units", "m", "--resolution", "2mm", "--out", tmp_path / "c.ply"],
             "--units applies to a mesh file")


def test_a_missing_recording_is_named_before_its_conf(tmp_path, capsys):
    """From a folder where the README's ``../shared/data`` paths do not exist, ``compare`` named
    the missing ``--conf`` file, not the missing recording given first."""
    rec, conf = tmp_path / "gone" / "bun000.ply", tmp_path / "gone" / "bun.conf"
    line = _refused(capsys, ["compare", rec, "--conf", conf, "--mesh", tmp_path / "m.ply", "--out", tmp_path / "o"],
                    rec, "no such file")
    assert "conf" not in line.split(str(rec))[1]


def test_calibrate_refuses_a_mesh_that_covers_a_small_part_of_the_recording(tmp_path, capsys):
    """An unrelated mesh (the flat target for the bunny) reached a valid-mask IoU of 0.16, over
    the 0.1 that refuses no overlap at all, and a sensor file of nonsense was written with a
    warning. A calibration now needs the joint fit's IoU at MIN_SENSOR_FIT_IOU (0.5); compare
    keeps its warning for such a twin."""
    from rangesim.twin.calibration import MIN_SENSOR_FIT_IOU

    rec = tmp_path / "rec.npz"
    grid_recording(60, 70, x0=-17.0, y0=-21.0).save(rec)  # 35 x 42 mm
    small = trimesh.creation.box(extents=(12.0, 14.0, 1.0))  # about a ninth of it
    mesh = tmp_path / "small.stl"
    small.export(mesh)
    out = tmp_path / "c.toml"
    _refused(capsys, ["calibrate", rec, "--mesh", mesh, "--sensor", "cyberware_3030", "--out", out,
                      "--geometry-only"], "overlap too little to calibrate on", f"at least {MIN_SENSOR_FIT_IOU}")
    assert not out.exists()
