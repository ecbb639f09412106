"""``rangesim detect``: edge maps of a scan, overlay pictures, and scores against ground truth."""
from __future__ import annotations

import argparse
import json
import zipfile
from pathlib import Path

import numpy as np

from rangesim.cli.common import (
    check_conf,
    check_out_files,
    json_safe,
    make_out_dir,
    positive,
    require_grid,
    scene_files,
    write_json,
    write_together,
)
from rangesim.core.constants import MAX_TOLERANCE_PX
from rangesim.core.errors import RangesimError

#: ``--sensor`` of the commands that read a recording (detect, features)
RECORDED_SENSOR_HELP = ("what recorded a .pcd frame (a preset such as kinect_v1, a sensor TOML, or auto: kinect_v1 "
                        "only if the depths sit on a block matcher's disparity lattice); a structured-light sensor "
                        "runs the detectors' block-matched paths. Default: none (recordings carry no sensor)")


def describe_sensor(scan, given) -> str:
    """One line on what ``--sensor given`` made of a recording's sensor metadata."""
    sensor = scan.meta.get("sensor")
    if not sensor:
        return f"sensor {given}: no disparity lattice in the depths, no sensor metadata (the detectors' default paths)"
    mode = sensor.get("mode", "unknown")
    line = f"sensor {given}: {sensor.get('name', 'unnamed')} ({mode}"
    window = (sensor.get("structured_light") or {}).get("window") if mode == "structured_light" else None
    line += f", matching window {window} px: the block-matched paths)" if window else ")"
    evidence = scan.meta.get("sensor_evidence")
    if evidence and evidence.get("fb_steps"):
        line += f", from the disparity lattice (8 f b = {evidence['fb_steps'] / 1000:.0f} k px mm)"
    return line


def sensor_summary(scan, given) -> dict:
    """``--sensor``'s outcome for a report: what was given, and the sensor recorded (None: none)."""
    sensor = scan.meta.get("sensor") or None
    summary = {"given": str(given), "name": None, "mode": None, "matching_window": None}
    if sensor:
        summary.update(name=sensor.get("name"), mode=sensor.get("mode"),
                       matching_window=(sensor.get("structured_light") or {}).get("window")
                       if sensor.get("mode") == "structured_light" else None)
    if scan.meta.get("sensor_evidence"):
        summary["evidence"] = scan.meta["sensor_evidence"]
    return summary


def _map_scan(path: Path) -> str | None:
    """The scan an edge map that ``rangesim detect`` wrote at ``path`` belongs to, or None (a file
    that is no such map, the input scan included, is never taken for one)."""
    if not path.is_file():
        return None
    try:
        with np.load(path) as npz:
            return str(npz["scan"]) if {"method", "mask", "scan"} <= set(npz.files) else None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):  # not an NPZ (empty, broken): not ours
        return None


def _another_scans_map(path: Path, scan_id: str) -> bool:
    """Whether ``path`` is an edge map ``rangesim detect`` wrote for another scan."""
    return _map_scan(path) not in (None, scan_id)


def _run_key(path: Path, args, sensor) -> dict:
    """What makes two ``detect`` runs' scores comparable: the scan file (resolved path, size and
    modification time: rewritten, it is another scan), the scene behind the truth and the
    scoring settings."""
    stat = path.stat()
    return json_safe({"scan": str(path.resolve()), "size": stat.st_size, "mtime_ns": stat.st_mtime_ns,
                      "scene": None if args.scene is None else str(Path(args.scene).resolve()),
                      "tolerance_px": args.tolerance, "crease_deg": args.crease_deg, "sensor": sensor})


def _earlier_scores(out: Path, scan_id: str, others: set[str], run: dict) -> dict[str, dict]:
    """The scores in ``out/scores.json`` of the methods in ``others`` that an earlier ``detect``
    wrote for the same run key (:func:`_run_key`), and whose maps are still there: kept beside
    this run's (``--method gradient`` then ``--method normal`` into one folder)."""
    try:
        earlier = json.loads((out / "scores.json").read_text())
    except (OSError, ValueError):
        return {}
    if not (isinstance(earlier, dict) and isinstance(earlier.get("methods"), dict) and earlier.get("run") == run):
        return {}
    return {m: r for m, r in earlier["methods"].items() if m in others and _map_scan(out / f"{m}_edges.npz") == scan_id}


def cmd_detect(args: argparse.Namespace) -> int:
    from rangesim.edges import DETECTORS
    from rangesim.evaluate.runs import load_scan_with_labels, run_detectors, scan_truth
    from rangesim.viz.edge_overlay import save_edge_overlay

    methods = list(DETECTORS) if args.method == "all" else [args.method]
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise RangesimError("output must be a directory", source=out)
    positive("--tolerance", args.tolerance, allow_zero=True, at_most=MAX_TOLERANCE_PX)
    positive("--crease-deg", args.crease_deg, upper=180)
    path = Path(args.scan)
    check_conf(path, args.conf)
    names = [f"{m}_edges.npz" for m in methods] + [f"{m}.png" for m in methods] + ["ground_truth.png", "scores.json"]
    check_out_files(out, names, [path, args.conf, args.scene, args.sensor])
    scan, segment_labels = load_scan_with_labels(path, args.conf, sensor=args.sensor)
    require_grid(scan, path)
    if not np.any(scan.valid & ~np.isnan(scan.depth)):  # as rangesim scan refuses to write one without --keep-empty
        raise RangesimError("no valid pixel (with a depth): nothing to detect (every score would be 1 for finding "
                            "nothing)", source=path)
    scene = args.scene
    if scene is not None:
        from rangesim.cli.common import load_scene_arg
        from rangesim.cli.scene_match import require_matching_scene, require_synthetic

        require_synthetic(scan, path, args.scene)
        scene = load_scene_arg(args.scene)
        require_matching_scene(scan, scene, path, args.scene)
        check_out_files(out, names, scene_files(scene))
    elif scan.xyz_true is not None and scan.K is not None and Path(str(scan.meta.get("scene", ""))).is_file():
        # the scene file the scan names is scored against only if it still makes this scan (it may
        # have been edited since: every score was 0 with no word)
        from rangesim.cli.scene_match import MIN_SCENE_MATCH, scene_match_share
        from rangesim.evaluate.runs import scene_of_scan

        named = str(scan.meta["scene"])
        scene = scene_of_scan(scan)
        share = scene_match_share(scan, scene)
        if share < MIN_SCENE_MATCH:
            raise RangesimError(
                f"the scene the scan names ({named}) no longer matches it: cast from the scan's pose it hits the "
                f"scan's true surface on {100 * share:.1f} % of its pixels (edited since the scan?); give --scene",
                source=path)
        check_out_files(out, names, scene_files(scene))
    else:
        from rangesim.cli.scene_match import warn_if_named_scene_is_gone

        warn_if_named_scene_is_gone(scan, path, "no ground truth, no scores")
    try:
        truth = scan_truth(scan, scene, segment_labels, crease_deg=args.crease_deg)
    except RangesimError as exc:  # (a scan without intrinsics, ...): name the file
        raise RangesimError(str(exc), source=path) from None
    try:
        results = run_detectors(scan, methods, truth, tolerance_px=args.tolerance)
    except RangesimError as exc:  # a detector's refusal names the scan's field: name the file too
        raise RangesimError(str(exc), source=path) from None
    if truth is not None:  # nothing to find (no true edge pixel): no score, as in sweeps (NaN, not 1)
        from rangesim.evaluate._edge_scores import undefined_as_nan

        for r in results.values():
            undefined_as_nan(r["scores"], "", r["scores"]["n_pred"], r["scores"]["n_gt"], ("fom",))

    make_out_dir(out)
    scan_id = str(path.resolve())
    # a reused folder: another scan's maps of the methods not run now would sit beside these
    stale = [old for other in sorted(set(DETECTORS) - set(methods))
             if _another_scans_map(out / f"{other}_edges.npz", scan_id)
             for old in (out / f"{other}_edges.npz", out / f"{other}.png")]
    sensor = sensor_summary(scan, args.sensor) if args.sensor is not None else None
    kept: dict[str, dict] = {}
    if truth is not None:
        run = _run_key(path, args, sensor)
        kept = _earlier_scores(out, scan_id, set(DETECTORS) - set(methods), run)
        # this scan's maps of other methods whose scores cannot be kept (another run key):
        # removed, so that the folder's maps and scores.json are one run's
        stale += [old for other in sorted(set(DETECTORS) - set(methods) - set(kept))
                  if _map_scan(out / f"{other}_edges.npz") == scan_id
                  for old in (out / f"{other}_edges.npz", out / f"{other}.png")]
    writes = []
    for method, result in results.items():
        edge_map = result["edge_map"]
        # self-describing: which scan and method made it, with the parameters it used (the
        # noise-adapted thresholds), as JSON text
        arrays = {"mask": edge_map.mask, "labels": edge_map.labels, "strength": edge_map.strength,
                  "method": np.str_(method), "scan": np.str_(scan_id),
                  "params": np.str_(json.dumps(json_safe(edge_map.params or {}), sort_keys=True))}
        for name in ("direction", "offset"):
            if getattr(edge_map, name) is not None:
                arrays[name] = getattr(edge_map, name)
        writes.append((out / f"{method}_edges.npz", lambda tmp, arrays=arrays: np.savez_compressed(tmp, **arrays)))
        writes.append((out / f"{method}.png", lambda tmp, m=edge_map: save_edge_overlay(scan, m, tmp)))
    if truth is not None:
        report = {
            "scan": str(path), "truth": truth.kind, "tolerance_px": args.tolerance, "crease_deg": args.crease_deg,
            # every prediction counted: rs.evaluate.score_edges(..., ignore_data_boundary=False) gives these
            "ignore_data_boundary": False,
            "run": run,
            "methods": {**kept, **{m: {"seconds": r["seconds"], **r["scores"]} for m, r in results.items()}},
        }
        if sensor is not None:
            report["sensor"] = sensor
        writes.append((out / "ground_truth.png", lambda tmp: save_edge_overlay(
            scan, truth.edge_map(), tmp, title=f"ground truth ({truth.kind})")))
        writes.append((out / "scores.json", lambda tmp: write_json(report, tmp)))  # strict JSON: NaN as null
    else:  # a scan without truth: a reused folder's old scores and truth picture are another scan's
        stale += [out / name for name in ("scores.json", "ground_truth.png")]
    write_together(writes)  # all files or none
    for old in stale:
        old.unlink(missing_ok=True)

    kind = truth.kind if truth else "none"
    if kind == "regions":  # a rangesim scan saved as PCD keeps its parts as labels, not its scene
        kind += " (the boundaries of the file's label regions: object outlines, no creases)"
    print(f"{path}: {scan.shape[1]} x {scan.shape[0]} px, truth: {kind}")
    if args.sensor is not None:
        print(describe_sensor(scan, args.sensor))
    print(f"{'method':<15}{'edges':>9}{'seconds':>9}" + ("" if truth is None else f"{'P':>7}{'R':>7}{'F1':>7}{'FOM':>7}"))
    for method, r in results.items():
        line = f"{method:<15}{int(r['edge_map'].mask.sum()):>9,}{r['seconds']:>9.3f}"
        if truth is not None:  # a score nothing defines (no true edge pixel, nothing found) prints "-"
            s = r["scores"]
            line += "".join(f"{s[k]:>7.3f}" if s[k] == s[k] else f"{'-':>7}" for k in ("precision", "recall", "f1", "fom"))
        print(line)
    if kept:
        print(f"scores.json keeps {', '.join(sorted(kept))} from an earlier run on this scan (same truth and settings)")
    print(f"wrote {out}/")
    return 0


def register(sub) -> None:
    from rangesim.edges import DETECTORS

    p = sub.add_parser("detect", help="detect edges in a scan",
                       description="Run edge detectors on a scan (synthetic or recorded); write edge maps "
                       "(NPZ), overlay pictures (PNG) and, where ground truth exists, scores (JSON).")
    p.add_argument("scan", metavar="SCAN", help="scan file (.exr, .npz, .ply range grid, .pcd, .msu)")
    p.add_argument("--method", default="all", choices=[*DETECTORS, "all"],
                   help="edge detector, or all of them (default all)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--scene", help="scene of a synthetic scan (default: the one named in the scan)")
    p.add_argument("--conf", help="Stanford .conf pose file for a recorded scan")
    p.add_argument("--sensor", metavar="NAME|TOML|auto", help=RECORDED_SENSOR_HELP)
    p.add_argument("--tolerance", type=float, default=2.0, help="score matching tolerance, pixels (default 2)")
    p.add_argument("--crease-deg", type=float, default=20.0, help="ground-truth crease angle, degrees (default 20)")
    p.set_defaults(func=cmd_detect)
