"""Thinning edge candidates: non-maximum suppression across the edge (Canny's thinning),
1-px 8-connected lines from staircases, and keeping creases clear of jumps.

Analysis layer: pure NumPy over arrays (image axes and directions:
:mod:`rangesim.edges._grid`).
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np
from scipy import ndimage

from rangesim.core.constants import FWHM_PER_SIGMA
from rangesim.core.params import MAX_WINDOW_PX
from rangesim.edges._grid import nonzero2

__all__ = ["nearest_axis", "nonmax_suppress", "ridge_offsets", "thin_staircases", "JUMP_CLEARANCE", "near_mask",
           "stripe_clearance", "hysteresis", "drop_specks", "SPECK_MAX_PX"]


def nearest_axis(direction: np.ndarray) -> np.ndarray:
    """Index (0..3) of the ``AXES`` nearest to each direction (radians, any range); int8."""
    d = np.where(np.isnan(direction), np.float32(0), direction)
    return np.rint(d * np.float32(4 / np.pi)).astype(np.int8) & 3


def _across(strength: np.ndarray, direction: np.ndarray, ii: np.ndarray, jj: np.ndarray,
            fill: float) -> tuple[np.ndarray, ...]:
    """The strength at pixels (ii, jj) and one step either side along ``direction``.

    Each side is interpolated linearly between the axis and the diagonal neighbour that
    bracket the direction (a step of 1 / max(|cos|, |sin|) px); ``fill`` stands for NaN and
    for what lies outside the image.

    Returns
    -------
    centre, minus, plus : (K,) float32
        Samples at the pixel, against ``direction`` and along it.
    theta : (K,) float
        The direction folded to [0, pi) (NaN: 0); (cos, sin) of it points to the plus side.
    step : (K,) float
        max(|cos theta|, |sin theta|): one step is 1 / step pixels.
    """
    d = direction[ii, jj]
    theta = np.mod(np.where(np.isnan(d), 0, d), np.pi)
    c, sn = np.abs(np.cos(theta)), np.sin(theta)          # sin >= 0 on [0, pi)
    xmajor = c >= sn
    step = np.maximum(c, sn)
    wgt = np.minimum(c, sn) / step                        # tan of the angle off the axis
    dx = np.where(theta > np.pi / 2, -1, 1)               # x component's sign
    # plus side: the axis neighbour (x or y) and the diagonal one bracketing the direction;
    # minus side: their mirror images (gathered sparsely: padding the image cost more)
    centre, pa, pd, ma, md = _gather_across(np.ascontiguousarray(strength, np.float32), ii, jj,
                                            xmajor, dx.astype(np.int64), np.float32(fill))
    plus = pa * (1 - wgt) + pd * wgt
    minus = ma * (1 - wgt) + md * wgt
    return centre, minus, plus, theta, step


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _gather_across(strength, ii, jj, xmajor, dx, fill):  # pragma: no cover - compiled
    """At each (ii, jj): the strength there, at the axis and diagonal neighbours on the plus
    side (axis: (0, dx) where ``xmajor``, else (1, 0); diagonal (1, dx)) and at their mirror
    images; ``fill`` outside the image and in place of NaN."""
    h, w = strength.shape
    k = ii.size
    out = np.empty((5, k), np.float32)
    for n in range(k):
        i, j, sx = ii[n], jj[n], dx[n]
        ar, ac = (0, sx) if xmajor[n] else (1, 0)
        for m, (di, dj) in enumerate(((0, 0), (ar, ac), (1, sx), (-ar, -ac), (-1, -sx))):
            r, c = i + di, j + dj
            v = strength[r, c] if 0 <= r < h and 0 <= c < w else fill
            out[m, n] = v if v == v else fill
    return out[0], out[1], out[2], out[3], out[4]


def nonmax_suppress(
    strength: np.ndarray,
    direction: np.ndarray,
    candidates: np.ndarray | None = None,
    return_sides: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep pixels that are maxima of ``strength`` across the edge (Canny's thinning).

    The strength one pixel away on either side along ``direction`` is interpolated
    linearly between the two neighbours that bracket it (an axis and a diagonal
    neighbour), so lines at any angle come out thin. A pixel survives if its strength is
    strictly above the minus side and at least the plus side: of a two-pixel plateau (an
    edge running between pixel centres) exactly one is kept. NaN strength never survives
    and counts as nothing beside a pixel.

    Parameters
    ----------
    strength : (H, W) float array
    direction : (H, W) float array
        Angle of the (x, y) vector across the edge, radians (any range; NaN: 0).
    candidates : (H, W) bool, optional
        Only these pixels are tested (e.g. those above a threshold; much faster when they
        are few); default all pixels with a finite strength.
    return_sides : bool
        Also return the kept pixels and the larger of the two interpolated side strengths
        at each (sparse: a full image of them cost more than the thinning).

    Returns
    -------
    keep : (H, W) bool
    kept : (K,) intp, only with ``return_sides``
        Flat indices of the kept pixels, ascending (``np.flatnonzero(keep)``).
    sides : (K,) float32, only with ``return_sides``
        The larger interpolated strength beside each kept pixel (NaN where there is none).
    """
    h, w = strength.shape
    if candidates is None:
        candidates = ~np.isnan(strength)
    ii, jj = nonzero2(candidates & ~np.isnan(strength))
    keep = np.zeros((h, w), bool)
    if ii.size == 0:
        return (keep, np.zeros(0, np.intp), np.zeros(0, np.float32)) if return_sides else keep
    low = np.float32(-1e30)                      # not -inf: 0 * -inf would be NaN
    s0, minus, plus, _, _ = _across(strength, direction, ii, jj, low)
    kept = (s0 > minus) & (s0 >= plus)
    keep[ii, jj] = kept
    if not return_sides:
        return keep
    side = np.maximum(plus[kept], minus[kept])
    return keep, ii[kept] * w + jj[kept], np.where(side > low / 2, side, np.nan).astype(np.float32)


def ridge_offsets(strength: np.ndarray, direction: np.ndarray, where: np.ndarray,
                  limit: float = 0.5, peak: str = "parabola", out: np.ndarray | None = None) -> np.ndarray:
    """Sub-pixel position of a ridge across its line: a parabola through three samples.

    At each pixel of ``where`` the strength is sampled as :func:`nonmax_suppress` samples
    it, at the pixel and one step either side along ``direction`` (each side interpolated
    linearly between the axis and diagonal neighbours that bracket it, a step of
    1 / max(|cos|, |sin|) px); the vertex of the parabola through the three is where the
    ridge most likely lies. A crease between two pixel centres gives both a response, the
    nearer the larger: the parabola moves the kept pixel towards the other.

    Parameters
    ----------
    strength : (H, W) float array
        The response the ridge was thinned on (NaN: undefined).
    direction : (H, W) float array
        Angle of the (x = column, y = row) vector across the ridge, radians (NaN: 0).
    where : (H, W) bool
        The pixels to place (the kept ridge pixels).
    limit : float
        Largest offset, pixels along ``direction``: a ridge pixel is the one nearest
        the ridge, so the ridge lies within half a step of it.
    peak : {"parabola", "triangle"}
        The ridge's shape. "parabola": the classic vertex, (m - p) / (2 (m - 2 s + p))
        steps (m, s, p the minus, centre and plus samples), right for a smoothed ridge.
        "triangle": (p - m) / (m + s + p) steps, exact for an unsmoothed second difference
        across a sampled roof, a triangle two samples wide (2 k (1 - f), 2 k f at a crease
        f px past the centre), where the parabola gives f / (4 - 6 f), half the way.

    Returns
    -------
    (H, W, 2) float32
        (dx, dy), pixels, from each pixel of ``where`` to the vertex; 0 elsewhere, and
        where a side sample is undefined (NaN, outside the image) or the three samples
        are not a maximum.
    out : (H, W, 2) float32, optional
        Offsets to add these to in place (float32 sums, as ``out += ridge_offsets(...)``
        at the placed pixels), saving a fresh image; returned.
    """
    if peak not in ("parabola", "triangle"):
        raise ValueError(f"peak must be 'parabola' or 'triangle', got {peak!r}")
    add = out is not None
    if out is None:
        out = np.zeros(strength.shape + (2,), np.float32)
    ii, jj = nonzero2(where & ~np.isnan(strength))
    if ii.size == 0:
        return out
    # the same samples as nonmax_suppress; a NaN side (a missing neighbour) stays NaN
    s0, minus, plus, theta, big = _across(strength, direction, ii, jj, np.nan)
    curv = minus - 2 * s0 + plus
    with np.errstate(invalid="ignore", divide="ignore"):
        # vertex in steps, times the step's length (1 / max(|cos|, |sin|) px)
        if peak == "parabola":
            t = (minus - plus) / (2 * curv) / big
        else:
            t = (plus - minus) / (minus + s0 + plus) / big
        # a NaN side (a missing neighbour) or a flat or valley-shaped triple: no move
        t = np.where(curv < 0, np.clip(t, -limit, limit), 0.0)
    t = np.nan_to_num(t, nan=0.0)
    # theta is in [0, pi): (cos, sin) with dx's sign is the plus side's unit vector
    dx, dy = (t * np.cos(theta)).astype(np.float32), (t * np.sin(theta)).astype(np.float32)
    if add:
        out[ii, jj, 0] += dx
        out[ii, jj, 1] += dy
    else:
        out[ii, jj, 0] = dx
        out[ii, jj, 1] = dy
    return out


def thin_staircases(mask: np.ndarray, droppable: np.ndarray | None = None, keep_corners: bool = False) -> np.ndarray:
    """Drop the inner corners of 2-px staircases, keeping 8-connectivity (1 px diagonals).

    Non-maximum suppression leaves diagonal edges as 4-connected staircases (a corner
    pixel at every step), which an 8-connected 1-px truth does not match one-to-one. A
    pixel is dropped when two of its 4-neighbours at a right angle (e.g. north and east)
    are set, the diagonal pixel between them is not (an L, not a 2x2 block), and the
    opposite 4-neighbours and diagonal are clear: the two stay 8-connected without it
    and nothing else depends on it. Pixels are removed in two passes by checkerboard
    parity, so two 4-adjacent pixels are never dropped together (a step's two corners).

    Parameters
    ----------
    mask : (H, W) bool
        Edge pixels (all of them count as neighbours).
    droppable : (H, W) bool, optional
        Only these may be dropped (default: all of ``mask``).
    keep_corners : bool
        Drop only a step's corner, one of whose two arms is a single pixel; a corner where
        two runs of 2 px or more meet (a box's outline seen square on, whose corner pixel an
        8-connected truth marks too) stays.

    Returns
    -------
    (H, W) bool
        The thinned mask (a new array).
    """
    h, w = mask.shape
    stride = w + 4                        # 2 px of padding: the arms' second pixels
    p = np.pad(mask, 2).ravel()
    cand = mask if droppable is None else (mask & droppable)
    ii, jj = nonzero2(cand)
    if ii.size == 0:
        return mask.copy()
    base = (ii + 2) * stride + (jj + 2)
    n, s, e, wst = -stride, stride, 1, -1
    # (a, b, their diagonal, opposite a, opposite b, opposite diagonal)
    corners = ((n, e, n + e, s, wst, s + wst), (e, s, s + e, wst, n, n + wst),
               (s, wst, s + wst, n, e, n + e), (wst, n, n + wst, e, s, s + e))
    parity = ((ii + jj) & 1).astype(bool)
    for ph in (False, True):
        b = base[parity == ph]
        drop = np.zeros(b.size, bool)
        for a_, b_, d_, oa, ob, od in corners:
            corner = p[b + a_] & p[b + b_] & ~p[b + d_] & ~p[b + oa] & ~p[b + ob] & ~p[b + od]
            if keep_corners:
                corner &= ~(p[b + 2 * a_] & p[b + 2 * b_])
            drop |= corner
        p[b[drop]] = False
    return p.reshape(h + 4, w + 4)[2:-2, 2:-2].copy()


#: no crease is kept within this many pixels of a jump: the crest beside an occluding edge
#: (and the surface just beyond it) is the jump itself, not a roof
JUMP_CLEARANCE = 2

#: light from across a step that still moves a stripe's peak: the sheet's Gaussian profile
#: beyond this many standard deviations (1 %, Phi(-2.326))
MIXING_SIGMAS = 2.326
#: sensor modes whose depth is a laser stripe's peak (:func:`stripe_clearance`)
_STRIPE_MODES = ("geometric", "rendered")


def stripe_clearance(scan: Any, footprint: np.ndarray, valid: np.ndarray) -> int:
    """Pixels beside a jump whose crease responses a laser stripe's width has made up.

    A stripe of Gaussian thickness (``laser.stripe_width`` the FWHM, sigma_w = FWHM / 2.355)
    straddling a step mixes the light of both surfaces in the peak
    (:mod:`rangesim.sensor.mixed_pixels`): a pixel ``d`` pixels from the step is moved while
    more than 1 % of the profile (:data:`MIXING_SIGMAS` sigma_w) lies beyond it, i.e. for
    ``d < MIXING_SIGMAS sigma_w / footprint`` (the stripe's image on a face square to the sheet;
    the mixing reaches further at grazing laser incidence, by up to 1 / cos of it). The jump's
    own pixel lies about half a pixel from the step, the k-th pixel beyond it k + 1/2: the
    mixed ones beyond the jump pixel are ``m = max(0, ceil(MIXING_SIGMAS sigma_w / fp - 3/2))``
    and a 3 x 3 operator sees one of them (or the jump pixel) up to ``m + 1`` px from the
    jump, the clearance returned. ``fp`` is the median footprint of the measured pixels.
    White Scanner (0.5 mm stripe, 0.27 mm footprints at its own resolution): 2; Cyberware
    (1 mm, 0.5 mm): 2; INRIA (1.5 mm, 1.45 mm: its stripe images under a pixel wide): 1; at
    most :data:`~rangesim.core.params.MAX_WINDOW_PX`. Scans without a laser stripe in
    ``meta["sensor"]`` (recordings read without a laser sensor, block-matched scans, whose
    matcher rounds a step over its window) keep :data:`JUMP_CLEARANCE`.
    """
    meta = getattr(scan, "meta", None) or {}
    sensor = meta.get("sensor") if isinstance(meta, dict) else None
    if not isinstance(sensor, dict) or sensor.get("mode") not in _STRIPE_MODES:
        return JUMP_CLEARANCE
    try:
        fwhm = float((sensor.get("laser") or {})["stripe_width"])
    except (KeyError, TypeError, ValueError):
        return JUMP_CLEARANCE
    fp = np.asarray(footprint, np.float64)
    fp = fp[np.asarray(valid, bool) & np.isfinite(fp)] if fp.ndim else fp
    if fp.size == 0 or not np.isfinite(fwhm) or fwhm < 0:
        return JUMP_CLEARANCE
    reach = MIXING_SIGMAS * fwhm / FWHM_PER_SIGMA / float(np.median(fp))
    return min(1 + max(0, int(np.ceil(reach - 1.5))), MAX_WINDOW_PX)


def near_mask(where: np.ndarray, ref: np.ndarray, r: int) -> np.ndarray:
    """True at pixels of ``where`` within chessboard distance ``r`` of a ``ref`` pixel.

    Sparse: only the pixels of ``where`` look at their (2r+1)^2 window (cheap when
    ``where`` is thin, e.g. edge candidates); False elsewhere. Compiled: rows without a
    pixel of ``where`` are skipped, windows clipped to the image (no padded copy of ``ref``).
    """
    if r <= 0:
        return np.zeros(where.shape, bool)
    return _near_mask(np.ascontiguousarray(where, np.bool_), np.ascontiguousarray(ref, np.bool_), int(r))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _near_mask(where, ref, r):  # pragma: no cover - compiled
    """:func:`near_mask`."""
    h, w = where.shape
    out = np.zeros((h, w), np.bool_)
    for i in range(h):
        row = where[i]
        n = 0
        for j in range(w):
            n += row[j]
        if n == 0:
            continue
        i0, i1 = max(i - r, 0), min(i + r + 1, h)
        for j in range(w):
            if not row[j]:
                continue
            j0, j1 = max(j - r, 0), min(j + r + 1, w)
            hit = False
            for a in range(i0, i1):
                for b in range(j0, j1):
                    if ref[a, b]:
                        hit = True
                        break
                if hit:
                    break
            out[i, j] = hit
    return out


def hysteresis(strength: np.ndarray, low: float | np.ndarray, high: float | np.ndarray) -> np.ndarray:
    """Pixels above ``low`` 8-connected to a pixel above ``high`` (Canny's edge tracing).

    Like :func:`skimage.filters.apply_hysteresis_threshold` but 8-connected, so thinned
    diagonal lines stay whole. ``low`` and ``high`` are numbers or per-pixel arrays; NaN
    strength counts as 0.
    """
    s = np.nan_to_num(strength, nan=0.0)
    weak = s > low
    labels, count = ndimage.label(weak, structure=np.ones((3, 3), bool))
    if count == 0:
        return weak
    strong = np.zeros(count + 1, bool)
    strong[np.unique(labels[s > high])] = True
    strong[0] = False
    return strong[labels]


#: crease fragments of at most this many pixels that touch no other edge pixel are dropped by
#: normal's single-threshold paths on noisy scans (:func:`drop_specks`): after NMS a crease is
#: a line, and a lone pixel or pair over one threshold is a noise excursion. Machined parts,
#: laser-stripe presets, noisy F1: tuning seeds 0-7 (inria_laser 20-29) +0.002-0.005, check
#: seeds 8-15 (30-39) +0.001-0.005 (3 px: within 0.001). Not on noise-free scans (there they
#: are small features: the Green Piece's F1 -0.002 / -0.006 with and without the stripe's
#: width), nor for gradient (tuning +0.001-0.009, but check seeds -0.002 to -0.013: its noisy
#: creases come in dashes along true edges), nor under hysteresis (which needs a strong pixel)
SPECK_MAX_PX = 2


def drop_specks(droppable: np.ndarray, mask: np.ndarray, max_px: int = SPECK_MAX_PX) -> np.ndarray:
    """``droppable`` without its pixels in 8-connected components of ``mask`` of at most
    ``max_px`` pixels that lie wholly in ``droppable``.

    Parameters
    ----------
    droppable : (H, W) bool
        Pixels that may go (creases).
    mask : (H, W) bool
        Every edge pixel (``droppable`` included); a fragment touching any other is kept.
    max_px : int
        Largest fragment dropped, pixels.

    Returns
    -------
    (H, W) bool
        The kept part of ``droppable``. Work follows the droppable pixels: each fragment is
        flooded until it holds ``max_px + 1`` pixels.
    """
    ii, jj = nonzero2(droppable)
    out = droppable.copy()
    if len(ii) and max_px >= 1:
        _drop_specks(np.ascontiguousarray(mask | droppable), np.ascontiguousarray(droppable), ii, jj, max_px, out)
    return out


@numba.njit(cache=True, nogil=True)
def _drop_specks(mask, droppable, ii, jj, max_px, out):  # pragma: no cover - compiled
    h, w = mask.shape
    seen = np.zeros((max_px + 1, 2), np.int64)
    for k in range(len(ii)):
        i0, j0 = ii[k], jj[k]
        if not out[i0, j0]:
            continue
        seen[0, 0], seen[0, 1] = i0, j0
        n, head, small = 1, 0, True
        while head < n and small:
            ci, cj = seen[head, 0], seen[head, 1]
            head += 1
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    ni, nj = ci + di, cj + dj
                    if (di == 0 and dj == 0) or ni < 0 or nj < 0 or ni >= h or nj >= w or not mask[ni, nj]:
                        continue
                    known = False
                    for m in range(n):
                        if seen[m, 0] == ni and seen[m, 1] == nj:
                            known = True
                            break
                    if known:
                        continue
                    if n == max_px or not droppable[ni, nj]:
                        small = False
                        break
                    seen[n, 0], seen[n, 1] = ni, nj
                    n += 1
                if not small:
                    break
        if small:
            for m in range(n):
                out[seen[m, 0], seen[m, 1]] = False
