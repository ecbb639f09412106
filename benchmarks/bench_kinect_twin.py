"""Structured-light twins of the recorded mOSD Kinect frames: the README's twin table.

Usage::

    python benchmarks/bench_kinect_twin.py [--sensor kinect_v1] [--seed 0] [--json OUT.json]

For each of the six labelled frames in ``../shared/data/mosd-kinect`` (``RANGESIM_DATA``
overrides), :func:`rangesim.twin.kinect.compare_kinect` fits the scene (table plane, boxes,
cylinders), scans it with the sensor at the recording's own focal length and compares the
twin with the recording: valid-mask IoU (and that of a twin without physics, valid wherever
the fitted scene is hit), the z^2 noise coefficient of both, the gaps between adjacent depth
levels in units of the sensor's 1/8 px step, the edge F1 of gradient and normal between
twin and recording, and the median over 24 px tiles of the scene's flat faces of the twin's
noise about its own local plane over the recording's (:func:`rangesim.twin.kinect.local_plane_std`:
no fitted scene's error in it). Nothing is fitted to the frames but the scene itself; the preset's
settings were chosen on other data (see ``benchmarks/README.md`` for which).
Prints the README's table and writes ``benchmarks/results_kinect_twin.json`` by default.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import rangesim as rs
from rangesim.evaluate.runs import load_scan_with_labels
from rangesim.twin.kinect import compare_kinect

FRAMES = ("test0", "test5", "test10", "test20", "test31", "test33")
HERE = Path(__file__).resolve().parent


def data_dir() -> Path:
    """The shared recordings: ``RANGESIM_DATA`` or ``../shared/data`` beside the repository."""
    return Path(os.environ.get("RANGESIM_DATA", HERE.parent.parent / "shared" / "data"))


def twin_row(frame: str, sensor, seed: int) -> dict:
    """The comparison of one frame with its twin, in the layout of ``results_kinect_twin.json``."""
    scan, labels = load_scan_with_labels(data_dir() / "mosd-kinect" / f"{frame}.pcd", None)
    m = compare_kinect(scan, labels, sensor, seed=seed, detectors=("gradient", "normal"))
    return {
        "frame": frame,
        "shapes": [shape["kind"] for shape in m["shapes"]],
        "iou": m["iou"],
        "iou_no_physics": m["iou_no_physics"],
        "k": m["z2_coefficient_mm_per_m2"],
        "noise_std_ratio": m["noise_std_ratio"],
        "z_spread": m.get("z_spread"),
        "gaps": {k: v["median"] for k, v in m["depth_level_gaps_in_steps"].items()},
        "by_depth": m["residual_by_depth"],
        "f1": {name: e["f1"] for name, e in m["edges"].items()},
        "local_plane": m["local_plane_std_mm"],
    }


def _nan_to_null(value):
    """``value`` with NaN (empty depth bins) as None, so the JSON is strict."""
    if isinstance(value, dict):
        return {k: _nan_to_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_nan_to_null(v) for v in value]
    if isinstance(value, float) and value != value:
        return None
    return float(value) if hasattr(value, "dtype") else value


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensor", default="kinect_v1", help="preset name or TOML (default kinect_v1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=HERE / "results_kinect_twin.json")
    args = ap.parse_args(argv)
    if not (data_dir() / "mosd-kinect").is_dir():
        print(f"{data_dir() / 'mosd-kinect'}: the recorded frames are not there (set RANGESIM_DATA)", file=sys.stderr)
        return 2
    sensor = rs.load_sensor(args.sensor)
    rows = []
    print("| frame | objects fitted | IoU / no-physics | k recorded / twin (mm/m^2) "
          "| depth-level gaps, steps, rec / twin | F1 gradient / normal | local-plane noise, twin / rec |")
    print("|---|---|---|---|---|---|---|")
    for frame in FRAMES:
        r = twin_row(frame, sensor, args.seed)
        rows.append(r)
        objects = ", ".join(s for s in r["shapes"] if s != "table")
        print(f"| {frame} | {objects} | {r['iou']:.3f} / {r['iou_no_physics']:.3f} "
              f"| {r['k']['recorded']:.2f} / {r['k']['twin']:.2f} "
              f"| {r['gaps']['recorded']:.2f} / {r['gaps']['twin']:.2f} "
              f"| {r['f1']['gradient']:.2f} / {r['f1']['normal']:.2f} "
              f"| {r['local_plane']['ratio_median']:.2f} |", flush=True)
    tmp = args.json.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_nan_to_null(rows), indent=1, allow_nan=False))
    tmp.replace(args.json)
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
