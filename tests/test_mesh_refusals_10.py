"""Mesh files that loaded wrongly or were refused in a library's words (review 10): every error one
line naming the file and the problem in the user's terms, exit 2 on the CLI, no file written."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli.main import main


def _refused(path: Path | str, *words: str) -> str:
    """The one-line RangesimError of ``rs.load_scene(path)``, checked for the file name and ``words``."""
    with pytest.raises(rs.RangesimError) as info:
        rs.load_scene(path)
    message = str(info.value)
    assert len(message.splitlines()) == 1 and Path(path).name in message, message
    for word in words:
        assert word in message, message
    return message


def _cli_refuses(argv: list[str], out: Path, capsys, *words: str) -> None:
    """``rangesim argv`` exits 2 with one error line holding ``words``, and writes nothing under ``out``."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rangesim: error: "), err
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists() or not [p for p in out.rglob("*") if p.is_file()]


def _scan_and_points(mesh: Path, tmp_path: Path, capsys, *words: str) -> None:
    out = tmp_path / "out"
    _cli_refuses(["scan", str(mesh), "--sensor", "white_scanner", "--out", str(out / "s.exr")], out, capsys,
                 mesh.name, *words)
    _cli_refuses(["points", str(mesh), "--resolution", "0.2mm", "--out", str(out / "p.ply"),
                  "--preview", str(out / "p.png")], out, capsys, mesh.name, *words)


# -- 1: no triangle of non-zero area ------------------------------------------------------------------

DEGENERATE = [
    pytest.param("collinear.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n",
                 ["no triangle of non-zero area", "all 2 faces are degenerate"], id="collinear-obj"),
    pytest.param("diagonal.obj", "v 0.1 0.2 0.3\nv 0.3 0.6 0.9\nv 0.7 1.4 2.1\nf 1 2 3\n",
                 ["no triangle of non-zero area", "only face is degenerate"], id="collinear-diagonal-obj"),
    pytest.param("equal.off", "OFF\n3 1 0\n1 1 1\n1 1 1\n1 1 1\n3 0 1 2\n",
                 ["no triangle of non-zero area"], id="equal-vertices-off"),
    # trimesh reads the 0-based `f 0 1 2` as one degenerate face; the file's own mistake is named
    pytest.param("zero_based.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
                 ["face index out of range", "line 4", "index 0", "start at 1"], id="zero-based-obj"),
]


@pytest.mark.parametrize(("name", "text", "words"), DEGENERATE)
def test_mesh_without_area_is_refused(tmp_path, capsys, name, text, words):
    path = tmp_path / name
    path.write_text(text)
    _refused(path, *words)
    _scan_and_points(path, tmp_path, capsys, *words)


def test_mesh_without_area_is_refused_from_memory_and_from_the_cache(tmp_path, monkeypatch):
    flat = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 1, 1], [2, 2, 2]], faces=[[0, 1, 2]], process=False)
    with pytest.raises(rs.RangesimError, match="mesh 0: mesh holds no triangle of non-zero area"):
        rs.load_scene([flat])
    monkeypatch.setenv("RANGESIM_MESH_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "collinear.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    for _ in range(2):  # not cached as valid the first time
        _refused(path, "no triangle of non-zero area")


def test_mesh_with_some_degenerate_faces_loads(tmp_path):
    path = tmp_path / "some.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 1 4\nf 1 2 4\n")
    mesh = rs.load_scene(path).objects[0].mesh
    assert len(mesh.faces) == 3 and mesh.area == pytest.approx(0.5)
    tiny = trimesh.creation.box(extents=(1e-6, 1e-6, 1e-6))  # small is not degenerate
    assert rs.load_scene([tiny]).objects[0].mesh.area == pytest.approx(6e-12)


# -- 2: coordinates too large to weld ------------------------------------------------------------------

def test_box_beyond_weld_limit_is_refused_not_flattened(tmp_path, capsys):
    box = trimesh.creation.box(extents=(100, 100, 100))
    box.apply_translation([1e11, 0, 0])
    path = tmp_path / "box_at_1e11.stl"
    box.export(path, file_type="stl_ascii")
    _refused(path, "coordinates reach 1e+11 file units", "too large to weld", "check the units")
    cube = trimesh.creation.box(extents=(2, 2, 2))
    cube.vertices *= 1e30
    huge = tmp_path / "huge.stl"
    cube.export(huge)
    _refused(huge, "coordinates reach 1e+30 file units")
    out = tmp_path / "out"
    _cli_refuses(["scan", str(huge), "--sensor", "white_scanner", "--out", str(out / "s.exr")], out, capsys,
                 "huge.stl", "1e+30", "too large to weld")
    _cli_refuses(["points", str(huge), "--resolution", "1e28mm", "--out", str(out / "p.ply")], out, capsys,
                 "huge.stl", "1e+30")


@pytest.mark.parametrize("offset", [1e5, 1e6, 1e7, 1e10])
def test_far_offsets_weld_exactly(tmp_path, offset):
    box = trimesh.creation.box(extents=(100, 100, 100))
    box.apply_translation([offset, 0, 0])
    path = tmp_path / "far.stl"
    box.export(path, file_type="stl_ascii")  # 36 corners welded back to 8 (float32 would merge 1e10 +- 50)
    mesh = rs.load_scene(path).objects[0].mesh
    assert len(mesh.vertices) == 8 and mesh.metadata["rangesim_closed"]
    stored = np.unique(trimesh.load(path, process=False).vertices, axis=0)
    np.testing.assert_array_equal(np.unique(mesh.vertices, axis=0), stored)
    np.testing.assert_allclose(mesh.extents, [100, 100, 100], rtol=1e-12)


# -- 3: the same broken-file message through a scene TOML and load_scene ---------------------------------

def _broken_stls(d: Path) -> dict[str, list[str]]:
    binary = trimesh.creation.box(extents=(1, 1, 1)).export(file_type="stl")
    (d / "trunc.stl").write_bytes(binary[:351])
    (d / "empty.stl").write_bytes(b"")
    (d / "zero.stl").write_bytes(b"\0" * 80 + struct.pack("<I", 0))
    return {"trunc": ["truncated binary STL", "12 triangles", "351 bytes"], "empty": ["file is empty"],
            "zero": ["binary STL with 0 triangles"]}


@pytest.mark.parametrize("name", ["trunc", "empty", "zero"])
def test_broken_stl_named_alike_on_every_path(tmp_path, capsys, name):
    words = _broken_stls(tmp_path)[name]
    stl = tmp_path / f"{name}.stl"
    scene = tmp_path / f"{name}.toml"
    scene.write_text(f'[[object]]\nname = "p"\nmesh = "{name}.stl"\n')
    _refused(stl, *words)
    with pytest.raises(rs.RangesimError) as info:
        rs.load_scene(scene)
    assert f"{name}.stl" in str(info.value) and all(w in str(info.value) for w in words), info.value
    out = tmp_path / "out"
    for source in (stl, scene):
        _cli_refuses(["scan", str(source), "--sensor", "white_scanner", "--out", str(out / "s.exr")], out, capsys,
                     f"{name}.stl", *words)


# -- 4: read errors in the user's terms, not a library's ------------------------------------------------

def _raw_cases(d: Path) -> None:
    box = trimesh.creation.box(extents=(1, 1, 1))
    ply = box.export(file_type="ply", encoding="ascii")
    (d / "trunc_ascii.ply").write_bytes(ply[: int(len(ply) * 0.6)])
    off = box.export(file_type="off")
    (d / "trunc.off").write_text(off[: int(len(off) * 0.6)])
    (d / "oor.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n")
    (d / "dir.stl").mkdir()
    (d / "ply_named.stl").write_bytes(ply)
    (d / "notes.stl").write_text("These are my notes about the part, not a mesh at all. " * 4)


RAW = [
    pytest.param("trunc_ascii.ply", ["truncated ASCII PLY", "expected 8 vertices and 12 faces",
                                     "found 4 vertices and 0 faces"], id="truncated-ascii-ply"),
    pytest.param("trunc.off", ["truncated OFF", "expected 8 vertices and 12 faces",
                               "found 6 vertices and 0 faces"], id="truncated-off"),
    pytest.param("oor.obj", ["face index out of range of the vertex list", "line 5", "vertex 9", "3 vertices"],
                 id="obj-index-past-end"),
    pytest.param("dir.stl", ["is a directory, not a mesh file"], id="directory-named-stl"),
    pytest.param("ply_named.stl", ["not an STL file (starts with 'ply')"], id="ply-named-stl"),
    pytest.param("notes.stl", ["not an STL file (starts with 'These are my notes"], id="text-named-stl"),
]


@pytest.mark.parametrize(("name", "words"), RAW)
def test_read_errors_say_the_problem(tmp_path, capsys, name, words):
    _raw_cases(tmp_path)
    message = _refused(tmp_path / name, *words)
    assert "Error:" not in message and "triangles (" not in message, message  # no library text, no bogus count
    scene = tmp_path / "scene.toml"
    scene.write_text(f'[[object]]\nname = "p"\nmesh = "{name}"\n')
    out = tmp_path / "out"
    for source in (tmp_path / name, scene):
        _cli_refuses(["scan", str(source), "--sensor", "white_scanner", "--out", str(out / "s.exr")], out, capsys,
                     name, *words)


def test_truncated_binary_stl_with_a_text_header_is_still_truncated(tmp_path):
    box = trimesh.creation.box(extents=(1, 1, 1))
    binary = bytearray(box.export(file_type="stl"))
    binary[:80] = b"solid exported by some CAD program".ljust(80)  # binary STLs may start with 'solid'
    (tmp_path / "cut.stl").write_bytes(bytes(binary[:300]))
    _refused(tmp_path / "cut.stl", "truncated binary STL", "12 triangles")
    (tmp_path / "whole.stl").write_bytes(bytes(binary))
    assert len(rs.load_scene(tmp_path / "whole.stl").objects[0].mesh.faces) == 12


# -- read without an error as a wrong mesh (review 12): truncated OFF / OBJ, OBJ index 0 ---------
@pytest.mark.parametrize(("ext", "keep", "words"), [
    ("off", 0.5, ["truncated OFF", "12 faces"]),
    ("off", 0.97, ["truncated OFF", "found 8 vertices and 10 faces"]),
    ("obj", 0.97, ["truncated OBJ", "last line"]),
])
def test_truncated_text_mesh_is_refused_not_half_read(tmp_path, ext, keep, words):
    """trimesh read a box's OFF or OBJ cut short as the faces before the cut, without an error."""
    whole = tmp_path / f"box.{ext}"
    trimesh.creation.box(extents=(10.0, 20.0, 30.0)).export(whole)
    data = whole.read_bytes()
    cut = tmp_path / f"cut.{ext}"
    cut.write_bytes(data[: int(len(data) * keep)])
    assert data[int(len(data) * keep) - 1:int(len(data) * keep)] != b"\n"  # cut inside a line
    _refused(cut, *words)
    assert len(rs.load_scene(whole).objects[0].mesh.faces) == 12  # the whole file loads


@pytest.mark.parametrize("face", ["f 0 2 4", "f 1/1 0/1 4/1", "f 2 4 0"])
def test_obj_index_zero_is_refused_among_good_faces(tmp_path, face):
    """OBJ counts vertices from 1; trimesh read index 0 as the last vertex (a wrong face, no error)."""
    path = tmp_path / "zero.obj"
    path.write_text(f"v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nvt 0 0\nf 1 2 3\n{face}\n")
    _refused(path, "line 7", "index 0", "start at 1")
    path.write_text("v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nvt 0 0\nf 1 2 3\nf 1 3 4\n")
    assert len(rs.load_scene(path).objects[0].mesh.faces) == 2  # zero coordinates are no index


def test_valid_text_meshes_with_edges_or_comments_still_load(tmp_path):
    """An OFF may list 1- and 2-vertex elements (trimesh drops them: fewer triangles than the
    count line, yet no truncation), and an OBJ comment may hold a 0."""
    box = trimesh.creation.box(extents=(10.0, 20.0, 30.0))
    lines = ["OFF", f"{len(box.vertices)} {len(box.faces) + 1} 0"]
    lines += [" ".join(f"{c:g}" for c in v) for v in box.vertices]
    lines += [f"3 {a} {b} {c}" for a, b, c in box.faces] + ["2 0 1"]
    off = tmp_path / "edges.off"
    off.write_text("\n".join(lines) + "\n")
    assert len(rs.load_scene(off).objects[0].mesh.faces) == 12
    obj = tmp_path / "comment.obj"
    obj.write_text("v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 2 3\nf 1 3 4\n# f 0 1 2\n")
    assert len(rs.load_scene(obj).objects[0].mesh.faces) == 2
    # trimesh cannot read a comment after a face; the refusal does not blame the 0 in it
    obj.write_text("v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 2 3 # was 0\nf 1 3 4\n")
    with pytest.raises(rs.RangesimError) as info:
        rs.load_scene(obj)
    assert "index 0" not in str(info.value)
