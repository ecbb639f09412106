"""Edges over a scan: convex white, concave grey, jump red, rim orange, on the dimmed shaded scan
(depth in viridis, which holds no red or orange, so the jump and rim lines stay visible on any
part of it; the statuses of the pixels without a depth in the legend)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rangesim.core.constants import EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.edges.edgemap import LABEL_NAMES, RIM
from rangesim.viz.figure import save_labelled_image
from rangesim.viz.preview import depth_limits, depth_rgb, status_legend

#: one colour per edge type, shared by every edge picture
EDGE_COLORS: dict[int, tuple[float, float, float]] = {
    EdgeLabel.JUMP: (0.95, 0.15, 0.1),
    EdgeLabel.CONVEX: (1.0, 1.0, 1.0),
    EdgeLabel.CONCAVE: (0.62, 0.62, 0.62),
    EdgeLabel.NONE: (1.0, 0.85, 0.1),  # an edge whose type the detector cannot tell
    RIM: (1.0, 0.55, 0.1),  # the measured surface ends where the neighbour returned nothing
}
#: how much the scan under the edges is dimmed, so white and grey edges stand out
BACKGROUND_DIM = 0.45
#: the depth colours under the edges: no red or orange in it (turbo's far end is red-brown, on
#: which the red jump and orange rim lines of a bunny or a table vanished)
BACKGROUND_CMAP = "viridis"


def edge_overlay_rgb(scan: RangeScan, edge_map) -> np.ndarray:
    """(H, W, 3) picture: the shaded scan, dimmed, with edge pixels coloured by type."""
    rgb = depth_rgb(scan, cmap=BACKGROUND_CMAP) * BACKGROUND_DIM
    for label, colour in EDGE_COLORS.items():
        rgb[edge_map.mask & (edge_map.labels == int(label))] = colour
    return rgb


def edge_legend(edge_map) -> list[tuple[tuple[float, float, float], str]]:
    """(colour, "<type> edge: <n> px") of every edge type the map holds, for a picture's legend."""
    legend = []
    for label in (EdgeLabel.CONVEX, EdgeLabel.CONCAVE, EdgeLabel.JUMP, RIM, EdgeLabel.NONE):
        n = int(np.count_nonzero(edge_map.mask & (edge_map.labels == int(label))))
        if n:
            name = "edge, type unknown" if label == EdgeLabel.NONE else f"{LABEL_NAMES[int(label)]} edge"
            legend.append((EDGE_COLORS[label], f"{name}: {n:,} px"))
    return legend


def save_edge_overlay(scan: RangeScan, edge_map, path: str | Path, *, title: str | None = None,
                      dpi: int = 150) -> Path:
    """Write the edges of ``edge_map`` over ``scan`` as a PNG with a legend of pixel counts."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    from rangesim.viz.figure import ColorbarSpec

    legend = edge_legend(edge_map) + status_legend(scan, dim=BACKGROUND_DIM)
    h, w = scan.shape
    default = f"{edge_map.method or 'edges'} — {w}x{h} px, {int(edge_map.mask.sum()):,} edge pixels"
    colorbar = None
    if np.any(scan.valid & np.isfinite(scan.depth)):  # the depth scale, dimmed as the picture draws it
        lo, hi = depth_limits(scan)
        dimmed = ListedColormap(colormaps[BACKGROUND_CMAP](np.linspace(0, 1, 256))[:, :3] * BACKGROUND_DIM)
        colorbar = ColorbarSpec(dimmed, lo, hi, "depth z [mm]")
    return save_labelled_image(edge_overlay_rgb(scan, edge_map), path, title=title or default,
                               legend=legend, colorbar=colorbar, dpi=dpi)


def save_edge_panels(scan: RangeScan, edge_maps: dict, path: str | Path, *, truth=None,
                     scores: dict | None = None, title: str | None = None, dpi: int = 110) -> Path:
    """Write one PNG: the shaded scan, then each detector's edges over it (and the truth, if any).

    Parameters
    ----------
    scan : RangeScan
    edge_maps : dict of str -> EdgeMap
        Detector name to its edge map.
    path : str or Path
        ``.png`` file, written atomically.
    truth : EdgeMap-like, optional
        Ground truth (``mask``, ``labels``), drawn as one more panel.
    scores : dict of str -> dict, optional
        Per detector ``precision``, ``recall``, ``f1``, shown in its panel's title.
    title : str, optional
        Figure title (default: the scan's size and valid count).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()
    >>> maps = {"gradient": rs.edges.gradient(scan)}
    >>> p = save_edge_panels(scan, maps, pathlib.Path(tempfile.mkdtemp()) / "edges.png")
    >>> p.stat().st_size > 1000
    True
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    from rangesim.core.errors import RangesimError
    from rangesim.io.atomic import atomic_path

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise RangesimError("picture must be a .png file", source=path)
    panels = [(depth_rgb(scan), "scan (depth, shaded)")]
    if truth is not None:
        panels.append((edge_overlay_rgb(scan, truth), f"ground truth: {int(truth.mask.sum()):,} px"))
    for name, edge_map in edge_maps.items():
        label = f"{name}: {int(edge_map.mask.sum()):,} px"
        if scores and name in scores and "f1" in scores[name]:
            s = scores[name]
            label += f"  P {s['precision']:.2f} R {s['recall']:.2f} F1 {s['f1']:.2f}"
        panels.append((edge_overlay_rgb(scan, edge_map), label))
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    h, w = scan.shape
    fig = Figure(figsize=(4.6 * cols, 4.6 * rows * h / max(w, 1) + 0.9))
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, (rgb, label) in zip(axes.ravel(), panels):
        # (panels smaller than the frame: see viz.compare, "antialiased" keeps 1 px edges)
        ax.imshow(np.clip(rgb, 0, 1), interpolation="antialiased")
        ax.set_title(label, fontsize=9)
    n_valid = int(scan.valid.sum())
    fig.suptitle(title or f"edges — {w} × {h} px (W × H), {n_valid:,} valid", fontsize=11)
    handles = [Patch(facecolor=EDGE_COLORS[label], edgecolor="0.3",
                     label=LABEL_NAMES[int(label)] if label != EdgeLabel.NONE else "type unknown")
               for label in (EdgeLabel.CONVEX, EdgeLabel.CONCAVE, EdgeLabel.JUMP, RIM, EdgeLabel.NONE)]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, metadata={"Software": "rangesim"})
    return path
