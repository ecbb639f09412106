"""An output path that names one of the command's inputs (or another output) is refused before any
work, and the input is left exactly as it was; folder commands write all their files or none."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def _refused(capsys, argv, *words):
    """``main(argv)`` exits 2 with one error line that holds every word."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rangesim: error:"), err
    for word in words:
        assert str(word) in lines[0], (word, lines[0])
    return lines[0]


def _box_mesh(path: Path) -> bytes:
    trimesh.creation.box(extents=(40.0, 30.0, 10.0)).export(path)
    return path.read_bytes()


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plate12")
    rs.datasets.plate_scan().save(folder / "plate.npz")
    return folder / "plate.npz"


def test_scan_onto_its_own_mesh_is_refused(tmp_path, capsys):
    # `rangesim scan part.ply --out part.ply` replaced the part with its scan, exit status 0
    mesh = tmp_path / "part.ply"
    before = _box_mesh(mesh)
    _refused(capsys, ["scan", mesh, "--units", "mm", "--out", mesh], "part.ply", "overwrite", "input")
    assert mesh.read_bytes() == before


def test_scan_onto_a_mesh_its_scene_names_is_refused(tmp_path, capsys):
    mesh = tmp_path / "part.ply"
    before = _box_mesh(mesh)
    scene = tmp_path / "scene.toml"
    scene.write_text('units = "mm"\n[[object]]\nname = "part"\nmesh = "part.ply"\n')
    # through another spelling of the same file (a link in the folder above)
    (tmp_path / "link").symlink_to(tmp_path)
    _refused(capsys, ["scan", scene, "--out", tmp_path / "link" / "part.ply"], "overwrite", "input")
    assert mesh.read_bytes() == before


def test_scan_preview_and_intensity_image_on_one_file_are_refused(tmp_path, capsys):
    mesh = tmp_path / "part.stl"
    _box_mesh(mesh)
    out = tmp_path / "s.npz"
    png = tmp_path / "p.png"
    _refused(capsys, ["scan", mesh, "--units", "mm", "--out", out, "--preview", png, "--intensity-image", png],
             "same file")
    assert not out.exists() and not png.exists()


def test_points_onto_the_model_they_sample_is_refused(tmp_path, capsys):
    mesh = tmp_path / "part.ply"
    before = _box_mesh(mesh)
    _refused(capsys, ["points", mesh, "--resolution", "2", "--out", mesh], "overwrite", "part.ply")
    assert mesh.read_bytes() == before


def test_detect_keeps_an_input_scan_named_like_a_map(tmp_path, capsys, plate):
    # the scan lies in the output folder under a detector's map name: it was deleted as "another
    # scan's map" when another detector ran, or overwritten when that detector ran
    out = tmp_path / "edges"
    out.mkdir()
    scan = out / "normal_edges.npz"
    scan.write_bytes(plate.read_bytes())
    assert main(["detect", str(scan), "--method", "gradient", "--out", str(out)]) == 0
    capsys.readouterr()
    assert scan.read_bytes() == plate.read_bytes()
    assert (out / "gradient_edges.npz").is_file()
    _refused(capsys, ["detect", scan, "--method", "normal", "--out", out], "overwrite", "normal_edges.npz")
    assert scan.read_bytes() == plate.read_bytes()


def test_detect_still_clears_another_scans_maps(tmp_path, capsys, plate):
    out = tmp_path / "edges"
    other = tmp_path / "other.npz"
    scan = rs.load_scan(plate)
    scan.meta = {**scan.meta, "note": "another file"}
    scan.save(other)
    assert main(["detect", str(other), "--method", "normal", "--out", str(out)]) == 0
    assert main(["detect", str(plate), "--method", "gradient", "--out", str(out)]) == 0
    capsys.readouterr()
    assert not (out / "normal_edges.npz").exists() and not (out / "normal.png").exists()
    with np.load(out / "gradient_edges.npz") as npz:
        assert str(npz["scan"]) == str(plate.resolve())


def test_features_refuse_an_output_onto_the_scan(tmp_path, capsys, plate):
    out = tmp_path / "f"
    out.mkdir()
    scan = out / "features.json"
    scan.write_bytes(b"{}")
    _refused(capsys, ["features", scan, "--out", out], "overwrite")
    assert scan.read_bytes() == b"{}"


def test_features_write_all_files_or_none(tmp_path, capsys, plate, monkeypatch):
    import rangesim.viz.features as viz

    def broken(*args, **kwargs):
        raise rs.RangesimError("drawing failed")

    monkeypatch.setattr(viz, "save_features_overlay", broken)
    out = tmp_path / "f"
    assert main(["features", str(plate), "--out", str(out)]) == 2
    capsys.readouterr()
    assert not out.exists() or sorted(p.name for p in out.iterdir()) == []


def test_calibrate_refuses_one_recording_twice(tmp_path, capsys):
    from tests.conftest import grid_recording

    rec = tmp_path / "rec.npz"
    grid_recording(40, 50).save(rec)
    mesh = tmp_path / "m.stl"
    _box_mesh(mesh)
    (tmp_path / "again.npz").symlink_to(rec)
    _refused(capsys, ["calibrate", rec, tmp_path / "again.npz", "--mesh", mesh, "--sensor", "cyberware_3030",
                      "--out", tmp_path / "c.toml"], "twice")



def test_calibrate_refuses_to_overwrite_the_preset_it_names(tmp_path, capsys, monkeypatch):
    """``--sensor NAME --out sensors/NAME.toml`` read the preset and wrote over it (exit 0)."""
    from tests.conftest import grid_recording

    presets = tmp_path / "presets"
    presets.mkdir()
    preset = presets / "my_scanner.toml"
    preset.write_bytes((ROOT / "sensors" / "cyberware_3030.toml").read_bytes())
    before = preset.read_bytes()
    monkeypatch.setenv("RANGESIM_SENSORS", str(presets))
    rec = tmp_path / "rec.npz"
    grid_recording(40, 50).save(rec)
    mesh = tmp_path / "m.stl"
    _box_mesh(mesh)
    _refused(capsys, ["calibrate", rec, "--mesh", mesh, "--sensor", "my_scanner", "--out", preset],
             "would overwrite", "an input of this command")
    assert preset.read_bytes() == before

def test_sigterm_leaves_no_temporary_file(tmp_path):
    """A terminated command (SIGTERM, as a batch system or `timeout` sends) removes its temporary
    files and exits 143 without a traceback."""
    out = tmp_path / "out"
    code = ("import time, sys\n"
            "import rangesim.cli.points_commands as pc\n"
            "real = pc.write_together\n"
            "def slow(writes):\n"
            "    def hang(tmp):\n"
            "        open(tmp, 'w').write('partial')\n"
            "        print('writing', flush=True)\n"
            "        time.sleep(60)\n"
            "    real([(writes[0][0], hang)])\n"
            "pc.write_together = slow\n"
            "from rangesim.cli.main import main\n"
            f"sys.exit(main(['points', 'green_piece', '--resolution', '3', '--out', {str(out / 'p.ply')!r}]))\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not any(out.glob(".*tmp-*")):
            time.sleep(0.05)
        assert any(out.glob(".*tmp-*")), "the command never started writing"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "terminated" in err
    assert not out.exists()   # no temporary file, and the folder the run made, left empty, is removed too


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_an_interrupted_sweep_stops_its_workers_at_once(tmp_path, how):
    """Ctrl-C (SIGINT to the whole process group) or SIGTERM to the driver halfway through a
    two-worker sweep: the command exits at once (130 / 143), its pool processes are gone and no
    temporary file is left; the finished tasks stay for a rerun."""
    from rangesim.experiments.results import TASKS_DIR
    from tests.test_experiments import SCENE_TOML, SENSOR_TOML, SWEEP_TOML

    (tmp_path / "scene.toml").write_text(SCENE_TOML)
    (tmp_path / "tiny.toml").write_text(SENSOR_TOML)
    (tmp_path / "sweep.toml").write_text(SWEEP_TOML.replace("views = 2", "views = 40"))  # 160 tasks
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "rangesim", "sweep", str(tmp_path / "sweep.toml"), "--out", str(out),
                             "--workers", "2", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None and not _finished_tasks(out / TASKS_DIR):
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        children = _children(proc.pid)
        assert len(children) >= 2  # the pool's processes (and the resource tracker)
        if how == "ctrl-c":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == (130 if how == "ctrl-c" else 143), err
    assert "Traceback" not in err
    time.sleep(0.5)
    assert not [pid for pid in children if Path(f"/proc/{pid}").exists() and _alive(pid)]
    assert not list(out.rglob(".*tmp-*"))
    assert _finished_tasks(out / TASKS_DIR)


def _finished_tasks(folder: Path) -> list[Path]:
    """Task files written and renamed (pathlib's glob also lists the hidden temporary names of
    files still being written, which an interrupt removes)."""
    return [p for p in folder.glob("*") if not p.name.startswith(".")]


def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (Linux /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    """Not a zombie (a finished child its parent has not reaped yet)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("command", ["sweep", "dataset"])
def test_workers_with_a_scheduler_is_refused(tmp_path, capsys, command):
    """--workers sizes the local pool; with --scheduler it was silently ignored."""
    args = ([command, "any.toml"] if command == "sweep" else [command, "--scene", "any.toml", "--sensor", "white_scanner",
                                                             "--views", "2"])
    _refused(capsys, [*args, "--out", tmp_path / "o", "--workers", "3", "--scheduler", "local:2"],
             "--workers 3", "--scheduler local:2")
    assert not (tmp_path / "o").exists()


def test_detect_beside_a_broken_map_file(tmp_path, capsys, plate):
    """An empty or corrupt *_edges.npz in the folder is no map of another scan: kept, no crash."""
    out = tmp_path / "edges"
    out.mkdir()
    (out / "normal_edges.npz").write_bytes(b"")
    (out / "curvature_edges.npz").write_bytes(b"PK\x03\x04 not a zip")
    assert main(["detect", str(plate), "--method", "gradient", "--out", str(out)]) == 0
    capsys.readouterr()
    assert (out / "normal_edges.npz").read_bytes() == b"" and (out / "gradient_edges.npz").is_file()
