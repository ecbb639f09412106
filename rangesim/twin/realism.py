"""Realism statistics of a range scan against the noise-free surface behind its cells.

One set of measurements serves the comparison of a twin with its recording
(:func:`rangesim.twin.comparison.compare_scans`) and the joint calibration
(:func:`rangesim.twin.joint.calibrate_views`), so both sides are always measured the same
way (the pitfalls in ``shared/notes/measuring-realism.md``):

* residual: the signed range-axis distance (mm) of a measured point from the noise-free hit
  of its cell's sample line; the hit's normal gives the cell's incidence (the angle
  between the surface normal and the range axis);
* spreads are robust (1.4826 x MAD), per incidence bin (:data:`INCIDENCE_BINS`);
* the neighbour correlation is the Pearson correlation of a cell's residual with the next
  cell's, along a row (next column) and down a column (next row), after clipping at
  :data:`CLIP_SIGMAS` robust sigmas so silhouette outliers do not dominate;
* tails: the 99th percentile of |residual| and the share more than 0.5 mm off.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "INCIDENCE_BINS", "CLIP_SIGMAS", "OFF_MM", "robust_std", "incidence_deg", "residual_grid",
    "neighbour_correlation", "binned_robust_std", "dropout_by_bin", "realism_stats",
]

#: incidence bins (degrees, [lo, hi)) of every per-incidence statistic
INCIDENCE_BINS: tuple[tuple[float, float], ...] = ((0.0, 30.0), (30.0, 60.0), (60.0, 75.0), (75.0, 90.01))
#: robust sigmas beyond which residuals are left out of the correlations
CLIP_SIGMAS = 4.0
#: a point "off" by more than this (mm) counts in the ``share_off`` tail statistic
OFF_MM = 0.5
#: a bin with fewer cells is reported but not used for targets or fits
MIN_BIN_CELLS = 200


def robust_std(values: np.ndarray) -> float:
    """1.4826 x the median absolute deviation from the median (NaN for no values).

    Examples
    --------
    >>> round(robust_std(np.random.default_rng(0).normal(0, 2, 100000)), 1)
    2.0
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def clipped_std(values: np.ndarray, k: float = 4.0) -> float:
    """Std of ``values`` after dropping, until none is left, those over ``k`` std from the
    mean (chance matches, outliers; a Gaussian loses 0.1 % of its std at k = 4). For errors
    that come in steps (a block matcher's 1/8 px levels), where :func:`robust_std`'s median
    is quantised to the step; NaN for no values.

    Examples
    --------
    >>> x = np.random.default_rng(0).normal(0, 2, 100000)
    >>> round(clipped_std(np.r_[x, 1e6]), 2), round(clipped_std(np.round(x * 2) / 2), 2)  # an outlier; 0.5 steps
    (2.0, 2.0)
    """
    v = np.asarray(values, dtype=np.float64)
    keep = np.isfinite(v)
    if not keep.any():
        return float("nan")
    while True:
        mean, std = v[keep].mean(), v[keep].std()
        new = keep & (np.abs(v - mean) <= k * std)
        if new.sum() == keep.sum():
            return float(std)
        keep = new


def bin_label(lo: float, hi: float) -> str:
    return f"{lo:.0f}-{min(hi, 90.0):.0f}"


def incidence_deg(normal: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (degrees) between unit normals (..., 3) and viewing axes (..., 3), 0..90; NaN where unknown."""
    with np.errstate(invalid="ignore"):
        c = np.abs(np.sum(np.asarray(normal, np.float64) * np.asarray(axis, np.float64), axis=-1))
        c /= np.linalg.norm(normal, axis=-1) * np.linalg.norm(axis, axis=-1)
        return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


def residual_grid(scan, truth: np.ndarray) -> np.ndarray:
    """(H, W) float64: ``scan``'s range (z) minus the noise-free ``truth`` z; NaN where either is missing."""
    out = np.full(scan.shape, np.nan)
    ok = scan.valid & np.isfinite(truth).all(axis=2) & np.isfinite(scan.xyz).all(axis=2)
    out[ok] = scan.xyz[ok, 2].astype(np.float64) - truth[ok, 2].astype(np.float64)
    return out


def neighbour_correlation(residual: np.ndarray) -> dict[str, float]:
    """Correlation of each cell's residual with the next cell's: ``row`` (next column), ``column`` (next row).

    Residuals beyond :data:`CLIP_SIGMAS` robust sigmas of the median are left out.

    Examples
    --------
    >>> r = np.cumsum(np.random.default_rng(1).normal(size=(50, 400)), axis=1)  # a random walk along rows
    >>> c = neighbour_correlation(r - r.mean(axis=1, keepdims=True))
    >>> bool(c["row"] > 0.9), bool(abs(c["column"]) < 0.5)
    (True, True)
    """
    r = np.array(residual, dtype=np.float64)
    s = robust_std(r)
    if np.isfinite(s) and s > 0:
        r[np.abs(r - np.nanmedian(r)) > CLIP_SIGMAS * s] = np.nan
    out = {}
    for name, (a, b) in {"row": (r[:, :-1], r[:, 1:]), "column": (r[:-1, :], r[1:, :])}.items():
        m = np.isfinite(a) & np.isfinite(b)
        out[name] = float(np.corrcoef(a[m], b[m])[0, 1]) if np.count_nonzero(m) > 10 else float("nan")
    return out


def binned_robust_std(residual: np.ndarray, incidence: np.ndarray) -> dict[str, dict[str, float]]:
    """Per incidence bin: ``robust_std`` (mm) and ``count`` of the finite residuals."""
    out = {}
    for lo, hi in INCIDENCE_BINS:
        sel = np.isfinite(residual) & (incidence >= lo) & (incidence < hi)
        out[bin_label(lo, hi)] = {"robust_std": robust_std(residual[sel]), "count": int(np.count_nonzero(sel))}
    return out


def dropout_by_bin(valid: np.ndarray, surface: np.ndarray, incidence: np.ndarray) -> dict[str, float]:
    """Per incidence bin: the share of ``surface`` cells (a mesh hit) that are not ``valid``."""
    out = {}
    for lo, hi in INCIDENCE_BINS:
        sel = surface & (incidence >= lo) & (incidence < hi)
        n = int(np.count_nonzero(sel))
        out[bin_label(lo, hi)] = float(np.count_nonzero(sel & ~valid) / n) if n else float("nan")
    return out


def realism_stats(residual: np.ndarray, incidence: np.ndarray) -> dict[str, Any]:
    """Every statistic of one residual grid (see the module docstring)."""
    r = residual[np.isfinite(residual)]
    return {
        "by_incidence": binned_robust_std(residual, incidence),
        "robust_std": robust_std(r),
        "neighbour_correlation": neighbour_correlation(residual),
        "p99_abs": float(np.percentile(np.abs(r), 99)) if r.size else float("nan"),
        "share_off": float(np.mean(np.abs(r) > OFF_MM)) if r.size else float("nan"),
        "off_mm": OFF_MM,
        "count": int(r.size),
    }
