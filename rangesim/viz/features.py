"""Features drawn over the edges (the paper's Fig. 16): segments, circles, arcs and ellipses
rasterised (``skimage.draw``) over the edge overlay, written as a labelled PNG."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from skimage.draw import line as draw_line

from rangesim.viz.edge_overlay import edge_legend, edge_overlay_rgb
from rangesim.viz.figure import save_labelled_image

FEATURE_COLORS = {
    "segments": (0.1, 0.85, 1.0),
    "circles": (0.2, 1.0, 0.2),
    "arcs": (0.25, 0.45, 1.0),  # not orange: rim edges are
    "ellipses": (1.0, 0.2, 1.0),
}


def _polyline(rgb: np.ndarray, pts: np.ndarray, colour, closed: bool) -> None:
    H, W = rgb.shape[:2]
    p = np.rint(pts).astype(int)
    if closed:
        p = np.vstack([p, p[:1]])
    for (x0, y0), (x1, y1) in zip(p[:-1], p[1:]):
        rr, cc = draw_line(y0, x0, y1, x1)
        ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        rgb[rr[ok], cc[ok]] = colour


def features_rgb(scan, edge_map, features: dict[str, list]) -> np.ndarray:
    """(H, W, 3) picture: edges over the dimmed scan, with the features drawn on top."""
    rgb = edge_overlay_rgb(scan, edge_map)
    for s in features.get("segments", []):
        _polyline(rgb, np.array([s.start, s.end]), FEATURE_COLORS["segments"], False)
    for c in features.get("circles", []):
        t = np.linspace(0, 2 * np.pi, max(16, int(2 * np.pi * c.radius / 2)), endpoint=False)
        _polyline(rgb, np.c_[c.center[0] + c.radius * np.cos(t), c.center[1] + c.radius * np.sin(t)],
                  FEATURE_COLORS["circles"], True)
    for a in features.get("arcs", []):
        t = np.linspace(a.start, a.end, max(8, int(a.radius * (a.end - a.start) / 2)))
        _polyline(rgb, np.c_[a.center[0] + a.radius * np.cos(t), a.center[1] + a.radius * np.sin(t)],
                  FEATURE_COLORS["arcs"], False)
    for e in features.get("ellipses", []):
        t = np.linspace(0, 2 * np.pi, max(16, int(2 * np.pi * e.axes[0] / 2)), endpoint=False)
        ca, sa = np.cos(e.orientation), np.sin(e.orientation)
        x, y = e.axes[0] * np.cos(t), e.axes[1] * np.sin(t)
        _polyline(rgb, np.c_[e.center[0] + ca * x - sa * y, e.center[1] + sa * x + ca * y],
                  FEATURE_COLORS["ellipses"], True)
    for kind in ("circles", "ellipses"):  # centres as small crosses
        for f in features.get(kind, []):
            cx, cy = (int(round(v)) for v in f.center)
            for dx in (-2, -1, 0, 1, 2):
                for px, py in ((cx + dx, cy), (cx, cy + dx)):
                    if 0 <= py < rgb.shape[0] and 0 <= px < rgb.shape[1]:
                        rgb[py, px] = FEATURE_COLORS[kind]
    return rgb


def save_features_overlay(scan, edge_map, features: dict[str, list], path: str | Path, *,
                          title: str | None = None, dpi: int = 150) -> Path:
    """Write the features over the edges as a PNG with a legend of feature counts."""
    # the features, then the edge types they were found on
    legend = [(FEATURE_COLORS[k], f"{k}: {len(features.get(k, []))}") for k in FEATURE_COLORS] + edge_legend(edge_map)
    h, w = scan.shape
    return save_labelled_image(features_rgb(scan, edge_map, features), path,
                               title=title or f"features on {edge_map.method or 'edges'} — {w}x{h} px",
                               legend=legend, dpi=dpi)
