"""``rangesim sweep`` and ``rangesim dataset``: many scans, locally or on Dask, resumable.

Examples
--------
::

    rangesim sweep scenes/snr_sweep.toml --out results/snr
    rangesim sweep sweep.toml --out results/ --scheduler local:4 --keep-scans
    rangesim dataset --scene scenes/green_piece.toml --sensor white_scanner --views 500 --out data/
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rangesim.core.errors import RangesimError


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {n}")
    return n


def _progress(args: argparse.Namespace) -> bool | None:
    return False if args.quiet else None


def _check_executor_options(args: argparse.Namespace) -> None:
    """``--workers`` sizes the local process pool; with ``--scheduler`` it was silently ignored."""
    if args.scheduler and args.workers is not None:
        raise RangesimError(f"--workers {args.workers} applies to the local process pool; with --scheduler "
                            f"{args.scheduler} the Dask cluster's workers run the tasks (local:N sets their number)")


def cmd_sweep(args: argparse.Namespace) -> int:
    """``rangesim sweep``: run a sweep file, write the table and plots, print a summary."""
    from rangesim.experiments.sweep import run_sweep

    _check_executor_options(args)
    run = run_sweep(args.sweep, args.out, keep_scans=args.keep_scans, workers=args.workers,
                    scheduler=args.scheduler, progress=_progress(args), plots=not args.no_plots)
    table = run.table
    if run.replaced:
        print(f"rangesim: warning: {args.out} held the results of sweep {run.replaced}: their task files stay "
              f"as a cache, the table and plots now follow {args.sweep}", file=sys.stderr)
    done = f"{run.n_run} run on {run.executor}, {run.n_reused} reused" if run.n_run else "all reused"
    print(f"{args.sweep}: {run.n_tasks} scans ({done}), {len(table)} rows in {run.seconds:.1f} s")
    if len(table):
        summary = table.groupby("detector", sort=False)["f1"].agg(["median", "min", "max"])
        print(f"{'detector':<15}{'F1 median':>10}{'min':>7}{'max':>7}")
        for det, row in summary.iterrows():
            print(f"{det:<15}{row['median']:>10.3f}{row['min']:>7.3f}{row['max']:>7.3f}")
        unscored = int((table["n_gt"] == 0).sum()) // max(table["detector"].nunique(), 1)
        if unscored:
            print(f"({unscored} of {run.n_tasks} scans had no true edge pixel to find: their scores are NaN, "
                  "left out of these figures and the plots)")
    print("wrote " + ", ".join(str(p) for p in run.files))
    return 0


def cmd_dataset(args: argparse.Namespace) -> int:
    """``rangesim dataset``: render views from random poses with ground truth and a manifest."""
    from rangesim.cli.common import positive
    from rangesim.cli.main import _parse_setting
    from rangesim.experiments.dataset import make_dataset

    _check_executor_options(args)
    changes = dict(_parse_setting(text) for text in args.set)
    if args.views < 1:
        raise RangesimError(f"--views must be at least 1, got {args.views}")
    if args.seed < 0:
        raise RangesimError(f"--seed must not be negative, got {args.seed}")
    positive("--cap-deg", args.cap_deg, allow_zero=True, at_most=180.0)  # 180: the whole sphere
    positive("--crease-deg", args.crease_deg, upper=180)
    distance = None
    if args.distance is not None:
        lo, hi = args.distance
        if not 0 < lo <= hi:
            raise RangesimError(f"--distance MIN MAX needs 0 < MIN <= MAX, got {lo:g} {hi:g}")
        distance = (lo, hi)
    run = make_dataset(args.scene, args.sensor, args.views, args.out, fmt=args.format, seed=args.seed,
                       cap_deg=args.cap_deg, distance=distance, axis=args.axis, target=args.target,
                       sensor_changes=changes or None, crease_deg=args.crease_deg, workers=args.workers,
                       scheduler=args.scheduler, progress=_progress(args))
    if run.replaced:  # as sweep says when its folder held another sweep
        print(f"rangesim: warning: {args.out} held {run.replaced} view(s) of another dataset (another scene, "
              "sensor, seed, view count, format or rangesim version): they were removed, the folder now holds "
              "this one",
              file=sys.stderr)
    for index, reason in run.empty:  # as `rangesim scan --keep-empty`: kept, and said once per view
        print(f"rangesim: warning: view {index}: {reason} (kept in the dataset)", file=sys.stderr)
    done = f"{run.n_run} rendered on {run.executor}, {run.n_reused} reused" if run.n_run else "all reused"
    print(f"{args.scene}: {run.n_views} views ({done}) "
          f"in {run.seconds:.1f} s; wrote {run.manifest} and {Path(args.out) / 'views'}/")
    return 0


def _execution_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scheduler", metavar="local:N|tcp://HOST:PORT",
                   help="run on Dask: a LocalCluster of N workers, or a running scheduler "
                   "(default: a local process pool)")
    p.add_argument("--workers", type=_workers, metavar="N",
                   help="local worker processes (default: the cores available; 0: in this process)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def register(sub) -> None:
    p = sub.add_parser("sweep", help="run a parameter sweep of scans and detectors",
                       description="Scan every combination of a sweep file (scenes, sensors, parameter grid, "
                       "random views, seeds), run the detectors, score them; write a tidy table (Parquet, CSV) "
                       "and plots (PNG). Resumable: finished tasks are kept and skipped on a rerun.")
    p.add_argument("sweep", metavar="SWEEP_TOML", help="sweep file (.toml)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--keep-scans", action="store_true", help="also write every scan (DIR/scans/<key>.exr)")
    p.add_argument("--no-plots", action="store_true", help="write the table only")
    _execution_options(p)
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("dataset", help="render a synthetic dataset with ground truth",
                       description="Render views of a scene from random poses (uniform over a spherical cap "
                       "around the part, with a distance range), each with ground truth (noise-free depth, "
                       "normals, part and sub-part labels, edge labels, features), and a manifest.json a "
                       "PyTorch-style loader reads (rangesim.experiments.SyntheticDataset). Resumable.")
    p.add_argument("--scene", required=True, metavar="SCENE", help="scene .toml or mesh file")
    p.add_argument("--sensor", default="white_scanner", metavar="NAME_OR_TOML",
                   help="sensor preset or .toml (default: white_scanner)")
    p.add_argument("--views", type=int, default=500, metavar="N", help="number of views (default: 500)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--format", choices=("exr", "npz"), default="exr", help="scan files (default: exr)")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="dataset seed (default: 0)")
    p.add_argument("--cap-deg", type=float, default=30.0, metavar="DEG",
                   help="half-angle of the cap of view directions (default: 30)")
    p.add_argument("--distance", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="camera-to-part distance range, mm (default: the sensor's working range less the "
                   "part's radius)")
    p.add_argument("--axis", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="cap axis towards the camera, world (default: towards the scene's [view])")
    p.add_argument("--target", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="point looked at, world mm (default: the first object's bounding-box centre)")
    p.add_argument("--crease-deg", type=float, default=20.0, help="ground-truth crease angle (default: 20)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a sensor key, e.g. camera.width=256 (repeatable; TOML values)")
    _execution_options(p)
    p.set_defaults(func=cmd_dataset)
