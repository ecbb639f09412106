#!/usr/bin/env python
"""Throughput of sweep tasks on 1 and 2 worker processes, and the scaling efficiency.

Scene: the Green Piece (``scenes/green_piece.toml``), sensor ``white_scanner`` with a
SIZE x SIZE camera (field of view unchanged, preset noise), random views from the cap of the
example sweep (20 degrees around the scene's view, 320-380 mm), seeded as a sweep seeds them.

Two workloads, each run through :class:`rangesim.experiments.executors.Executor` (a spawned
``ProcessPoolExecutor``, Dr.Jit on one thread per worker):

* ``scan``: one ``rangesim.scan`` per task (the pose drawn from the cap, the scene built once
  per worker); the task returns the valid-pixel count.
* ``pipeline``: a full sweep task, exactly what ``rangesim sweep`` runs per scan
  (:func:`rangesim.experiments.tasks.run_sweep_task`): scan, ground-truth edges, SNR, all
  five detectors and their scores; the task returns its result rows.

For each worker count the pool is started and warmed up (every worker imports rangesim and
builds the scene on ``2 * workers`` tasks), then the tasks are timed from the first
submission to the last result: rate = tasks / seconds. Every run has views of its own, from
a seed taken from the clock unless ``--seed`` is given, as every scan of a real sweep has a
view of its own. New views reuse the compiled kernels (poses and noise seeds are opaque
kernel inputs). Scaling efficiency = rate(2 workers) / (2 * rate(1 worker)); the target is
>= 80 %.
For reference, ``in-process`` runs the same tasks one after the other in this process with
Dr.Jit's default thread pool (both cores inside one scan).

Usage::

    python benchmarks/bench_sweep.py [--size 512] [--scan-tasks 80] [--pipeline-tasks 12]
                                     [--json benchmarks/results_sweep_cpu_2core.json]
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_info  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
TARGET_EFFICIENCY = 0.8

SWEEP_TOML = """\
name = "bench_sweep"
scenes = ["{scene}"]
sensors = ["white_scanner"]
views = {views}
seed = {seed}
[set]
"camera.width" = {size}
"camera.height" = {size}
[pose]
cap_deg = 20
distance = [320, 380]
"""


def scan_task(payload: dict) -> int:
    """A scan-only task: the sweep task's scene, sensor and pose, no evaluation."""
    import numpy as np

    import rangesim as rs
    from rangesim.experiments.scenes import load_task_scene
    from rangesim.experiments.tasks import task_pose

    scene = load_task_scene(payload["scene_path"], payload["objects"])
    sensor = rs.load_sensor(payload["sensor"])
    pose, _ = task_pose(payload, scene, sensor)
    scan = rs.scan(scene, sensor, pose=pose, seed=payload["noise_seed"])
    return int(np.count_nonzero(scan.valid))


def pipeline_task(payload: dict) -> dict:
    """A full sweep task, as ``rangesim sweep`` runs it: scan, ground truth, SNR, every
    detector and its scores; returns the task's result (its rows) to the driver."""
    from rangesim.experiments.tasks import run_sweep_task

    return run_sweep_task(payload)


def payloads(size: int, n: int, seed: int) -> list[dict]:
    """``n`` sweep-task payloads (distinct views and noise) at SIZE x SIZE."""
    from rangesim.experiments import load_sweep
    from rangesim.experiments.grid import plan_sweep

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        path.write_text(SWEEP_TOML.format(scene=REPO / "scenes" / "green_piece.toml", views=n, size=size,
                                          seed=seed))
        return [t.payload for t in plan_sweep(load_sweep(path))]


def timed_run(fn, items: list[dict], workers: int, warmup: list[dict]) -> dict:
    """Start a pool of ``workers`` (0: this process), warm it up, time ``items``."""
    from rangesim.experiments.executors import Executor

    with Executor(workers=workers) as ex:
        t0 = time.perf_counter()
        for _, _, err in ex.run(fn, warmup):
            if err is not None:
                raise err
        warm = time.perf_counter() - t0
        load_before = os.getloadavg()[0]
        t0 = time.perf_counter()
        for _, _, err in ex.run(fn, items):
            if err is not None:
                raise err
        seconds = time.perf_counter() - t0
    return {"workers": workers, "tasks": len(items), "seconds": seconds, "rate_per_s": len(items) / seconds,
            "warmup_s": warm, "loadavg_1min_before": load_before}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=512, help="camera width and height, px (default 512)")
    ap.add_argument("--scan-tasks", type=int, default=80, help="timed scan-only tasks per run (default 80)")
    ap.add_argument("--pipeline-tasks", type=int, default=12, help="timed pipeline tasks per run (default 12)")
    ap.add_argument("--seed", type=int, help="seed of the views (default: from the clock, so every run has "
                    "views of its own, as in a sweep)")
    ap.add_argument("--json", type=Path, help="write the figures to this JSON file")
    args = ap.parse_args(argv)

    import drjit
    import mitsuba
    import numpy

    import rangesim
    from rangesim.core.backend import mitsuba as mitsuba_module

    seed = args.seed if args.seed is not None else int(time.time()) % 2**31
    results: dict = {}
    lines = [f"seed {seed}"]
    print(lines[0], flush=True)
    for k, (name, fn, n) in enumerate((("scan", scan_task, args.scan_tasks),
                                        ("pipeline", pipeline_task, args.pipeline_tasks))):
        # every run gets views of its own, as every scan of a sweep has
        per_run = n + 4
        items = payloads(args.size, 3 * per_run, seed + k)
        runs = {}
        for r, workers in enumerate((0, 1, 2)):
            chunk = items[r * per_run:(r + 1) * per_run]
            label = "in-process" if workers == 0 else f"{workers} worker{'s' if workers > 1 else ''}"
            runs[label] = timed_run(fn, chunk[:n], workers, chunk[n:n + max(2, 2 * workers)])
            r_ = runs[label]
            lines.append(f"{name:<8} {label:<11} {r_['tasks']:>5} tasks {r_['seconds']:>8.2f} s "
                         f"{r_['rate_per_s']:>8.2f} scans/s")
            print(lines[-1], flush=True)
        eff = runs["2 workers"]["rate_per_s"] / (2 * runs["1 worker"]["rate_per_s"])
        results[name] = {"runs": runs, "efficiency": eff, "pass": eff >= TARGET_EFFICIENCY}
        lines.append(f"{name:<8} scaling efficiency rate2 / (2 rate1) = {100 * eff:.0f} % "
                     f"(target {100 * TARGET_EFFICIENCY:.0f} %): {'PASS' if eff >= TARGET_EFFICIENCY else 'FAIL'}")
        print(lines[-1], flush=True)

    if args.json:
        report = {
            "date": datetime.date.today().isoformat(),
            "cpu": cpu_info(),
            "versions": {"python": platform.python_version(), "numpy": numpy.__version__,
                         "rangesim": rangesim.__version__, "mitsuba": mitsuba.__version__,
                         "drjit": drjit.__version__},
            "variant": mitsuba_module().variant(),
            "scene": "scenes/green_piece.toml", "sensor": "white_scanner", "size": args.size, "seed": seed,
            "target_efficiency": TARGET_EFFICIENCY, "results": results, "summary": lines,
        }
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0 if all(r["pass"] for r in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
