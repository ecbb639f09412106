"""Curvature maps of a parametric surface: Gaussian, mean, maximum and minimum (paper Fig. 11).

Four grey-level panels over the (u, v) domain: dark is negative, bright positive, zero
mid-grey (limits symmetric about zero per panel), each with a colour bar in 1/mm (1/mm^2
for the Gaussian curvature). Signs follow :func:`rangesim.cad.bspline.surface_curvatures`:
positive where the surface bends towards its normal ``S_u x S_v``.

Matplotlib through its object API only (``Figure`` + ``FigureCanvasAgg``), like
:mod:`rangesim.viz.preview`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from rangesim.core.errors import RangesimError
from rangesim.io.atomic import atomic_path

#: (key, panel title, power of the length unit in the colour-bar label), in reading order
PANELS: tuple[tuple[str, str, int], ...] = (
    ("K", "Gaussian curvature K", 2),
    ("H", "mean curvature H", 1),
    ("k1", "maximum curvature k1", 1),
    ("k2", "minimum curvature k2", 1),
)

#: below this fraction of the largest principal curvature a value is rounding, drawn as zero
_NOISE_FLOOR = 1e-9
_MAX_RESOLUTION = 4000


def curvature_grid(
    surface, resolution: int = 200
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Exact curvatures of ``surface`` on a regular grid over its domain.

    Parameters
    ----------
    surface : ParametricSurface
        Anything with ``domain`` and ``curvatures(u, v)`` (B-spline, NURBS, Coons patch).
    resolution : int
        Samples per parameter direction (>= 2), domain ends included.

    Returns
    -------
    u : (resolution,) float
    v : (resolution,) float
    curvatures : dict of str -> (resolution, resolution) float
        ``"K", "H", "k1", "k2"``, indexed ``[j, i]`` = at ``(u[i], v[j])`` (image rows
        are v) -- 1/mm^2 and 1/mm.
    """
    if int(resolution) != resolution or not 2 <= resolution <= _MAX_RESOLUTION:
        raise RangesimError(
            f"curvature map resolution must be an integer in [2, {_MAX_RESOLUTION}], got {resolution!r}"
        )
    (u0, u1), (v0, v1) = surface.domain
    u = np.linspace(u0, u1, int(resolution))
    v = np.linspace(v0, v1, int(resolution))
    uu, vv = np.meshgrid(u, v)  # "xy" indexing: rows follow v
    curv = surface.curvatures(uu, vv)
    return u, v, {key: np.asarray(curv[key], dtype=np.float64) for key, _, _ in PANELS}


def symmetric_limit(values: np.ndarray, scale: float) -> float:
    """Colour limit ``L`` for the range ``[-L, L]``: the largest finite ``|value|``.

    Values below ``scale * 1e-9`` are rounding (a cylinder's ``K ~ 1e-49``) and must not
    be stretched into black and white; an all-zero map gets ``L = 1`` (mid-grey).
    """
    finite = np.abs(values[np.isfinite(values)])
    peak = float(finite.max()) if finite.size else 0.0
    if peak <= _NOISE_FLOOR * scale:  # includes peak == 0
        return 1.0 if scale == 0.0 else scale
    return peak


def save_curvature_maps(
    surface,
    path: str | Path,
    resolution: int = 200,
    *,
    title: str | None = None,
    unit: str = "mm",
    dpi: int = 120,
) -> Path:
    """Write a PNG with the four curvature maps of a surface, like the paper's Fig. 11.

    Parameters
    ----------
    surface : ParametricSurface
        Anything with ``domain`` and ``curvatures(u, v)``.
    path : str or Path
        Output file; must end in ``.png``. Written atomically (a failure leaves no file).
    resolution : int
        Samples per parameter direction.
    title : str, optional
        Figure title; default the surface's ``repr``.
    unit : str
        Length unit of the surface, for the colour-bar labels.
    dpi : int
        Resolution of the PNG (the figure is 10 x 8.6 inches).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    RangesimError
        If ``path`` does not end in ``.png`` or the resolution is out of range.
    """
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise RangesimError("curvature maps must be a .png file", source=path)
    u, v, curv = curvature_grid(surface, resolution)
    # the largest principal curvature sets what counts as rounding in every panel
    kmax = max(float(np.nanmax(np.abs(curv[k]), initial=0.0)) for k in ("k1", "k2"))

    fig = Figure(figsize=(10.0, 8.6), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    cmap = colormaps["gray"].with_extremes(bad=(0.75, 0.45, 0.45))  # NaN (singular points): muted red
    axes = fig.subplots(2, 2)
    for ax, (key, name, power) in zip(axes.ravel(), PANELS):
        limit = symmetric_limit(curv[key], kmax**power)
        image = ax.imshow(
            curv[key], cmap=cmap, vmin=-limit, vmax=limit, origin="lower", interpolation="nearest",
            extent=(u[0], u[-1], v[0], v[-1]), aspect="auto",
        )
        ax.set_title(name)
        ax.set_xlabel("u")
        ax.set_ylabel("v")
        cbar = fig.colorbar(image, ax=ax, shrink=0.9)
        cbar.set_label(f"{key} [1/{unit}{'²' if power == 2 else ''}]")
        cbar.formatter.set_powerlimits((-3, 3))  # small curvatures as 1e-3 multiples, not 0.000
    fig.suptitle(repr(surface) if title is None else title)
    fig.supxlabel("dark < 0 < bright (zero mid-grey); positive where the surface bends towards "
                  "its normal S_u x S_v", fontsize=8, color="0.35")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path
