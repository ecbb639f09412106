"""B-spline surface evaluation: the hand-written basis (Piegl & Tiller A2.3) against scipy's NdBSpline.

``BSplineSurface`` evaluates points and partial derivatives with
``scipy.interpolate.NdBSpline`` (one call per derivative order, ``nu=(k, l)``); the
hand-written vectorised basis recursion (``_homogeneous_partials_by_hand``) is the
reference and the fallback for scipy < 1.12. This script times both through the public
methods on the same surface and parameters -- interleaved (hand, scipy, hand, ...) so
drifting clocks or caches hit both alike, median of the runs -- and prints the largest
difference, absolute and relative to the largest value.

Cases: a bicubic 12 x 10 B-spline and an exact NURBS sphere patch (rational: the quotient
rule needs every lower partial), each for points, first derivatives, normals and the
curvatures (the five partials of second order).

Run: ``python benchmarks/bench_bspline.py [--points 100000] [--repeat 7]``
"""
from __future__ import annotations

import argparse
import copy
import statistics
import time
from functools import partial

import numpy as np

from rangesim.cad.bspline import BSplineSurface


def _surfaces() -> dict[str, BSplineSurface]:
    rng = np.random.default_rng(0)
    p = q = 3
    n_u, n_v = 12, 10
    knots_u = np.r_[[0.0] * p, np.linspace(0, 1, n_u - p + 1), [1.0] * p]
    knots_v = np.r_[[0.0] * q, np.linspace(0, 1, n_v - q + 1), [1.0] * q]
    return {
        "bicubic 12x10": BSplineSurface(rng.normal(size=(n_u, n_v, 3)) * 10.0, knots_u, knots_v, p, q),
        "NURBS sphere": BSplineSurface.sphere_patch(20.0),
    }


def _hand(surface: BSplineSurface) -> BSplineSurface:
    """The same surface, evaluated with the hand-written basis (no NdBSpline)."""
    other = copy.copy(surface)
    other._spline = None
    return other


_QUERIES = {
    "points": lambda s, u, v: s.evaluate(u, v),
    "S_u, S_v": lambda s, u, v: np.stack([s.derivative(u, v, 1, 0), s.derivative(u, v, 0, 1)]),
    "normals": lambda s, u, v: s.normal(u, v),
    "curvatures": lambda s, u, v: np.stack(list(s.curvatures(u, v).values())),  # K, H, k1, k2
}


def _interleaved(fa, fb, repeat: int) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Median seconds of ``fa`` and ``fb``, run alternately after one warm-up each."""
    ra, rb = fa(), fb()
    ta, tb = [], []
    for i in range(repeat):
        for f, times in ((fa, ta), (fb, tb)) if i % 2 == 0 else ((fb, tb), (fa, ta)):
            t0 = time.perf_counter()
            f()
            times.append(time.perf_counter() - t0)
    return statistics.median(ta), statistics.median(tb), ra, rb


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(1)
    u, v = rng.uniform(0.0, 1.0, args.points), rng.uniform(0.0, 1.0, args.points)
    print(f"{args.points:,} points, median of {args.repeat} interleaved runs")
    print(f"{'surface':<15}{'query':<12}{'hand [ms]':>10}{'scipy [ms]':>11}{'speed-up':>9}"
          f"{'max |diff|':>12}{'relative':>10}")
    for name, surface in _surfaces().items():
        hand = _hand(surface)
        for query, fn in _QUERIES.items():
            t_hand, t_scipy, r_hand, r_scipy = _interleaved(
                partial(fn, hand, u, v), partial(fn, surface, u, v), args.repeat)
            diff = float(np.nanmax(np.abs(r_hand - r_scipy)))
            rel = diff / float(np.nanmax(np.abs(r_hand)))
            print(f"{name:<15}{query:<12}{1e3 * t_hand:>10.2f}{1e3 * t_scipy:>11.2f}"
                  f"{t_hand / t_scipy:>8.2f}x{diff:>12.1e}{rel:>10.1e}")


if __name__ == "__main__":
    main()
