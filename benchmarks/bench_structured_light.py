#!/usr/bin/env python
"""Speed of the structured-light mode (kinect_v1, 640 x 480) and of its block matching against OpenCV.

Scene: a 300 x 200 x 150 mm box on a floor, 1.5 m below the camera (kinect_v1 preset, 640 x 480).
Timed (one cold run, then the median of --repeat interleaved runs):

* ``scan``: ``rs.scan`` in structured-light mode end to end (rays, shadows, pattern, IR image,
  block matching, triangulation); target < 1 s on 2 CPU cores;
* ``block_match``: rangesim's ZNCC block matching (9 x 9, the preset's disparity range,
  sub-pixel, uniqueness and left-right checks) on the scan's IR image against its reference;
* ``StereoBM``: OpenCV's ``cv2.StereoBM`` (9 x 9 SAD on x-Sobel-prefiltered 8-bit images,
  16-pixel multiple of the same disparity range, its own uniqueness check) on the same pair,
  8-bit scaled: the named baseline.

Also printed: the valid share and the |depth error| (median, 90th percentile) of both matchers on the pair.

Usage::

    python benchmarks/bench_structured_light.py [--repeat 5] [--json OUT.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import cpu_info  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", default=str(ROOT / "benchmarks" / "results_structured_light_cpu_2core.json"))
    args = parser.parse_args()

    import rangesim as rs
    from rangesim.core.geometry import look_at
    from rangesim.sensor.block_matching import block_match
    from rangesim.sensor.structured_light import matching_setup

    floor = trimesh.creation.box(extents=(4000, 4000, 10))
    floor.apply_translation((0, 0, -5))
    part = trimesh.creation.box(extents=(300, 200, 150))
    part.apply_translation((0, 0, 75))
    scene = rs.load_scene([floor, part])
    sensor = rs.load_sensor("kinect_v1")
    pose = look_at((0, 0, 1500), (0, 0, 0), up=(0, 1, 0))

    t0 = time.perf_counter()
    scan = rs.scan(scene, sensor, pose=pose, seed=0)
    cold = time.perf_counter() - t0

    # the same pair for both matchers
    sl = sensor.params["structured_light"]
    w, h = sensor.width, sensor.height
    pair = matching_setup(sensor)
    d_min, d_max, d0, margin = pair.d_min, pair.d_max, pair.d0, pair.margin
    reference = pair.reference(w, h)
    image = scan.intensity.astype(np.float64) * sl["exposure_e"]

    import cv2

    scale = 255.0 / max(float(np.percentile(image, 99.9)), 1e-9)
    left = np.clip(image * scale, 0, 255).astype(np.uint8)
    ref_img = reference[:, margin:margin + w]
    right = np.clip(ref_img / max(float(ref_img.max()), 1e-9) * 255, 0, 255).astype(np.uint8)
    n_disp = int(np.ceil((d_max - d_min + 1) / 16.0) * 16)
    bm = cv2.StereoBM_create(numDisparities=n_disp, blockSize=sl["window"])
    bm.setMinDisparity(d_min - d0)
    bm.setUniquenessRatio(10)

    def ours():
        return block_match(image, reference, d_min - d0, d_max - d0, window=sl["window"],
                           subpixel_steps=sl["subpixel_steps"], min_score=sl["min_score"],
                           uniqueness=sl["uniqueness"], lr_check=sl["lr_check"])

    def opencv():
        return bm.compute(left, right)

    def full():
        return rs.scan(scene, sensor, pose=pose, seed=1)

    times = {"scan": [], "block_match": [], "StereoBM": []}
    for fn in (full, ours, opencv):
        fn()  # warm-up
    for _ in range(args.repeat):  # interleaved
        for name, fn in (("scan", full), ("block_match", ours), ("StereoBM", opencv)):
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    med = {k: statistics.median(v) for k, v in times.items()}

    fb = sensor.focal_px * sensor.params["laser"]["baseline"]
    z_true = scan.xyz_true[..., 2].astype(np.float64)

    def quality(disparity):
        with np.errstate(invalid="ignore", divide="ignore"):
            z = fb / disparity
        ok = np.isfinite(z) & np.isfinite(z_true) & (z > 0)
        e = np.abs(z[ok] - z_true[ok])
        return float(ok.mean()), float(np.median(e)), float(np.percentile(e, 90))

    ours_d, _ = ours()
    cv_raw = opencv().astype(np.float64) / 16.0
    cv_d = np.where(cv_raw >= d_min - d0, cv_raw + d0, np.nan)
    q = {"block_match": quality(ours_d + d0), "StereoBM": quality(cv_d)}
    print(f"kinect_v1 640 x 480, box on a floor at 1.5 m, disparities {d_min}..{d_max} px; 2-core CPU")
    print(f"  scan (structured_light, end to end): {med['scan']:.3f} s median (cold {cold:.2f} s); target < 1 s")
    for name in ("block_match", "StereoBM"):
        print(f"  {name:<12} {med[name] * 1e3:8.1f} ms   valid {q[name][0]:.3f}   |depth error| median "
              f"{q[name][1]:.2f} mm, 90 % {q[name][2]:.2f} mm")
    print(f"  ratio block_match / StereoBM: {med['block_match'] / med['StereoBM']:.1f}x")
    out = {"benchmark": "structured light", "machine": cpu_info(), "median_s": med, "cold_scan_s": cold,
           "quality": {k: {"valid": v[0], "abs_error_median_mm": v[1], "abs_error_p90_mm": v[2]} for k, v in q.items()},
           "ratio_block_match_over_stereobm": med["block_match"] / med["StereoBM"], "repeat": args.repeat}
    Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
