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
from scipy import ndimage

from rangesim.core.errors import RangesimError
from rangesim.core.params import MAX_WINDOW_PX
from rangesim.core.quantisation import DEFAULT_MATCHER_WINDOW, disparity_lattice
from rangesim.edges._discontinuities import segment_broken
from rangesim.edges._grid import AXES

__all__ = ["disparity_lattice", "matching_window", "ridge_sigma", "rounding_gain", "strided_pairs", "strided_responses",
           "window_directions"]


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
        the :data:`DEFAULT_MATCHER_PRESET` preset, :data:`DEFAULT_MATCHER_WINDOW` (9). Off by default (the detectors do not
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
            return DEFAULT_MATCHER_WINDOW
    if not isinstance(sensor, dict) or sensor.get("mode") != "structured_light":
        return None
    window = (sensor.get("structured_light") or {}).get("window")
    try:
        window = int(window)
    except (TypeError, ValueError):
        return None
    if window > MAX_WINDOW_PX:  # (a sensor loaded through load_sensor never holds one: meta edited by hand)
        raise RangesimError(f"the scan's meta['sensor'] has structured_light.window = {window} px: the detectors "
                            f"take it as their scale, at most {MAX_WINDOW_PX} px")
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


def window_directions(direction: np.ndarray, mask: np.ndarray, window: int) -> np.ndarray:
    """Edge directions averaged over a block matcher's window.

    A block matcher's depth is the surface seen through a ``window`` x ``window`` box, and
    where it crosses a contour the box's pixels straddle both sides: the measured contour
    comes out ragged by a pixel or two along its length, and a 3 x 3 direction taken on it
    swings with each step of the rag (on the machined parts' kinect_v1 scans 25-43 % of a rim's
    edge pixels lie more than 25 degrees off its true normal). The contour's direction is
    only resolved at the window's scale. Each edge pixel's direction becomes the mean of the
    edge pixels' directions around it, as axes (angles doubled, so a normal and its
    opposite agree), under a Gaussian of ``window / 4`` px reaching ``window // 2`` px: the
    box's half-width.

    Parameters
    ----------
    direction : (H, W) float
        Edge-normal angles, radians, as axes (the sense ignored; NaN: none).
    mask : (H, W) bool
        Edge pixels: only they are averaged, and only theirs change.
    window : int
        Matcher window, pixels (odd; 1 or less: no matcher's box, nothing averaged).

    Returns
    -------
    (H, W) float32
        A copy of ``direction`` with the averaged axis, in [0, pi) as the gradient
        detector's, at every edge pixel that had one.

    Examples
    --------
    >>> d = np.zeros((9, 9)); d[4, 2:7] = [0.0, 0.4, -0.4, 0.4, 0.0]
    >>> m = np.zeros((9, 9), bool); m[4, 2:7] = True
    >>> out = window_directions(d, m, 9)
    >>> bool(np.abs(np.sin(out[4, 2:7])).max() < np.sin(0.4))   # nearer the contour's normal, 0
    True
    """
    direction = np.array(direction, np.float32)  # a copy: the caller's array is left as it is
    have = np.asarray(mask, bool) & np.isfinite(direction)
    h = int(window) // 2
    if h < 1 or not have.any():
        return direction
    sigma = float(window) / 4.0
    taps = np.exp(-0.5 * (np.arange(-h, h + 1) / sigma) ** 2).astype(np.float32)
    doubled = 2.0 * direction[have].astype(np.float64)   # trigonometry at the edge pixels only
    axes = []
    for values in (np.cos(doubled), np.sin(doubled)):
        part = np.zeros(direction.shape, np.float32)
        part[have] = values
        for axis in (0, 1):
            part = ndimage.correlate1d(part, taps, axis=axis, mode="constant")
        axes.append(part[have])
    mean = np.mod(0.5 * np.arctan2(axes[1], axes[0], dtype=np.float64), np.pi)
    direction[have] = mean
    direction[have & (direction >= np.float32(np.pi))] = 0.0  # pi - tiny rounds up to pi in float32
    return direction


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

