"""``rangesim compare``: a recorded scan against its simulated twin (metrics JSON + picture).

Without ``--mesh`` (e.g. mOSD Kinect PCDs) only the readers and edge detectors run, and the
detectors are scored against the region boundaries of the scan's labels, if it has any.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from rangesim.cli.common import check_conf, check_out_files, make_out_dir, positive, write_json, write_together
from rangesim.core.constants import MAX_TOLERANCE_PX
from rangesim.core.errors import RangesimError
from rangesim.evaluate.runs import load_scan_with_labels

#: what ``rangesim compare`` writes into its folder
OUT_FILES = ("metrics.json", "compare.png")


def _write_outputs(out: Path, metrics: dict, draw) -> None:
    """The metrics (strict JSON) and the picture ``draw(path)`` makes: both files or neither."""
    make_out_dir(out)
    write_together([(out / OUT_FILES[0], lambda tmp: write_json(metrics, tmp)), (out / OUT_FILES[1], draw)])


def _detectors_only(scan, labels, args, out: Path) -> tuple[dict, dict, Any]:
    from rangesim.edges import DETECTORS
    from rangesim.evaluate.runs import run_detectors, scan_truth

    truth = scan_truth(scan, None, labels)
    metrics: dict[str, Any] = {
        "recorded": str(Path(args.recorded).resolve()), "mesh": None, "valid": int(scan.valid.sum()),
        "truth": None if truth is None else truth.kind, "edges": {},
        **_recorded_sensor(scan, args),
    }
    results = run_detectors(scan, DETECTORS, truth, tolerance_px=args.tolerance)
    for name, result in results.items():
        entry: dict[str, Any] = {"edges": int(result["edge_map"].mask.sum())}
        if truth is not None:
            s = result["scores"]
            entry.update(precision=float(s["precision"]), recall=float(s["recall"]), f1=float(s["f1"]))
        metrics["edges"][name] = entry
    return metrics, {name: r["edge_map"] for name, r in results.items()}, truth


def _recorded_sensor(scan, args) -> dict[str, Any]:
    """``{"recorded_sensor": ...}`` for metrics.json when --recorded-sensor was given, else nothing."""
    if args.recorded_sensor is None:
        return {}
    from rangesim.cli.edge_commands import sensor_summary

    return {"recorded_sensor": sensor_summary(scan, args.recorded_sensor)}


def _structured_light(name: str) -> bool:
    """Whether ``name`` is a structured-light sensor (an unknown name is not: the detectors-only path)."""
    from rangesim.sensor import load_sensor

    try:
        return load_sensor(name).mode == "structured_light"
    except RangesimError:
        return False


def _kinect_twin(scan, labels, args, out: Path) -> int:
    """A labelled Kinect-type frame against the structured-light twin of its fitted scene."""
    from rangesim.twin.kinect import compare_kinect
    from rangesim.viz.compare import save_comparison

    try:
        metrics, twin_scan, edge_maps = compare_kinect(scan, labels, args.sensor, seed=args.seed, return_scans=True)
    except RangesimError as exc:
        if exc.source is not None:
            raise
        raise RangesimError(str(exc), source=args.recorded) from exc  # (no table, no object: the frame's)
    # absolute paths: metrics.json is read from its own folder
    metrics = {"recorded": str(Path(args.recorded).resolve()), "mesh": None, "sensor": args.sensor,
               **_recorded_sensor(scan, args),
               **metrics}
    _write_outputs(out, metrics, lambda tmp: save_comparison(scan, twin_scan, metrics, tmp, detector=args.detector,
                                                             edge_maps=edge_maps))
    shapes = ", ".join(s["kind"] for s in metrics["shapes"])
    print(f"twin: {shapes} fitted to the labels, scanned by {args.sensor} at f = {metrics['focal_px']:.1f} px")
    print(f"IoU {metrics['iou']:.3f} (no-physics twin {metrics['iou_no_physics']:.3f})")
    k = metrics["z2_coefficient_mm_per_m2"]
    g = metrics["depth_level_gaps_in_steps"]
    print(f"  depth noise sigma_z = k z^2: k recorded {k['recorded']:.2f}, twin {k['twin']:.2f} mm/m^2; depth-level "
          f"gaps recorded {g['recorded']['median']:.2f}, twin {g['twin']['median']:.2f} disparity steps")
    for name, e in metrics["edges"].items():
        print(f"  {name:<15} F1 {e['f1']:.3f}")
    print(f"wrote {out}/metrics.json, {out}/compare.png")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise RangesimError("output must be a directory", source=out)
    positive("--sigma-mm", args.sigma_mm, allow_zero=True)
    positive("--tolerance", args.tolerance, allow_zero=True, at_most=MAX_TOLERANCE_PX)
    if args.min_cos is not None and not 0 <= args.min_cos < 1:
        raise RangesimError(f"--min-cos must lie in [0, 1), got {args.min_cos:g}")
    for name in ("theta_deg", "alpha_deg"):
        value = getattr(args, name)
        if value is not None and not abs(value) < 90:
            raise RangesimError(f"--{name.replace('_', '-')} must lie within (-90, 90) degrees, got {value:g}")
    if args.fit and args.no_fit:
        raise RangesimError("--fit and --no-fit exclude each other")
    if args.seed < 0:
        raise RangesimError(f"--seed must not be negative, got {args.seed}")
    path = Path(args.recorded)
    check_conf(path, args.conf)
    check_out_files(out, OUT_FILES, [path, args.conf, args.mesh, args.sensor, args.recorded_sensor])
    scan, labels = load_scan_with_labels(path, args.conf, sensor=args.recorded_sensor)
    from rangesim.cli.common import require_grid
    from rangesim.cli.edge_commands import describe_sensor

    require_grid(scan, path)
    if args.recorded_sensor is not None:
        print(describe_sensor(scan, args.recorded_sensor).replace("sensor ", "recorded-sensor ", 1))
    if args.mesh is None and labels is not None and _structured_light(args.sensor):
        return _kinect_twin(scan, labels, args, out)
    if args.mesh is None:
        from rangesim.viz.edge_overlay import save_edge_panels

        metrics, edge_maps, truth = _detectors_only(scan, labels, args, out)
        # no twin to compare with: the picture shows the recording and what each detector finds in it
        _write_outputs(out, metrics, lambda tmp: save_edge_panels(
            scan, edge_maps, tmp, truth=None if truth is None else truth.edge_map(), scores=metrics["edges"],
            title=f"{path.name}: edges (no mesh, so no twin)"))
        for name, e in metrics["edges"].items():
            score = f"  F1 {e['f1']:.3f}" if "f1" in e else ""
            print(f"{name:<15}{e['edges']:>9,}{score}")
        print(f"wrote {out}/metrics.json and {out}/compare.png")
        return 0

    from rangesim.twin.comparison import compare
    from rangesim.viz.compare import save_comparison

    if not scan.valid.any():
        raise RangesimError("the recorded scan has no valid point", source=path)
    fixed = {k: getattr(args, k) for k in ("theta_deg", "alpha_deg", "sigma_mm", "min_cos")
             if getattr(args, k) is not None}
    if args.no_fit:
        fit: Any = []
    elif args.fit:
        fit = [k for k in ("theta_deg", "alpha_deg", "sigma_mm") if k not in fixed]
    else:
        fit = "auto"  # a calibrated sensor (a [twin] table) is used as it is
    try:
        metrics, twin_scan, edge_maps = compare(scan, args.mesh, args.sensor, params=fixed, fit=fit,
                                                seed=args.seed, return_scans=True)
    except RangesimError as exc:
        if exc.source is not None:
            raise
        # the twin's refusals (no overlap) concern the mesh against the recording, as calibrate's do
        raise RangesimError(str(exc), source=f"{args.mesh} with {path}") from exc
    metrics = {"recorded": str(Path(path).resolve()), "mesh": str(Path(args.mesh).resolve()), "sensor": args.sensor,
               **_recorded_sensor(scan, args),
               **metrics}
    _write_outputs(out, metrics, lambda tmp: save_comparison(scan, twin_scan, metrics, tmp, detector=args.detector,
                                                             edge_maps=edge_maps))
    p = metrics["params"]
    noise = "the sensor's noise model" if p["sigma_mm"] is None else f"sigma {p['sigma_mm']:.3f} mm"
    print(f"twin: theta {p['theta_deg']:.1f} deg, alpha {p['alpha_deg']:.1f} deg, {noise}, "
          f"min_cos {p['min_cos']:.2f}")
    print(f"IoU {metrics['iou']:.3f} (no-physics twin {metrics['iou_no_physics']:.3f})  hole recall "
          f"{metrics['hole_recall']:.3f}  noise std ratio {metrics['noise_std_ratio']:.3f}")
    r = metrics["realism"]
    print("  std ratio by incidence: " + "  ".join(f"{k} {v:.2f}" for k, v in r["std_ratio_by_incidence"].items()))
    print("  neighbour correlation recorded/twin: " + "  ".join(
        f"{k} {r['recorded']['neighbour_correlation'][k]:.2f}/{r['twin']['neighbour_correlation'][k]:.2f}"
        for k in ("row", "column")) + f"  p99 ratio {r['p99_ratio']:.2f}")
    for name, e in metrics["edges"].items():
        print(f"  {name:<15} F1 {e['f1']:.3f}")
    print(f"wrote {out}/metrics.json, {out}/compare.png")
    return 0


def register(sub) -> None:
    from rangesim.edges import DETECTORS

    p = sub.add_parser("compare", help="compare a recorded scan with its simulated twin",
                       description="Twin a recorded scan (scan the mesh from its viewpoint on its grid with the "
                       "sensor's calibration; an uncalibrated sensor's angles and noise are fitted to this view) "
                       "and write metrics.json and compare.png. With a structured-light --sensor (kinect_v1) and a "
                       "labelled frame (mOSD) and no --mesh: the table and objects are fitted to the labels and "
                       "scanned again. "
                       "Without --mesh: run the detectors and score them against the scan's label regions.")
    p.add_argument("recorded", metavar="RECORDED", help="recorded scan (.ply range grid, .pcd, .msu, ...)")
    p.add_argument("--mesh", help="reference mesh of the object (world frame)")
    p.add_argument("--conf", help="Stanford .conf pose file")
    p.add_argument("--sensor", default="cyberware_3030", help="sensor preset (default cyberware_3030)")
    p.add_argument("--recorded-sensor", dest="recorded_sensor", metavar="NAME|TOML|auto",
                   help="what recorded a .pcd frame, for its own edge maps (a preset such as kinect_v1, a sensor TOML, "
                   "or auto: kinect_v1 only if the depths sit on a disparity lattice); a structured-light one runs "
                   "the detectors' block-matched paths on the recording. Default: none (the twin carries --sensor)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--theta-deg", dest="theta_deg", type=float, help="fix the camera angle (else fitted)")
    p.add_argument("--alpha-deg", dest="alpha_deg", type=float, help="fix the laser angle (else fitted)")
    p.add_argument("--sigma-mm", dest="sigma_mm", type=float, help="fix the depth noise std (else fitted)")
    p.add_argument("--min-cos", dest="min_cos", type=float, help="grazing-dropout cosine threshold")
    p.add_argument("--no-fit", action="store_true", help="no calibration: sensor defaults and the values given")
    p.add_argument("--fit", action="store_true",
                   help="refit the angles and a white noise on this view even if the sensor is calibrated")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--detector", default="gradient", choices=list(DETECTORS), help="edges shown in the picture (default gradient)")
    p.add_argument("--tolerance", type=float, default=2.0, help="edge matching tolerance, pixels (without --mesh)")
    p.set_defaults(func=cmd_compare)
