"""One labelled-image figure for every picture drawn pixel for pixel (scan previews, edge
overlays): the RGB image with square, crisp pixels, an optional colour bar, a legend below
the image (never over the data) and a title. Matplotlib's object API only (``Figure`` +
``FigureCanvasAgg``, no ``pyplot``), written atomically.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from rangesim.core.errors import RangesimError
from rangesim.io.atomic import atomic_path


@dataclass(frozen=True)
class ColorbarSpec:
    """A colour bar beside the image: colormap, limits, label, and which ends are clipped."""

    cmap: Colormap
    lo: float
    hi: float
    label: str
    extend: str = "neither"


def save_labelled_image(
    rgb: np.ndarray,
    path: str | Path,
    *,
    title: str,
    legend: list[tuple[tuple[float, float, float], str]] = (),
    colorbar: ColorbarSpec | None = None,
    dpi: int = 150,
    image_size: tuple[int, int] | None = None,
) -> Path:
    """Write an (H, W, 3) RGB image in [0, 1] as a labelled PNG.

    Parameters
    ----------
    rgb : (H, W, 3) float array
    path : str or Path
        Output ``.png``; parent folders are created; the write is atomic.
    title : str
    legend : list of (colour, label)
        Legend entries, drawn below the image.
    colorbar : ColorbarSpec, optional
    dpi : int
        Resolution; fonts and margins scale with it.
    image_size : (W, H), optional
        Size of the image ``rgb`` was thinned from (a picture of a large scan from every
        k-th pixel): the axes count its pixels. Default ``rgb``'s own.
    """
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise RangesimError("picture must be a .png file", source=path)
    h, w = rgb.shape[:2]

    # -- layout, in pixels so the image lands on whole pixels (crisp nearest-neighbour) --
    long_side = max(h, w, 1)
    mag = max(1, 900 // long_side) if long_side <= 2400 else 2400 / long_side
    img_w, img_h = max(1, round(w * mag)), max(1, round(h * mag))
    inch = float(dpi)
    left, right = round(0.8 * inch), round(0.2 * inch)
    gap, cbar_w, cbar_label = (round(v * inch) for v in (0.15, 0.16, 0.95)) if colorbar else (0, 0, 0)
    top, xlabel = round(0.5 * inch), round(0.55 * inch)
    cbar_h = max(img_h, round(1.6 * inch)) if colorbar else img_h  # a colour bar needs some height
    body_h = max(img_h, cbar_h)
    body_w = left + img_w + gap + cbar_w + cbar_label + right
    fig_w = max(body_w, round(6.0 * inch))  # room for title and legend on narrow images
    x0 = left + (fig_w - body_w) // 2

    handles = [Patch(facecolor=c, edgecolor="0.4", linewidth=0.5, label=label) for c, label in legend]
    fontsize = 8.5
    if handles:
        char_w = 0.55 * fontsize / 72 * inch
        entry_w = max(len(p.get_label()) for p in handles) * char_w + 0.45 * inch
        ncol = max(1, min(len(handles), int((fig_w - 0.2 * inch) // entry_w)))
        legend_h = round((0.1 + 0.24 * math.ceil(len(handles) / ncol)) * inch)
    else:
        ncol, legend_h = 1, 0
    bottom = xlabel + legend_h
    fig_h = top + body_h + bottom

    fig = Figure(figsize=(fig_w / inch, fig_h / inch), dpi=dpi)
    FigureCanvasAgg(fig)
    img_y = bottom + (body_h - img_h) // 2
    ax = fig.add_axes((x0 / fig_w, img_y / fig_h, img_w / fig_w, img_h / fig_h))
    # extent on pixel edges: pixel (i, j) covers [j, j+1] x [i, i+1], like the K convention
    full_w, full_h = image_size or (w, h)
    ax.imshow(np.clip(rgb, 0, 1), interpolation="nearest", aspect="equal", origin="upper",
              extent=(0, full_w, full_h, 0), resample=False)
    ax.set_xlabel("column [px]", fontsize=fontsize)
    ax.set_ylabel("row [px]", fontsize=fontsize)
    ax.tick_params(labelsize=fontsize - 1, length=3)
    ax.set_title(title, fontsize=fontsize + 1.5, pad=8)

    if colorbar is not None:
        cax = fig.add_axes((
            (x0 + img_w + gap) / fig_w, (bottom + (body_h - cbar_h) // 2) / fig_h,
            cbar_w / fig_w, cbar_h / fig_h,
        ))
        cbar = fig.colorbar(ScalarMappable(Normalize(colorbar.lo, colorbar.hi), colorbar.cmap), cax=cax,
                            extend=colorbar.extend)
        cbar.set_label(colorbar.label, fontsize=fontsize)
        cbar.ax.tick_params(labelsize=fontsize - 1, length=3)

    if handles:
        fig.legend(
            handles=handles, loc="lower center", ncol=ncol, frameon=False,
            bbox_to_anchor=(0.5, 0.05 * inch / fig_h), fontsize=fontsize,
            handlelength=1.0, handleheight=1.0, columnspacing=1.5, borderaxespad=0.0,
        )
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, metadata={"Software": "rangesim"})
    return path
