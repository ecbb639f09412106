"""Plots of a sweep's results table: F1 against edge SNR per detector, and F1 against each
swept parameter. Matplotlib's object API (``Figure`` + ``FigureCanvasAgg``), written
atomically.

Spread over views: each point of a line is one setting of the grid (every view and repeat
of it pooled); the line joins the medians and the band spans the quartiles of F1. The F1
against SNR plot also shows every scan as a faint dot, and puts noise-free scans (infinite
SNR) at a tick marked "inf" on the right.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

from rangesim.io.atomic import atomic_path

#: parameter columns that are not settings of the grid
NON_GRID = {"view", "repeat", "seed"}


def detector_colors(names: Sequence[str]) -> dict[str, Any]:
    """A fixed colour per detector (the order of :data:`rangesim.edges.DETECTORS` first)."""
    from matplotlib import colormaps

    from rangesim.edges import DETECTORS

    order = list(DETECTORS) + [n for n in names if n not in DETECTORS]
    cmap = colormaps["tab10"]
    return {name: cmap(order.index(name) % 10) for name in names}


def _grid_columns(table, swept: Sequence[str]) -> list[str]:
    """Columns that identify a grid setting: scene, sensor and every grid key present."""
    cols = []
    for c in table.columns:  # rows start with scene, sensor, the grid keys, then view
        if c == "view":
            break
        cols.append(c)
    return cols + [s for s in swept if s not in cols and s in table.columns]


def _save(fig: Figure, path: Path, dpi: int) -> Path:
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    return path


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_")


def _line_groups(d, groups: list[str], binned: bool, inf_x: float):
    """The points of a detector's line: one per grid setting when a single key is swept
    (its values order the line), else log-spaced SNR bins (three per decade) pooling every
    scan whose SNR falls in the bin, noise-free scans in a bin of their own."""
    if not binned:
        return d.groupby(groups, sort=False, dropna=False)
    snr = d["snr"].to_numpy(dtype=float)
    x = np.where(np.isinf(snr), inf_x, snr)
    ok = np.isfinite(x) & (x > 0)
    bins = np.full(len(x), -1)
    bins[ok] = np.floor(np.log10(x[ok]) * 3).astype(int)
    bins[np.isinf(snr)] = np.iinfo(np.int64).max // 2
    return d.groupby(bins, sort=True)


def plot_f1_vs_snr(table, path: str | Path, *, swept: Sequence[str] = (), title: str = "",
                   tolerance_px: float = 2.0, dpi: int = 150) -> Path:
    """F1 against the scan's headline SNR, one line per detector, one panel per scene x sensor.

    Parameters
    ----------
    table : pandas.DataFrame
        A sweep's results (columns ``detector``, ``snr``, ``f1``, ``scene``, ``sensor`` and
        the grid columns).
    path : str or Path
        Output ``.png``.
    swept : sequence of str
        The grid keys with more than one value (they define the points of a line).
    """
    path = Path(path)
    groups = _grid_columns(table, swept)
    panels = list(dict.fromkeys(zip(table["scene"], table["sensor"])))
    detectors = list(dict.fromkeys(table["detector"]))
    colors = detector_colors(detectors)
    n = len(panels)
    fig = Figure(figsize=(6.4 * min(n, 2), 4.6 * math.ceil(n / 2)), layout="constrained")
    finite = table["snr"].to_numpy(dtype=float)
    finite = finite[np.isfinite(finite) & (finite > 0)]
    lo = finite.min() / 1.5 if finite.size else 0.1
    hi = finite.max() * 1.5 if finite.size else 10.0
    inf_x = hi * 2.5
    has_inf = bool(np.isinf(table["snr"].to_numpy(dtype=float)).any())
    for k, (scene, sensor) in enumerate(panels):
        ax = fig.add_subplot(math.ceil(n / 2), min(n, 2), k + 1)
        sub = table[(table["scene"] == scene) & (table["sensor"] == sensor)]
        for det in detectors:
            d = sub[sub["detector"] == det]
            x_all = d["snr"].to_numpy(dtype=float)
            x_all = np.where(np.isinf(x_all), inf_x, x_all)
            ax.scatter(x_all, d["f1"], s=7, color=colors[det], alpha=0.25, linewidths=0)
            stats = []
            for _, g in _line_groups(d, groups, len(swept) > 1, inf_x):
                x = g["snr"].to_numpy(dtype=float)
                x = np.where(np.isinf(x), inf_x, x)
                x = x[np.isfinite(x) & (x > 0)]
                if not x.size:
                    continue
                q = _quartiles(g["f1"].to_numpy(dtype=float))
                if np.isnan(q[0]):  # every scan with nothing to find (no true edge pixel)
                    continue
                stats.append((float(np.median(x)), *q))
            if not stats:
                continue
            s = np.array(sorted(stats))
            ax.fill_between(s[:, 0], s[:, 1], s[:, 3], color=colors[det], alpha=0.18, linewidth=0)
            # the quartiles as bars too: a band through one point has no width
            ax.errorbar(s[:, 0], s[:, 2], yerr=[s[:, 2] - s[:, 1], s[:, 3] - s[:, 2]], fmt="none",
                        ecolor=colors[det], alpha=0.6, capsize=2, linewidth=1)
            ax.plot(s[:, 0], s[:, 2], "-o", color=colors[det], markersize=3.5, linewidth=1.6, label=det)
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlim(lo, inf_x * 1.5 if has_inf else hi)
        if has_inf:
            ticks = [m * 10.0 ** e for e in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
                     for m in (1, 2, 5) if lo <= m * 10.0 ** e <= hi]
            ax.set_xticks(ticks + [inf_x])
            ax.set_xticklabels([f"{t:g}" for t in ticks] + ["inf\n(noise-free)"])
            ax.axvline(math.sqrt(hi * inf_x), color="0.7", linewidth=0.8, linestyle=":")
        ax.set_ylim(0, 1.02)
        ax.grid(True, which="major", alpha=0.3)
        ax.set_xlabel("edge SNR (median over the true edge pixels of a scan)")
        ax.set_ylabel(f"F1 ({tolerance_px:g} px tolerance)")
        ax.set_title(f"{scene}, {sensor}", fontsize=10)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="lower right", fontsize=8, title="detector: median, quartiles", title_fontsize=8)
        else:
            ax.text(0.5, 0.5, "no scan with a true edge pixel", ha="center", va="center", transform=ax.transAxes)
    n_scans = table.groupby(["scene", "sensor"] + [c for c in ("view", "repeat", "seed") if c in table.columns]).ngroups
    fig.suptitle(f"{title + ': ' if title else ''}F1 against edge SNR ({n_scans} scans)", fontsize=11)
    return _save(fig, path, dpi)


def _quartiles(f1: np.ndarray) -> np.ndarray:
    """25 / 50 / 75 % of the finite F1 values (NaN: a scan with nothing to find), NaN if none."""
    f1 = f1[np.isfinite(f1)]
    return np.percentile(f1, [25, 50, 75]) if f1.size else np.full(3, np.nan)


def plot_f1_vs_param(table, key: str, path: str | Path, *, swept: Sequence[str] = (), title: str = "",
                     tolerance_px: float = 2.0, dpi: int = 150) -> Path:
    """F1 against one grid parameter, one line per detector (median and quartiles over views,
    repeats, and the other swept parameters), the median SNR under each value."""
    path = Path(path)
    detectors = list(dict.fromkeys(table["detector"]))
    colors = detector_colors(detectors)
    values = list(dict.fromkeys(table[key].tolist()))
    xs = np.arange(len(values))
    fig = Figure(figsize=(max(6.4, 0.9 * len(values) + 2.5), 4.6), layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    for det in detectors:
        d = table[table["detector"] == det]
        q = np.array([_quartiles(d.loc[d[key] == v, "f1"].to_numpy(dtype=float)) for v in values])
        ax.fill_between(xs, q[:, 0], q[:, 2], color=colors[det], alpha=0.18, linewidth=0)
        ax.errorbar(xs, q[:, 1], yerr=[q[:, 1] - q[:, 0], q[:, 2] - q[:, 1]], fmt="none", ecolor=colors[det],
                    alpha=0.6, capsize=2, linewidth=1)
        ax.plot(xs, q[:, 1], "-o", color=colors[det], markersize=3.5, linewidth=1.6, label=det)
    first = table[table["detector"] == detectors[0]]
    labels = []
    for v in values:
        snr = first.loc[first[key] == v, "snr"].to_numpy(dtype=float)
        snr = snr[~np.isnan(snr)]
        med = float(np.median(snr)) if snr.size else float("nan")
        shown = "inf" if math.isinf(med) else ("n/a" if math.isnan(med) else f"{med:.3g}")
        labels.append(f"{v:g}\nSNR {shown}" if isinstance(v, (int, float)) else f"{v}\nSNR {shown}")
    ax.set_xticks(xs)
    ax.set_xticklabels(labels, fontsize=8)
    ax.set_ylim(0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.set_xlabel(key)
    ax.set_ylabel(f"F1 ({tolerance_px:g} px tolerance)")
    others = [s for s in swept if s != key]
    pooled = "views" + (", repeats" if "repeat" in table.columns and table["repeat"].nunique() > 1 else "")
    pooled += "".join(f", {o}" for o in others)
    ax.set_title(f"median and quartiles over {pooled}", fontsize=9)
    if np.isfinite(table["f1"].to_numpy(dtype=float)).any():
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"{title + ': ' if title else ''}F1 against {key}", fontsize=11)
    return _save(fig, path, dpi)


def save_sweep_plots(table, swept: Sequence[str], out_dir: str | Path, *, title: str = "",
                     tolerance_px: float = 2.0, dpi: int = 150) -> list[Path]:
    """``f1_vs_snr.png`` and ``f1_vs_<key>.png`` per swept key in ``out_dir``; returns the paths."""
    out_dir = Path(out_dir)
    paths = [plot_f1_vs_snr(table, out_dir / "f1_vs_snr.png", swept=swept, title=title,
                            tolerance_px=tolerance_px, dpi=dpi)]
    for key in swept:
        if key in table.columns and table[key].nunique(dropna=False) > 1:
            paths.append(plot_f1_vs_param(table, key, out_dir / f"f1_vs_{_safe(key)}.png", swept=swept,
                                          title=title, tolerance_px=tolerance_px, dpi=dpi))
    return paths


def plot_snr_definition(path: str | Path, *, dpi: int = 150, seed: int = 3) -> Path:
    """The README's figure of the SNR definitions (:mod:`rangesim.experiments.snr`): a jump
    edge (step height over depth noise) and a crease (change of slope over the noise of a
    k-pixel least-squares slope), drawn on simulated depth profiles with noise."""
    from matplotlib.patches import FancyArrowPatch

    rng = np.random.default_rng(seed)
    fig = Figure(figsize=(10.5, 4.2), layout="constrained")
    sigma = 0.35

    # -- jump ----------------------------------------------------------------------------
    ax = fig.add_subplot(1, 2, 1)
    u = np.arange(-8, 8) + 0.5
    z_true = np.where(u < 0, 2.0, 6.0)
    z = z_true + rng.normal(0, sigma, u.size)
    ax.fill_between(u[u < 0], 2 - sigma, 2 + sigma, color="tab:blue", alpha=0.15, linewidth=0)
    ax.fill_between(u[u > 0], 6 - sigma, 6 + sigma, color="tab:blue", alpha=0.15, linewidth=0)
    ax.plot([-8, 0], [2, 2], color="tab:blue", linewidth=2, label="true surface")
    ax.plot([0, 8], [6, 6], color="tab:blue", linewidth=2)
    ax.plot(u, z, "o", color="k", markersize=3.5, label="measured depth (one per pixel)")
    ax.add_patch(FancyArrowPatch((0.9, 2), (0.9, 6), arrowstyle="<->", mutation_scale=12, color="tab:red"))
    ax.text(1.3, 4.0, r"step $\Delta z$", color="tab:red", va="center")
    ax.annotate(r"$\pm\sigma_z$ (depth noise)", xy=(-5.5, 2 + sigma), xytext=(-7.5, 4.2),
                arrowprops={"arrowstyle": "->", "color": "0.3"}, color="0.3")
    ax.axvline(0, color="0.6", linestyle=":", linewidth=1)
    ax.set_title(r"jump edge:  SNR$_\mathrm{jump} = \Delta z \, / \, \sigma_z$", fontsize=11)
    ax.set_xlabel("pixel across the edge")
    ax.set_ylabel("depth z (arbitrary units)")
    ax.set_ylim(0, 8.5)
    ax.legend(loc="upper left", fontsize=8)

    # -- crease --------------------------------------------------------------------------
    ax = fig.add_subplot(1, 2, 2)
    k = 3
    g1, g2 = 0.9, -0.2
    u = np.arange(-6, 6) + 0.5
    z_true = 5.0 + np.where(u < 0, g1 * u, g2 * u)
    z = z_true + rng.normal(0, sigma * 0.6, u.size)
    uu = np.linspace(-6, 6, 200)
    ax.plot(uu, 5.0 + np.where(uu < 0, g1 * uu, g2 * uu), color="tab:blue", linewidth=2, label="true surface")
    ax.plot(u, z, "o", color="k", markersize=3.5, label="measured depth")
    for side, colour in ((-1, "tab:orange"), (1, "tab:green")):
        sel = (u * side > 0) & (np.abs(u) < k)
        fit = np.polyfit(u[sel], z[sel], 1)
        line = np.linspace(0, side * (k + 0.6), 20)
        ax.plot(line, np.polyval(fit, line), "--", color=colour, linewidth=1.6,
                label=f"least-squares slope over k = {k} px" if side < 0 else None)
        ax.axvspan(min(0, side * k), max(0, side * k), color=colour, alpha=0.08, linewidth=0)
    ax.text(-5.8, 5.0 + g1 * -4.2, r"slope $g_1$", color="tab:orange", fontsize=10)
    ax.text(2.8, 5.0 + g2 * 3.5 + 0.55, r"slope $g_2$", color="tab:green", fontsize=10)
    ax.axvline(0, color="0.6", linestyle=":", linewidth=1)
    ax.set_title(r"crease:  SNR$_\mathrm{crease} = |g_1 - g_2| \, / \, \sigma_{\Delta g}$", fontsize=11)
    ax.text(0.98, 0.03,
            "g: depth slope per pixel footprint (z/f mm)\n"
            r"$\sigma_{\Delta g} = \sqrt{2}\;\sigma_{fp}\,\sqrt{12 / (k(k^2-1))}$,"
            "  $\\sigma_{fp} = \\sigma_z / (z/f)$",
            transform=ax.transAxes, fontsize=8.5, va="bottom", ha="right",
            bbox={"boxstyle": "round", "facecolor": "white", "edgecolor": "0.8"})
    ax.set_xlabel("pixel across the crease (1 pixel footprint apart)")
    ax.set_ylabel("depth z (arbitrary units)")
    ax.set_ylim(-1.5, 7.5)
    ax.legend(loc="upper right", fontsize=8)
    fig.suptitle("Edge SNR of a scan: per true edge pixel, then the median over the scan's edge pixels "
                 "(headline SNR: all types together)", fontsize=10)
    return _save(fig, Path(path), dpi)
