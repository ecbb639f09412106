"""``rangesim curvature``: the four curvature maps of a demo patch, like the paper's Fig. 11.

Examples
--------
::

    rangesim curvature --out maps.png                       # Coons patch, wavy boundaries
    rangesim curvature --patch sphere --resolution 100 --out sphere.png
"""
from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from rangesim.cad.bspline import BSplineSurface, ParametricSurface
from rangesim.cad.coons import coons_patch
from rangesim.cli.common import check_suffix, writing
from rangesim.core.errors import RangesimError

SIZE = 100.0  # mm, edge of the square demo patches


def _wavy_coons() -> ParametricSurface:
    """A 100 mm Coons patch whose four boundaries are sine waves of different phase."""
    def curve(start, end, amplitude, waves):
        a, b = np.asarray(start, float), np.asarray(end, float)
        return lambda t: a + np.multiply.outer(t, b - a) + np.multiply.outer(
            amplitude * np.sin(waves * math.pi * np.asarray(t)), [0.0, 0.0, 1.0])

    return coons_patch(
        curve((0, 0, 0), (SIZE, 0, 0), 10.0, 2),       # c0 = S(s, 0)
        curve((0, SIZE, 0), (SIZE, SIZE, 0), -8.0, 3),  # c1 = S(s, 1)
        curve((0, 0, 0), (0, SIZE, 0), 15.0, 1),       # d0 = S(0, t)
        curve((SIZE, 0, 0), (SIZE, SIZE, 0), -12.0, 2),  # d1 = S(1, t)
    )


def _saddle() -> ParametricSurface:
    """The hyperbolic paraboloid ``z = (x^2 - y^2) / (2 R)``, R = 50 mm, exactly (biquadratic)."""
    radius, half = 50.0, SIZE / 2
    xs = np.array([-half, 0.0, half])             # linear x(u) as a quadratic
    sq = np.array([half**2, -half**2, half**2])   # x^2 as a quadratic Bezier (blossom x1 x2)
    z = (sq[:, None] - sq[None, :]) / (2 * radius)
    ctrl = np.stack(np.broadcast_arrays(xs[:, None], xs[None, :], z), -1)
    knots = [0, 0, 0, 1, 1, 1]
    return BSplineSurface(ctrl, knots, knots, 2, 2)


def _bump() -> ParametricSurface:
    """A Gaussian bump (height 20 mm, sigma 20 mm) interpolated by a bicubic on a 15 x 15 grid."""
    g = np.linspace(-SIZE / 2, SIZE / 2, 15)
    x, y = np.meshgrid(g, g, indexing="ij")
    z = 20.0 * np.exp(-(x**2 + y**2) / (2 * 20.0**2))
    return BSplineSurface.from_grid(np.stack([x, y, z], -1))


#: --patch name -> (builder, description)
PATCHES: dict[str, tuple[Callable[[], ParametricSurface], str]] = {
    "coons": (_wavy_coons, "Coons patch from four wavy boundary curves, 100 mm"),
    "sphere": (lambda: BSplineSurface.sphere_patch(50.0), "NURBS sphere patch, r = 50 mm"),
    "cylinder": (lambda: BSplineSurface.cylinder_patch(30.0, SIZE, math.pi),
                 "NURBS half cylinder, r = 30 mm"),
    "saddle": (_saddle, "saddle z = (x^2 - y^2) / 100 mm"),
    "bump": (_bump, "bicubic Gaussian bump, 100 mm"),
}


def cmd_curvature(args: argparse.Namespace) -> int:
    """Render the curvature maps of the chosen patch and summarise their ranges."""
    from rangesim.viz.curvature_maps import curvature_grid, save_curvature_maps

    out = Path(args.out)
    check_suffix(out, (".png",), "curvature maps")
    if not 2 <= args.resolution <= 4000:
        raise RangesimError(f"--resolution must be in [2, 4000], got {args.resolution}")
    start = time.perf_counter()
    build, description = PATCHES[args.patch]
    surface = build()
    with writing(out):
        save_curvature_maps(surface, out, args.resolution, title=f"Curvatures: {description}")
    _, _, curv = curvature_grid(surface, min(args.resolution, 100))  # cheap summary grid
    ranges = ", ".join(
        f"{key} {np.nanmin(curv[key]):.3g} .. {np.nanmax(curv[key]):.3g}"
        for key in ("K", "H", "k1", "k2")
    )
    n = args.resolution
    print(
        f"Wrote {out}: curvature maps of the {description} ({n} x {n} samples); "
        f"{ranges} (1/mm, K 1/mm^2) in {time.perf_counter() - start:.2f} s."
    )
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``curvature`` subcommand to the ``rangesim`` parser."""
    p = subparsers.add_parser(
        "curvature", help="draw the curvature maps of a surface patch",
        description="Draw the Gaussian, mean, maximum and minimum curvature of a B-spline or "
        "Coons patch over its (u, v) domain (dark negative, bright positive), like Fig. 11 "
        "of the CAD-models paper.",
    )
    p.add_argument("--patch", choices=sorted(PATCHES), default="coons",
                   help="the patch: " + "; ".join(f"{k}: {d}" for k, (_, d) in PATCHES.items())
                   + " (default: coons)")
    p.add_argument("--resolution", type=int, default=200, metavar="N",
                   help="samples per parameter direction (default: 200)")
    p.add_argument("--out", required=True, metavar="PNG", help="picture to write (.png)")
    p.set_defaults(func=cmd_curvature)
