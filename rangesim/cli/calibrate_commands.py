"""``rangesim calibrate``: one sensor calibration fitted jointly on several recordings (a sensor TOML)."""
from __future__ import annotations

import argparse
import re
from pathlib import Path

from rangesim.cli.common import check_conf, check_outputs, same_file, write_json, write_together
from rangesim.core.errors import RangesimError

#: what ``--name`` may be: a sensor name as the presets spell them (it becomes ``name = "..."`` in TOML)
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*")


def cmd_calibrate(args: argparse.Namespace) -> int:
    from rangesim.io import load_scan
    from rangesim.twin.joint import calibrate_views

    out = Path(args.out)
    if out.suffix.lower() != ".toml":
        raise RangesimError("the calibrated sensor must be written to a .toml file", source=out)
    if args.evaluations < 1:
        raise RangesimError(f"--evaluations must be an integer >= 1, got {args.evaluations}")
    if args.name is not None and not _NAME.fullmatch(args.name):
        raise RangesimError(f"--name must be a non-empty name of letters, digits, '_', '-' or '.', got {args.name!r}")
    report = Path(args.report) if args.report else None
    if report is not None:
        if report.suffix.lower() != ".json":
            raise RangesimError("the fit's report must be written to a .json file", source=report)
    # a preset given by name is read from its file (sensors/NAME.toml): an input like any other
    from rangesim.sensor import load_sensor
    sensor_file = load_sensor(args.sensor).source
    check_outputs([(out, "calibrated sensor"), (report, "report")],
                  [args.mesh, args.conf, args.sensor, sensor_file, *args.recorded])
    for k, name in enumerate(args.recorded):  # one view twice would count twice in the joint fit
        twin = next((other for other in args.recorded[:k] if same_file(other, name)), None)
        if twin is not None:
            raise RangesimError(f"the same recording is given twice ({twin} and {name})", source=name)
    mesh = Path(args.mesh)
    if not mesh.is_file():
        raise RangesimError("mesh file not found", source=mesh)
    from rangesim.twin.stage import fit_grid

    recordings = []
    for name in args.recorded:
        check_conf(name, args.conf)
        scan = load_scan(name, conf=args.conf) if args.conf else load_scan(name)
        if not scan.valid.any():
            raise RangesimError("the recorded scan has no valid point", source=name)
        if scan.xyz_true is not None:
            raise RangesimError("a synthetic scan (made by rangesim, with its noise-free hits), not a recording: "
                                "calibrate fits a sensor to recorded range grids (Stanford .ply with --conf, "
                                "organized .pcd, ...)", source=name)
        try:
            fit_grid(scan)
        except RangesimError as exc:
            raise RangesimError(f"not a recording this command can use ({exc})", source=name) from exc
        recordings.append(scan)
    try:
        result = calibrate_views(recordings, mesh, args.sensor, names=[Path(r).stem for r in args.recorded],
                                 fit_noise=not args.geometry_only, max_evaluations=args.evaluations)
    except RangesimError as exc:
        if exc.source is not None:
            raise
        # the fit's refusals (no overlap, a non-finite cost) concern the mesh against the recordings
        raise RangesimError(str(exc), source=f"{mesh} with {', '.join(args.recorded)}") from exc
    text = result["toml"]
    if args.name:
        text = text.replace(f'name = "{result["sensor"].name}"', f'name = "{args.name}"', 1)
    writes = [(out, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))]
    if report is not None:
        writes.append((report, lambda tmp: write_json({k: result[k] for k in ("geometry", "iou", "dropout", "noise",
                                                                              "views")}, tmp)))
    write_together(writes)
    g, d, n = result["geometry"], result["dropout"], result["noise"]
    print(f"geometry: theta {g['theta_deg']:.1f} deg, alpha {g['alpha_deg']:.1f} deg, min_cos {g['min_cos']:.2f}"
          f"  (joint noise-free IoU {result['iou']:.4f})")
    print(f"dropouts: min_signal {d['min_signal']:.4g}, signal_contrast {d['signal_contrast']:.2f}"
          f"  (joint IoU {d['iou']:.4f})")
    if n:
        print("range error: " + ", ".join(f"{k} {v:.4g}" for k, v in n.items() if k not in ("cost", "evaluations"))
              + f"  (cost {n['cost']:.4f}, {n['evaluations']} evaluations)")
    print(f"wrote {out}" + (f" and {report}" if report is not None else ""))
    return 0


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="fit one sensor calibration to several recordings",
                       description="Fit one twin geometry, dropout curve and range-error model jointly to every "
                       "recording given (the views differ only by their pose) and write it as a sensor TOML that "
                       "scan, twin, compare and sweeps take like any preset.")
    p.add_argument("recorded", nargs="+", metavar="REC", help="recorded organized scans of one scanner")
    p.add_argument("--mesh", required=True, help="reference mesh of the object (world frame)")
    p.add_argument("--conf", help="Stanford .conf file with the recordings' poses")
    p.add_argument("--sensor", required=True, help="the scanner's preset (starting values, everything not fitted)")
    p.add_argument("--out", required=True, metavar="SENSOR.toml", help="calibrated sensor file")
    p.add_argument("--name", help="name of the calibrated sensor (default: the preset's)")
    p.add_argument("--report", metavar="FIT.json", help="also write the fit's report as JSON")
    p.add_argument("--geometry-only", action="store_true", help="fit geometry and dropouts, keep the noise terms")
    p.add_argument("--evaluations", type=int, default=300, help="budget of the range-error fit (default 300)")
    p.set_defaults(func=cmd_calibrate)
