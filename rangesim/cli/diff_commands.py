"""``rangesim diff``: two scans of one view side by side with their depth-difference map."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rangesim.cli.common import check_outputs, check_suffix, positive, require_grid, writing


def cmd_diff(args: argparse.Namespace) -> int:
    from rangesim.io import load_scan
    from rangesim.viz.scan_difference import save_scan_difference

    out = Path(args.out)
    check_suffix(out, (".png",), "difference pictures")
    positive("--limit", args.limit, at_most=1e6)  # mm: a kilometre of depth difference
    check_outputs([(out, "difference picture")], [args.scan_a, args.scan_b])
    a, b = load_scan(args.scan_a), load_scan(args.scan_b)
    from rangesim.core.errors import RangesimError

    for scan, path in ((a, args.scan_a), (b, args.scan_b)):
        require_grid(scan, path, needs="diff compares pixel by pixel: it needs", operators=False)
        if scan.valid.size == 0:
            raise RangesimError(f"empty scan ({scan.shape[1]} x {scan.shape[0]} px): nothing to compare", source=path)
    if a.shape != b.shape:
        raise RangesimError(f"the scans differ in size: {args.scan_a} is {a.shape[1]:,} x {a.shape[0]:,} px, "
                            f"{args.scan_b} is {b.shape[1]:,} x {b.shape[0]:,} (W x H); diff compares two scans "
                            "of one view", source=args.scan_b)
    gap = float(np.linalg.norm(np.asarray(a.pose)[:3, 3] - np.asarray(b.pose)[:3, 3]))
    turn = float(np.degrees(np.arccos(np.clip((np.trace(np.asarray(a.pose)[:3, :3].T @ np.asarray(b.pose)[:3, :3]) - 1) / 2,
                                              -1.0, 1.0))))
    if gap > 1e-3 or turn > 1e-3:  # the same pixel then looks at other surface points
        import warnings

        warnings.warn(f"{args.scan_b} was taken from another pose than {args.scan_a} ({gap:.1f} mm and {turn:.1f} "
                      "degrees apart): the pixel-by-pixel difference compares different surface points", stacklevel=1)
    labels = tuple(args.labels) if args.labels else (Path(args.scan_a).stem, Path(args.scan_b).stem)
    with writing(out):
        stats = save_scan_difference(a, b, out, labels=labels, limit_mm=args.limit)
    differences = (f"{stats['both']:,} px valid in both, median |d| {stats['median_abs_mm']:.4f} mm, "
                   f"p95 {stats['p95_abs_mm']:.4f} mm, mean {stats['mean_mm']:+.4f} mm" if stats["both"]
                   else "no pixel valid in both (no depth differences)")
    print(f"{labels[1]} - {labels[0]}: {differences}; {stats['only_a']:,} only in {labels[0]}, "
          f"{stats['only_b']:,} only in {labels[1]}. Wrote {out}.")
    return 0


def register(sub) -> None:
    p = sub.add_parser("diff", help="compare two scans of one view (depth difference map)",
                       description="Show two scans of the same view side by side with the map of "
                       "their depth difference (B - A), e.g. the geometric and rendered modes.")
    p.add_argument("scan_a", metavar="SCAN_A", help="scan file (.exr, .npz, a range-grid .ply, an organized .pcd)")
    p.add_argument("scan_b", metavar="SCAN_B", help="scan file of the same view and size")
    p.add_argument("--out", required=True, metavar="PNG", help="picture to write (.png)")
    p.add_argument("--labels", nargs=2, metavar=("A", "B"), help="panel titles (default: file stems)")
    p.add_argument("--limit", type=float, metavar="MM",
                   help="difference at the ends of the colour scale, mm (default: 95th percentile)")
    p.set_defaults(func=cmd_diff)
