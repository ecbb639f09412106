"""line_fit on block-matched scans: the line test one matching window out.

Analysis layer: pure NumPy / scipy.ndimage over arrays.

A structured-light scanner's block matcher (:mod:`rangesim.edges._matching_scale`) returns
about the true surface smoothed by a ``window`` x ``window`` box, with errors correlated over
that window and heavy-tailed (patches of wrong matches). Its creases are rounded over the
window: the lines through a pixel drawn to its nearest neighbours, or a few pixels out,
stay within the rounding and see a fraction of the bend, under a noise that falls slowly
with the stride (:func:`~rangesim.edges._noise.stride_gain`). Here the paper's test is taken
at the matcher's scale:

* each pixel's four compass pairs of :mod:`~rangesim.edges._line_rings` are drawn ``s`` pixels
  out (``s`` = the window), one line each. A chord that meets invalid pixels skips over them
  (a dropout strand on a steep face is no edge of the surface); a chord that crosses a depth
  jump (a broken neighbour pair, or a step from the pixel of more than the jump rule allows
  over its length) is shortened to its last good end, down to :func:`min_reach`, else the line
  is not drawn;
* the bend of each line (180 degrees less the angle at the pixel) is divided by the share of
  a box-rounded crease's bend it sees where it actually crosses the crease
  (:func:`crossing_bends`: ``cos a * rounding_gain(w, reach |u| cos a)``, ``a`` the line's
  angle to the crease normal, estimated by the second harmonic of the four bends), an
  estimate of the surface's own bend;
* only the lines within 60 degrees of the normal are tested (:data:`CONE_COS`: three on an
  axis or a diagonal, two between), and not those the image frame cuts within ``s`` (the
  matcher's window is clipped there): the pixel has no two straight lines through it (the
  paper's edge) where every tested line is bent, i.e. the least of them exceeds the tolerance
  (that least, rounding-corrected, is the crease strength); a pixel with fewer than
  :data:`MIN_LINES` drawn lines or fewer than two tested is not tested;
* the tolerance is per line, in its own noise: its raw bend over the bend noise measured at
  its reach (:func:`bend_noise`: the robust RMS of depth's second differences at that lag
  over as many footprints, the estimator of :func:`~rangesim.edges._noise.stride_gain`) must
  exceed :func:`lines_k` of :data:`K_SL` and the number ``n`` of tested lines, which keeps a
  plane's false-crease rate the same for two lines as for three (with half-normal bends,
  ``P1(k_2) ** 2 = P1(k_3) ** 3``); and its rounding-corrected bend must exceed the
  noise-free :data:`FLOOR_DEG`;
* the bands this leaves (every pixel within about ``s - w / 2`` of a crease sees it) are
  thinned by non-maximum suppression across the crease (the compass axis of the largest
  bend) on the strength smoothed over the matcher's support
  (:func:`~rangesim.edges._matching_scale.ridge_sigma`).
"""
from __future__ import annotations

import numba
import numpy as np
from scipy.special import erfc, erfcinv

from rangesim.edges._grid import AXES, AXIS_ANGLES, pad_last2, padded_view
from rangesim.edges._matching_scale import ridge_sigma, rounding_gain
from rangesim.edges._pcl_scale import nan_gaussian
from rangesim.edges._trig import half_atan2

__all__ = ["sl_stride", "min_reach", "bend_noise", "sl_strength", "sl_tolerance", "sl_creases",
           "crossing_gain", "crossing_bends", "cone_strength", "lines_k", "CONE_COS", "GAIN_FLOOR",
           "K_SL", "MIN_LINES"]

#: the tolerance in RMS bends of one line at its reach, for the least of three tested lines
#: (:func:`lines_k` gives it for two: 1.97). On tuning seeds 0-7 (kinect_v1 and
#: structured_light_bench, noise-free / noise) 1.5 / 2 gave F1 0.742 / 0.720 / 0.739 / 0.733
#: and 0.711 / 0.665 / 0.735 / 0.726 (1.25, before the frame's lines were left out: 0.741 /
#: 0.724 / 0.736 / 0.728)
K_SL = 1.5
#: the least rounding-corrected bend of a crease (degrees), the noise-free tolerance
FLOOR_DEG = 15.0
#: lines a pixel needs for the test: with two, one bent line says little about whether a
#: second straight one exists (fewer: untested; jumps and rims are the jump rule's). 2 / 3 / 4
#: gave F1 0.70 / 0.71 / 0.71 on the tuning seeds, crease precision 0.62 / 0.70 / 0.73
MIN_LINES = 3


def sl_stride(window: int, stride: int | None = None) -> int:
    """The line test's stride on a block-matched scan: ``stride``, else the matcher's window."""
    return max(2, int(window if stride is None else stride))


def min_reach(stride: int) -> int:
    """The shortest chord (pixels) a line may have where a gap or a jump cuts it:
    ``ceil(s / 2)``, past the rounding's half-width at ``s`` = the window (a shorter chord from a
    crease pixel ends inside the rounding and sees little of the bend).

    Examples
    --------
    >>> min_reach(9), min_reach(4)
    (5, 2)
    """
    return max(1, (int(stride) + 1) // 2)


def bend_noise(z: np.ndarray, fp: np.ndarray, stride: int) -> float:
    """RMS bend (radians, a face seen head-on) of a line ``stride`` pixels either side of a
    pixel, measured on the depth: the second differences of depth at lag ``s`` over ``s``
    footprints, along rows and columns, every 4th line, within 4 robust sigmas (1.4826 MAD
    about 0) of their own (beyond are edges). The estimator of
    :func:`~rangesim.edges._noise.stride_gain` at one lag, not as a ratio: ``bend_noise(s) =
    bend_noise(1) * stride_gain(s)``. 0.0 with fewer than 100 differences.
    """
    z = np.asarray(z, np.float32)
    lag = int(stride)
    if 2 * lag >= min(z.shape):
        return 0.0
    zc, fc = z[:, ::4], fp[:, ::4]
    zr, fr = z[::4], fp[::4]
    with np.errstate(invalid="ignore", divide="ignore"):
        d0 = (zc[:-2 * lag] - 2 * zc[lag:-lag] + zc[2 * lag:]) / fc[lag:-lag]
        d1 = (zr[:, :-2 * lag] - 2 * zr[:, lag:-lag] + zr[:, 2 * lag:]) / fr[:, lag:-lag]
    d = np.abs(np.concatenate([d0[np.isfinite(d0)], d1[np.isfinite(d1)]]).astype(np.float64))
    if d.size < 100:
        return 0.0
    d = d[d <= 4 * 1.4826 * np.median(d)]
    return float(np.sqrt(np.mean(d * d)) / lag) if d.size else 0.0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _skip_bends(xyz, z, valid, broken, jump_mm, stride, min_reach):  # pragma: no cover - compiled
    """Bends (radians; NaN: no line) of each pixel's four compass lines and their reaches.

    The chord along ``AXES[a]`` forwards and backwards reaches the largest ``t`` in
    ``min_reach..stride`` whose end is valid, with no broken neighbour pair (``broken``,
    between valid pixels) on the way and a depth step from the pixel of at most ``t`` times
    its jump threshold ``jump_mm``; invalid pixels on the way are skipped over (a dropout
    strand on a continuous face). Returns ``(bends (4, H, W) float32, reach (4, H, W) int64)``,
    the reach being the shorter of the line's two chords.
    """
    h, w = valid.shape
    bends = np.full((4, h, w), np.nan, np.float32)
    reach = np.zeros((4, h, w), np.int64)
    for i in range(h):
        for j in range(w):
            if not valid[i, j]:
                continue
            px, py, pz = float(xyz[i, j, 0]), float(xyz[i, j, 1]), float(xyz[i, j, 2])
            for a in range(4):
                dr, dc = _AXES[a, 0], _AXES[a, 1]
                ends = np.zeros(2, np.int64)
                for g in range(2):
                    sg = 1 - 2 * g
                    best = 0
                    for t in range(1, stride + 1):
                        r, c = i + sg * t * dr, j + sg * t * dc
                        if r < 0 or r >= h or c < 0 or c >= w:
                            break
                        # the unit pair from the previous pixel to this one
                        pr, pc = (r - dr, c - dc) if sg == 1 else (r, c)
                        if broken[a, pr, pc]:
                            break
                        if not valid[r, c]:
                            continue
                        if abs(z[r, c] - z[i, j]) > t * jump_mm[i, j]:
                            break
                        if t >= min_reach:
                            best = t
                    ends[g] = best
                if ends[0] == 0 or ends[1] == 0:
                    continue
                r0, c0 = i + ends[0] * dr, j + ends[0] * dc
                r1, c1 = i - ends[1] * dr, j - ends[1] * dc
                a0, a1, a2 = xyz[r0, c0, 0] - px, xyz[r0, c0, 1] - py, xyz[r0, c0, 2] - pz
                b0, b1, b2 = xyz[r1, c1, 0] - px, xyz[r1, c1, 1] - py, xyz[r1, c1, 2] - pz
                cs = (a0 * b0 + a1 * b1 + a2 * b2) / np.sqrt((a0 * a0 + a1 * a1 + a2 * a2) * (b0 * b0 + b1 * b1 + b2 * b2))
                bends[a, i, j] = np.arccos(min(1.0, max(-1.0, -cs)))
                reach[a, i, j] = min(ends[0], ends[1])
    return bends, reach


_AXES = np.array(AXES, np.int64)


def sl_strength(bends: np.ndarray, min_lines: int = MIN_LINES) -> tuple[np.ndarray, np.ndarray]:
    """``(strength, across)``: the second least bend of each pixel's drawn lines, (H, W)
    float32, NaN where fewer than ``max(min_lines, 2)`` are drawn, and the axis index of its
    largest bend (the direction across a crease), (H, W) int.

    Examples
    --------
    >>> b = np.array([0.1, 0.9, 0.5, np.nan], np.float32).reshape(4, 1, 1)
    >>> s, a = sl_strength(b, 3)
    >>> round(float(s[0, 0]), 3), int(a[0, 0]), bool(np.isnan(sl_strength(b, 4)[0][0, 0]))
    (0.5, 1, True)
    """
    drawn = np.isfinite(bends)
    srt = np.sort(np.where(drawn, bends, np.inf), axis=0)
    strength = np.where(drawn.sum(axis=0) >= max(int(min_lines), 2), srt[1], np.nan)
    across = np.argmax(np.where(drawn, bends, -np.inf), axis=0)
    return strength.astype(np.float32), across


def sl_tolerance(noise_rad: float, window: int, stride: int, k: float = K_SL, floor_deg: float = 15.0) -> float:
    """The line test's tolerance (radians, on the rounding-corrected bend): ``k`` times the
    measured bend noise at the stride over :func:`~rangesim.edges._matching_scale.rounding_gain`,
    at least ``floor_deg``.

    Examples
    --------
    >>> round(float(np.degrees(sl_tolerance(0.1, 9, 9, 3.0))), 2)
    22.92
    >>> round(float(np.degrees(sl_tolerance(0.01, 9, 9, 3.0))), 2)
    15.0
    """
    return float(max(np.radians(floor_deg), k * noise_rad / rounding_gain(window, stride)))


#: least |cos| of a line's angle to the crease normal for the line to be tested: the lines
#: within 60 degrees of the normal (two between the compass axes, three on an axis or a
#: diagonal); a line nearer the crease sees too little of its bend to tell it from noise
CONE_COS = 0.5
#: least crossing gain a bend is divided by (a floor on the noise's amplification)
GAIN_FLOOR = 0.25
_AXIS_LEN = np.array([1.0, np.sqrt(2.0), 1.0, np.sqrt(2.0)], np.float32)


def crossing_gain(window: float, reach_px, cos_a):
    """The share of a box-rounded crease's bend seen by a line crossing it ``alpha`` off its
    normal with chords ``reach_px`` long (pixels, along the line): the slope change along the
    line is ``cos(alpha)`` of that across, and the chord reaches ``reach_px cos(alpha)`` across
    the rounded zone (``w / cos(alpha)`` of the line's length)."""
    w = float(window)
    sn = np.asarray(reach_px, np.float32) * cos_a
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(sn <= w / 2, sn / w, 1.0 - w / (4.0 * sn))
    return (cos_a * g).astype(np.float32)


def crossing_bends(bends: np.ndarray, reach: np.ndarray, window: int,
                   cone_cos: float = CONE_COS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each line's bend over its crossing gain, the crease normal's compass axis, and which
    lines lie within the cone about the normal.

    The crease normal ``phi`` (image angle) is the second harmonic of the four raw bends
    (a crease bends its across line most, its along line least): ``half_atan2(b1 - b3,
    b0 - b2)``. Line ``a`` meets it ``alpha = AXIS_ANGLES[a] - phi`` off the normal and is
    divided by :func:`crossing_gain` of its reach (times the axis' pixel length), at least
    :data:`GAIN_FLOOR`. Returns ``(corrected (4, H, W) float32, across (H, W) int,
    in_cone (4, H, W) bool)``.
    """
    b0 = np.where(np.isfinite(bends), bends, np.float32(0))
    phi = half_atan2(np.ascontiguousarray(b0[1] - b0[3]), np.ascontiguousarray(b0[0] - b0[2]))
    out = np.empty_like(bends)
    cone = np.empty(bends.shape, bool)
    for a in range(4):
        ca = np.abs(np.cos(np.float32(AXIS_ANGLES[a]) - phi)).astype(np.float32)
        g = crossing_gain(window, reach[a] * _AXIS_LEN[a], ca)
        out[a] = bends[a] / np.maximum(g, np.float32(GAIN_FLOOR))
        cone[a] = ca >= cone_cos
    across = np.rint(np.mod(phi, np.pi) / (np.pi / 4)).astype(np.int64) % 4
    return out, across, cone


def cone_strength(corrected: np.ndarray, cone: np.ndarray,
                  min_lines: int = MIN_LINES) -> tuple[np.ndarray, np.ndarray]:
    """``(strength, tested)``: the least corrected bend of the drawn lines within the cone
    about the crease normal, (H, W) float32, NaN where fewer than ``min_lines`` lines are
    drawn or fewer than two of the cone's are; and how many lines that least is taken over,
    (H, W) int."""
    drawn = np.isfinite(corrected)
    inc = drawn & cone
    st = np.min(np.where(inc, corrected, np.inf), axis=0)
    n = inc.sum(axis=0)
    ok = (drawn.sum(axis=0) >= max(int(min_lines), 2)) & (n >= 2)
    return np.where(ok, st, np.nan).astype(np.float32), n


def lines_k(k: float, n, ref: int = 3):
    """The tolerance multiple for the least of ``n`` tested lines that keeps a plane's false
    crease rate that of ``k`` over ``ref`` lines. Each line's bend on a plane is taken as
    independent half-normal noise, ``P1(t) = erfc(t / sqrt 2)`` in RMS bends; the least of
    ``n`` exceeds ``t`` with ``P1(t) ** n``, so equal rates need ``P1(k_n) ** n = P1(k) **
    ref``: ``k_n = sqrt 2 erfcinv(erfc(k / sqrt 2) ** (ref / n))``.

    Examples
    --------
    >>> round(float(lines_k(1.5, 3)), 3), round(float(lines_k(1.5, 2)), 3)
    (1.5, 1.97)
    """
    n = np.maximum(np.asarray(n, np.float64), 1.0)
    return np.sqrt(2.0) * erfcinv(erfc(k / np.sqrt(2.0)) ** (ref / n))


def _nms(ridge: np.ndarray, across: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``keep`` pixels whose ``ridge`` is at least that of both neighbours along ``AXES[across]``.

    NaN neighbours (gaps) do not suppress: on the tuning scans most true creases lie within
    2 px of a gap (a steep face's dropouts), and a pixel beside one keeps its crease.
    Interpolating the ridge over gaps instead raised the creases' precision (0.65 -> 0.87) but
    cost more recall (0.45 -> 0.31; F1 0.71 -> 0.70 on tuning seeds 0-7).
    """
    h, w = ridge.shape
    rp = pad_last2(ridge, 1, np.nan)
    out = keep.copy()
    for a, (dr, dc) in enumerate(AXES):
        sel = keep & (across == a)
        if not sel.any():
            continue
        for sgn in (1, -1):
            nb = padded_view(rp, 1, sgn * dr, sgn * dc, (h, w))
            with np.errstate(invalid="ignore"):
                out &= ~(sel & (nb > ridge))
    return out


def _frame_cut(shape: tuple[int, int], stride: int) -> np.ndarray:
    """(4, H, W) bool: the compass line through the pixel would leave the image within
    ``stride`` pixels (a chord cut by the frame, where the matcher's window is clipped)."""
    h, w = shape
    ii, jj = np.mgrid[:h, :w]
    ri, rj = np.minimum(ii, h - 1 - ii), np.minimum(jj, w - 1 - jj)
    big = np.full((h, w), stride, np.int64)
    out = np.empty((4, h, w), bool)
    for a, (dr, dc) in enumerate(AXES):
        out[a] = np.minimum(ri if dr else big, rj if dc else big) < stride
    return out


def sl_creases(xyz: np.ndarray, z: np.ndarray, valid: np.ndarray, pairs: np.ndarray | None,
               footprint: np.ndarray, jump_mm: np.ndarray, window: int, stride: int | None = None,
               k: float = K_SL, min_lines: int = MIN_LINES) -> tuple[np.ndarray, dict]:
    """Crease pixels of a block-matched scan by the line test at the matcher's scale (module
    docstring), thinned to the ridge of the smoothed strength.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm
    z : (H, W) float, depth, NaN where invalid
    valid : (H, W) bool
    pairs : (4, H, W) bool or None
        Broken neighbour pairs (depth discontinuities between valid pixels).
    footprint : (H, W) float
        Pixel footprint, mm.
    jump_mm : (H, W) float
        The jump rule's depth step per pixel, mm: a chord rising more per pixel crosses a jump.
    window : int
        The matcher's window, pixels.
    stride : int, optional
        The lines' half-length, pixels (default the window).
    k, min_lines
        :data:`K_SL`, :data:`MIN_LINES`.

    Returns
    -------
    crease : (H, W) bool
    info : dict
        ``stride``, ``tolerance_deg``, ``bend_noise`` (radians, at the stride),
        ``strength`` ((H, W) float32, rounding-corrected radians, NaN where untested).
    """
    s = sl_stride(window, stride)
    bends, reach = _skip_bends(
        np.ascontiguousarray(xyz, np.float32), np.ascontiguousarray(z, np.float32),
        np.ascontiguousarray(valid, np.bool_),
        np.ascontiguousarray(pairs if pairs is not None else np.zeros((4,) + z.shape, bool)),
        np.ascontiguousarray(np.broadcast_to(jump_mm, z.shape), np.float32), s, min_reach(s))
    corrected, across, cone = crossing_bends(bends, reach, window)
    strength, tested = cone_strength(corrected, cone, min_lines)
    noise = bend_noise(z, footprint, s)
    tol = sl_tolerance(noise, window, s, k)
    kn = lines_k(k, np.arange(5)).astype(np.float32)
    inc = np.isfinite(corrected) & cone & ~_frame_cut(z.shape, s)
    tested = inc.sum(axis=0)
    strength = np.where(np.isfinite(strength) & (tested >= 2),
                        np.min(np.where(inc, corrected, np.inf), axis=0), np.nan).astype(np.float32)
    lag_noise = np.array([noise] + [bend_noise(z, footprint, t) if t < s else noise
                                    for t in range(1, s + 1)], np.float32)
    raw_min = np.min(np.where(inc, bends / np.maximum(lag_noise[reach], np.float32(1e-9)), np.inf), axis=0)
    floor = np.float32(np.radians(FLOOR_DEG))
    ridge = nan_gaussian(strength, ridge_sigma(window, s))
    with np.errstate(invalid="ignore"):
        keep = (strength > floor) & (raw_min > kn[tested])
        crease = _nms(ridge, across, keep)
    return crease, {"stride": s, "tolerance_deg": float(np.degrees(tol)), "bend_noise": noise,
                    "strength": strength}
