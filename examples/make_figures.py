"""Rebuild every figure of the README: run each example script into one folder.

Run: ``python examples/make_figures.py [--out DIR] [--small] [--only NAME ...]`` (or
``python -m rangesim.docs`` with the same options). Default folder: ``docs/images/``. The
scripts that need the shared data (``../shared/data`` or ``$RANGESIM_DATA``) or the rendered
mode's libLLVM 19 say so and skip their figures when those are absent.
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:  # the scripts import _gallery from this folder
    sys.path.insert(0, str(HERE))

from _gallery import DEFAULT_OUT  # noqa: E402

#: script -> the figures it writes (those behind a "needs" are skipped without it)
EXAMPLES: dict[str, tuple[str, ...]] = {
    "scan_a_part": ("green_piece_scan.png", "renault_piece_scan.png"),
    "scan_modes": ("green_piece_modes.png", "green_piece_white_light.png"),  # needs libLLVM 19
    "structured_light": ("structured_light_green_piece.png",),
    "edges_and_scores": ("edges_green_piece_gradient.png",
                         "edges_bunny_gradient.png", "edges_mosd_normal.png"),  # these two: shared data
    "hough_features": ("features_green_piece.png",),
    "curvature_maps": ("coons_curvature.png",),
    "surface_points": ("green_piece_points.png",),
    "volumes_and_cylinders": ("part_tree_green_piece.png", "gc_recursions.png", "gc_ellipsoid.png", "gc_renault.png"),
    "twin_of_a_recording": ("compare_mosd_test31.png", "compare_bun000.png"),  # shared data
    "snr_sweep": ("snr_definition.png", "snr_sweep_f1.png"),
    "dataset": ("dataset_views.png",),
}


def load(name: str):
    """The example script ``examples/<name>.py`` as a module (its ``main(argv)`` runs it)."""
    spec = importlib.util.spec_from_file_location(f"rangesim_example_{name}", HERE / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(name: str, out: Path, small: bool = False) -> float:
    """Run one example into ``out``; seconds taken."""
    start = time.perf_counter()
    load(name).main(["--out", str(out)] + (["--small"] if small else []))
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for the figures (default: docs/images)")
    parser.add_argument("--small", action="store_true", help="small sizes (quick check, not the README's quality)")
    parser.add_argument("--only", nargs="+", choices=sorted(EXAMPLES), metavar="NAME",
                        help=f"run only these examples ({', '.join(EXAMPLES)})")
    args = parser.parse_args(argv)
    times = {}
    for name in args.only or EXAMPLES:
        print(f"== examples/{name}.py", flush=True)
        times[name] = run(name, args.out, args.small)
    print("\n".join(f"{name:<24}{seconds:7.1f} s" for name, seconds in times.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
