"""Generalized-cylinder extraction time against m * log2(n) (m polygons, n cross-sections).

Deformed ellipsoids (icosphere subdivisions 2..6) and bent tubes (rings x segments growing);
the resolution is fixed, so n stays about the same while m grows. The paper claims
O(m log n): the ratio time / (m log2 n) should stay roughly constant.

Run: ``python benchmarks/bench_gc.py``
"""
from __future__ import annotations

import math
import time

from rangesim.volumes import generalized_cylinders
from rangesim.volumes.shapes import bent_tube, deformed_ellipsoid


def timed(mesh, resolution, repeat=3):
    best, gcs = math.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        gcs = generalized_cylinders(mesh, resolution)
        best = min(best, time.perf_counter() - t)
    return best, sum(len(g.sections) for g in gcs)


def main() -> None:
    print(f"{'object':<22}{'m':>9}{'n':>5}{'time [s]':>10}{'t/(m log2 n) [us]':>20}")
    cases = [(f"ellipsoid sub={s}", deformed_ellipsoid(subdivisions=s)[0], 3.0) for s in range(2, 7)]
    cases += [(f"tube {k}x{4 * k}", bent_tube(n_around=k, n_along=4 * k)[0], 3.0) for k in (16, 32, 64, 128)]
    for name, mesh, res in cases:
        t, n = timed(mesh, res)
        m = len(mesh.faces)
        print(f"{name:<22}{m:>9,}{n:>5}{t:>10.3f}{1e6 * t / (m * math.log2(n)):>20.3f}")


if __name__ == "__main__":
    main()
