"""Two scans of one view side by side, and the map of their depth difference."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from rangesim.core.constants import Status, status_name
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io.atomic import atomic_path
from rangesim.viz.preview import depth_limits, depth_rgb, status_color

__all__ = ["depth_difference", "save_scan_difference"]

#: colour of pixels that only one scan (or neither) measured, in the difference panel
ONE_OR_NEITHER = (0.82, 0.82, 0.82)


def depth_difference(a: RangeScan, b: RangeScan) -> tuple[np.ndarray, dict[str, float]]:
    """Depth of ``b`` minus depth of ``a`` where both measured, and its summary.

    Returns
    -------
    difference : (H, W) float64, mm; NaN where either scan has no valid point
    stats : dict
        ``both`` (pixels valid in both), ``only_a``, ``only_b``, ``median_abs_mm``,
        ``p95_abs_mm``, ``mean_mm``.
    """
    if a.shape != b.shape:
        raise RangesimError(f"scans of different sizes cannot be compared: {a.shape} and {b.shape}")
    both = a.valid & b.valid & np.isfinite(a.depth) & np.isfinite(b.depth)
    difference = np.where(both, b.depth.astype(np.float64) - a.depth, np.nan)
    values = np.abs(difference[both])
    stats = {
        "both": int(both.sum()),
        "only_a": int((a.valid & ~b.valid).sum()),
        "only_b": int((b.valid & ~a.valid).sum()),
        "median_abs_mm": float(np.median(values)) if values.size else float("nan"),
        "p95_abs_mm": float(np.percentile(values, 95)) if values.size else float("nan"),
        "mean_mm": float(np.mean(difference[both])) if values.size else float("nan"),
    }
    return difference, stats


def save_scan_difference(a: RangeScan, b: RangeScan, path: str | Path, *, labels=("a", "b"),
                         limit_mm: float | None = None) -> dict[str, float]:
    """Write a PNG: scan ``a``, scan ``b`` (same depth colours) and ``b - a`` in mm.

    Parameters
    ----------
    a, b : RangeScan
        Scans of the same view (same size).
    path : str or Path
        The .png to write (atomically).
    labels : (str, str)
        Panel titles.
    limit_mm : float, optional
        Difference mapped to the ends of the diverging colour scale; default the 95th
        percentile of |b - a| (at least 0.05 mm).

    Returns
    -------
    dict
        The statistics of :func:`depth_difference`.
    """
    difference, stats = depth_difference(a, b)
    lo_a, hi_a = depth_limits(a)
    lo_b, hi_b = depth_limits(b)
    limits = (min(lo_a, lo_b), max(hi_a, hi_b))
    if limit_mm is None:
        limit_mm = max(0.05, stats["p95_abs_mm"]) if stats["both"] else 1.0
    h, w = a.shape
    fig = Figure(figsize=(15, 5.2 * h / w + 1.3), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3)
    for ax, scan, label in zip(axes[:2], (a, b), labels):
        ax.imshow(depth_rgb(scan, limits=limits), interpolation="nearest")
        ax.set_title(f"{label}: {int(scan.valid.sum()):,} valid px")
    # the depth scale: one bar for both panels, which then keep one size (a bar beside the
    # second alone shrank it); and what the unmeasured pixels' colours mean
    fig.colorbar(ScalarMappable(Normalize(*limits), "turbo"), ax=list(axes[:2]), fraction=0.046, pad=0.02, shrink=0.75,
                 label="depth z [mm]")
    codes = sorted({int(c) for scan in (a, b) for c in np.unique(scan.status[~scan.valid])})
    if codes:
        axes[0].legend(handles=[Patch(color=status_color(c), label=status_name(c, a.meta.get("mode")))
                                for c in codes if c in set(Status)], loc="lower left", fontsize=8)
    diff_rgb = np.empty((h, w, 3))
    diff_rgb[:] = ONE_OR_NEITHER
    norm = Normalize(-limit_mm, limit_mm)
    from matplotlib import colormaps

    both = np.isfinite(difference)
    diff_rgb[both] = colormaps["RdBu_r"](norm(difference[both]))[:, :3]
    axes[2].imshow(diff_rgb, interpolation="nearest")
    axes[2].set_title(f"{labels[1]} - {labels[0]}\nmedian |d| {stats['median_abs_mm']:.3f} mm, "
                      f"p95 {stats['p95_abs_mm']:.3f} mm", fontsize=10)  # two lines: one ran over the bar beside it
    # arrows where differences go beyond the limit (by default its 95th percentile: 5 % do)
    beyond = np.abs(difference[both]) > limit_mm
    fig.colorbar(ScalarMappable(norm, "RdBu_r"), ax=axes[2], fraction=0.046, pad=0.02, label="depth difference [mm]",
                 extend="both" if beyond.any() else "neither")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.supxlabel(f"grey in the difference: measured by only one ({stats['only_a']:,} {labels[0]} only, "
                  f"{stats['only_b']:,} {labels[1]} only) or neither", fontsize=9)
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            fig.savefig(handle, format="png", dpi=90)
    return stats
