"""Creases at the scale of a block matcher: the window it smoothed depth over, and
second differences taken across it.

Analysis layer: pure NumPy over arrays (the scan's ``meta`` is read as a plain dict).

A structured-light scanner (dot pattern and block matching, ``meta["sensor"]["mode"] ==
"structured_light"``) measures at each pixel the disparity that best aligns a ``window`` x
``window`` block of its image with the reference: about the mean disparity over the
block. Its depth is therefore the true surface smoothed by a box of about the window's
width, and a crease comes out rounded over ``window`` pixels. The 3 x 3 operators then see a
bend spread over nine pixels, a ninth of it per pixel, under the matcher's noise; a second
difference at a stride ``s`` of about the window compares the slopes of the faces *beside*
the rounding and sees most of the bend (:func:`rounding_gain`).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from rangesim.edges._discontinuities import segment_broken
from rangesim.edges._grid import AXES
from rangesim.edges._noise import depth_quantum

__all__ = ["disparity_lattice", "matching_window", "ridge_sigma", "rounding_gain", "strided_pairs", "strided_responses"]


#: the preset whose matcher stands for a block-matched recording of unknown make
DEFAULT_MATCHER_PRESET = "kinect_v1"
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

    * the image is quantised (:func:`~rangesim.edges._noise.depth_quantum`: neighbours a level
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


def default_matcher() -> dict[str, Any]:
    """``meta["sensor"]`` for a block-matched recording of unknown make: the
    :data:`DEFAULT_MATCHER_PRESET` preset's parameters (its matching window: 9 px)."""
    from rangesim.sensor.config import load_sensor

    return load_sensor(DEFAULT_MATCHER_PRESET).to_dict()


def matching_window(scan: Any, *, detect: bool = False) -> int | None:
    """The block matcher's window (pixels) behind a scan's depth, or None.

    Parameters
    ----------
    scan : RangeScan or any object with ``meta``
        ``meta["sensor"]`` as a sensor's parameters: ``mode`` and, for ``"structured_light"``,
        ``structured_light.window``.
    detect : bool
        Where the scan has no ``meta["sensor"]`` (a recording read without ``sensor=``),
        look at its depth: if :func:`disparity_lattice` finds it block-matched, the window of
        the :data:`DEFAULT_MATCHER_PRESET` preset (9). Off by default (the detectors do not
        detect: on the recorded mOSD frames the block-matched paths are not better across
        the board); a reader's ``sensor="auto"`` does the same once, at reading.

    Returns
    -------
    int or None
        The odd window side, pixels, where the depth comes from block matching of a pattern
        (structured light); None for every other scan (laser stripes, recordings without
        that metadata unless ``detect`` finds the lattice).

    Examples
    --------
    >>> class S: meta = {"sensor": {"mode": "structured_light", "structured_light": {"window": 9}}}
    >>> matching_window(S()), matching_window(object())
    (9, None)
    """
    meta = getattr(scan, "meta", None) or {}
    sensor = meta.get("sensor") if isinstance(meta, dict) else None
    if sensor is None and detect and getattr(scan, "depth", None) is not None:
        if disparity_lattice(scan.depth) is not None:
            sensor = default_matcher()
    if not isinstance(sensor, dict) or sensor.get("mode") != "structured_light":
        return None
    window = (sensor.get("structured_light") or {}).get("window")
    try:
        window = int(window)
    except (TypeError, ValueError):
        return None
    return window if window > 1 else None


def rounding_gain(window: float, stride: int) -> float:
    """The share of a crease's slope change that a second difference at ``stride`` sees after
    a box of ``window`` pixels smoothed the depth (dimensionless, 0..1).

    A crease whose slope changes by ``D`` (per pixel, across it), smoothed by a box of width
    ``w``, becomes a parabola over ``|x| <= w / 2`` (slope ``D x / w``) joining the two faces.
    The chords from the crease's centre to ``+-s`` then differ in slope by ``D s / w`` for
    ``s <= w / 2`` and by ``D (1 - w / (4 s))`` beyond (the centre lies ``D w / 8`` off the
    faces' meeting point). Dividing a strided response by this gain estimates the crease's
    own bend; for a square window seen across a diagonal crease the centre's offset is
    ``w / (6 sqrt 2)`` instead of ``w / 8`` (6 % less), close enough.

    Parameters
    ----------
    window : float
        Box width, pixels (1 or less: no smoothing, gain 1).
    stride : int
        Half-width of the second difference, pixels.

    Examples
    --------
    >>> rounding_gain(9, 9), rounding_gain(9, 3), rounding_gain(1, 1)
    (0.75, 0.3333333333333333, 1.0)
    """
    w, s = float(window), float(stride)
    if w <= 1.0:
        return 1.0
    return s / w if s <= w / 2 else 1.0 - w / (4.0 * s)


def ridge_sigma(window: int | None, stride: int) -> float:
    """Smoothing (pixels, a Gaussian's standard deviation) under which a strided crease
    response's ridge is thinned.

    A response at stride ``s`` sees a crease from every pixel within about ``s - w / 2`` of
    it and peaks broadly (the box-rounded crease's response falls by ``2 / w`` of itself per
    pixel aside), so non-maximum suppression on it as it is leaves parallel ridges a few
    pixels apart wherever the matcher's noise tips the balance. Smoothed over the matcher's
    own support, a Gaussian of the box's variance ``w^2 / 12`` (``s^2 / 12`` without a
    matcher), the ridge keeps its centre and loses the noise's false peaks.

    Examples
    --------
    >>> round(ridge_sigma(9, 9), 3), round(ridge_sigma(None, 6), 3)
    (2.598, 1.732)
    """
    return float(window or stride) / float(np.sqrt(12.0))


def strided_pairs(pairs: np.ndarray | None, valid: np.ndarray, stride: int) -> np.ndarray:
    """Broken neighbour pairs of the lattice of step ``stride``.

    ``out[a, i, j]``: the path from pixel (i, j) to (i, j) + stride * ``AXES[a]`` crosses a
    discontinuity (``pairs``) or an invalid pixel: a second difference over that step would
    straddle a jump or a gap (a dropout strand on a steep face), so it must not be taken.

    Parameters
    ----------
    pairs : (4, H, W) bool or None
        Broken unit pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`).
    valid : (H, W) bool
    stride : int
        Step, pixels (>= 1).

    Returns
    -------
    (4, H, W) bool
    """
    h, w = valid.shape
    s = int(stride)
    out = np.zeros((4, h, w), bool)
    invalid = np.pad(~np.asarray(valid, bool), s, constant_values=True)
    for a, (dr, dc) in enumerate(AXES):
        if pairs is not None:
            out[a] = segment_broken(pairs, a, 0, s)
        for k in range(1, s):
            out[a] |= invalid[s + k * dr:s + k * dr + h, s + k * dc:s + k * dc + w]
    return out


def strided_responses(
    z: np.ndarray,
    pairs: np.ndarray | None,
    stride: int,
    second_differences: Callable[..., list[np.ndarray]],
) -> list[np.ndarray]:
    """The four 3 x 3 operators dilated to step ``stride`` (a trous), NaN- and jump-aware.

    The operators at step ``s`` are the 3 x 3 ones on each of the ``s^2`` sub-lattices
    ``z[r::s, c::s]``: each is passed to ``second_differences`` (the exact rule of
    :func:`~rangesim.edges._gradient.second_differences`) with its own broken pairs
    (:func:`strided_pairs`), and the results are put back in place and divided by ``s``:
    like the 3 x 3 responses, a change of depth slope per pixel of length across the edge
    (mm / px), here between the chords from the centre to ``+-s`` pixels.

    Parameters
    ----------
    z : (H, W) float32
        Depth, NaN where invalid.
    pairs : (4, H, W) bool or None
        Broken unit pairs.
    stride : int
        Step, pixels (1 gives the 3 x 3 responses).
    second_differences : callable
        ``second_differences(z, pairs) -> list of 4 (h, w) arrays`` (passed in so this module
        needs nothing from the detector's).

    Returns
    -------
    list of 4 (H, W) float32
        Responses of the 0, 45, 90 and 135 degree operators, NaN where undefined.
    """
    s = int(stride)
    z = np.ascontiguousarray(z, np.float32)
    if s <= 1:
        return second_differences(z, pairs)
    h, w = z.shape
    broken = strided_pairs(pairs, np.isfinite(z), s)
    out = [np.full((h, w), np.nan, np.float32) for _ in range(4)]
    inv_s = np.float32(1.0 / s)
    for r in range(s):
        for c in range(s):
            sub = np.ascontiguousarray(z[r::s, c::s])
            if min(sub.shape) < 3:
                continue
            resp = second_differences(sub, np.ascontiguousarray(broken[:, r::s, c::s]))
            for o, rs_ in zip(out, resp):
                o[r::s, c::s] = rs_ * inv_s
    return out
