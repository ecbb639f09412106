"""Inputs a new user's audit (twentieth session) found handled loosely: each is now refused in one
line naming the file and the problem, or described as what it is."""
from __future__ import annotations

import gzip
import json
import warnings

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli.main import main
from rangesim.core.errors import RangesimError

GREEN = str(__import__("pathlib").Path(__file__).resolve().parents[1] / "scenes" / "green_piece.toml")
TINY = ["--set", "camera.width=64", "--set", "camera.height=48"]


def _error(capsys, argv) -> str:
    """``main(argv)`` exits 2 with one error line, no traceback; the line."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("rangesim: error:") and "Traceback" not in err, err
    return err


@pytest.fixture(scope="module")
def plate_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plate20")
    scan = rs.datasets.plate_scan()
    scan.save(folder / "plate.exr")
    scan.save(folder / "plate.ply")  # a point list: the measured points only
    return folder


def test_info_calls_a_point_list_a_point_list(plate_files, capsys):
    scan = rs.load_scan(plate_files / "plate.exr")
    assert main(["info", str(plate_files / "plate.ply")]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    n = int(scan.valid.sum())
    assert f"{n:,} points (a point list" in first and "x 1 px" not in first


def test_diff_refuses_point_lists(plate_files, capsys, tmp_path):
    out = tmp_path / "d.png"
    err = _error(capsys, ["diff", plate_files / "plate.ply", plate_files / "plate.ply", "--out", out])
    assert "plate.ply" in err and "not an organized range image" in err
    assert not out.exists()


def test_a_non_mesh_file_named_as_a_mesh_says_so(tmp_path):
    from rangesim.cad.meshes import load_mesh

    path = tmp_path / "frame.pcd"
    path.write_text("# .PCD v0.7\n")
    with pytest.raises(RangesimError, match=r"frame.pcd: unknown mesh file type '.pcd'; use a mesh \(.stl"):
        load_mesh(path)


def test_a_scene_names_its_missing_mesh_as_written(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text('[[object]]\nname = "part"\nmesh = "gone.stl"\n')
    err = _error(capsys, ["scan", scene, "--out", tmp_path / "x.npz", *TINY])
    assert "s.toml: [[object]] 0 (part): mesh = 'gone.stl'" in err and "no such mesh file" in err


def test_a_pose_entry_that_is_no_number_is_named():
    from rangesim.core.geometry import check_pose

    bad = [["a", 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    with pytest.raises(RangesimError, match="pose entries must be numbers, got 'a' at row 0, column 0"):
        check_pose(bad)
    with pytest.raises(RangesimError, match="got a str"):
        check_pose("abc")
    numeric_text = [["1", "0", 0, 0], [0, 1, 0, 0], [0, 0, 1, "5"], [0, 0, 0, 1]]
    assert check_pose(numeric_text)[2, 3] == 5.0  # as NumPy reads it
    with pytest.raises(RangesimError, match="got 'a' at row 0, column 1"):
        check_pose([["1", "a", 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])


def test_detect_keeps_this_scans_scores_of_another_method(plate_files, tmp_path, capsys):
    """gradient, then normal into one folder: both maps and both scores; then line_fit at another
    tolerance: the earlier maps, scored at the old one, go."""
    scan, out = tmp_path / "g.exr", tmp_path / "det"
    assert main(["scan", GREEN, "--out", str(scan), "--set", "camera.width=96", "--set", "camera.height=90"]) == 0
    assert main(["detect", str(scan), "--method", "gradient", "--out", str(out)]) == 0
    first = json.loads((out / "scores.json").read_text())["methods"]["gradient"]
    assert main(["detect", str(scan), "--method", "normal", "--out", str(out)]) == 0
    assert "keeps gradient" in capsys.readouterr().out
    methods = json.loads((out / "scores.json").read_text())["methods"]
    assert sorted(methods) == ["gradient", "normal"] and methods["gradient"] == first
    assert main(["detect", str(scan), "--method", "line_fit", "--tolerance", "3", "--out", str(out)]) == 0
    assert sorted(json.loads((out / "scores.json").read_text())["methods"]) == ["line_fit"]
    assert sorted(p.name for p in out.glob("*_edges.npz")) == ["line_fit_edges.npz"]


def test_msu_gz_that_is_no_gzip_or_no_msu(tmp_path, capsys):
    plain = tmp_path / "a.msu.gz"
    plain.write_bytes(b"notgzip")
    assert "not a gzip file" in _error(capsys, ["info", plain])
    junk = tmp_path / "b.msu.gz"
    junk.write_bytes(gzip.compress(bytes(range(256)) * 4))
    assert "not an MSU range image (binary data" in _error(capsys, ["info", junk])


def test_truncated_text_meshes_say_so(tmp_path):
    from rangesim.cad.meshes import load_mesh

    sphere = trimesh.creation.icosphere(3)
    obj = trimesh.exchange.obj.export_obj(sphere)
    (tmp_path / "cut.obj").write_text(obj[: obj.index("\nf ")])  # its vertices, none of its faces
    with pytest.raises(RangesimError, match=r"cut.obj: file holds 642 vertices and no faces .*cut short"):
        load_mesh(tmp_path / "cut.obj")
    stl = trimesh.exchange.stl.export_stl_ascii(sphere)
    (tmp_path / "cut.stl").write_text(stl[: len(stl) // 2])
    with pytest.raises(RangesimError, match="cut.stl: truncated ASCII STL"):
        load_mesh(tmp_path / "cut.stl")
    (tmp_path / "whole.stl").write_text(stl)
    assert len(load_mesh(tmp_path / "whole.stl").faces) == len(sphere.faces)
    # padding after 'endsolid' (NULs, a DOS end-of-file byte) is no truncation
    from rangesim.io.mesh_check import diagnose_mesh_file

    (tmp_path / "padded.stl").write_bytes(stl.encode() + b"\n\x1a\0\0")
    assert diagnose_mesh_file(tmp_path / "padded.stl", full=True) is None


def test_a_missing_sensors_folder_is_named(monkeypatch, tmp_path):
    import rangesim.sensor.config as config

    missing = tmp_path / "nowhere"
    monkeypatch.setenv("RANGESIM_SENSORS", str(missing))
    monkeypatch.setattr(config, "_WARNED_DIRS", set())
    with pytest.warns(UserWarning, match="nowhere: no such folder"):
        names = config.preset_names()
    assert "white_scanner" in names
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        config.preset_names()  # once per process


def test_dataset_names_a_bad_mesh_as_given(tmp_path, capsys, monkeypatch):
    trimesh.creation.box(extents=(20.0, 20.0, 20.0)).export(tmp_path / "box.stl")
    (tmp_path / "cut.stl").write_bytes((tmp_path / "box.stl").read_bytes()[:300])
    monkeypatch.chdir(tmp_path)
    err = _error(capsys, ["dataset", "--scene", "cut.stl", "--views", "1", "--out", "ds", *TINY])
    assert "error: cut.stl: truncated binary STL" in err and str(tmp_path) not in err


def test_the_green_piece_without_its_dent():
    whole = rs.cad.green_piece(segments=24, threads=[])
    plain = rs.cad.green_piece(segments=24, threads=[], dent=[])
    assert "dent_rim" in {c.name for c in whole.features.circles}
    assert "dent_rim" not in {c.name for c in plain.features.circles}
    assert plain.mesh.is_watertight and plain.mesh.volume > whole.mesh.volume + 10.0  # the dent's cap, mm^3
    assert rs.cad.green_piece(segments=24, threads=[], dent=False).mesh.volume == pytest.approx(plain.mesh.volume)


def test_a_viewpoint_inside_the_part_is_refused():
    from rangesim.scene.visibility import visible_surface_points

    box = trimesh.creation.box(extents=(40.0, 30.0, 10.0))
    with pytest.raises(RangesimError, match=r"viewpoint \(1, 2, 3\) mm lies inside the part"):
        visible_surface_points(box, 2.0, (1.0, 2.0, 3.0))
    seen = visible_surface_points(box, 2.0, (0.0, 0.0, 200.0))
    assert len(seen) > 100 and np.all(seen.normals[:, 2] > 0)


def test_the_memory_refusal_separates_pixels_from_the_fixed_cost(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", "1K")
    err = _error(capsys, ["scan", GREEN, "--out", tmp_path / "m.npz", *TINY])
    assert "64 x 48 px" in err and "on the renderer's fixed 300.0 MB" in err


def test_detect_merges_only_the_same_scan_file_and_keeps_maps_without_truth(tmp_path, capsys):
    """A scan rewritten in place (another seed) is another scan: its earlier scores are not kept.
    Without ground truth there is no scores.json to keep in step: the other maps stay."""
    scan, out = tmp_path / "g.exr", tmp_path / "det"
    small = ["--set", "camera.width=96", "--set", "camera.height=90"]
    assert main(["scan", GREEN, "--out", str(scan), *small]) == 0
    assert main(["detect", str(scan), "--method", "gradient", "--out", str(out)]) == 0
    assert main(["scan", GREEN, "--out", str(scan), "--seed", "7", *small]) == 0
    assert main(["detect", str(scan), "--method", "normal", "--out", str(out)]) == 0
    assert "keeps" not in capsys.readouterr().out
    assert sorted(json.loads((out / "scores.json").read_text())["methods"]) == ["normal"]
    assert not (out / "gradient_edges.npz").exists()
    bare, out2 = tmp_path / "bare.npz", tmp_path / "det2"
    rs.datasets.plate_scan().save(bare)  # no scene named: no truth
    assert main(["detect", str(bare), "--method", "gradient", "--out", str(out2)]) == 0
    assert main(["detect", str(bare), "--method", "normal", "--out", str(out2)]) == 0
    assert (out2 / "gradient_edges.npz").is_file() and (out2 / "normal_edges.npz").is_file()


def test_a_one_row_grid_is_no_point_list(tmp_path, capsys):
    row = tmp_path / "row.npz"
    assert main(["scan", GREEN, "--out", str(row), "--set", "camera.width=64", "--set", "camera.height=1"]) == 0
    capsys.readouterr()
    assert main(["info", str(row)]) == 0
    assert "64 x 1 px" in capsys.readouterr().out
    assert main(["diff", str(row), str(row), "--out", str(tmp_path / "d.png")]) == 0
