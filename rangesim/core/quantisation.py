"""Quantised depth: the levels a depth image's values sit on, and whether they are a block
matcher's disparity lattice.

Core layer: pure NumPy (SciPy for one robust slope) over a depth array, so that the readers
of recorded formats (which tag a recording as block-matched) and the edge detectors (which
treat quantisation steps as no jump) share one rule.
"""
from __future__ import annotations

import numpy as np

__all__ = ["depth_quantum", "looks_continuous", "disparity_lattice", "DEFAULT_MATCHER_PRESET", "DEFAULT_MATCHER_WINDOW"]

#: the sensor preset whose block matcher stands for a block-matched recording of unknown make,
#: and its matching window (px; the core reads no sensor files: tests/test_recorded_matching.py
#: holds this to the preset's ``structured_light.window``)
DEFAULT_MATCHER_PRESET = "kinect_v1"
DEFAULT_MATCHER_WINDOW = 9


#: sampled pixels for the quantisation test of :func:`depth_quantum`
_QUANTUM_SAMPLES = 20_000
#: a depth image is quantised when sampled neighbours that differ lie at most this many
#: distinct depth levels apart (median): rounded data steps by one or two levels, while
#: continuous depths take a new value at nearly every pixel, so that hundreds of distinct
#: values lie between two neighbours on a slanted face
_QUANTUM_MAX_LEVELS = 3
#: fewest distinct depth levels a quantised image must show
_QUANTUM_MIN_LEVELS = 20


def _strided(z: np.ndarray, target: int) -> np.ndarray:
    """``z`` on every k-th row and column, k chosen to leave about ``target`` pixels."""
    k = max(1, int(np.sqrt(z.size / target)))
    return z[::k, ::k]


def _levels_close(z: np.ndarray, levels: np.ndarray) -> bool:
    """Whether sampled neighbours that differ lie at most :data:`_QUANTUM_MAX_LEVELS` of
    ``levels`` apart (median; False with fewer than 100 such pairs)."""
    k = max(1, int(np.sqrt(z.size / _QUANTUM_SAMPLES)))
    h, w = z.shape
    hk, wk = (h - 1) // k * k, (w - 1) // k * k      # pairs of true neighbours, sampled
    apart = []
    for a, b in ((z[:hk:k, :wk:k], z[:hk:k, 1:wk + 1:k]), (z[:hk:k, :wk:k], z[1:hk + 1:k, :wk:k])):
        differ = np.isfinite(a) & np.isfinite(b) & (a != b)
        apart.append(np.abs(np.searchsorted(levels, a[differ]) - np.searchsorted(levels, b[differ])))
    apart = np.concatenate(apart)
    return bool(apart.size >= 100 and np.median(apart) <= _QUANTUM_MAX_LEVELS)


def looks_continuous(z: np.ndarray, valid: np.ndarray | None = None) -> bool:
    """The cheap first test of :func:`depth_quantum`: True (not quantised) when the first 4000
    finite depths of a strided sample of about 20 000 pixels are more than half distinct,
    or fewer than 200. ``valid`` (optional, (H, W) bool): pixels outside it count as NaN, so
    that ``looks_continuous(depth, valid)`` decides as ``depth_quantum`` on the depth with NaN
    off ``valid``, without that copy of the image (a scan's noise model asks per call)."""
    sub = np.asarray(_strided(np.asarray(z), _QUANTUM_SAMPLES), np.float32)
    ok = np.isfinite(sub)
    if valid is not None:
        ok &= np.asarray(_strided(np.asarray(valid), _QUANTUM_SAMPLES), bool)
    head = sub[ok][:4000]
    return bool(head.size < 200 or np.unique(head).size > 0.5 * head.size)


def depth_quantum(z: np.ndarray) -> np.ndarray | None:
    """Quantisation step of a depth image at every pixel (mm), or None if it is not quantised.

    Kinect-type sensors report depth on a discrete set of levels (disparity in steps of
    1/8 px, so levels ``f b / d`` spaced ``z^2 / (8 f b)``: 3 mm at 1 m, 12 mm at 2 m;
    then rounded to whole millimetres). The levels are the distinct values the depths
    take; the local quantum is the larger of the two gaps beside a level (rounding to
    uneven levels moves two neighbours apart by up to that), a running median over 9
    levels (a level that no pixel of this image holds doubles a gap, and is outvoted),
    interpolated at each pixel's depth. The image counts as quantised when it shows at least
    :data:`_QUANTUM_MIN_LEVELS` levels and horizontal and vertical neighbours that differ
    lie a level or two apart (median at most :data:`_QUANTUM_MAX_LEVELS`). Continuous
    depths fail that (nearly every pixel is a level of its own), and so do noise-free
    synthetic scans whose frontal planes repeat one exact depth (few levels, or slanted
    faces between them).

    Parameters
    ----------
    z : (H, W) float array
        Depth, mm, NaN where invalid.

    Returns
    -------
    (H, W) float32 or None
        The quantum at every pixel (NaN where ``z`` is), mm; None for unquantised depth.
    """
    z = np.asarray(z, np.float32)
    # cheap rejection: continuous depths are (nearly) all distinct
    if looks_continuous(z):
        return None
    # the test: neighbours that differ are a level or two apart. First on the levels of
    # every 2nd row and column, a subset of the image's: neighbours lie at most as many
    # of those apart as of all levels, so a failure there is a failure (sorting a quarter
    # of the pixels, not all: 13 against 48 ms at 1024 x 1024 on a noise-free scan)
    quarter = z[::2, ::2]
    if not _levels_close(z, np.unique(quarter[np.isfinite(quarter)]).astype(np.float64)):
        return None
    levels = np.unique(z[np.isfinite(z)]).astype(np.float64)
    if levels.size < _QUANTUM_MIN_LEVELS or not _levels_close(z, levels):
        return None
    # rounding to uneven levels (a Kinect's millimetres over its disparity steps: gaps
    # 1, 2, 1, 2 mm) moves a pair by up to the larger gap beside a level: the running
    # median of that over 9 levels (a level no pixel holds doubles a gap, and is outvoted)
    gaps = np.diff(levels)
    wider = np.maximum(gaps[1:], gaps[:-1]) if gaps.size > 1 else gaps
    padded = np.pad(wider, 4, mode="edge")
    gap = np.median(np.lib.stride_tricks.sliding_window_view(padded, 9), axis=1)
    mids = levels[1:-1] if gaps.size > 1 else 0.5 * (levels[1:] + levels[:-1])
    out = np.interp(z, mids, gap).astype(np.float32)
    out[~np.isfinite(z)] = np.nan
    return out


#: a gap between adjacent depth levels is resolved (a lattice step, not the recording's
#: rounding) when it is at least this many rounding units (an error of one unit then
#: moves it by at most half)
_LATTICE_RESOLVED_UNITS = 2.0
#: fewest resolved single-step gaps, and least depth span (deepest / nearest) they must
#: cover to tell gaps growing as z^2 from constant ones (over a span s the two differ by s^2)
_LATTICE_MIN_GAPS = 20
_LATTICE_MIN_SPAN = 1.25
#: accepted log-log slope of the gaps against depth (2 for a disparity lattice, 0 for
#: depth rounded to a fixed unit)
_LATTICE_SLOPE = (1.5, 2.5)
#: least share of the gaps deeper than where q z^2 reaches two rounding units that are
#: resolved (a lattice's all are; a fixed-unit quantiser's mostly one unit)
_LATTICE_MIN_RESOLVED_SHARE = 0.7
#: most median |log(gap / (q z^2))| over the single steps (rounding scatters them)
_LATTICE_MAX_SCATTER = 0.25


def _rounding_unit(levels: np.ndarray) -> float:
    """The unit a recording rounded its depths to: 1 mm when (nearly) every level is a whole
    number of millimetres (OpenNI / Kinect depth images), else 0 (depths not rounded)."""
    off = np.abs(levels - np.round(levels))
    return 1.0 if np.mean(off < 0.01) >= 0.95 else 0.0


def disparity_lattice(z: np.ndarray) -> dict[str, float] | None:
    """Evidence that a depth image came from a block matcher (structured light), or None.

    The rule (physics): a block matcher measures disparity ``d`` in fixed sub-pixel steps
    (1/8 px for PrimeSense / Kinect v1) and reports depth ``z = f b / d``, so ``1 / z`` lies on
    a lattice of step ``q = 1 / (steps f b)`` and adjacent depth levels are ``q z^2`` apart: the
    gaps between the levels grow as the square of depth (1 mm at 0.6 m, 3 mm at 1 m, 12 mm at
    2 m for a Kinect). Depth quantised to a fixed unit (a laser scanner's or a ToF camera's
    millimetres) has constant gaps; continuous depth (noisy or noise-free synthetic scans)
    has no levels at all. A recording rounded to whole millimetres (OpenNI) shows 1 mm gaps
    where ``q z^2 < 1 mm``; only the gaps of at least two units (resolved) are tested.

    Accepted when all hold:

    * the image is quantised (:func:`depth_quantum`: neighbours a level
      or two apart, at least 20 levels);
    * at least 20 resolved single-step gaps (``q z^2`` within a factor 0.6-1.6, ``q`` the
      resolved gaps' median of ``gap / z^2``; larger ones are levels no pixel took) deeper
      than where ``q z^2`` reaches two rounding units (shallower, gaps of one and two units
      alternate whatever ``q``), covering depths at least 1.25 : 1 (over a narrower span
      ``z^2`` and a constant are not told apart: ambiguous);
    * their log-log slope against depth is 1.5-2.5 (Theil-Sen), their median
      ``|log(gap / (q z^2))|`` at most 0.25;
    * at least 70 % of the gaps deeper than where ``q z^2`` reaches two rounding units are
      resolved (a lattice's all are there; a fixed-unit quantiser's mostly one unit).

    Parameters
    ----------
    z : (H, W) float array
        Depth, mm, NaN where invalid.

    Returns
    -------
    dict or None
        ``inverse_depth_step`` (q, 1/mm), ``fb_steps`` (1/q: steps x f x b, px mm),
        ``slope``, ``scatter``, ``gaps`` (resolved single steps used), ``span``,
        ``rounding_mm`` (0 when depths are not rounded); None when the rule is not met.

    Notes
    -----
    ``fb_steps`` is exact on unrounded depths but reads 2-6 % low on depths rounded to whole
    millimetres: a lattice step of, say, 2.4 mm shows as gaps of 2 and 3 mm, the 2 mm ones the
    more frequent, and q is their median (synthetic 1/8 px lattices of 8 f b = 315 k and 344 k
    px mm, rounded to 1 mm: 299 k and 325 k over 0.6-1.2 m, 310 k and 336 k over 0.7-1.5 m).
    The accept / reject decision does not depend on it. For f b itself, use the gaps where the
    step is at least 3 mm (z above about 1 m on a Kinect): the six mOSD frames give 8 f b =
    343-345 k px mm there, against 322-338 k from ``fb_steps``.
    """
    z = np.asarray(z, np.float64)
    if z.ndim != 2 or depth_quantum(z) is None:
        return None
    levels = np.unique(z[np.isfinite(z) & (z > 0)])
    if levels.size < _LATTICE_MIN_GAPS + 1:
        return None
    unit = _rounding_unit(levels)
    gaps = np.diff(levels)
    mids = 0.5 * (levels[1:] + levels[:-1])
    resolved = gaps >= _LATTICE_RESOLVED_UNITS * unit if unit > 0 else np.ones(gaps.size, bool)
    if resolved.sum() < _LATTICE_MIN_GAPS:
        return None
    q = float(np.median(gaps[resolved] / mids[resolved] ** 2))
    # where the lattice's step q z^2 reaches two units, rounding leaves every gap resolved
    deeper = mids >= np.sqrt(_LATTICE_RESOLVED_UNITS * unit / q)
    share = float(resolved[deeper].mean()) if deeper.any() else 0.0
    ratio = gaps / (q * mids ** 2)
    # shallower, gaps of 1 and 2 units alternate whatever q: only the deeper ones measure it
    single = deeper & resolved & (ratio > 0.6) & (ratio < 1.6)
    if single.sum() < _LATTICE_MIN_GAPS or share < _LATTICE_MIN_RESOLVED_SHARE:
        return None
    span = float(mids[single].max() / mids[single].min())
    if span < _LATTICE_MIN_SPAN:
        return None
    from scipy.stats import theilslopes

    x, y = np.log(mids[single]), np.log(gaps[single])
    if x.size > 2000:  # Theil-Sen is quadratic in the points
        x, y = x[:: x.size // 1000], y[:: y.size // 1000]
    slope = float(theilslopes(y, x)[0])
    scatter = float(np.median(np.abs(np.log(ratio[single]))))
    if not (_LATTICE_SLOPE[0] <= slope <= _LATTICE_SLOPE[1]) or scatter > _LATTICE_MAX_SCATTER:
        return None
    return {"inverse_depth_step": q, "fb_steps": 1.0 / q, "slope": slope, "scatter": scatter,
            "gaps": int(single.sum()), "span": span, "rounding_mm": unit, "resolved_share": share}
