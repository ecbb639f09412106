"""Sweeps, datasets, SNR and the executors of ``rangesim.experiments``.

Kept small and fast: the sweeps scan a box on a floor with a 64 x 48 camera (a few
milliseconds a scan), so most of the time goes into starting worker processes (a spawned
pool, a Dask LocalCluster on 127.0.0.1, a ``rangesim sweep`` subprocess killed with SIGKILL).
"""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import rangesim as rs
from rangesim.cli.main import main
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.experiments import SyntheticDataset, edge_snr, load_sweep, make_dataset, run_sweep
from rangesim.experiments.grid import derive_seed, plan_sweep, task_key
from rangesim.experiments.poses import cap_directions
from rangesim.experiments.results import TASKS_DIR, read_table
from rangesim.experiments.snr import depth_noise, slope_noise_factor
from rangesim.experiments.tasks import TIMING_COLUMNS
from tests.conftest import BOX_SCENE_TOML

REPO = Path(__file__).resolve().parents[1]

SCENE_TOML = BOX_SCENE_TOML + """
[view]
position = [0, -250, 380]
look_at = [0, 0, 20]
"""

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
[noise]
sigma_px = 0.1
quantization_px = 0.0625
"""

SWEEP_TOML = """\
name = "tiny_sweep"
scenes = ["scene.toml"]
sensors = ["tiny.toml"]
views = 2
seed = 7

[detectors.gradient]
jump_clearance = 2

[detectors.normal]

[detectors.pcl_organized]

[pose]
cap_deg = 25
distance = [350, 450]

[grid]
"noise.sigma_px" = [0.05, 0.5]
"object.box.albedo" = [0.6, 0.9]
"""


@pytest.fixture(scope="module")
def sweep_dir(tmp_path_factory) -> Path:
    """A folder with scene.toml, tiny.toml (sensor) and sweep.toml (8 tasks)."""
    d = tmp_path_factory.mktemp("sweep")
    (d / "scene.toml").write_text(SCENE_TOML)
    (d / "tiny.toml").write_text(SENSOR_TOML)
    (d / "sweep.toml").write_text(SWEEP_TOML)
    return d


@pytest.fixture(scope="module")
def serial_run(sweep_dir):
    """The sweep run in this process (workers=0): the reference table."""
    return run_sweep(sweep_dir / "sweep.toml", sweep_dir / "serial", workers=0, progress=False)


def _comparable(table):
    return table.drop(columns=[c for c in TIMING_COLUMNS if c in table.columns]).reset_index(drop=True)


def _assert_same_results(a, b) -> None:
    import pandas as pd

    pd.testing.assert_frame_equal(_comparable(a), _comparable(b), check_exact=True)


# -- SNR -----------------------------------------------------------------------------------
def _synthetic(z_true: np.ndarray, normals: np.ndarray, f: float, sigma: float, seed: int = 0) -> rs.RangeScan:
    """A RangeScan of a given noise-free depth image: pinhole K, Gaussian depth noise sigma (mm)."""
    h, w = z_true.shape
    K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]])
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ray = np.stack([(jj - w / 2) / f, (ii - h / 2) / f, np.ones_like(jj)], axis=-1)
    depth = z_true + np.random.default_rng(seed).normal(0.0, sigma, z_true.shape)
    zeros = np.zeros((h, w), np.int32)
    return rs.RangeScan(
        depth=depth, xyz=ray * depth[..., None], valid=np.ones((h, w), bool), normal=normals,
        intensity=np.ones((h, w)), part=zeros, face=zeros, status=np.zeros((h, w), np.uint8),
        meta={"K": K.tolist()}, xyz_true=ray * z_true[..., None],
    )


def test_snr_of_a_jump_is_step_over_depth_noise():
    h, w, sigma = 64, 64, 0.05
    z = np.where(np.arange(w)[None, :] < w // 2, 500.0, 520.0) * np.ones((h, 1))
    normals = np.broadcast_to([0.0, 0.0, -1.0], (h, w, 3)).copy()
    labels = np.zeros((h, w), np.uint8)
    labels[:, w // 2 - 1] = EdgeLabel.JUMP  # the near side
    scan = _synthetic(z, normals, 100.0, sigma)
    sigma_z, sigma_fp = depth_noise(scan)
    assert sigma_z == pytest.approx(sigma, rel=0.05)
    assert sigma_fp == pytest.approx(sigma / (510.0 / 100.0), rel=0.06)
    snr = edge_snr(scan, labels)
    assert snr.snr_jump == pytest.approx(20.0 / sigma, rel=0.05)
    assert snr.snr == snr.snr_jump and snr.n_jump == h and snr.n_crease == 0
    assert math.isnan(snr.snr_crease)
    assert np.isnan(snr.per_pixel[labels == 0]).all()
    noise_free = edge_snr(_synthetic(z, normals, 100.0, 0.0), labels)
    assert math.isinf(noise_free.snr_jump) and noise_free.sigma_z == 0.0


def test_snr_of_a_crease_is_slope_change_over_slope_noise():
    """A roof z = z0 + s X (X < 0) and z0 - s X (X > 0) seen head-on: the slope changes by
    2 s; the slope of a k-pixel least-squares fit has noise sigma_fp sqrt(12 / (k (k^2 - 1)))."""
    h, w, f, z0, s, sigma = 64, 64, 100.0, 500.0, 0.3, 0.05
    xr = (np.arange(w) + 0.5 - w / 2) / f  # x' of each column
    slope = np.where(xr < 0, s, -s)
    z_row = z0 / (1.0 - slope * xr)  # z = z0 + slope X on the ray X = z x'
    z = np.broadcast_to(z_row, (h, w)).copy()
    n = np.stack([slope, np.zeros(w), -np.ones(w)], axis=-1) / np.sqrt(1 + s * s)
    normals = np.broadcast_to(n, (h, w, 3)).copy()
    labels = np.zeros((h, w), np.uint8)
    labels[:, w // 2 - 1] = EdgeLabel.CONVEX
    scan = _synthetic(z, normals, f, sigma)
    for k in (2, 3, 5):
        snr = edge_snr(scan, labels, window=k)
        sigma_fp = sigma / (z0 / f)
        expected = 2 * s / (math.sqrt(2) * sigma_fp * math.sqrt(12 / (k * (k * k - 1))))
        assert snr.snr_crease == pytest.approx(expected, rel=0.06), k
        assert snr.n_crease == h and math.isnan(snr.snr_jump)


def test_slope_noise_factor_matches_least_squares():
    rng = np.random.default_rng(1)
    for k in (2, 3, 7):
        x = np.arange(k, dtype=float)
        y = rng.normal(size=(40000, k))
        slopes = (y * (x - x.mean())).sum(axis=1) / ((x - x.mean()) ** 2).sum()
        assert slopes.std() == pytest.approx(slope_noise_factor(k), rel=0.02)


def test_measured_depth_noise_follows_the_triangulation_model():
    """A plane head-on at 400 mm: sigma_z = z^2 sigma_u / (f b) on the axis."""
    from tests.conftest import make_sensor, plane, top_down_pose

    sensor = make_sensor(**{"noise.sigma_px": 0.3})
    scan = rs.scan([plane()], sensor, pose=top_down_pose(400.0), seed=3)
    sigma_z, _ = depth_noise(scan)
    expected = 400.0 ** 2 * 0.3 / (sensor.focal_px * 150.0)
    assert sigma_z == pytest.approx(expected, rel=0.15)


# -- poses, keys, seeds --------------------------------------------------------------------
def test_cap_directions_are_uniform_in_solid_angle():
    rng = np.random.default_rng(0)
    axis = np.array([0.2, -1.0, 1.4])
    d = cap_directions(rng.random(20000), rng.random(20000), axis, 40.0)
    cos_t = d @ (axis / np.linalg.norm(axis))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert cos_t.min() >= math.cos(math.radians(40.0)) - 1e-12
    # cos(theta) uniform on [cos 40, 1]: mean and spread of a uniform distribution
    lo = math.cos(math.radians(40.0))
    assert cos_t.mean() == pytest.approx((1 + lo) / 2, abs=0.003)
    assert cos_t.std() == pytest.approx((1 - lo) / math.sqrt(12), rel=0.02)


def test_keys_and_seeds_derive_from_parameters(sweep_dir):
    spec = load_sweep(sweep_dir / "sweep.toml")
    tasks = plan_sweep(spec)
    assert len(tasks) == spec.n_tasks == 8
    assert len({t.key for t in tasks}) == 8 and len({t.payload["noise_seed"] for t in tasks}) == 8
    again = plan_sweep(load_sweep(sweep_dir / "sweep.toml"))
    assert [t.key for t in again] == [t.key for t in tasks]
    # the same views at every noise level (paired comparison), other noise
    by = {(t.columns["noise.sigma_px"], t.columns["object.box.albedo"], t.columns["view"]): t for t in tasks}
    a, b = by[(0.05, 0.6, 1)], by[(0.5, 0.6, 1)]
    assert a.payload["pose_seed"] == b.payload["pose_seed"]
    assert a.payload["noise_seed"] != b.payload["noise_seed"]
    assert derive_seed(7, {"x": 1}) == derive_seed(7, {"x": 1}) != derive_seed(8, {"x": 1})
    assert task_key({"a": 1, "b": [1, 2]}) == task_key({"b": [1, 2], "a": 1})


@pytest.mark.parametrize("body, words", [
    ('scenes = ["scene.toml"]\nviewz = 3', ["viewz"]),
    ('scenes = ["scene.toml"]\n[grid]\n"noise.sigma_px" = 0.1', ["[grid] noise.sigma_px", "list"]),
    ('scenes = ["scene.toml"]\n[grid]\nnoise.sigma_px = [0.1]', ["[grid] noise", "quote"]),
    ('scenes = ["scene.toml"]\n[grid]\n"noise.sigmapx" = [1]', ["sigmapx"]),
    ('scenes = ["scene.toml"]\n[grid]\n"noise.sigma_px" = [0.1, -1]', ["noise.sigma_px", "negative"]),
    ('scenes = ["scene.toml"]\ndetectors = ["canny"]', ["canny"]),
    ('scenes = ["scene.toml"]\n[detectors.gradient]\nthresh = 1', ["detectors.gradient", "thresh"]),
    # values too, before any scan (they once failed every task after scanning)
    ('scenes = ["scene.toml"]\n[detectors.gradient]\nthreshold = -5', ["detectors.gradient", "threshold", "-5"]),
    ('scenes = ["scene.toml"]\n[detectors.normal]\nthreshold_deg = "abc"', ["detectors.normal", "threshold_deg", "abc"]),
    ('scenes = ["scene.toml"]\ncrease_deg = 180', ["crease_deg", "below 180"]),  # every task refused it
    ('scenes = ["scene.toml"]\n[grid]\n"object.nothing.albedo" = [0.5]', ["object.nothing.albedo", "nothing"]),
    ('scenes = ["scene.toml"]\n[grid]\n"object.box.colour" = [1]', ["object.box.colour"]),
    ('scenes = ["missing.toml"]', ["missing.toml"]),
    ('scenes = ["scene.toml"]\n[pose]\ncap_deg = 200', ["cap_deg"]),
    ('scenes = ["scene.toml"]\n[grid]\n"pose.roll" = [1]', ["pose.roll"]),
    ('scenes = ["scene.toml"]\nviews = -1', ["views"]),
    ('scenes = ["scene.toml"]\nsensors = ["no_such_sensor"]', ["no_such_sensor"]),
    ('views = 2', ["scenes"]),
])
def test_bad_sweep_files_fail_in_one_line_naming_file_and_key(sweep_dir, tmp_path, body, words):
    (tmp_path / "scene.toml").write_text(SCENE_TOML)
    path = tmp_path / "bad.toml"
    path.write_text(body + "\n")
    with pytest.raises(RangesimError) as info:
        load_sweep(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path)), message
    for word in words:
        assert word in message, (word, message)


# -- sweeps -----------------------------------------------------------------------------------
def test_sweep_writes_table_plots_and_task_files(serial_run, sweep_dir):
    out = sweep_dir / "serial"
    table = serial_run.table
    assert serial_run.n_tasks == 8 and serial_run.n_run == 8 and serial_run.n_reused == 0
    assert len(table) == 8 * 3 and list(dict.fromkeys(table["detector"])) == ["gradient", "normal", "pcl_organized"]
    for column in ("scene", "sensor", "noise.sigma_px", "object.box.albedo", "view", "repeat", "seed", "snr",
                   "snr_jump", "snr_crease", "sigma_z_mm", "precision", "recall", "f1", "fom", "jump_f1",
                   "pose_distance_mm", *TIMING_COLUMNS):
        assert column in table.columns, column
    assert table["f1"].between(0, 1).all() and (table["snr"] > 0).all()
    assert table["pose_distance_mm"].between(350, 450).all() and table["pose_polar_deg"].between(0, 25).all()
    # noisier scans have the lower SNR, for every view
    snr = table.groupby(["noise.sigma_px", "view"])["snr"].median().unstack()
    assert (snr.loc[0.5] < snr.loc[0.05] / 4).all()
    assert len(list((out / TASKS_DIR).glob("*.json"))) == 8
    _assert_same_results(read_table(out / "results.parquet"), table)
    csv = read_table(out / "results.csv")
    assert list(csv.columns) == list(table.columns) and len(csv) == len(table)
    for name in ("f1_vs_snr.png", "f1_vs_noise.sigma_px.png", "f1_vs_object.box.albedo.png"):
        assert (out / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    # a rerun reuses every task and writes the same table
    again = run_sweep(sweep_dir / "sweep.toml", out, workers=0, progress=False, plots=False)
    assert again.n_run == 0 and again.n_reused == 8
    _assert_same_results(again.table, table)
    assert again.table[list(TIMING_COLUMNS)].equals(table[list(TIMING_COLUMNS)])  # read back, not rerun


def test_pool_of_two_workers_gives_the_serial_table(serial_run, sweep_dir):
    run = run_sweep(sweep_dir / "sweep.toml", sweep_dir / "pool2", workers=2, progress=False, plots=False,
                    keep_scans=True)
    assert run.executor == "2 local processes" and run.n_run == 8
    _assert_same_results(run.table, serial_run.table)
    scans = sorted((sweep_dir / "pool2" / "scans").glob("*.exr"))
    assert len(scans) == 8
    scan = rs.load_scan(scans[0])
    assert scan.shape == (48, 64) and scan.xyz_true is not None


def test_dask_local_cluster_gives_the_serial_table(serial_run, sweep_dir):
    pytest.importorskip("dask.distributed")
    run = run_sweep(sweep_dir / "sweep.toml", sweep_dir / "dask", scheduler="local:2", progress=False, plots=False)
    assert run.executor == "Dask LocalCluster of 2 workers" and run.n_run == 8
    _assert_same_results(run.table, serial_run.table)


def test_dask_scheduler_address_gives_the_serial_table(serial_run, sweep_dir):
    """``tcp://HOST:PORT``: a scheduler someone else started (here: a one-worker cluster on loopback)."""
    distributed = pytest.importorskip("dask.distributed")
    import logging

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        run = run_sweep(sweep_dir / "sweep.toml", sweep_dir / "tcp", scheduler=address, progress=False,
                        plots=False)
    assert run.executor == f"Dask scheduler {address}" and run.n_run == 8
    _assert_same_results(run.table, serial_run.table)


def test_sigkill_halfway_then_rerun_gives_the_uninterrupted_table(serial_run, sweep_dir):
    out = sweep_dir / "killed"
    cmd = [sys.executable, "-m", "rangesim", "sweep", str(sweep_dir / "sweep.toml"), "--out", str(out),
           "--workers", "1", "--quiet", "--no-plots"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    tasks = out / TASKS_DIR
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if tasks.is_dir() and any(p.suffix == ".json" and not p.name.startswith(".") for p in tasks.iterdir()):
                break
            time.sleep(0.01)
        assert proc.poll() is None, f"the sweep ended before it could be killed: {proc.stderr.read()!r}"
        os.killpg(proc.pid, signal.SIGKILL)  # the driver and its pool worker
    finally:
        proc.wait(timeout=30)
        proc.stderr.close()
    done = [p for p in tasks.iterdir() if not p.name.startswith(".")]
    assert 1 <= len(done) < 8, len(done)
    assert not (out / "results.parquet").exists()
    for p in done:  # whole files only (temporary names start with a dot)
        json.loads(p.read_text())
    code = main(["sweep", str(sweep_dir / "sweep.toml"), "--out", str(out), "--workers", "1", "--quiet",
                 "--no-plots"])
    assert code == 0
    table = read_table(out / "results.parquet")
    _assert_same_results(table, serial_run.table)
    csv = read_table(out / "results.csv")
    _assert_same_results(csv, read_table(sweep_dir / "serial" / "results.csv"))


def test_sweep_cli_summary_and_errors(sweep_dir, capsys, tmp_path):
    code = main(["sweep", str(sweep_dir / "sweep.toml"), "--out", str(sweep_dir / "serial"), "--workers", "0",
                 "--quiet", "--no-plots"])
    out = capsys.readouterr().out
    assert code == 0 and "8 scans (all reused)" in out and "gradient" in out
    for args, words in (
        (["--scheduler", "udp://x"], "local:N or tcp://HOST:PORT"),
        (["--scheduler", "local:0"], "local:N"),
    ):
        code = main(["sweep", str(sweep_dir / "sweep.toml"), "--out", str(tmp_path / "x"), *args])
        err = capsys.readouterr().err
        assert code == 2 and words in err and err.count("\n") == 1, err
        assert not (tmp_path / "x").exists()  # options are checked before any file is written
    code = main(["sweep", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and "nope.toml" in err and err.count("\n") == 1
    (tmp_path / "file").write_text("")
    code = main(["sweep", str(sweep_dir / "sweep.toml"), "--out", str(tmp_path / "file")])
    assert code == 2 and "must be a directory" in capsys.readouterr().err


def test_failed_tasks_are_reported_and_the_others_kept(sweep_dir, tmp_path):
    bad = tmp_path / "sweep.toml"
    for name in ("scene.toml", "tiny.toml"):
        (tmp_path / name).write_text((sweep_dir / name).read_text())
    # an albedo above 1 passes the sweep file (object values are the scene's to check) but fails its tasks
    bad.write_text(SWEEP_TOML.replace('"object.box.albedo" = [0.6, 0.9]', '"object.box.albedo" = [0.6, 1.5]'))
    with pytest.raises(RangesimError) as info:
        run_sweep(bad, tmp_path / "out", workers=0, progress=False)
    message = str(info.value)
    assert "4 of 8 tasks failed" in message and "albedo" in message and "\n" not in message
    assert len(list((tmp_path / "out" / TASKS_DIR).glob("*.json"))) == 4
    assert not (tmp_path / "out" / "results.parquet").exists()


# -- datasets -----------------------------------------------------------------------------------
def test_dataset_poses_manifest_and_loader(sweep_dir, tmp_path):
    out = tmp_path / "data"
    run = make_dataset(sweep_dir / "scene.toml", sweep_dir / "tiny.toml", 3, out, seed=5, cap_deg=35,
                       distance=(300, 500), workers=0, progress=False)
    assert run.n_views == 3 and run.n_run == 3
    manifest = json.loads((out / "manifest.json").read_text())
    cap = manifest["cap"]
    axis, target = np.array(cap["axis"]), np.array(cap["target"])
    assert np.allclose(target, [0, 0, 25]) and cap["distance"] == [300.0, 500.0]
    ds = SyntheticDataset(out)
    assert len(ds) == 3
    poses = []
    for i in range(3):
        rec = ds.record(i)
        pose = np.asarray(rec["pose"])
        offset = pose[:3, 3] - target
        d = np.linalg.norm(offset)
        assert 300 <= d <= 500 and d == pytest.approx(rec["distance_mm"])
        assert math.degrees(math.acos(offset @ axis / d)) <= 35 + 1e-9
        assert np.allclose(pose[:3, 2], -offset / d)  # looks at the target
        sample = ds[i]
        assert sample["depth"].shape == (48, 64) and sample["xyz_true"].shape == (48, 64, 3)
        assert sample["edges"].shape == (48, 64) and sample["edges"].dtype == np.uint8
        assert set(np.unique(sample["edges"])) <= {0, 1, 2, 3} and (sample["edges"] == EdgeLabel.JUMP).any()
        assert sample["subpart"].shape == (48, 64) and sample["subpart"].max() <= 1
        assert np.allclose(sample["pose"], pose) and sample["K"].shape == (3, 3)
        hit = sample["part"] >= 0
        assert np.allclose(sample["depth_true"][hit], sample["xyz_true"][..., 2][hit])
        poses.append(pose)
    assert not np.allclose(poses[0], poses[1])
    depth_only = SyntheticDataset(out, fields=["depth", "edges"])
    assert set(depth_only[-1]) == {"depth", "edges"}
    with pytest.raises(IndexError):
        ds[3]
    # a rerun renders nothing and lists the same views; more views keep the first ones
    again = make_dataset(sweep_dir / "scene.toml", sweep_dir / "tiny.toml", 4, out, seed=5, cap_deg=35,
                         distance=(300, 500), workers=0, progress=False)
    assert again.n_reused == 3 and again.n_run == 1
    assert [r["key"] for r in again.records[:3]] == [ds.record(i)["key"] for i in range(3)]


def test_dataset_cli(sweep_dir, tmp_path, capsys):
    out = tmp_path / "cli_data"
    code = main(["dataset", "--scene", str(sweep_dir / "scene.toml"), "--sensor", str(sweep_dir / "tiny.toml"),
                 "--views", "2", "--out", str(out), "--format", "npz", "--workers", "0", "--quiet",
                 "--set", "camera.width=32", "--set", "camera.height=24"])
    assert code == 0, capsys.readouterr().err
    assert "2 views (2 rendered" in capsys.readouterr().out
    ds = SyntheticDataset(out)
    assert ds.record(0)["scan"].endswith(".npz") and ds[1]["depth"].shape == (24, 32)
    code = main(["dataset", "--scene", str(sweep_dir / "scene.toml"), "--views", "2", "--out", str(out),
                 "--distance", "500", "100"])
    assert code == 2 and "--distance" in capsys.readouterr().err


def test_sweep_over_the_scanner_mode_includes_structured_light(sweep_dir, tmp_path):
    body = SWEEP_TOML.replace('''[grid]
"noise.sigma_px" = [0.05, 0.5]
"object.box.albedo" = [0.6, 0.9]''', '''[grid]
"mode" = ["geometric", "structured_light"]''').replace('[detectors.gradient]\njump_clearance = 2\n', '')
    for name in ("scene.toml", "tiny.toml"):
        (tmp_path / name).write_text((sweep_dir / name).read_text())
    (tmp_path / "modes.toml").write_text(body)
    run = run_sweep(tmp_path / "modes.toml", tmp_path / "out", workers=0, progress=False, plots=False)
    table = run.table
    assert set(table["mode"]) == {"geometric", "structured_light"}
    assert table["f1"].notna().all()


def test_cli_sweep_logs_progress_lines_when_stderr_is_not_a_terminal(sweep_dir, tmp_path, capsys, monkeypatch):
    from rangesim.core import progress

    monkeypatch.setattr(progress, "DELAY_S", 0.0)  # the 8 tiny tasks end within the usual delay
    code = main(["sweep", str(sweep_dir / "sweep.toml"), "--out", str(tmp_path / "logged"), "--workers", "0",
                 "--no-plots"])
    err = capsys.readouterr().err.splitlines()
    assert code == 0
    lines = [x for x in err if x.startswith("rangesim: sweep ")]
    assert len(lines) >= 4 and "8/8 tasks (100 %)" in lines[-1], err
    assert progress._default == "auto"  # the command line's setting does not outlive the command
    code = main(["sweep", str(sweep_dir / "sweep.toml"), "--out", str(tmp_path / "quiet"), "--workers", "0",
                 "--no-plots", "--quiet"])
    assert code == 0 and not [x for x in capsys.readouterr().err.splitlines() if x.startswith("rangesim: sweep")]


def test_another_sweep_into_the_same_folder_is_said(serial_run, sweep_dir, tmp_path, capsys):
    # the folder's finished tasks are a cache (reused by parameters), but the table now follows
    # the new sweep: the CLI says so in one line instead of silently replacing sweep.json
    import shutil

    from rangesim.cli.main import main

    out = tmp_path / "out"
    shutil.copytree(serial_run.out, out)
    (sweep_dir / "renamed.toml").write_text(SWEEP_TOML.replace('name = "tiny_sweep"', 'name = "renamed"'))
    same = run_sweep(sweep_dir / "sweep.toml", out, workers=0, progress=False, plots=False)
    assert same.replaced is None
    assert main(["sweep", str(sweep_dir / "renamed.toml"), "--out", str(out), "--workers", "0", "--no-plots"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "'tiny_sweep'" in err and err.count("\n") == 1
    assert run_sweep(sweep_dir / "renamed.toml", out, workers=0, progress=False, plots=False).replaced is None


def test_a_dead_worker_pool_says_how_to_call_from_a_script():
    # a script that starts a sweep at its top level starts it again in every spawned worker,
    # which dies: the error once said only "BrokenProcessPool"
    from rangesim.core.errors import RangesimError
    from rangesim.experiments.executors import Executor

    with Executor(workers=1) as pool:
        (index, result, error), = list(pool.run(os._exit, [3]))  # the worker dies mid-task
    assert index == 0 and result is None
    assert isinstance(error, RangesimError) and 'if __name__ == "__main__":' in str(error)


# -- sweeps that could not be resumed or described themselves wrongly (a new user's probe) ------------
@pytest.mark.parametrize(("grid", "words"), [
    # one scan, two columns: a task file that never matched, whatever was deleted
    ('"noise.sigma_px" = [0, 0.0]', ["noise.sigma_px=0,", "noise.sigma_px=0.0,"]),
    ('"noise.sigma_px" = [0.5, 0.5]', ["noise.sigma_px=0.5,"]),  # scanned twice, two rows
])
def test_two_entries_that_make_one_scan_are_refused(sweep_dir, tmp_path, grid, words):
    from rangesim.experiments.grid import plan_sweep
    from rangesim.experiments.sweep_file import load_sweep

    path = tmp_path / "sweep.toml"
    for name in ("scene.toml", "tiny.toml"):
        (tmp_path / name).write_text((sweep_dir / name).read_text())
    path.write_text(SWEEP_TOML.replace('"noise.sigma_px" = [0.05, 0.5]', grid))
    with pytest.raises(RangesimError, match="two entries of the sweep make the same scan") as info:
        plan_sweep(load_sweep(path))
    assert all(word in str(info.value) for word in words)


def test_a_changed_mesh_changes_the_scene_digest(tmp_path):
    import hashlib

    import trimesh

    from rangesim.experiments.scenes import scene_digest

    trimesh.creation.box(extents=(10.0, 10.0, 10.0)).export(tmp_path / "part.stl")
    scene = tmp_path / "scene.toml"
    scene.write_text('[[object]]\nname = "part"\nmesh = "part.stl"\n')
    before = scene_digest(scene)
    trimesh.creation.box(extents=(10.0, 10.0, 12.0)).export(tmp_path / "part.stl")  # the scene file unchanged
    assert scene_digest(scene) != before  # sweeps and datasets once reused the old mesh's results
    plain = tmp_path / "plain.toml"
    plain.write_text(BOX_SCENE_TOML)  # no mesh file: the file's own SHA-1, as before (old results stay valid)
    assert scene_digest(plain) == hashlib.sha1(plain.read_bytes()).hexdigest()


def test_a_failed_rerun_leaves_no_table_of_another_sweep(serial_run, sweep_dir, tmp_path):
    import shutil

    out = tmp_path / "reused"
    shutil.copytree(serial_run.out, out)
    assert (out / "results.csv").is_file() and list((out / "plots").glob("*.png"))
    bad = sweep_dir / "bad_albedo.toml"
    bad.write_text(SWEEP_TOML.replace('"object.box.albedo" = [0.6, 0.9]', '"object.box.albedo" = [0.6, 1.5]'))
    with pytest.raises(RangesimError, match="4 of 4 tasks failed"):  # the 0.6 half is reused
        run_sweep(bad, out, workers=0, progress=False)
    assert json.loads((out / "sweep.json").read_text())["sweep"] == str(bad)
    assert not (out / "results.csv").exists() and not list((out / "plots").glob("*.png"))


def test_an_unreachable_scheduler_writes_nothing(sweep_dir, tmp_path, monkeypatch):
    from rangesim.experiments import executors

    def refuse(self):
        raise RangesimError("cannot reach the Dask scheduler", source="tcp://127.0.0.1:1")

    monkeypatch.setattr(executors.Executor, "__enter__", refuse)
    with pytest.raises(RangesimError, match="cannot reach"):
        run_sweep(sweep_dir / "sweep.toml", tmp_path / "out", workers=0, scheduler="tcp://127.0.0.1:1", progress=False)
    assert not (tmp_path / "out").exists()  # once held a sweep.json


def test_dataset_resume_redoes_views_whose_files_are_gone(sweep_dir, tmp_path):
    out = tmp_path / "data"
    kwargs = dict(seed=3, distance=(300, 500), workers=0, progress=False, sensor_changes={"camera.width": 32,
                                                                                         "camera.height": 24})
    make_dataset(sweep_dir / "scene.toml", sweep_dir / "tiny.toml", 2, out, **kwargs)
    next((out / "views").glob("000000_*.exr")).unlink()
    next((out / "views").glob("000001_*_truth.npz")).unlink()
    again = make_dataset(sweep_dir / "scene.toml", sweep_dir / "tiny.toml", 2, out, **kwargs)
    assert again.n_run == 2 and again.n_reused == 0  # once "2 reused", and the loader then failed
    assert SyntheticDataset(out)[0]["depth"].shape == (24, 32) and SyntheticDataset(out)[1]["edges"].shape == (24, 32)


def test_dataset_checks_the_crease_angle_and_snr_its_window_before_work(sweep_dir, tmp_path):
    from rangesim.experiments.snr import edge_snr

    with pytest.raises(RangesimError, match="crease_deg must be a finite angle"):  # once after every view
        make_dataset(sweep_dir / "scene.toml", sweep_dir / "tiny.toml", 2, tmp_path / "d", crease_deg=500,
                     workers=0, progress=False)
    assert not (tmp_path / "d").exists()
    scan = rs.datasets.plate_scan(width=32, height=30)
    with pytest.raises(RangesimError, match="snr_window must be a whole number of pixels with 2 k"):
        edge_snr(scan, np.zeros(scan.shape, np.uint8), window=100000)  # once an SNR of 6.65e7


def test_damaged_dataset_folders_are_named_not_raw_errors(sweep_dir, tmp_path):
    out = tmp_path / "data"
    make_dataset(sweep_dir / "scene.toml", sweep_dir / "tiny.toml", 1, out, workers=0, progress=False,
                 sensor_changes={"camera.width": 32, "camera.height": 24})
    truth = next((out / "views").glob("*_truth.npz"))
    truth.write_bytes(truth.read_bytes()[:50])  # truncated: once zipfile.BadZipFile
    with pytest.raises(RangesimError, match="unreadable truth file"):
        SyntheticDataset(out)[0]
    truth.unlink()  # once FileNotFoundError
    with pytest.raises(RangesimError, match="truth file missing"):
        SyntheticDataset(out, fields=["edges"])[0]
    manifest = json.loads((out / "manifest.json").read_text())
    for damaged in ([], {**manifest, "views": None}, {k: v for k, v in manifest.items() if k != "K"},
                    {**manifest, "views": [{"index": 0}]}):  # once AttributeError / KeyError
        (out / "manifest.json").write_text(json.dumps(damaged))
        with pytest.raises(RangesimError, match="manifest"):
            SyntheticDataset(out)


def test_task_scene_cache_follows_the_mesh_files(tmp_path):
    """A mesh changed under an unchanged scene file: a long-lived process (a notebook's
    workers=0 run, a Dask worker) once kept serving the old geometry under the new task keys."""
    import trimesh

    from rangesim.experiments.scenes import load_task_scene

    mesh = tmp_path / "part.stl"
    trimesh.creation.box((20, 20, 10)).export(mesh)
    scene_file = tmp_path / "s.toml"
    scene_file.write_text('units = "mm"\n[[object]]\nname = "part"\nmesh = "part.stl"\n')
    first = load_task_scene(scene_file)
    assert load_task_scene(scene_file) is first  # cached while nothing changed
    trimesh.creation.box((20, 20, 10)).apply_translation((15, 0, 0)).export(mesh)
    os.utime(mesh, ns=(time.time_ns() + 10**9,) * 2)  # (a later mtime even on a coarse clock)
    moved = load_task_scene(scene_file)
    assert moved is not first
    assert moved.objects[0].mesh.bounds[0][0] == pytest.approx(first.objects[0].mesh.bounds[0][0] + 15)


def test_task_keys_follow_the_code(monkeypatch, sweep_dir):
    """A sweep resumed after a code update must not reuse the old code's rows: the task keys
    hold a fingerprint of the package's sources."""
    from rangesim.experiments import grid

    spec = load_sweep(sweep_dir / "sweep.toml")
    before = [t.key for t in plan_sweep(spec)]
    assert before == [t.key for t in plan_sweep(spec)]  # stable within one code version
    monkeypatch.setattr(grid, "code_fingerprint", lambda: "another-version")
    after = [t.key for t in plan_sweep(spec)]
    assert not set(before) & set(after)


def test_code_fingerprint_is_a_digest_of_the_sources():
    from rangesim.experiments.grid import code_fingerprint

    fp = code_fingerprint()
    assert len(fp) == 16 and int(fp, 16) >= 0 and code_fingerprint() == fp


def test_sweep_refuses_views_that_cannot_reach_the_part(sweep_dir, tmp_path):
    """A distance range outside the sensor's working range made every scan empty, and empty
    scans scored F1 1.0 (nothing to find, nothing found): refused before any scan, as datasets do."""
    import dataclasses

    spec = load_sweep(sweep_dir / "sweep.toml")
    spec = dataclasses.replace(spec, pose={**spec.pose, "distance": [50000.0, 50001.0]})
    with pytest.raises(RangesimError, match="outside .* working range .* every view would be empty"):
        run_sweep(spec, tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out" / "results.csv").exists()


def test_a_scan_with_nothing_to_find_scores_nan():
    from rangesim.evaluate._edge_scores import undefined_as_nan as _undefined_as_nan

    row = {"precision": 1.0, "recall": 1.0, "f1": 1.0, "fom": 1.0, "jump_precision": 1.0, "jump_recall": 1.0,
           "jump_f1": 1.0}
    _undefined_as_nan(row, "", 0, 0, ("fom",))
    _undefined_as_nan(row, "jump_", 3, 0)
    assert all(math.isnan(v) for v in row.values())
    row = {"precision": 1.0, "recall": 0.0, "f1": 0.0}
    _undefined_as_nan(row, "", 0, 5)  # found nothing of something: recall and F1 0, precision undefined
    assert math.isnan(row["precision"]) and row["recall"] == 0.0 and row["f1"] == 0.0


def test_one_sweep_by_two_paths_is_the_same_sweep(sweep_dir, serial_run, monkeypatch):
    """``../s.toml`` and ``/abs/s.toml`` once warned that the folder "held the results of another sweep"."""
    monkeypatch.chdir(sweep_dir)
    again = run_sweep("sweep.toml", sweep_dir / "serial", workers=0, progress=False, plots=False)
    assert again.replaced is None and again.n_run == 0


DRIVER = '''
import time
from rangesim.experiments.executors import Executor

def slow(x):
    time.sleep(120)
    return x

if __name__ == "__main__":
    with Executor(1, None, max_tasks=1) as ex:
        for _ in ex.run(slow, [1]):
            pass
'''


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_pool_workers_exit_when_the_driver_is_killed(tmp_path):
    """A sweep driver killed with SIGKILL left its pool worker blocked on a pipe for good."""
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    driver = subprocess.Popen([sys.executable, str(script)], cwd=tmp_path)
    workers: list[int] = []
    try:
        deadline = time.time() + 60
        while time.time() < deadline:
            out = subprocess.run(["pgrep", "-f", "-P", str(driver.pid), "spawn_main"], capture_output=True, text=True)
            workers = [int(p) for p in out.stdout.split()]
            if workers:
                break
            time.sleep(0.2)
        assert workers, "the pool worker did not start"
        time.sleep(2.0)  # the worker has run its initializer and taken the task
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait()
        deadline = time.time() + 10
        alive = workers
        while alive and time.time() < deadline:
            alive = [p for p in workers if Path(f"/proc/{p}").exists()
                     and "State:\tZ" not in Path(f"/proc/{p}/status").read_text()]
            time.sleep(0.2)
        assert not alive
    finally:
        driver.kill()
        for p in workers:
            try:
                os.kill(p, signal.SIGKILL)
            except OSError:
                pass


def _cone_sensor():
    return rs.load_sensor("white_scanner").with_params({"camera.width": 64, "camera.height": 48})


@pytest.mark.parametrize("inside", [True, False])
def test_part_seen_from_cap_is_the_image_corner_cone(inside):
    """With a cap of one pose (0 deg, one distance) the test is exact: a small part straight
    along the image diagonal's corner ray plus or minus 0.5 deg is seen or not."""
    import math

    from rangesim.experiments.poses import _part_seen_from_cap

    sensor = _cone_sensor()
    K = sensor.K
    half_diagonal = math.atan(math.hypot(K[0, 2] / K[0, 0], K[1, 2] / K[1, 1]))
    d = 350.0  # camera at (0, 0, d) looking down -z at the origin
    angle = half_diagonal + math.radians(-0.5 if inside else 0.5)
    r = 0.05  # mm: 0.008 deg at 350 mm, far under the 0.5 deg margin
    centre = np.array([d * math.tan(angle), 0.0, 0.0])  # angle off the optical axis at the camera
    vertices = centre + r * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    cap = {"target": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "cap_deg": 0.0, "distance": [d, d]}
    assert _part_seen_from_cap(cap, vertices, sensor) is inside


def test_part_seen_from_cap_needs_the_working_range():
    from rangesim.experiments.poses import _part_seen_from_cap

    sensor = _cone_sensor()
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    vertices = np.array([[-1.0, -1, -1], [1, 1, 1]])  # a 1.7 mm sphere at the target
    for d, seen in ((near - 5, False), ((near + far) / 2, True), (far + 5, False)):
        cap = {"target": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "cap_deg": 0.0, "distance": [d, d]}
        assert _part_seen_from_cap(cap, vertices, sensor) is seen
    # a cap of distances reaching into the range is seen
    cap = {"target": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "cap_deg": 0.0, "distance": [10.0, far + 100]}
    assert _part_seen_from_cap(cap, vertices, sensor)
    # and so is a wide range whose even grid of distances (100, 575, ... 2000 mm) steps over
    # the whole working range (250-450 mm) between two of its points
    cap["distance"] = [100.0, 2000.0]
    assert _part_seen_from_cap(cap, vertices, sensor)


def test_sweep_refuses_a_target_away_from_the_part(sweep_dir, tmp_path):
    import dataclasses

    spec = load_sweep(sweep_dir / "sweep.toml")
    spec = dataclasses.replace(spec, pose={**spec.pose, "target": [3000.0, 0.0, 0.0]})
    with pytest.raises(RangesimError, match="field of view .* every view would be empty"):
        run_sweep(spec, tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out" / "results.csv").exists()


def test_part_seen_from_cap_takes_the_range_in_depth():
    """The working range bounds depth along the optical axis: a part 12.8 deg off the axis at
    depth 440 mm lies 451 mm away, past white_scanner's far (450 mm) in a straight line, and is
    seen (a distance rule refused it)."""
    from rangesim.experiments.poses import _part_seen_from_cap

    sensor = _cone_sensor()
    assert sensor.params["range"]["far"] == 450.0
    d = 440.0  # camera at (0, 0, d) looking down -z at the origin
    centre = np.array([100.0, 0.0, 0.0])
    vertices = centre + 0.05 * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    cap = {"target": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "cap_deg": 0.0, "distance": [d, d]}
    assert np.hypot(100.0, d) > 450.0 and _part_seen_from_cap(cap, vertices, sensor)
    cap["distance"] = [455.0, 455.0]  # now its depth is past far too
    assert not _part_seen_from_cap(cap, vertices, sensor)


def test_sweep_range_check_runs_once_per_scene_and_optics(sweep_dir, monkeypatch):
    """The pre-flight range check reads the scene, the pose table and the sensor's camera and working
    range: a noise parameter swept does not repeat it (a 10^4-task noise grid sat silent for minutes)."""
    import rangesim.experiments.poses as poses
    import rangesim.experiments.scenes as scenes
    from rangesim.experiments.sweep import _check_parts_in_range

    calls = {"scene": 0, "check": 0}
    load, check = scenes.load_task_scene, poses.check_distance_in_range

    def counted_load(*args, **kwargs):
        calls["scene"] += 1
        return load(*args, **kwargs)

    def counted_check(*args, **kwargs):
        calls["check"] += 1
        return check(*args, **kwargs)

    monkeypatch.setattr(scenes, "load_task_scene", counted_load)
    monkeypatch.setattr(poses, "check_distance_in_range", counted_check)
    tasks = plan_sweep(load_sweep(sweep_dir / "sweep.toml"))  # noise.sigma_px x object.box.albedo, 2 x 2
    assert len({json.dumps(t.payload["sensor"], sort_keys=True) for t in tasks}) == 2
    _check_parts_in_range(tasks, None)
    assert calls == {"scene": 2, "check": 2}   # one per albedo (the scene's objects), not per noise level


def test_a_sweep_over_a_bare_mesh_says_how_to_make_it_a_scene(tmp_path):
    from rangesim.experiments.sweep_file import load_sweep

    (tmp_path / "part.stl").write_text("solid x\nendsolid x\n")
    (tmp_path / "sweep.toml").write_text('name = "m"\nscenes = ["part.stl"]\nsensors = ["white_scanner"]\n'
                                         'views = 1\n\n[detectors.gradient]\n')
    with pytest.raises(RangesimError, match=r"'part.stl' is a mesh; a sweep takes scene .toml files"):
        load_sweep(tmp_path / "sweep.toml")


def test_a_misspelt_model_parameter_is_refused_before_any_task(sweep_dir, tmp_path):
    """``object.NAME.params.KEY`` is the model's to check, so the sweep file passes; a key no
    task's scene can take failed every task after the folder was made. Now refused first,
    with the model's own message, and nothing written."""
    root = Path(__file__).resolve().parents[1]
    (tmp_path / "tiny.toml").write_text((sweep_dir / "tiny.toml").read_text())
    path = tmp_path / "typo.toml"
    path.write_text(f'name = "typo"\nscenes = ["{root / "scenes" / "green_piece.toml"}"]\nsensors = ["tiny.toml"]\n'
                    'views = 1\n[detectors.gradient]\n[grid]\n"object.green_piece.params.thicknes" = [10, 12]\n')
    with pytest.raises(RangesimError) as info:
        run_sweep(path, tmp_path / "out", workers=0, progress=False)
    message = str(info.value)
    assert "\n" not in message and "thicknes" in message and "no task's scene can be built" in message, message
    assert not (tmp_path / "out").exists()


def test_a_reused_folder_keeps_the_users_own_files(sweep_dir, serial_run, tmp_path):
    """A sweep rerun into its folder rebuilds its own plots (f1_vs_*.png) and no other
    picture; a dataset's views folder loses only the view files of an earlier plan (its own
    names: index_key.exr / .npz / _truth.npz / .json), not a user's files beside them."""
    import shutil

    from rangesim.experiments.dataset import _remove_stale_views

    out = tmp_path / "reused"
    shutil.copytree(sweep_dir / "serial", out)
    (out / "plots" / "my_figure.png").write_bytes(b"\x89PNG mine")
    run_sweep(sweep_dir / "sweep.toml", out, workers=0, progress=False)
    assert (out / "plots" / "my_figure.png").read_bytes() == b"\x89PNG mine"
    assert (out / "plots" / "f1_vs_snr.png").is_file()

    views = tmp_path / "views"
    views.mkdir()
    mine = ["photo.exr", "data.npz", "readme.json", "12_a.exr", "000001_abcdef012x.json"]
    kept = ["000000_0123456789.exr", "000000_0123456789_truth.npz", "000000_0123456789.json"]
    stale = ["000007_fedcba9876.exr", "000007_fedcba9876_truth.npz", "000007_fedcba9876.json",
             "000000_0123456789.npz"]                            # the kept view in another format
    for name in mine + kept + stale:
        (views / name).write_text("x")
    assert _remove_stale_views(views, ["000000_0123456789"], "exr") == 1
    assert sorted(p.name for p in views.iterdir()) == sorted(mine + kept)


def test_a_grid_key_one_sensor_does_not_read_repeats_its_scans(sweep_dir, tmp_path):
    """structured_light.window swept over a laser sensor and a structured-light one: the laser
    sensor's scans are the same at every value (the same noise seed: the planner's warning says
    they repeat; they drew new noise per value, and its plot showed the noise as an effect),
    the structured-light sensor's differ."""
    import shutil

    from rangesim.experiments.grid import plan_sweep
    from rangesim.experiments.sweep_file import load_sweep

    for name in ("scene.toml", "tiny.toml"):
        shutil.copy(sweep_dir / name, tmp_path / name)
    (tmp_path / "s.toml").write_text(
        'name = "mixed"\nscenes = ["scene.toml"]\nsensors = ["tiny.toml", "kinect_v1"]\nviews = 1\nseed = 3\n'
        'detectors = ["gradient"]\n[pose]\ncap_deg = 10\ndistance = [600, 700]\n'
        '[grid]\n"structured_light.window" = [7, 9]\n')
    with pytest.warns(UserWarning, match="which tiny.toml .* does not use: those scans repeat"):
        spec = load_sweep(tmp_path / "s.toml")
    seeds = {}
    for task in plan_sweep(spec):
        seeds.setdefault(task.columns["sensor"], []).append(task.payload["noise_seed"])
    laser, = (v for k, v in seeds.items() if k.startswith("tiny"))
    matched, = (v for k, v in seeds.items() if not k.startswith("tiny"))
    assert len(laser) == 2 and laser[0] == laser[1]
    assert len(matched) == 2 and matched[0] != matched[1]
