"""Edges over a scan: convex white, concave grey, jump red, on the dimmed shaded scan."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rangesim.core.constants import EDGE_LABEL_NAMES, EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.viz.figure import save_labelled_image
from rangesim.viz.preview import depth_rgb

#: one colour per edge type, shared by every edge picture
EDGE_COLORS: dict[EdgeLabel, tuple[float, float, float]] = {
    EdgeLabel.JUMP: (0.95, 0.15, 0.1),
    EdgeLabel.CONVEX: (1.0, 1.0, 1.0),
    EdgeLabel.CONCAVE: (0.62, 0.62, 0.62),
    EdgeLabel.NONE: (1.0, 0.85, 0.1),  # an edge whose type the detector cannot tell
}
#: how much the scan under the edges is dimmed, so white and grey edges stand out
BACKGROUND_DIM = 0.45


def edge_overlay_rgb(scan: RangeScan, edge_map) -> np.ndarray:
    """(H, W, 3) picture: the shaded scan, dimmed, with edge pixels coloured by type."""
    rgb = depth_rgb(scan) * BACKGROUND_DIM
    for label, colour in EDGE_COLORS.items():
        rgb[edge_map.mask & (edge_map.labels == int(label))] = colour
    return rgb


def save_edge_overlay(scan: RangeScan, edge_map, path: str | Path, *, title: str | None = None,
                      dpi: int = 150) -> Path:
    """Write the edges of ``edge_map`` over ``scan`` as a PNG with a legend of pixel counts."""
    legend = []
    for label in (EdgeLabel.CONVEX, EdgeLabel.CONCAVE, EdgeLabel.JUMP, EdgeLabel.NONE):
        n = int(np.count_nonzero(edge_map.mask & (edge_map.labels == int(label))))
        if n:
            name = "edge, type unknown" if label == EdgeLabel.NONE else f"{EDGE_LABEL_NAMES[label]} edge"
            legend.append((EDGE_COLORS[label], f"{name}: {n:,} px"))
    h, w = scan.shape
    default = f"{edge_map.method or 'edges'} — {w}x{h} px, {int(edge_map.mask.sum()):,} edge pixels"
    return save_labelled_image(edge_overlay_rgb(scan, edge_map), path, title=title or default,
                               legend=legend, dpi=dpi)
