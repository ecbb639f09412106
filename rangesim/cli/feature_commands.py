"""``rangesim features``: segments, circles, arcs and ellipses of a scan's edges, their relations,
an overlay picture and, with a scene, scores against the analytic ground truth."""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from rangesim.cli.common import check_out_files, make_out_dir, positive, scene_files, write_json, write_together
from rangesim.core.errors import RangesimError


def _plain(obj):
    if dataclasses.is_dataclass(obj):
        return {k: _plain(v) for k, v in dataclasses.asdict(obj).items()}
    if isinstance(obj, (np.ndarray, tuple, list)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


def cmd_features(args: argparse.Namespace) -> int:
    import rangesim.features as F
    from rangesim.edges import DETECTORS
    from rangesim.io import load_scan
    from rangesim.scene import load_scene
    from rangesim.viz.features import save_features_overlay

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise RangesimError("output must be a directory", source=out)
    positive("--rmin", args.rmin)
    positive("--rmax", args.rmax)
    if args.rmin > args.rmax:  # equal: one radius, as the API's radii=(r, r)
        raise RangesimError(f"--rmin ({args.rmin:g}) must not exceed --rmax ({args.rmax:g})")
    names = ["features.json", "relations.csv", "features.png"]
    check_out_files(out, names, [args.scan, args.scene, args.sensor])
    if args.sensor is None:
        scan = load_scan(args.scan)
    else:  # as detect: a recording's sensor (a .pcd frame's) switches the detectors' block-matched paths on
        from rangesim.evaluate.runs import load_scan_with_labels

        scan = load_scan_with_labels(args.scan, None, sensor=args.sensor)[0]
    from rangesim.cli.common import require_grid
    from rangesim.cli.edge_commands import describe_sensor

    require_grid(scan, Path(args.scan))
    if not np.any(scan.valid & ~np.isnan(scan.depth)):  # (an infinite one: the detectors name it)
        raise RangesimError("no valid pixel (with a depth): no edges, no features to find", source=args.scan)
    scene = args.scene
    given_model = None
    if scene is not None:
        from rangesim.cli.common import load_scene_arg
        from rangesim.cli.scene_match import require_matching_scene, require_synthetic

        require_synthetic(scan, args.scan, scene)
        given_model = load_scene_arg(scene)
        require_matching_scene(scan, given_model, args.scan, scene)
    if scene is None and scan.xyz_true is not None:
        from rangesim.cli.scene_match import warn_if_named_scene_is_gone
        from rangesim.evaluate.runs import scene_of_scan

        warn_if_named_scene_is_gone(scan, args.scan, "no model: ellipses from the edges alone, no scores")
        given_model = scene_of_scan(scan)  # (a bare mesh in its own units, as it was scanned)
        scene = given_model.source if given_model is not None else None
    if given_model is not None:
        check_out_files(out, names, scene_files(given_model))
    # rims are fitted whole: keep the creases a jump would otherwise clear around it
    options = {"jump_clearance": 0} if args.edges == "gradient" else {}
    try:
        edge_map = DETECTORS[args.edges](scan, **options)
    except RangesimError as exc:  # a detector's refusal names the scan's field: name the file too
        raise RangesimError(str(exc), source=args.scan) from None
    radii = (args.rmin, args.rmax)
    segs = F.lines(edge_map, scan)
    circ = F.circles(edge_map, radii)
    arc = F.arcs(edge_map, radii)
    # the analysis layer takes a loaded scene (it does not read scene files itself)
    model = given_model if given_model is not None else (load_scene(scene) if scene else None)
    try:
        ell = F.ellipses(edge_map, scan if scene else None, model, explained=(*segs, *circ, *arc))
    except RangesimError as exc:  # (a scan without intrinsics for the model's ellipses): name the file
        raise RangesimError(str(exc), source=args.scan) from None
    feats = {"segments": segs, "circles": circ, "arcs": arc, "ellipses": ell}
    rows = F.relations(segs, circ, ell)
    make_out_dir(out)
    report = {"scan": str(args.scan), "edges": args.edges, "scene": scene, **_plain(feats)}
    if scene is not None and scan.xyz_true is not None:
        from rangesim.evaluate._feature_scores import feature_scores
        from rangesim.evaluate.ground_truth import ground_truth_features

        truth = ground_truth_features(scan, model if model is not None else scene)
        report["scores"] = _plain(feature_scores(feats, truth, scan))
    write_together([  # all three or none
        (out / "features.json", lambda tmp: write_json(report, tmp)),  # strict JSON: NaN as null
        (out / "relations.csv", lambda tmp: Path(tmp).write_text(F.relations_to_csv(rows))),
        (out / "features.png", lambda tmp: save_features_overlay(scan, edge_map, feats, tmp)),
    ])
    print(f"{args.scan}: {len(segs)} segments, {len(circ)} circles, {len(arc)} arcs, {len(ell)} ellipses, "
          f"{len(rows)} relations")
    if args.sensor is not None:
        print(describe_sensor(scan, args.sensor))
    if "scores" in report:
        s = report["scores"]
        def share(value):  # a share of nothing (no truth, nothing found) is no number
            return "-" if value is None or value != value else f"{value:.2f}"

        print(f"round features: recall {share(s['round']['recall'])} precision {share(s['round']['precision'])}; "
              f"segments: recall {share(s['segments']['recall'])}")
    print(f"wrote {out}/")
    return 0


def register(sub) -> None:
    from rangesim.cli.edge_commands import RECORDED_SENSOR_HELP
    from rangesim.edges import DETECTORS

    p = sub.add_parser("features", help="lines, circles, arcs and ellipses of a scan's edges",
                       description="Find segments, circles, arcs and (model-guided with --scene) ellipses "
                       "in a scan's edge map; write features.json, relations.csv and features.png.")
    p.add_argument("scan", metavar="SCAN", help="scan file (.exr, .npz, .ply range grid, .pcd, .msu)")
    p.add_argument("--edges", default="gradient", choices=list(DETECTORS),
                   help="edge detector the features are found on (default gradient)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--scene", help="scene of the scan (default: the one named in a synthetic scan)")
    p.add_argument("--rmin", type=float, default=5.0, help="least circle radius, px")
    p.add_argument("--rmax", type=float, default=80.0, help="largest circle radius, px")
    p.add_argument("--sensor", metavar="NAME|TOML|auto", help=RECORDED_SENSOR_HELP)
    p.set_defaults(func=cmd_features)
