"""Hough benchmark: rangesim's direction-guided circle finder against scikit-image's
``hough_circle`` + ``hough_circle_peaks``, and its ellipse finder against ``hough_ellipse``
(on a small crop holding one ellipse, as ``hough_ellipse`` is slow), on the same edge maps
of the noise-free Green Piece (white_scanner, 512 x 480). Prints times, ratios and recall.

    python benchmarks/bench_hough.py [--repeat 3]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from skimage.transform import hough_circle, hough_circle_peaks, hough_ellipse

import rangesim as rs
import rangesim.edges  # noqa: F401
import rangesim.evaluate  # noqa: F401
import rangesim.features as F
from rangesim.core.geometry import look_at
from rangesim.evaluate._feature_scores import feature_scores

ROOT = Path(__file__).resolve().parents[1]
QUIET = {"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": 0}


class _C:  # a found circle for feature_scores
    def __init__(self, x, y, r):
        self.center, self.radius = (float(x), float(y)), float(r)


def best_time(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    scene = rs.load_scene(ROOT / "scenes/green_piece.toml")
    sensor = rs.load_sensor("white_scanner").with_params(QUIET)

    # -- circles: head-on view, radii 5..70 px --
    scan = rs.scan(scene, sensor, seed=0, pose=look_at((0, 0, 300), (0, 0, 0), up=(0, 1, 0)))
    edges = rs.edges.gradient(scan, jump_clearance=0)
    truth = rs.evaluate.ground_truth_features(scan, scene)
    n_truth = sum(c.visible >= 0.5 for c in truth["circles"])
    radii = np.arange(5, 71)
    F.circles(edges, radii=(5, 70))  # warm-up
    t_ours, ours = best_time(lambda: F.circles(edges, radii=(5, 70)), args.repeat)

    def skimage_circles():
        acc = hough_circle(edges.mask, radii)
        _, cx, cy, r = hough_circle_peaks(acc, radii, min_xdistance=3, min_ydistance=3,
                                          total_num_peaks=len(ours))
        return [_C(x, y, rr) for x, y, rr in zip(cx, cy, r)]

    t_sk, sk = best_time(skimage_circles, args.repeat)
    s_ours = feature_scores({"circles": ours}, truth, scan, center_tol_px=2.0)["round"]
    s_sk = feature_scores({"circles": sk}, truth, scan, center_tol_px=2.0)["round"]
    print(f"edge map: {edges.mask.shape[1]}x{edges.mask.shape[0]} px, {int(edges.mask.sum())} edge px, "
          f"{n_truth} visible rims, radii 5..70 px")
    print(f"circles  rangesim  {t_ours * 1e3:8.1f} ms  recall {s_ours['recall']:.2f}  precision "
          f"{s_ours['precision']:.2f}  max centre error {s_ours['center_error_px']['max']:.2f} px")
    print(f"circles  skimage   {t_sk * 1e3:8.1f} ms  recall {s_sk['recall']:.2f}  precision "
          f"{s_sk['precision']:.2f}  (same number of peaks)")
    print(f"circles  speed-up  {t_sk / t_ours:8.1f}x")

    # -- ellipse: tilted view, one hole rim in a crop --
    scan = rs.scan(scene, sensor, seed=0)
    edges = rs.edges.gradient(scan, jump_clearance=0)
    truth = rs.evaluate.ground_truth_features(scan, scene)
    g = next(c for c in truth["circles"] if c.name == "hole_2_rim_top")
    half = int(np.ceil(g.axes[0])) + 4
    x0, y0 = int(round(g.center[0])) - half, int(round(g.center[1])) - half
    crop = edges.mask[y0:y0 + 2 * half + 1, x0:x0 + 2 * half + 1]
    local = np.asarray(g.center) - (x0, y0)
    F.ellipses(crop, remove_explained=False)
    t_ours, ours = best_time(lambda: F.ellipses(crop, remove_explained=False), args.repeat)
    d_ours = min((np.hypot(*(np.asarray(e.center) - local)) for e in ours), default=np.inf)
    t = time.perf_counter()
    res = hough_ellipse(crop, accuracy=2, threshold=10, min_size=int(g.axes[1]) - 2,
                        max_size=int(g.axes[0]) + 2)
    t_sk = time.perf_counter() - t
    if len(res):
        res.sort(order="accumulator")
        best = res[-1]
        d_sk = float(np.hypot(best["xc"] - local[0], best["yc"] - local[1]))
    else:
        d_sk = np.inf
    print(f"ellipse crop {crop.shape[1]}x{crop.shape[0]} px, {int(crop.sum())} edge px ({g.name})")
    print(f"ellipse  rangesim  {t_ours * 1e3:8.1f} ms  centre error {d_ours:.2f} px")
    print(f"ellipse  skimage   {t_sk * 1e3:8.1f} ms  centre error {d_sk:.2f} px")
    print(f"ellipse  speed-up  {t_sk / t_ours:8.1f}x")


if __name__ == "__main__":
    main()
