#!/usr/bin/env python
"""Speed of the rendered scanner (path-traced stripe, spacetime peaks) against the geometric one.

Scene: the Green Piece (``scenes/green_piece.toml``) from its [view]. Sensor: ``white_scanner``
with a SIZE x SIZE camera (field of view unchanged), ``mode = "rendered"``, ``render.frames``
FRAMES spread over the sweep that covers the view (about 150 mm: 1.2 mm per frame at 128), so
the stripe is widened to 2 mm FWHM (the spacetime peak needs the stripe to span >= 1.5 frames).

Timed (each: one cold run, then the median of --repeat runs):

* ``rendered``: ``rs.scan`` in rendered mode (primary rays for the truth, ``spp`` paths per
  pixel to ``max_depth``, frames, image noise, peaks, triangulation), with its per-stage
  seconds from ``scan.meta["seconds"]``;
* ``geometric``: ``rs.scan`` of the same view in geometric mode: the named baseline.

Then the cost of quality: spp in {1, 4, 16} and max_depth in {2, 3, 4}, and the preset at
its own size (512 x 480, stripe 0.5 mm, one frame per 0.25 mm: several hundred frames).
The kernel-cache figures (``meta["kernels"]``) show that tiles after the first compile
nothing.

Usage::

    python benchmarks/bench_rendered.py [--size 256] [--frames 128] [--repeat 3] [--json OUT.json]
"""
from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_info, timed  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: the target: a 256 x 256 scan with 128 frames on 2 CPU cores
TARGET_SECONDS = 60.0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--frames", type=int, default=128)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)

    import drjit as dr
    import mitsuba as mi

    import rangesim as rs

    scene = rs.load_scene(ROOT / "scenes" / "green_piece.toml")
    sensor = rs.load_sensor("white_scanner").with_params({
        "camera.width": args.size, "camera.height": args.size, "laser.stripe_width": 2.0,
        "mode": "rendered", "render.frames": args.frames,
    })
    rows = []

    def run(label, sensor_, repeat=args.repeat):
        cold, median, times, result = timed(lambda: rs.scan(scene, sensor_, seed=0), repeat)
        row = {"name": label, "median_s": median, "min_s": min(times), "cold_s": cold, "times": times,
               "valid": int(result.valid.sum()), "pixels": int(result.valid.size)}
        if result.meta["mode"] == "rendered":
            row.update(frames=result.meta["frames"], tiles=result.meta["tiles"], seconds=result.meta["seconds"],
                       kernels=result.meta["kernels"])
        rows.append(row)
        return row

    main_row = run(f"rendered {args.size}x{args.size}, {args.frames} frames, spp 4, depth 3", sensor)
    base = run(f"geometric {args.size}x{args.size} (baseline)", sensor.with_params({"mode": "geometric"}))
    for spp in (1, 16):
        run(f"rendered, spp {spp}", sensor.with_params({"render.spp": spp}), repeat=1)
    for depth in (2, 4):
        run(f"rendered, max_depth {depth}", sensor.with_params({"render.max_depth": depth}), repeat=1)
    preset = rs.load_sensor("white_scanner").with_params({"mode": "rendered"})
    run("rendered white_scanner preset 512x480, auto frames", preset, repeat=1)

    variant = mi.variant()
    print(f"rangesim {rs.__version__}, Mitsuba {mi.__version__} {variant}, Dr.Jit {dr.__version__}, "
          f"LLVM {'.'.join(map(str, dr.detail.llvm_version())) if variant.startswith('llvm') else '-'}, "
          f"{cpu_info().get('model', '?')}, {cpu_info().get('affinity', '?')} cores")
    print(f"{'name':58s} {'median s':>9s} {'cold s':>7s} {'frames':>6s} {'x geometric':>11s}")
    for row in rows:
        print(f"{row['name']:58s} {row['median_s']:9.3f} {row['cold_s']:7.2f} {row.get('frames', ''):>6} "
              f"{row['median_s'] / base['median_s']:11.1f}")
    print("stages of the main run (s):", ", ".join(f"{k} {v:.3f}" for k, v in main_row["seconds"].items()))
    print("kernels:", main_row["kernels"], "| preset run:", rows[-1]["kernels"])
    ok = main_row["median_s"] < TARGET_SECONDS
    print(f"target: {args.size}x{args.size} with {args.frames} frames under {TARGET_SECONDS:.0f} s: "
          f"{'PASS' if ok else 'FAIL'} ({main_row['median_s']:.2f} s)")
    if args.json:
        args.json.write_text(json.dumps({
            "date": datetime.date.today().isoformat(), "variant": variant, "python": platform.python_version(),
            "cpu": cpu_info(), "rows": rows, "target_seconds": TARGET_SECONDS, "pass": ok,
        }, indent=1))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
