"""The ``rangesim`` command line: scans, listings, and one-line errors without tracebacks.

Most tests call :func:`rangesim.cli.main.main` in-process (fast); one runs
``python -m rangesim`` in a subprocess to check the real exit code and stderr. Scans use
a 64 x 48 sensor and a box on a plane, so each takes a fraction of a second.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
import rangesim.cli.main as cli
from rangesim.cli.main import main
from rangesim.core.constants import STATUS_NAMES, Status
from rangesim.core.errors import RangesimError

REPO = Path(__file__).resolve().parents[1]
W, H = 64, 48

SENSOR_TOML = f"""\
name = "tiny_scanner"
description = "white_scanner at 64 x 48 pixels, for tests"
mode = "geometric"

[camera]
width = {W}
height = {H}
fov_deg = 22.0
aperture_mm = 6.0

[laser]
baseline = 150.0
sweep = "rotating"
step = 0.25
stripe_width = 0.5
wavelength_nm = 632.8

[range]
near = 250.0
far = 450.0

[noise]
sigma_px = 0.1
quantization_px = 0.0625
min_signal = 0.02
speckle_contrast = 0.5
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


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Tiny sensor and scene files, a box mesh, and broken meshes, written once."""
    d = tmp_path_factory.mktemp("cli_inputs")
    (d / "tiny_sensor.toml").write_text(SENSOR_TOML)
    (d / "scene.toml").write_text(SCENE_TOML)
    trimesh.creation.box(extents=(60.0, 40.0, 30.0)).export(d / "box.stl")
    (d / "empty.stl").write_text("solid empty\nendsolid empty\n")  # valid STL, no facets
    (d / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")  # vertices, no faces
    (d / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (d / "pose_3x3.json").write_text(json.dumps(np.eye(3).tolist()))
    (d / "pose_bottom_row.json").write_text(json.dumps([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 300], [5, 5, 5, 5]]))
    (d / "a_file").write_text("not a directory")
    (d / "a_dir.exr").mkdir()
    return {p.name: p for p in d.iterdir()}


@pytest.fixture(scope="module")
def scanned(inputs, tmp_path_factory) -> tuple[Path, str]:
    """One successful scan (.exr + .png) shared by the tests that read its outputs."""
    out = tmp_path_factory.mktemp("cli_scan") / "scan.exr"
    code, stdout = _run_ok(
        "scan", inputs["scene.toml"], "--sensor", inputs["tiny_sensor.toml"],
        "--out", out, "--preview", out.with_suffix(".png"), "--seed", "3",
    )
    assert code == 0
    return out, stdout


def _run_ok(*args) -> tuple[int, str]:
    """``main(args)`` and its stdout, checking stderr stays empty (usable outside capsys)."""
    buf_out, buf_err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf_out), contextlib.redirect_stderr(buf_err):
        code = main([str(a) for a in args])
    assert buf_err.getvalue() == "", buf_err.getvalue()
    return code, buf_out.getvalue()


def _files_under(folder: Path) -> list[Path]:
    """Every file (hidden temporaries included) below ``folder``."""
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


# -- successful commands -------------------------------------------------------------------
def test_scan_writes_exr_and_png_that_load_back(scanned):
    out, stdout = scanned
    png = out.with_suffix(".png")
    assert out.is_file() and png.is_file()
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    scan = rs.load_scan(out)
    assert scan.shape == (H, W)
    assert scan.meta["seed"] == 3 and scan.meta["sensor"]["name"] == "tiny_scanner"
    assert 0 < scan.valid.sum() < H * W  # the box casts a laser shadow on the ground
    # the summary: one paragraph with size, valid share, every status and the outputs
    assert stdout.strip().count("\n") == 0
    assert f"{W} x {H} px" in stdout and "valid" in stdout
    for code in Status:
        if code != Status.VALID:
            assert f"{STATUS_NAMES[code]} {scan.count(code):,}" in stdout
    assert str(out) in stdout and str(png) in stdout
    assert sorted(p.name for p in _files_under(out.parent)) == ["scan.exr", "scan.png"]


def test_scan_of_a_mesh_file_with_overrides_and_pose(inputs, tmp_path):
    sensor = rs.load_sensor(inputs["tiny_sensor.toml"])
    scene = rs.load_scene(inputs["box.stl"])
    pose = rs.default_pose(scene, sensor)
    np.save(tmp_path / "pose.npy", pose)
    out = tmp_path / "box.npz"
    code, stdout = _run_ok(
        "scan", inputs["box.stl"], "--sensor", inputs["tiny_sensor.toml"], "--out", out,
        "--pose", tmp_path / "pose.npy", "--set", "noise.sigma_px=0", "--set", "laser.sweep=rotating",
    )
    assert code == 0 and "box.stl" in stdout
    scan = rs.load_scan(out)
    assert scan.shape == (H, W) and scan.valid.any()
    assert scan.meta["sensor"]["noise"]["sigma_px"] == 0
    np.testing.assert_allclose(scan.pose, pose)


def test_sensors_lists_presets_with_descriptions(capsys):
    assert main(["sensors"]) == 0
    stdout = capsys.readouterr().out
    for name in ("white_scanner", "cyberware_3030", "inria_laser"):
        line = next(line for line in stdout.splitlines() if line.startswith(name + " "))
        assert rs.load_sensor(name).description in line


def test_info_prints_size_status_counts_depth_sensor_and_pose(scanned, capsys):
    out, _ = scanned
    assert main(["info", str(out)]) == 0
    stdout = capsys.readouterr().out
    scan = rs.load_scan(out)
    assert f"{W} x {H} px" in stdout and "tiny_scanner" in stdout and "seed 3" in stdout
    for code in Status:
        row = next(line for line in stdout.splitlines() if line.strip().startswith(STATUS_NAMES[code]))
        assert f"{scan.count(code):,}" in row
    depth = scan.depth[scan.valid]
    assert f"{depth.min():.3f} .. {depth.max():.3f} mm" in stdout
    assert "pose" in stdout and "-180.0000" in stdout  # the scene's [view] position


@pytest.mark.parametrize(
    ("raw", "expected"),
    [("0", 0), ("1.5", 1.5), ("true", True), ('"rotating"', "rotating"), ("translating", "translating")],
)
def test_set_values_parse_as_toml(raw, expected):
    assert cli._parse_setting(f"laser.x={raw}") == ("laser.x", expected)


def test_help_exits_zero(capsys):
    assert main(["--help"]) == 0
    assert "scan" in capsys.readouterr().out


# -- errors: one line, exit 2, no traceback, no output files ----------------------------------
# (arguments after SCENE, scene key in `inputs` or a missing name, words the message must hold)
ERRORS = [
    pytest.param([], "missing.stl", ["missing.stl", "no such mesh file"], id="missing-mesh"),
    pytest.param([], "missing.toml", ["missing.toml", "no such file"], id="missing-scene"),
    pytest.param([], "empty.stl", ["empty.stl", "no triangle mesh"], id="empty-stl"),
    pytest.param([], "points.obj", ["points.obj", "not a triangle mesh"], id="obj-without-faces"),
    pytest.param([], "nan.obj", ["nan.obj", "NaN"], id="nan-vertices"),
    pytest.param(["--sensor", "no_such_sensor"], "scene.toml",
                 ["no_such_sensor", "unknown sensor preset", "white_scanner"], id="unknown-preset"),
    pytest.param(["--set", "camera.width=0"], "scene.toml",
                 ["tiny_sensor.toml", "camera.width must be positive"], id="zero-width"),
    pytest.param(["--set", "laser.baseline=-10"], "scene.toml",
                 ["tiny_sensor.toml", "laser.baseline must be positive"], id="negative-baseline"),
    pytest.param(["--set", "range.near=450"], "scene.toml",
                 ["tiny_sensor.toml", "range.near", "less than range.far"], id="near-not-below-far"),
    pytest.param(["--set", "noise.sigma=0"], "scene.toml",
                 ["tiny_sensor.toml", "unknown key(s) sigma in [noise]"], id="unknown-set-key"),
    pytest.param(["--set", "name.x=1"], "scene.toml",
                 ["tiny_sensor.toml", "name.x", "not a table"], id="set-into-non-table"),
    pytest.param(["--set", "camera.width=true"], "scene.toml",
                 ["camera.width must be a number"], id="boolean-width"),
    pytest.param(["--set", "camerawidth"], "scene.toml", ["KEY=VALUE", "camerawidth"], id="set-without-equals"),
    pytest.param(["--seed", "-1"], "scene.toml", ["seed must be a non-negative integer"], id="negative-seed"),
    pytest.param(["--pose", "{inputs}/pose_3x3.json"], "scene.toml",
                 ["pose_3x3.json", "4x4"], id="pose-wrong-shape"),
    pytest.param(["--pose", "{inputs}/pose_bottom_row.json"], "scene.toml",
                 ["pose_bottom_row.json", "bottom row 0 0 0 1"], id="pose-not-rigid"),
    pytest.param(["--out", "{out}/scan.txt"], "scene.toml",
                 ["scan.txt", "'.txt'", ".exr"], id="bad-scan-suffix"),
    pytest.param(["--preview", "{out}/scan.jpg"], "scene.toml",
                 ["scan.jpg", "'.jpg'", ".png"], id="bad-preview-suffix"),
    # outputs that cannot be written are refused before the scan, so no other output is left
    pytest.param(["--out", "{inputs}/a_file/scan.exr"], "scene.toml",
                 ["a_file/scan.exr", "a_file is not a directory"], id="out-under-a-file"),
    pytest.param(["--preview", "{inputs}/a_file/scan.png"], "scene.toml",
                 ["a_file/scan.png", "a_file is not a directory"], id="preview-under-a-file"),
    pytest.param(["--out", "{inputs}/a_dir.exr", "--intensity-image", "{out}/intensity.png"], "scene.toml",
                 ["a_dir.exr", "a directory of that name exists"], id="out-is-a-directory"),
    pytest.param(["--intensity-image", "{inputs}/a_file/i.png"], "scene.toml",
                 ["a_file/i.png", "a_file is not a directory"], id="intensity-under-a-file"),
]


@pytest.mark.parametrize(("extra", "scene", "words"), ERRORS)
def test_errors_are_one_line_without_traceback_or_outputs(inputs, tmp_path, capsys, extra, scene, words):
    out = tmp_path / "out"
    folder = str(next(iter(inputs.values())).parent)
    extra = [a.format(inputs=folder, out=out) for a in extra]
    scene_path = inputs.get(scene, Path(folder) / scene)
    args = ["scan", str(scene_path), "--sensor", str(inputs["tiny_sensor.toml"]),
            "--out", str(out / "scan.exr"), "--preview", str(out / "scan.png"), *extra]
    code = main(args)
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rangesim: error: "), captured.err
    for word in words:
        assert word in lines[0]
    assert _files_under(out) == []
    assert not list(Path(folder).glob(".*tmp-*"))  # no temporaries beside the inputs either


def test_outputs_written_together_all_or_none(tmp_path):
    from rangesim.cli.common import write_together

    first, second = tmp_path / "a.txt", tmp_path / "sub" / "b.txt"
    first.write_text("old")

    def fail(tmp):
        Path(tmp).write_text("half")
        raise RangesimError("the drawing failed")

    with pytest.raises(RangesimError, match="the drawing failed"):
        write_together([(first, lambda tmp: Path(tmp).write_text("new")), (second, fail)])
    assert first.read_text() == "old" and not second.exists()
    assert sorted(p.name for p in _files_under(tmp_path)) == ["a.txt"]  # no temporaries left
    write_together([(first, lambda tmp: Path(tmp).write_text("new")), (second, lambda tmp: Path(tmp).write_text("b"))])
    assert first.read_text() == "new" and second.read_text() == "b"


def test_info_of_a_missing_file_is_a_user_error(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nope.exr")]) == 2
    assert capsys.readouterr().err.strip() == f"rangesim: error: {tmp_path / 'nope.exr'}: no such file"


def test_internal_errors_and_interrupts(monkeypatch, inputs, tmp_path, capsys):
    def boom(*args, **kwargs):
        raise RuntimeError("something broke")

    args = ["scan", str(inputs["scene.toml"]), "--out", str(tmp_path / "s.exr")]
    monkeypatch.setattr(cli, "scan", boom)
    monkeypatch.delenv("RANGESIM_DEBUG", raising=False)
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "RuntimeError: something broke" in err and "Traceback" not in err
    monkeypatch.setenv("RANGESIM_DEBUG", "1")
    assert main(args) == 1
    assert "Traceback" in capsys.readouterr().err

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.delenv("RANGESIM_DEBUG")
    monkeypatch.setattr(cli, "scan", interrupt)
    assert main(args) == 130
    assert capsys.readouterr().err == "rangesim: error: interrupted\n"
    assert _files_under(tmp_path) == []


def test_python_m_rangesim_reports_errors_without_traceback(inputs, tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    env.pop("RANGESIM_DEBUG", None)
    result = subprocess.run(
        [sys.executable, "-m", "rangesim", "scan", str(inputs["nan.obj"]), "--out", "out/scan.exr"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines() == [
        f"rangesim: error: {inputs['nan.obj']}: 1 vertices have NaN or infinite coordinates"
    ]
    assert not (tmp_path / "out").exists()


def test_info_names_valid_pixels_without_a_depth(scanned, tmp_path, capsys):
    import dataclasses

    scan = rs.load_scan(scanned[0])
    depth = scan.depth.copy()
    holes = np.flatnonzero(scan.valid)[:5]
    depth.ravel()[holes] = np.nan  # punched without updating valid: the detectors take them as holes
    path = tmp_path / "punched.npz"
    dataclasses.replace(scan, depth=depth).save(path)
    assert main(["info", str(path)]) == 0
    assert "note: 5 pixels marked valid have no depth (NaN)" in capsys.readouterr().out


def test_info_says_when_the_valid_mask_and_the_status_disagree(scanned, tmp_path, capsys):
    """An edited mask (fields may be reassigned, ``valid`` rules): ``info``'s counts are the
    status codes', and it said nothing of the mask the detectors use (an independent probe)."""
    import dataclasses

    scan = rs.load_scan(scanned[0])
    valid = scan.valid.copy()
    valid.ravel()[np.flatnonzero(valid)[:7]] = False
    depth = np.where(scan.valid, np.inf, scan.depth).astype(np.float32)
    dataclasses.replace(scan, valid=valid).save(tmp_path / "masked.npz")
    dataclasses.replace(scan, depth=depth).save(tmp_path / "infinite.npz")
    assert main(["info", str(tmp_path / "masked.npz")]) == 0
    out = capsys.readouterr().out
    assert "valid and status disagree at 7 pixels" in out and f"use the {int(valid.sum()):,} valid" in out
    assert main(["info", str(tmp_path / "infinite.npz")]) == 0
    out = capsys.readouterr().out
    assert f"{int(scan.valid.sum()):,} pixels marked valid have an infinite depth" in out and "disagree" not in out


@pytest.mark.parametrize(("args", "mode"), [
    (["info", "x.exr"], "log"), (["info", "x.exr", "--quiet"], "off"), (["--quiet", "info", "x.exr"], "off"),
    (["compare", "x.pcd", "--out", "o", "--quiet"], "off"), (["detect", "x.exr", "--out", "o", "--quiet"], "off"),
])
def test_every_command_takes_quiet(monkeypatch, capsys, args, mode):
    # the README promises --quiet for long work; only sweep and dataset took it
    from rangesim.core import progress

    seen = []

    def record(*a, **k):
        seen.append(progress._default)
        raise RangesimError("stop here")

    import rangesim.cli.compare_commands
    import rangesim.cli.edge_commands
    import rangesim.evaluate.runs

    for module in (cli, rangesim.cli.compare_commands, rangesim.cli.edge_commands):
        if hasattr(module, "load_scan"):
            monkeypatch.setattr(module, "load_scan", record)
    monkeypatch.setattr(rangesim.cli.compare_commands, "load_scan_with_labels", record, raising=False)
    monkeypatch.setattr(rangesim.evaluate.runs, "load_scan_with_labels", record)
    assert main(args) == 2
    assert seen == [mode], capsys.readouterr().err


def test_warnings_print_as_one_line(monkeypatch, capsys):
    import warnings

    def warn(args):
        warnings.warn("first line\n  second line", RuntimeWarning, stacklevel=1)
        return 0

    monkeypatch.setattr(cli, "cmd_info", warn)
    monkeypatch.delenv("RANGESIM_DEBUG", raising=False)
    assert main(["info", "x.exr"]) == 0
    assert capsys.readouterr().err == "rangesim: warning: first line second line\n"  # not file:line and source


def test_points_far_from_the_origin_warn_under_the_file_s_own_name(tmp_path, capsys):
    box = trimesh.creation.box(extents=(10.0, 10.0, 10.0))
    box.apply_translation((1e7, 0.0, 0.0))  # 10 km: a .ply's float32 steps by 1 mm there
    box.export(tmp_path / "far.stl")
    out = tmp_path / "far.ply"
    assert main(["points", str(tmp_path / "far.stl"), "--resolution", "2mm", "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err == ("rangesim: warning: far.ply: coordinates reach 1e+07 mm, where float32 steps by 1 mm; "
                   "a .ply stores float32: write .npz (float64)\n")  # the file's name, not its temporary's
    assert main(["points", str(tmp_path / "far.stl"), "--resolution", "2mm", "--out", str(tmp_path / "f.npz"),
                 "--quiet"]) == 0
    assert capsys.readouterr().err == ""
