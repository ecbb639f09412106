"""One side-by-side picture of a recorded scan and its simulated twin."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io.atomic import atomic_path

__all__ = ["save_comparison", "mask_disagreement_rgb"]

#: colours of the valid-mask comparison
BOTH, RECORDED_ONLY, TWIN_ONLY, NEITHER = (0.75, 0.75, 0.75), (0.85, 0.15, 0.1), (0.1, 0.35, 0.9), (1.0, 1.0, 1.0)


def mask_disagreement_rgb(recorded: RangeScan, twin: RangeScan) -> np.ndarray:
    """(H, W, 3): grey where both are valid, red recorded only, blue twin only, white neither."""
    rgb = np.empty(recorded.shape + (3,))
    r, t = recorded.valid, twin.valid
    rgb[r & t], rgb[r & ~t], rgb[~r & t], rgb[~r & ~t] = BOTH, RECORDED_ONLY, TWIN_ONLY, NEITHER
    return rgb


def _edges_rgb(scan: RangeScan, mask: np.ndarray) -> np.ndarray:
    from rangesim.viz.preview import depth_rgb

    rgb = depth_rgb(_shaded_alike(scan)) * 0.45
    rgb[mask] = (1.0, 1.0, 0.2)
    return rgb


def save_comparison(recorded: RangeScan, twin: RangeScan, metrics: dict[str, Any], path: str | Path, *,
                    detector: str = "gradient", edge_maps: dict | None = None, dpi: int = 110) -> Path:
    """Write a PNG: recorded vs twin depth, valid masks with the disagreement coloured,
    residual histograms, and one detector's edges on both.

    ``edge_maps`` ({name: (recorded_map, twin_map)}) avoids running ``detector`` again.
    """
    from rangesim.edges import DETECTORS
    from rangesim.viz.preview import depth_limits, depth_rgb

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise RangesimError("picture must be a .png file", source=path)
    if edge_maps and detector in edge_maps:
        rec_map, twin_map = edge_maps[detector]
    else:
        rec_map, twin_map = DETECTORS[detector](recorded), DETECTORS[detector](twin)
    limits = depth_limits(recorded) if recorded.valid.any() else None

    fig = Figure(figsize=(20, 9.5))
    axes = fig.subplots(2, 4)
    panels = [
        (axes[0, 0], depth_rgb(_shaded_alike(recorded), limits=limits), "recorded depth"),
        (axes[0, 1], depth_rgb(_shaded_alike(twin), limits=limits), "twin depth"),
        (axes[0, 2], mask_disagreement_rgb(recorded, twin), f"valid masks (IoU {metrics.get('iou', float('nan')):.3f})"),
        (axes[1, 0], _edges_rgb(recorded, rec_map.mask), f"{detector} edges: recorded"),
        (axes[1, 1], _edges_rgb(twin, twin_map.mask), f"{detector} edges: twin"
         f" (F1 {metrics.get('edges', {}).get(detector, {}).get('f1', float('nan')):.3f})"),
    ]
    for ax, rgb, title in panels:
        # drawn smaller than the frame: "antialiased" keeps 1 px edges continuous where "nearest"
        # drops every other one (a 640 px frame in a 345 px panel)
        ax.imshow(np.clip(rgb, 0, 1), interpolation="antialiased")
        ax.set_title(title, fontsize=10)
        ax.set_xticks([]), ax.set_yticks([])
    axes[0, 2].legend(handles=[Patch(color=BOTH, label="both valid"), Patch(color=RECORDED_ONLY, label="recorded only"),
                               Patch(color=TWIN_ONLY, label="twin only")], loc="lower right", fontsize=8)

    ax = axes[1, 2]
    truth = twin.xyz_true
    if truth is not None:
        from rangesim.twin.calibration import range_residuals

        rec_res, twin_res = range_residuals(recorded, truth), range_residuals(twin, truth)
        both = np.concatenate([rec_res, twin_res])
        span = float(np.percentile(np.abs(both), 99)) if both.size else 1.0
        bins = np.linspace(-span, span, 81)
        # the outer 1 % is left out and counted (clipped into the end bins it drew false modes)
        outside = float(np.mean(np.abs(both) > span)) if both.size else 0.0
        ax.hist(rec_res[np.abs(rec_res) <= span], bins=bins, histtype="step", color=RECORDED_ONLY, label="recorded")
        ax.hist(twin_res[np.abs(twin_res) <= span], bins=bins, histtype="step", color=TWIN_ONLY, label="twin")
        ax.legend(fontsize=8, title=f"{100 * outside:.1f} % beyond +-{span:.2g} mm not drawn", title_fontsize=8)
        ax.set_yscale("log")
    ratio = metrics.get("noise_std_ratio", float("nan"))
    reference = "the fitted surfaces" if "shapes" in metrics else "the mesh"
    ax.set_title(f"residuals to {reference} along z (std ratio {ratio:.2f})", fontsize=10)
    ax.set_xlabel("mm")
    _noise_vs_incidence(axes[0, 3], recorded, twin)
    if metrics.get("realism"):
        _realism_table(axes[1, 3], metrics["realism"])
    else:  # a structured-light twin of a labelled frame: its own figures
        _structured_light_table(axes[1, 3], metrics)
    p = metrics.get("params", {})
    source = recorded.meta.get("source", "recorded")
    name = source.get("file", "recorded") if isinstance(source, dict) else Path(str(source)).name
    sigma = p.get("sigma_mm")
    noise = "sensor noise model" if sigma is None else f"sigma {sigma:.3f} mm"
    if "shapes" in metrics:  # a structured-light twin of a scene fitted to the frame's labels
        shapes = ", ".join(s["kind"] for s in metrics["shapes"])
        title = f"{name} vs twin: {shapes} fitted to the labels, scanned by {metrics.get('sensor', 'the sensor')}"
    else:
        title = (f"{name} vs twin: theta {p.get('theta_deg', float('nan')):.1f} deg,"
                 f" alpha {p.get('alpha_deg', float('nan')):.1f} deg, {noise},"
                 f" hole recall {metrics.get('hole_recall', float('nan')):.2f}")
    fig.suptitle(title, fontsize=12)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        FigureCanvasAgg(fig).print_png(str(tmp))
    return path


def _noise_vs_incidence(ax, recorded: RangeScan, twin: RangeScan) -> None:
    """Robust std of the range residual against incidence (5-degree bins), recording and twin."""
    from rangesim.twin.realism import incidence_deg, residual_grid, robust_std

    if twin.xyz_true is None:
        ax.set_axis_off()
        return
    incidence = incidence_deg(twin.normal, np.array([0.0, 0.0, 1.0]))
    edges = np.arange(0.0, 90.01, 5.0)
    for scan, color, label in ((recorded, RECORDED_ONLY, "recorded"), (twin, TWIN_ONLY, "twin")):
        r = residual_grid(scan, twin.xyz_true)
        centres, stds = [], []
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = np.isfinite(r) & (incidence >= lo) & (incidence < hi)
            if np.count_nonzero(sel) >= 30:
                centres.append(0.5 * (lo + hi))
                stds.append(robust_std(r[sel]))
        ax.plot(centres, stds, "o-", color=color, label=label, ms=4)
    ax.set_yscale("log")
    ax.set_xlabel("incidence (deg, normal vs range axis)")
    ax.set_ylabel("robust std of the range residual (mm)")
    ax.set_title("noise vs incidence", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def _realism_table(ax, realism: dict | None) -> None:
    """The realism metrics as text: per-bin std ratio, correlations, tails, dropouts."""
    ax.set_axis_off()
    if not realism:
        return
    rec, tw = realism["recorded"], realism["twin"]
    lines = ["incidence   rec std   twin std   ratio   drop rec/twin"]
    for key, b in rec["by_incidence"].items():
        d = realism["dropout_by_incidence"]
        lines.append(f"{key:>8}  {b['robust_std']:8.3f}  {tw['by_incidence'][key]['robust_std']:9.3f}"
                     f"  {realism['std_ratio_by_incidence'][key]:6.2f}   {d['recorded'][key]:.3f}/{d['twin'][key]:.3f}")
    rc, tc = rec["neighbour_correlation"], tw["neighbour_correlation"]
    lines += ["", f"neighbour corr. row     {rc['row']:.2f} / {tc['row']:.2f}",
              f"neighbour corr. column  {rc['column']:.2f} / {tc['column']:.2f}",
              f"p99 |residual|          {rec['p99_abs']:.2f} / {tw['p99_abs']:.2f} mm",
              f"share > {rec['off_mm']} mm          {rec['share_off']:.3f} / {tw['share_off']:.3f}",
              "(recorded / twin)"]
    ax.text(0.0, 1.0, "\n".join(lines), family="monospace", fontsize=9, va="top", transform=ax.transAxes)
    ax.set_title("realism metrics", fontsize=10)


def _structured_light_table(ax, metrics: dict[str, Any]) -> None:
    """The structured-light twin's figures as text (what ``compare`` prints for a Kinect frame)."""
    ax.set_axis_off()
    k, gaps, spread = (metrics.get(key) or {} for key in ("z2_coefficient_mm_per_m2", "depth_level_gaps_in_steps",
                                                          "z_spread"))
    rows = [("z^2 noise k (mm/m^2)", k.get("recorded"), k.get("twin")),
            ("depth-level gap (steps)", (gaps.get("recorded") or {}).get("median"), (gaps.get("twin") or {}).get("median")),
            ("residual / sigma spread", spread.get("recorded"), spread.get("twin"))]
    lines = [f"{'':<24}{'recorded':>9}{'twin':>9}"]
    lines += [f"{label:<24}{a:9.2f}{b:9.2f}" for label, a, b in rows if a is not None and b is not None]
    lines += ["", f"valid-mask IoU {metrics.get('iou', float('nan')):.3f} "
              f"(no physics {metrics.get('iou_no_physics', float('nan')):.3f})"]
    lines += [f"edge F1 {name:<14}{e['f1']:.3f}" for name, e in (metrics.get("edges") or {}).items() if "f1" in e]
    ax.text(0.0, 1.0, "\n".join(lines), family="monospace", fontsize=9, va="top", transform=ax.transAxes)
    ax.set_title("structured-light twin", fontsize=10)


def _shaded_alike(scan):
    """The scan with its normals dropped, so recorded and twin are both shaded from depth
    (the twin's exact normals and the recording's estimated ones look different)."""
    from dataclasses import replace

    return replace(scan, normal=np.full(scan.normal.shape, np.nan, dtype=np.float32))
