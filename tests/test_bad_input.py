"""Malformed inputs and arguments: exit code 2, one line on stderr naming the culprit, no traceback,
no file left behind (issue 16). Memory limits are exercised with RANGESIM_MEMORY_LIMIT, never by
allocating."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from rangesim.cli.main import main

SENSOR_TOML = """\
name = "tiny"
[camera]
width = 64
height = 48
fov_deg = 40.0
[laser]
baseline = 150.0
[range]
near = 100.0
far = 1000.0
"""

SCENE_TOML = """\
units = "mm"

[[object]]
name = "box"
primitive = "box"
size = [50, 40, 20]
translate = [0, 0, 10]
albedo = 0.6

[[object]]
name = "ground"
primitive = "plane"
size = [300, 300]
albedo = 0.3

[view]
position = [0, -180, 300]
look_at = [0, 0, 10]
"""

#: garbage bytes for every extension a reader accepts
GARBAGE = b"\x00\xff\xfe garbage \x89\x1b[31m not a file of this kind \x07\x00" * 3


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("bad_inputs")
    (d / "tiny.toml").write_text(SENSOR_TOML)
    (d / "scene.toml").write_text(SCENE_TOML)
    for suffix in ("exr", "npz", "ply", "pcd", "msu", "xyz", "stl", "obj", "off", "glb", "json", "npy", "conf"):
        (d / f"garbage.{suffix}").write_bytes(GARBAGE)
    (d / "empty.stl").write_bytes(b"")
    (d / "empty.exr").write_bytes(b"")
    box = trimesh.creation.box(extents=(60.0, 40.0, 30.0))
    binary = box.export(file_type="stl")
    (d / "truncated.stl").write_bytes(binary[:-30])
    (d / "short_header.stl").write_bytes(binary[:60])
    (d / "zero.stl").write_bytes(b"\x00" * 80 + struct.pack("<I", 0))
    ply = box.export(file_type="ply")
    (d / "truncated.ply").write_bytes(ply[: len(ply) // 2])
    (d / "no_end_header.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    (d / "bad.glb").write_bytes(b"glTF" + struct.pack("<II", 2, 100000) + b"\x00" * 20)
    (d / "points_only.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 20\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n" + "".join(f"{i} {i % 3} {300 + i}\n" for i in range(20)))
    (d / "bad_size.toml").write_text(SCENE_TOML.replace("size = [50, 40, 20]", 'size = "big"'))
    (d / "far.toml").write_text(SCENE_TOML.replace("position = [0, -180, 300]", "position = [0, -1800, 3000]"))
    (d / "pose.json").write_text("[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1]]")
    (d / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (d / "a_file").write_text("not a directory")
    return d


@pytest.fixture(scope="module")
def good_scan(inputs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bad_inputs_scan") / "scan.exr"
    assert main(["scan", str(inputs / "scene.toml"), "--sensor", str(inputs / "tiny.toml"), "--out", str(out)]) == 0
    return out


def _scan(scene, *extra):
    return ["scan", "{in}/" + scene, "--sensor", "{in}/tiny.toml", "--out", "{out}/scan.exr", *extra]


#: (arguments with {in}, {out} and {scan} placeholders, words the one error line must hold)
CASES = [
    # garbage files of every extension a reader accepts
    *[pytest.param(["info", "{in}/garbage." + s], ["garbage." + s], id=f"info-garbage-{s}")
      for s in ("exr", "npz", "ply", "pcd", "msu", "xyz")],
    pytest.param(["info", "{in}/empty.exr"], ["empty.exr"], id="info-empty-exr"),
    pytest.param(["info", "{in}/scene.toml"], ["scene.toml", "cannot read scans"], id="info-unknown-suffix"),
    pytest.param(["info", "{in}/missing.exr"], ["missing.exr", "no such file"], id="info-missing"),
    *[pytest.param(["detect", "{in}/garbage." + s, "--out", "{out}/d"], ["garbage." + s], id=f"detect-garbage-{s}")
      for s in ("exr", "ply", "pcd", "msu")],
    # garbage and broken meshes
    *[pytest.param(_scan("garbage." + s), ["garbage." + s], id=f"scan-garbage-{s}")
      for s in ("stl", "obj", "off", "glb", "ply")],
    pytest.param(_scan("empty.stl"), ["empty.stl", "empty"], id="scan-empty-stl"),
    pytest.param(_scan("truncated.stl"), ["truncated.stl", "truncated binary STL", "12 triangles"],
                 id="scan-truncated-stl"),
    pytest.param(_scan("short_header.stl"), ["short_header.stl", "84-byte header"], id="scan-stl-short-header"),
    pytest.param(_scan("zero.stl"), ["zero.stl", "0 triangles"], id="scan-stl-zero-triangles"),
    pytest.param(_scan("truncated.ply"), ["truncated.ply"], id="scan-truncated-ply"),
    pytest.param(_scan("no_end_header.ply"), ["no_end_header.ply", "end_header"], id="scan-ply-no-end-header"),
    pytest.param(_scan("bad.glb"), ["bad.glb", "truncated GLB"], id="scan-truncated-glb"),
    pytest.param(_scan("nan.obj"), ["nan.obj", "NaN"], id="scan-nan-obj"),
    pytest.param(["model", "green_piece", "--out", "{out}/m.stl", "--param", "holes=[[0,0,100]]"],
                 ["green_piece", "holes"], id="model-hole-too-big"),
    pytest.param(["model", "green_piece", "--out", "{out}/m.stl", "--param", "segments=100000"],
                 ["segments", "4096"], id="model-segments-limit"),
    pytest.param(["model", "green_piece", "--out", "{out}/m.stl", "--param", "segments=2.5"],
                 ["segments", "integer"], id="model-segments-not-integer"),
    pytest.param(["model", "green_piece", "--out", "{out}/m.stl", "--param", "no_such=1"],
                 ["no_such"], id="model-unknown-param"),
    # scene and pose files
    pytest.param(_scan("bad_size.toml"), ["bad_size.toml", "size"], id="scene-size-not-numbers"),
    pytest.param(_scan("scene.toml", "--pose", "{in}/pose.json"), ["pose.json", "4x4"], id="pose-not-4x4"),
    pytest.param(_scan("scene.toml", "--pose", "{in}/garbage.json"), ["garbage.json"], id="pose-garbage-json"),
    pytest.param(_scan("scene.toml", "--pose", "{in}/garbage.npy"), ["garbage.npy"], id="pose-garbage-npy"),
    # scans that see nothing
    pytest.param(_scan("far.toml"), ["far.toml", "working range", "--keep-empty"], id="scan-beyond-range"),
    pytest.param(_scan("scene.toml", "--units", "m"), ["--units", "bare mesh"], id="units-on-a-scene"),
    # sizes: refused up front against a small limit, nothing allocated
    pytest.param(_scan("scene.toml", "--set", "camera.width=20000", "--set", "camera.height=20000"),
                 ["camera.width x camera.height", "20,000 x 20,000", "GB"], id="scan-too-many-pixels"),
    pytest.param(["model", "green_piece", "--out", "{out}/m.stl", "--param", "segments=4000"],
                 ["segments=4000", "GB"], id="model-segments-memory"),
    # arguments
    pytest.param(_scan("scene.toml", "--set", "noise.sigma_px=-1"), ["noise.sigma_px"], id="set-negative-noise"),
    pytest.param(_scan("scene.toml", "--set", "camera.width=0"), ["camera.width"], id="set-zero-width"),
    pytest.param(_scan("scene.toml", "--set", "nope.key=1"), ["nope"], id="set-unknown-table"),
    pytest.param(_scan("scene.toml", "--seed", "-1"), ["seed"], id="scan-negative-seed"),
    pytest.param(["scan", "{in}/scene.toml", "--out", "{out}/scan.tiff"], ["scan.tiff", "supported"],
                 id="scan-out-suffix"),
    pytest.param(["scan", "{in}/scene.toml", "--sensor", "{in}/tiny.toml", "--out", "{in}/a_file/scan.exr"],
                 ["a_file is not a directory"], id="scan-out-under-a-file"),
    pytest.param(["features", "{scan}", "--rmin", "50", "--rmax", "10", "--out", "{out}/f"], ["--rmin", "--rmax"],
                 id="features-rmin-above-rmax"),
    pytest.param(["features", "{scan}", "--rmin", "-5", "--out", "{out}/f"], ["--rmin"], id="features-negative-rmin"),
    pytest.param(["detect", "{scan}", "--tolerance", "-1", "--out", "{out}/d"], ["--tolerance"],
                 id="detect-negative-tolerance"),
    pytest.param(["detect", "{scan}", "--crease-deg", "0", "--out", "{out}/d"], ["--crease-deg"],
                 id="detect-crease-zero"),
    pytest.param(["detect", "{scan}", "--crease-deg", "nan", "--out", "{out}/d"], ["--crease-deg"],
                 id="detect-crease-nan"),
    pytest.param(["detect", "{in}/points_only.ply", "--out", "{out}/d"], ["points_only.ply", "organized"],
                 id="detect-points-only-ply"),
    pytest.param(["diff", "{scan}", "{scan}", "--limit", "-1", "--out", "{out}/d.png"], ["--limit"],
                 id="diff-negative-limit"),
    pytest.param(["compare", "{scan}", "--sigma-mm", "-1", "--out", "{out}/c"], ["--sigma-mm"],
                 id="compare-negative-sigma"),
    pytest.param(["compare", "{scan}", "--min-cos", "2", "--out", "{out}/c"], ["--min-cos"], id="compare-min-cos"),
    pytest.param(["dataset", "--scene", "{in}/scene.toml", "--views", "0", "--out", "{out}/ds"], ["--views"],
                 id="dataset-zero-views"),
    pytest.param(["dataset", "--scene", "{in}/scene.toml", "--cap-deg", "-3", "--out", "{out}/ds"], ["--cap-deg"],
                 id="dataset-negative-cap"),
]


@pytest.mark.parametrize(("args", "words"), CASES)
def test_bad_input_is_one_line_exit_2_no_outputs(inputs, good_scan, tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", "1G")
    out = tmp_path / "out"
    before = sorted(p.name for p in inputs.iterdir())
    argv = [a.replace("{in}", str(inputs)).replace("{out}", str(out)).replace("{scan}", str(good_scan))
            for a in args]
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 2, captured.err
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rangesim: error: "), captured.err
    assert "Traceback" not in captured.err and "internal error" not in captured.err
    assert lines[0].isprintable(), lines[0]  # no raw bytes or escape codes echoed to the terminal
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists() or [p for p in out.rglob("*") if p.is_file()] == []
    assert sorted(p.name for p in inputs.iterdir()) == before  # nothing beside the inputs either


def test_table_is_large_enough():
    assert len(CASES) >= 40


def test_keep_empty_writes_the_scan_with_a_warning(inputs, tmp_path, capsys):
    out = tmp_path / "scan.npz"
    code = main(["scan", str(inputs / "far.toml"), "--sensor", str(inputs / "tiny.toml"), "--out", str(out),
                 "--keep-empty"])
    err = capsys.readouterr().err
    assert code == 0 and out.is_file()
    assert err.startswith("rangesim: warning: ") and "working range" in err and len(err.splitlines()) == 1


def test_units_scales_a_bare_mesh(inputs, tmp_path, capsys):
    mesh = tmp_path / "box_m.stl"
    trimesh.creation.box(extents=(0.06, 0.04, 0.03)).export(mesh)  # metres
    code = main(["scan", str(mesh), "--sensor", str(inputs / "tiny.toml"), "--out", str(tmp_path / "a.npz")])
    assert code == 2 and "--units" in capsys.readouterr().err
    code = main(["scan", str(mesh), "--sensor", str(inputs / "tiny.toml"), "--out", str(tmp_path / "b.npz"),
                 "--units", "m"])
    assert code == 0
    scan = np.load(tmp_path / "b.npz", allow_pickle=False)
    assert "depth" in scan.files and np.isfinite(scan["depth"]).sum() > 0


def test_latin1_text_meshes_load(tmp_path):
    from rangesim.cad.meshes import load_mesh

    box = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    stl = trimesh.exchange.stl.export_stl_ascii(box).replace("solid", "solid caf\xe9", 1)
    (tmp_path / "latin1.stl").write_bytes(stl.encode("latin-1"))
    (tmp_path / "latin1.obj").write_bytes(b"# caf\xe9 cr\xe8me\n" + trimesh.exchange.obj.export_obj(box).encode())
    for name in ("latin1.stl", "latin1.obj"):
        assert len(load_mesh(tmp_path / name).faces) == 12


def test_memory_limit_names_parameter(monkeypatch):
    from rangesim.core.errors import RangesimError
    from rangesim.core.memory import check_memory, parse_size

    assert parse_size("2G") == 2 * 1024**3 and parse_size("512m") == 512 * 1024**2
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", "1M")
    with pytest.raises(RangesimError, match="the thing needs about 2.0 MB"):
        check_memory(2 * 1024**2, "the thing")
    check_memory(1000, "small")  # fits
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", "lots")
    with pytest.raises(RangesimError, match="RANGESIM_MEMORY_LIMIT"):
        check_memory(1000, "small")


def test_reused_dataset_folder_loses_stale_views(tmp_path):
    from rangesim.experiments.dataset import _remove_stale_views

    views = tmp_path / "views"
    views.mkdir()
    a, b = "000000_0123456789", "000001_abcdefabcd"  # the dataset's own names: index_key
    for name in (f"{a}.exr", f"{a}_truth.npz", f"{a}.json", f"{b}.exr", f"{b}.json", f"{a}.npz", "notes.txt"):
        (views / name).write_text("x")
    assert _remove_stale_views(views, [a], "exr") == 1  # one view of the other plan (its record)
    assert sorted(p.name for p in views.iterdir()) == [f"{a}.exr", f"{a}.json", f"{a}_truth.npz", "notes.txt"]


def test_a_dataset_over_another_says_it_replaced_it(tmp_path, capsys):
    """A second ``dataset`` into the folder of another (here another image width) removed the
    first one's views without a word; ``sweep`` says so in the same case."""
    from rangesim.cli.main import main
    from tests.conftest import BOX_SCENE_TOML

    scene = tmp_path / "box.toml"
    scene.write_text(BOX_SCENE_TOML)
    out = tmp_path / "ds"
    base = ["dataset", "--scene", str(scene), "--views", "2", "--out", str(out)]
    assert main([*base, "--set", "camera.width=40", "--set", "camera.height=30"]) == 0
    assert "another dataset" not in capsys.readouterr().err
    assert main([*base, "--set", "camera.width=48", "--set", "camera.height=30"]) == 0
    err = capsys.readouterr().err
    assert f"{out} held 2 view(s) of another dataset" in err and "removed" in err
    assert main([*base, "--set", "camera.width=48", "--set", "camera.height=30"]) == 0  # the same again: quiet
    assert "another dataset" not in capsys.readouterr().err


def test_empty_scan_warnings_say_why():
    import rangesim as rs
    from rangesim.core.geometry import look_at
    from rangesim.sensor._scan import EmptyScanWarning

    sensor = rs.load_sensor({"name": "tiny", "camera": {"width": 32, "height": 24, "fov_deg": 40.0},
                             "laser": {"baseline": 150.0}, "range": {"near": 100.0, "far": 1000.0}})
    box = trimesh.creation.box(extents=(60.0, 60.0, 60.0))
    with pytest.warns(EmptyScanWarning, match="camera at .* is inside 'object0'"):
        rs.scan([box], sensor, pose=look_at((0, 0, 10), (0, 0, -30), up=(0, 1, 0)))
    tiny = trimesh.creation.box(extents=(0.06, 0.06, 0.06))  # a 60 mm box written in metres
    with pytest.warns(EmptyScanWarning, match=r"only 0\.104 mm across.*--units m"):
        rs.scan([tiny], sensor)
    with pytest.warns(EmptyScanWarning, match="outside tiny's working range 100-1000 mm"):
        rs.scan([box], sensor, pose=look_at((0, 0, 1500), (0, 0, 0), up=(0, 1, 0)))
    # surfaces in range, measured depths not (a huge peak error): the message said the hits at
    # 460-530 mm lay outside 100-1000 mm
    loud = sensor.with_params({"noise.sigma_px": 1e6})
    with pytest.warns(EmptyScanWarning, match="inside tiny's working range 100-1000 mm, but the depth noise"):
        rs.scan([box], loud, pose=look_at((0, 0, 500), (0, 0, 0), up=(0, 1, 0)))
    # a pose in metres: the camera among an open plate's surfaces (no closed part to be inside);
    # the hits, a few mm away, said only that they lay outside the range
    plate = rs.datasets.plate_scene()
    metres = look_at((0, -180, 300), (0, 0, 10))
    metres[:3, 3] /= 1000
    with pytest.warns(EmptyScanWarning, match=r"hits lie at [\d.]+-[\d.]+ mm, outside .*inside the scene's bounding "
                                              r"box: a pose written in metres\?"):
        rs.scan(plate, sensor, pose=metres)


@pytest.mark.parametrize(("variant", "words"), [("scalar_rgb", "traces one ray at a time"),
                                                ("llvm_rgbx", "unknown Mitsuba variant")])
def test_a_variant_rangesim_cannot_run_is_refused_in_one_line(tmp_path, variant, words):
    """A scalar variant (listed by Mitsuba, chosen in a fresh process) failed inside the first
    cast with an internal TypeError; it is refused before any work, naming the variable."""
    import os
    import subprocess
    import sys

    trimesh.creation.box((50, 50, 50)).export(tmp_path / "box.stl")
    out = tmp_path / "s.npz"
    run = subprocess.run([sys.executable, "-m", "rangesim", "scan", str(tmp_path / "box.stl"), "--out", str(out)],
                         env={**os.environ, "RANGESIM_VARIANT": variant}, capture_output=True, text=True,
                         timeout=120)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and "Traceback" not in run.stderr
    assert "RANGESIM_VARIANT" in lines[0] and words in lines[0] and "llvm_ad_rgb" in lines[0]
    assert not out.exists()


def test_scan_arrays_that_contradict_themselves_are_refused_naming_the_file(good_scan, tmp_path, capsys):
    """Valid pixels with an infinite depth: ``features`` said so without the file's name (``detect``
    named it); status codes past the documented 0-4: ``info`` printed "valid 0" and ``detect``
    scored the stored mask. An independent probe's cases."""
    from rangesim.io import load_scan

    load_scan(good_scan).save(tmp_path / "good.npz")
    arrays = dict(np.load(tmp_path / "good.npz"))
    infinite = {**arrays, "depth": np.where(arrays["valid"], np.inf, arrays["depth"]).astype(np.float32)}
    np.savez(tmp_path / "infinite.npz", **infinite)
    np.savez(tmp_path / "status.npz", **{**arrays, "status": (arrays["status"] + 7).astype(np.uint8)})
    for argv, words in ((["features", str(tmp_path / "infinite.npz"), "--out", str(tmp_path / "f")],
                         ["infinite.npz", "infinite depth"]),
                        (["info", str(tmp_path / "status.npz")], ["status.npz", "status holds code", "0-4"]),
                        (["detect", str(tmp_path / "status.npz"), "--out", str(tmp_path / "d")], ["status.npz"])):
        assert main(argv) == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 1 and all(w in lines[0] for w in words), lines
    assert not (tmp_path / "f").exists() and not (tmp_path / "d").exists()


def test_compare_refuses_a_camera_image_as_a_range_grid(tmp_path, capsys):
    """A perspective scan's points do not lie on a sweep's sample lines: its fitted grid had a
    row step near 0, the twin's noise correlation came out at 1.3 million cells and ``compare``
    ran for over 10 minutes (an independent probe). The Stanford bunny's grids stray 0.00 and
    0.15 steps; this one about 2."""
    import rangesim as rs
    from rangesim.twin.stage import GRID_MAX_RESIDUAL

    box = trimesh.creation.box((50, 50, 50))
    box.export(tmp_path / "box.stl")
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 64, "camera.height": 64})
    rs.scan([box], sensor).save(tmp_path / "small.npz")
    out = tmp_path / "c"
    assert main(["compare", str(tmp_path / "small.npz"), "--mesh", str(tmp_path / "box.stl"), "--out", str(out)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and "small.npz" in lines[0] and "range grid" in lines[0], lines
    stray = float(lines[0].split("stray ")[1].split(" ")[0])
    assert stray > GRID_MAX_RESIDUAL and not out.exists()
