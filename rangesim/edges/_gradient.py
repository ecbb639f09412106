"""Technique 1 of the founding paper: roof edges from four 3x3 second-derivative operators."""
from __future__ import annotations

import functools
from typing import Any

import numba
import numpy as np

from rangesim.core import params as P
from rangesim.core.constants import EdgeLabel
from rangesim.edges._differences import central_difference
from rangesim.edges._discontinuities import JUMP_THRESHOLD, discontinuities, with_gap_creases
from rangesim.edges._gradient_steps import step_smooth, tap5_sum
from rangesim.edges._grid import shift
from rangesim.edges._matching_scale import (
    matching_window,
    ridge_sigma,
    rounding_gain,
    strided_responses,
    window_directions,
)
from rangesim.edges._noise import (
    NOISE_FLOOR,
    NOISE_K_GRADIENT,
    NOISE_MEASURABLE,
    estimate_depth_noise,
    noise_threshold,
    raised_noise_threshold,
)
from rangesim.edges._scan_access import scan_depth
from rangesim.edges._thinning import (
    JUMP_CLEARANCE,
    near_mask,
    nonmax_suppress,
    ridge_offsets,
    stripe_clearance,
    thin_staircases,
)
from rangesim.edges._trig import above_tan_half, atan2, bend_degrees
from rangesim.edges.edgemap import RIM, EdgeMap

__all__ = ["gradient", "OPERATORS"]

_SQRT2 = np.float32(np.sqrt(2.0))

#: the paper's four operators as correlation kernels, keyed by the angle (degrees) of the
#: vector across the edge they respond to, in (x = column, y = row); the paper names them
#: by the edge's own orientation (its 0 degree operator, rows 1 1 1 / -2 -2 -2 / 1 1 1,
#: finds edges running along x, i.e. across-vector at 90 degrees here)
OPERATORS: dict[int, np.ndarray] = {
    0: np.array([[1, -2, 1], [1, -2, 1], [1, -2, 1]], np.float32),
    45: np.array([[1, 1, -2], [1, -2, 1], [-2, 1, 1]], np.float32),
    90: np.array([[1, 1, 1], [-2, -2, -2], [1, 1, 1]], np.float32),
    135: np.array([[-2, 1, 1], [1, -2, 1], [1, 1, -2]], np.float32),
}


#: largest smoothing sigma (px) done with a 5-tap kernel by slicing (else gaussian_filter)
SMALL_SIGMA = 1.25


def _taps5(sigma: float) -> tuple[np.float32, np.float32, np.float32]:
    """Centre, first and second weights of a 5-tap kernel of standard deviation ``sigma``.

    For sigma = 1 the binomial [1 4 6 4 1] / 16 (variance exactly 1); otherwise the
    sampled Gaussian on -2..2 with its outer weight raised so that the variance stays
    sigma^2 (truncation at 2 px would otherwise narrow it).
    """
    if abs(sigma - 1.0) < 1e-6:
        return np.float32(6 / 16), np.float32(4 / 16), np.float32(1 / 16)
    g = np.exp(-0.5 * (np.arange(3) / sigma) ** 2)
    g /= g[0] + 2 * g[1] + 2 * g[2]
    # w0 + 2 w1 + 2 w2 = 1 and 2 w1 + 8 w2 = sigma^2, w1 / w0 as the Gaussian's
    ratio = g[1] / g[0]
    w0 = (1 - sigma ** 2 / 4) / (1 + 2 * ratio - ratio / 2)
    w1 = ratio * w0
    w2 = (1 - w0 - 2 * w1) / 2
    return np.float32(w0), np.float32(w1), np.float32(w2)


def _smooth5(a: np.ndarray, sigma: float) -> np.ndarray:
    """Separable 5-tap smoothing of standard deviation ``sigma`` (:func:`_taps5`), zeros outside.

    A fraction of ``gaussian_filter``'s cost: two compiled passes. Two
    ``scipy.ndimage.correlate1d`` passes with the same taps agree to 1.2e-7.
    """
    w0, w1, w2 = _taps5(sigma)
    return _smooth5_rows_cols(np.ascontiguousarray(a, np.float32), w0, w1, w2)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _smooth5_rows_cols(a, w0, w1, w2):  # pragma: no cover - compiled
    """The two 5-tap passes of :func:`_smooth5`, float32 and zeros outside the image, each
    tap pair summed as ``((x-2 + x+2) w2 + (x-1 + x+1) w1) + w0 x`` (as ``_smooth5_at``)."""
    h, w = a.shape
    zero = np.float32(0)
    r = np.empty((h, w), np.float32)
    for i in range(h):
        row = a[i]
        for j in range(w):
            m2 = row[j - 2] if j >= 2 else zero
            m1 = row[j - 1] if j >= 1 else zero
            p1 = row[j + 1] if j + 1 < w else zero
            p2 = row[j + 2] if j + 2 < w else zero
            r[i, j] = ((m2 + p2) * w2 + (m1 + p1) * w1) + w0 * row[j]
    out = np.empty((h, w), np.float32)
    zrow = np.zeros(w, np.float32)
    for i in range(h):
        m2 = r[i - 2] if i >= 2 else zrow
        m1 = r[i - 1] if i >= 1 else zrow
        p1 = r[i + 1] if i + 1 < h else zrow
        p2 = r[i + 2] if i + 2 < h else zrow
        c = r[i]
        o = out[i]
        for j in range(w):
            o[j] = ((m2[j] + p2[j]) * w2 + (m1[j] + p1[j]) * w1) + w0 * c[j]
    return out


def _near(mask: np.ndarray, r: int, border: bool = True) -> np.ndarray:
    """Pixels within chessboard distance ``r`` of a ``mask`` pixel (or of the image border)."""
    if r <= 0:
        return np.array(mask, bool)
    return _dilate(np.ascontiguousarray(mask, np.bool_), int(r), bool(border))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _dilate(mask, r, border):  # pragma: no cover - compiled
    """:func:`_near`: OR over the (2r + 1)^2 window, separable (rows, then columns; shifted
    ORs on aligned slices, loops that vectorise; a third of the padded array form's time)."""
    h, w = mask.shape
    rows = np.empty((h, w), np.bool_)
    for i in range(h):
        m, rr = mask[i], rows[i]
        for j in range(w):
            rr[j] = m[j]
        for k in range(1, min(r, w - 1) + 1):
            dst, src = rr[k:w], m[0:w - k]
            for j in range(w - k):
                dst[j] |= src[j]
            dst, src = rr[0:w - k], m[k:w]
            for j in range(w - k):
                dst[j] |= src[j]
        if border:
            for j in range(min(r, w)):
                rr[j] = True
                rr[w - 1 - j] = True
    out = np.empty((h, w), np.bool_)
    for i in range(h):
        o = out[i]
        if border and (i < r or i >= h - r):
            o[:] = True
            continue
        src = rows[i]
        for j in range(w):
            o[j] = src[j]
        for k in range(max(0, i - r), min(h, i + r + 1)):
            if k != i:
                src = rows[k]
                for j in range(w):
                    o[j] |= src[j]
    return out


def _smooth5_at(a: np.ndarray, sigma: float, idx: np.ndarray) -> np.ndarray:
    """:func:`_smooth5` of ``a`` at the flat pixel indices ``idx`` only, to the last bit.

    The same products and sums in the same order as the dense passes, on the 5 x 5
    window of each pixel (zeros outside the image).
    """
    w0, w1, w2 = _taps5(sigma)
    h, w = a.shape
    stride = w + 4
    p = np.zeros((h + 4, w + 4), np.float32)
    p[2:-2, 2:-2] = a
    flat = p.ravel()
    r_, c_ = np.divmod(idx, w)
    base = (r_ + 2) * stride + (c_ + 2)
    rows = []
    for k in range(-2, 3):
        b = base + k * stride
        r = flat[b - 2] + flat[b + 2]
        r *= w2
        t = flat[b - 1] + flat[b + 1]
        t *= w1
        r += t
        r += w0 * flat[b]
        rows.append(r)
    out = rows[0] + rows[4]
    out *= w2
    t = rows[1] + rows[3]
    t *= w1
    out += t
    out += w0 * rows[2]
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _validity5_at(bad, idx, w0, w1, w2):  # pragma: no cover - compiled
    """``_smooth5_at((~bad).astype(np.float32), sigma, idx)`` to the bit (its operations in
    its order, on the validity read from ``bad``; zeros outside the image), compiled: no
    full-size validity image, no gathers."""
    h, w = bad.shape
    zero, one = np.float32(0), np.float32(1)
    out = np.empty(idx.size, np.float32)
    rows = np.empty(5, np.float32)
    v = np.empty(5, np.float32)
    for n in range(idx.size):
        i, j = idx[n] // w, idx[n] % w
        for k in range(5):
            ii = i + k - 2
            for m in range(5):
                jj = j + m - 2
                inside = ii >= 0 and ii < h and jj >= 0 and jj < w
                v[m] = one if inside and not bad[ii, jj] else zero
            rows[k] = tap5_sum(v, w0, w1, w2)
        out[n] = tap5_sum(rows, w0, w1, w2)
    return out


def _nan_gaussian(z: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing by normalised convolution; NaN stays NaN and never leaks.

    sigma <= :data:`SMALL_SIGMA` (the preset noise's choice, ~1 px) uses a 5-tap kernel of
    the same variance (:func:`_smooth5`); larger sigmas scipy's ``gaussian_filter``
    (truncated at 3 sigma).
    """
    bad = np.isnan(z)
    any_bad = bool(bad.any())
    z0 = np.array(z, np.float32)
    if any_bad:
        np.copyto(z0, 0, where=bad)
    if sigma <= SMALL_SIGMA:
        num = _smooth5(z0, sigma)
        # the weights of valid pixels sum to one constant except within 2 px of a gap or
        # the border: divide by it everywhere, and by each pixel's own sum only there
        # (the same value as smoothing the validity mask, for a fraction of the cost)
        interior = _smooth5(np.ones((5, 5), np.float32), sigma)[2, 2]
        idx = np.flatnonzero(_near(bad, 2) & ~bad)
        den = _validity5_at(bad, idx, *_taps5(sigma))
        with np.errstate(invalid="ignore", divide="ignore"):
            edge = num.ravel()[idx] / den
        num /= interior
        num.ravel()[idx] = edge
    else:
        from scipy.ndimage import gaussian_filter

        def smooth(a: np.ndarray) -> np.ndarray:
            # 3 sigma of kernel keeps 99.7 % of the weight, a quarter cheaper than scipy's 4
            return gaussian_filter(a, sigma, mode="constant", truncate=3.0)
        num = smooth(z0)
        den = smooth((~bad).astype(np.float32) if any_bad else np.ones(z.shape, np.float32))
        with np.errstate(invalid="ignore", divide="ignore"):
            num /= den
    if any_bad:
        np.copyto(num, np.nan, where=bad)
    return num


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _hessian_direction(r0, r45, r90, r135, mag):  # pragma: no cover - compiled
    """The Hessian (the four responses' 3x3 sums), ``half_atan2`` of its arctan2 terms and the direction in one
    pass, to the same bits: the direction across the edge (NaN where ``mag`` is) and whether
    the dominant eigenvalue is positive (the crease type), without the five full-size
    images of the three steps (on a shared VM a fresh image costs more than its arithmetic)."""
    h, w = r0.shape
    direction = np.empty((h, w), np.float32)
    positive = np.empty((h, w), np.bool_)
    zrow = np.zeros(w, np.float32)            # the rows beyond the image: zeros
    work = np.zeros((7, w + 2), np.float32)
    for i in range(h):
        up = i - 1 if i >= 1 else -1
        dn = i + 1 if i + 1 < h else -1
        _hessian_row(r0[up] if up >= 0 else zrow, r45[up] if up >= 0 else zrow, r90[up] if up >= 0 else zrow,
                     r135[up] if up >= 0 else zrow, r0[i], r45[i], r90[i], r135[i],
                     r0[dn] if dn >= 0 else zrow, r45[dn] if dn >= 0 else zrow, r90[dn] if dn >= 0 else zrow,
                     r135[dn] if dn >= 0 else zrow, mag[i], direction[i], positive[i], work)
    return direction, positive


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _nan0(v):  # pragma: no cover - compiled
    """``v``, 0 in place of NaN."""
    return v if v == v else np.float32(0)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _hessian_row(u0, u45, u90, u135, m0, m45, m90, m135, d0, d45, d90, d135, mag, direction, positive,
                 work):  # pragma: no cover - compiled
    """One row of :func:`_hessian_direction` from the responses of the rows above (``u*``), at
    (``m*``) and below it (``d*``; zeros beyond the image): column sums ``(up + mid) +
    down`` (NaN read as 0), then ``(left + centre) + right``, the eigen-terms, the arc
    tangent and the direction, each in a simple loop over the row (each vectorises; one loop
    with all of it did not). ``work``: (7, W + 2) float32 scratch, columns 0 and W + 1 zero."""
    w = m0.shape[0]
    zero = np.float32(0)
    k = np.float32(np.sqrt(2.0) / 6.0)
    two, half_f = np.float32(2), np.float32(0.5)
    quarter, half_turn = np.float32(np.pi / 2), np.float32(np.pi)
    nan = np.float32(np.nan)
    cxx, cyy, cxy, t2, dd, th, mn = work[0], work[1], work[2], work[3], work[4], work[5], work[6]
    for j in range(w):
        cxx[j + 1] = (_nan0(u0[j]) + _nan0(m0[j])) + _nan0(d0[j])
        cyy[j + 1] = (_nan0(u90[j]) + _nan0(m90[j])) + _nan0(d90[j])
        cxy[j + 1] = (_nan0(u45[j] - u135[j]) + _nan0(m45[j] - m135[j])) + _nan0(d45[j] - d135[j])
    for j in range(w):
        xx = (cxx[j] + cxx[j + 1]) + cxx[j + 2]
        yy = (cyy[j] + cyy[j + 1]) + cyy[j + 2]
        xy = ((cxy[j] + cxy[j + 1]) + cxy[j + 2]) * k
        m = (xx + yy) / two
        hd = (xx - yy) / two
        r = np.sqrt(hd * hd + xy * xy)
        minor = abs(m - r) > abs(m + r)
        mn[j] = np.float32(1) if minor else zero
        positive[j] = (m - r if minor else m + r) > zero
        t2[j] = two * xy
        dd[j] = xx - yy
    for j in range(w):
        th[j] = half_f * np.float32(atan2(np.float64(t2[j]), np.float64(dd[j])))
    for j in range(w):
        t = th[j] + quarter if mn[j] != zero else th[j] + zero
        t = t + half_turn if t < 0 else t
        direction[j] = nan if np.isnan(mag[j]) else t


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _scale_and_magnitude(r0, r45, r90, r135, scale):  # pragma: no cover - compiled
    """Multiply the four responses by ``scale`` in place and return ``fmax`` of their absolute
    values (NaN only where all four are NaN), float32."""
    h, w = r0.shape
    mag = np.empty((h, w), np.float32)
    for i in range(h):
        _scale_mag_row(r0[i], r45[i], r90[i], r135[i], scale[i], mag[i])
    return mag


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _scale_mag_row(r0, r45, r90, r135, scale, mag):  # pragma: no cover - compiled
    """One row of :func:`_scale_and_magnitude`."""
    for j in range(r0.shape[0]):
        f = scale[j]
        a, b, c, d = r0[j] * f, r45[j] * f, r90[j] * f, r135[j] * f
        r0[j], r45[j], r90[j], r135[j] = a, b, c, d
        m = abs(a)
        for v in (abs(b), abs(c), abs(d)):
            if m != m or v > m:
                m = v
        mag[j] = m


def second_differences(z: np.ndarray, pairs: np.ndarray | None = None,
                       skip: np.ndarray | None = None) -> list[np.ndarray]:
    """The four operators' responses, NaN-aware, each normalised to a slope change.

    Every operator is a sum of three-point second differences ``a - 2c + b`` across the
    edge direction: three parallel ones (rows or columns, step 1) for the 0 and 90 degree
    operators; for the diagonal ones the diagonal through the centre (step sqrt 2) and the
    remaining six taps, which form one linear-exact group (two L-shaped half-step
    differences). A part is used only if all its pixels are valid, so a NaN hole never
    makes a response, and only if no two consecutive pixels of it lie across a depth
    discontinuity (``pairs``), so a step makes none; the response is the sum of the valid
    parts over the sum of their steps, i.e. the change of depth slope per pixel of length
    across the edge (mm / px)
    for a crease through the centre pixel. Needed: 2 of the 3 parts (axes) or 1 of the
    2 (diagonals); planes give 0 in every part (up to perspective, 2 z tan^2(phi) / f^2
    for a plane at slant phi).

    Parameters
    ----------
    z : (H, W) float32
        Depth, NaN where invalid.
    pairs : (4, H, W) bool, optional
        Discontinuity pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`).
    skip : (H, W) bool, optional
        Pixels whose responses the caller discards (e.g. too near a jump): left undefined.

    Returns
    -------
    list of 4 (H, W) float32
        Responses of the 0, 45, 90 and 135 degree operators (across-vector angles), NaN at
        invalid pixels and where too few parts are valid.

    Notes
    -----
    Computed densely as the plain operators, then redone exactly (sparsely) at the pixels
    whose 3x3 window holds a NaN or touches a broken pair; both give the same bits.
    """
    h, w = z.shape
    z = np.ascontiguousarray(z, np.float32)
    # Every pixel first as if its whole 3x3 window were valid and unbroken: the plain
    # operators (compiled, one pass), in the same order of operations as the exact rule
    # below. A NaN anywhere in the window makes them NaN, and a broken pair can only lie in
    # the window of a pixel next to it: those pixels (a few percent) are redone exactly.
    out = list(_plain_second_differences(z, 1))
    # redone where the plain response is NaN or the window touches a pair: valid pixels not
    # skipped (in place, one compiled pass)
    use_skip = skip is not None
    _exact_where_needed(z, *_pairs_arg(pairs), np.ascontiguousarray(skip) if use_skip else np.zeros((1, 1), bool),
                        use_skip, *out)
    return out


def _pairs_arg(pairs: np.ndarray | None) -> tuple[np.ndarray, bool]:
    """``pairs`` and whether there are any, as :func:`_exact_at` takes them."""
    if pairs is None:
        return np.zeros((4, 1, 1), bool), False
    return pairs, True


def sampled_second_differences(z: np.ndarray, pairs: np.ndarray | None, skip: np.ndarray | None,
                               step: int) -> list[np.ndarray]:
    """:func:`second_differences` on every ``step``-th row and column only: the dense
    responses' ``[::step, ::step]`` to the bit, for about ``1 / step^2`` of the work (the
    noise search samples its medians so)."""
    h, w = z.shape
    z = np.ascontiguousarray(z, np.float32)
    out = list(_plain_second_differences(z, step))
    sub = (slice(None, None, step), slice(None, None, step))
    redo = np.isnan(out[0])
    if pairs is not None:
        any_pair = pairs[0] | pairs[1]
        any_pair |= pairs[2]
        any_pair |= pairs[3]
        # _near(any_pair, 1, border=False) at the samples: a pair in the 3 x 3 window
        pp = np.pad(any_pair, 1, constant_values=False)
        hs, ws = redo.shape
        for dr in range(3):
            for dc in range(3):
                redo |= pp[dr:dr + h:step, dc:dc + w:step][:hs, :ws]
    redo &= ~np.isnan(z[sub])
    if skip is not None:
        redo &= ~skip[sub]
    ri, ci = np.nonzero(redo)
    if ri.size:
        _exact_at(z, *_pairs_arg(pairs), ri, ci, step, *out)
    return out


def _plain_second_differences(z: np.ndarray, step: int) -> tuple[np.ndarray, ...]:
    """The four operators at every ``step``-th row and column (1: every pixel) as if the 3x3
    window were valid and unbroken (float32, the exact rule's order of operations; NaN on
    the image border): :func:`_plain_dense` at every pixel, else :func:`_plain_strided`."""
    if step == 1 and z.shape[0] >= 3 and z.shape[1] >= 3:
        return _plain_dense(z)
    return _plain_strided(z, step)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _plain_strided(z, step):  # pragma: no cover - compiled
    """:func:`_plain_second_differences` at every ``step``-th row and column."""
    h, w = z.shape
    hs, ws = (h + step - 1) // step, (w + step - 1) // step
    two, three, two_steps = np.float32(2), np.float32(3), np.float32(2) * _SQRT2
    r0 = np.full((hs, ws), np.nan, np.float32)
    r45 = np.full((hs, ws), np.nan, np.float32)
    r90 = np.full((hs, ws), np.nan, np.float32)
    r135 = np.full((hs, ws), np.nan, np.float32)
    for a in range(hs):
        i = a * step
        if i < 1 or i >= h - 1:
            continue
        up, mid, dn = z[i - 1], z[i], z[i + 1]
        for b in range(ws):
            j = b * step
            if j < 1 or j >= w - 1:
                continue
            nw, n, ne = up[j - 1], up[j], up[j + 1]
            west, c, e = mid[j - 1], mid[j], mid[j + 1]
            sw, s, se = dn[j - 1], dn[j], dn[j + 1]
            r0[a, b] = ((((nw - two * n) + ne) + ((west - two * c) + e)) + ((sw - two * s) + se)) / three
            r90[a, b] = ((((nw - two * west) + sw) + ((n - two * c) + s)) + ((ne - two * e) + se)) / three
            c2 = two * c
            s4 = ((n + west) + e) + s
            r45[a, b] = (((nw - c2) + se) + (s4 - (ne + sw) * two)) / two_steps
            r135[a, b] = (((ne - c2) + sw) + (s4 - (nw + se) * two)) / two_steps
    return r0, r45, r90, r135


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _plain_dense(z):  # pragma: no cover - compiled
    """:func:`_plain_second_differences` at every pixel (``step`` 1, at least 3 x 3): the same
    operations on row slices aligned to the output, so that no index is offset and the
    compiler vectorises the loop (2-3x faster than the strided loop)."""
    h, w = z.shape
    # four images, not one (4, H, W) block: a block that size is mapped fresh on every call
    r0, r45 = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
    r90, r135 = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
    for i in range(h):
        _plain_row(z, i, r0[i], r45[i], r90[i], r135[i])
    return r0, r45, r90, r135


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _plain_row(z, i, o0, o45, o90, o135):  # pragma: no cover - compiled
    """Row ``i`` of :func:`_plain_dense` (NaN on the image's border)."""
    h, w = z.shape
    two, three, two_steps = np.float32(2), np.float32(3), np.float32(2) * _SQRT2
    nan = np.float32(np.nan)
    if i < 1 or i >= h - 1:
        for o in (o0, o45, o90, o135):
            o[:] = nan
        return
    up, mid, dn = z[i - 1], z[i], z[i + 1]
    nw, n, ne = up[0:w - 2], up[1:w - 1], up[2:w]
    we, c, e = mid[0:w - 2], mid[1:w - 1], mid[2:w]
    sw, s, se = dn[0:w - 2], dn[1:w - 1], dn[2:w]
    p0, p45, p90, p135 = o0[1:w - 1], o45[1:w - 1], o90[1:w - 1], o135[1:w - 1]
    for k in range(w - 2):
        p0[k] = ((((nw[k] - two * n[k]) + ne[k]) + ((we[k] - two * c[k]) + e[k]))
                 + ((sw[k] - two * s[k]) + se[k])) / three
        p90[k] = ((((nw[k] - two * we[k]) + sw[k]) + ((n[k] - two * c[k]) + s[k]))
                  + ((ne[k] - two * e[k]) + se[k])) / three
        c2 = two * c[k]
        s4 = ((n[k] + we[k]) + e[k]) + s[k]
        p45[k] = (((nw[k] - c2) + se[k]) + (s4 - (ne[k] + sw[k]) * two)) / two_steps
        p135[k] = (((ne[k] - c2) + sw[k]) + (s4 - (nw[k] + se[k]) * two)) / two_steps
    for o in (o0, o45, o90, o135):
        o[0] = nan
        o[w - 1] = nan


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _px(z, i, j):  # pragma: no cover - compiled
    """``z[i, j]``, NaN outside the image (the padding of the array form)."""
    # (no chained comparison: Numba compiles ``0 <= i < h`` some ten times slower)
    h, w = z.shape
    if i >= 0 and i < h and j >= 0 and j < w:
        return z[i, j]
    return np.float32(np.nan)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _broken(pairs, use_pairs, a, i, j):  # pragma: no cover - compiled
    """``pairs[a, i, j]``, False outside the image or without pairs."""
    if not use_pairs:
        return False
    _, h, w = pairs.shape
    if i >= 0 and i < h and j >= 0 and j < w:
        return pairs[a, i, j]
    return False


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _part(v, cut):  # pragma: no cover - compiled
    """A stencil part, NaN where one of its steps crosses a discontinuity."""
    return np.float32(np.nan) if cut else v


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _exact_at(z, pairs, use_pairs, rows, cols, step, r0, r45, r90, r135):  # pragma: no cover - compiled
    """The exact rule of :func:`second_differences` (``tests/gradient_reference.py``'s array form, the same
    float32 operations in the same order: the same bits) at the pixels ``(rows, cols) *
    step`` of ``z``, written to ``r*[rows, cols]`` (one compiled pass instead of some hundred
    NumPy calls on gathered copies: 4 ms -> well under 1 at 1024^2)."""
    for n in range(rows.size):
        a, b = rows[n], cols[n]
        r0[a, b], r45[a, b], r90[a, b], r135[a, b] = _exact_px(z, pairs, use_pairs, a * step, b * step)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _exact_where_needed(z, pairs, use_pairs, skip, use_skip, r0, r45, r90, r135):  # pragma: no cover - compiled
    """:func:`second_differences`' redo step in place, in one pass: at the pixels whose
    plain response is NaN or whose 3 x 3 window touches a broken pair (``pairs[a, i, j]``
    of any axis), that are valid and not ``skip``, the exact rule (:func:`_exact_px`).
    The pixels are flagged a row at a time by loops that vectorise (no mask images, no
    index arrays) and visited in blocks of 32 that hold one."""
    h, w = z.shape
    work = np.zeros((5, w), np.uint8)
    if use_pairs:
        _any_pair_row(pairs, 0, work[0])
    for i in range(h):
        _redo_row(z, pairs, use_pairs, skip, use_skip, i, work, r0[i], r45[i], r90[i], r135[i])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _redo_row(z, pairs, use_pairs, skip, use_skip, i, work, o0, o45, o90, o135):  # pragma: no cover - compiled
    """Row ``i`` of :func:`_exact_where_needed` (``o*``: the plain responses of the row, redone
    in place). ``work`` (5, W) uint8: rows 0-2 a ring of the any-axis pairs of rows i - 1, i,
    i + 1 (mod 3; row ``i``'s and the one above filled already, the one below filled here),
    rows 3-4 scratch."""
    h, w = z.shape
    col, fm = work[3], work[4]
    # broken pairs in rows i - 1..i + 1, per column, then over columns j - 1..j + 1
    col[:] = 0
    if use_pairs:
        if i + 1 < h:
            _any_pair_row(pairs, i + 1, work[(i + 1) % 3])
        for r in range(max(i - 1, 0), min(i + 2, h)):
            rr = work[r % 3]
            for j in range(w):
                col[j] |= rr[j]
    for j in range(w):
        fm[j] = col[j]
    right, left_col = fm[1:w], col[0:w - 1]      # (aligned slices: vectorises)
    for j in range(w - 1):
        right[j] |= left_col[j]                   # a pair one column left
    left_px, right_col = fm[0:w - 1], col[1:w]
    for j in range(w - 1):
        left_px[j] |= right_col[j]                # one column right
    zr = z[i]
    for j in range(w):
        fm[j] = (fm[j] | (o0[j] != o0[j])) & (zr[j] == zr[j])
    if use_skip:
        sk = skip[i]
        for j in range(w):
            fm[j] = 0 if sk[j] else fm[j]
    left = 0
    for j in range(w):
        left += fm[j]
    for c0 in range(0, w, 32):
        if left == 0:
            break
        c1 = min(c0 + 32, w)
        n = 0
        for j in range(c0, c1):
            n += fm[j]
        if n == 0:
            continue
        left -= n
        for j in range(c0, c1):
            if fm[j]:
                o0[j], o45[j], o90[j], o135[j] = _exact_px(z, pairs, use_pairs, i, j)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _streamed_responses(z, pairs, use_pairs, scale):  # pragma: no cover - compiled
    """:func:`second_differences` (no skip), :func:`_scale_and_magnitude` and
    :func:`_hessian_direction` streamed a row at a time, to the same bits: the four responses
    live in a ring of three rows, never as images (16 MB at 1024^2 that a VM maps fresh on
    every call). Returns ``mag``, ``direction`` and ``positive`` as those do."""
    h, w = z.shape
    ring = np.empty((3, 4, w), np.float32)    # scaled responses of rows i - 1, i, i + 1 (mod 3)
    zrow = np.zeros(w, np.float32)
    mag = np.empty((h, w), np.float32)
    direction = np.empty((h, w), np.float32)
    positive = np.empty((h, w), np.bool_)
    work = np.zeros((5, w), np.uint8)
    hwork = np.zeros((7, w + 2), np.float32)
    skip = np.zeros((1, 1), np.bool_)
    if use_pairs:
        _any_pair_row(pairs, 0, work[0])
    for i in range(h + 1):
        if i < h:
            rr = ring[i % 3]
            _plain_row(z, i, rr[0], rr[1], rr[2], rr[3])
            _redo_row(z, pairs, use_pairs, skip, False, i, work, rr[0], rr[1], rr[2], rr[3])
            _scale_mag_row(rr[0], rr[1], rr[2], rr[3], scale[i], mag[i])
        if i >= 1:
            c = i - 1                          # the row whose Hessian has all its rows now
            m = ring[c % 3]
            u = ring[(c - 1) % 3]
            d = ring[(c + 1) % 3]
            has_u, has_d = c >= 1, c + 1 < h
            _hessian_row(u[0] if has_u else zrow, u[1] if has_u else zrow, u[2] if has_u else zrow,
                         u[3] if has_u else zrow, m[0], m[1], m[2], m[3],
                         d[0] if has_d else zrow, d[1] if has_d else zrow, d[2] if has_d else zrow,
                         d[3] if has_d else zrow, mag[c], direction[c], positive[c], hwork)
    return mag, direction, positive


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _any_pair_row(pairs, i, out):  # pragma: no cover - compiled
    """``out[j]`` = a pair of any axis broken at (i, j)."""
    p0, p1, p2, p3 = pairs[0, i], pairs[1, i], pairs[2, i], pairs[3, i]
    for j in range(out.size):
        out[j] = (p0[j] | p1[j]) | (p2[j] | p3[j])


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _exact_px(z, pairs, use_pairs, i, j):  # pragma: no cover - compiled
    """The four responses of the exact rule at pixel (i, j) (see :func:`_exact_at`)."""
    zero, two = np.float32(0), np.float32(2)
    sq2 = _SQRT2
    nw, no, ne = _px(z, i - 1, j - 1), _px(z, i - 1, j), _px(z, i - 1, j + 1)
    we, c, ea = _px(z, i, j - 1), z[i, j], _px(z, i, j + 1)
    sw, so, se = _px(z, i + 1, j - 1), _px(z, i + 1, j), _px(z, i + 1, j + 1)
    # 0 deg: the three rows' second differences, 2 of 3 needed
    total, count = zero, 0
    for k in range(3):
        ii = i + k - 1
        a, b, d = _px(z, ii, j - 1), _px(z, ii, j), _px(z, ii, j + 1)
        part = _part((a - two * b) + d, _broken(pairs, use_pairs, 0, ii, j - 1)
                     or _broken(pairs, use_pairs, 0, ii, j))
        ok = part == part
        total += part if ok else zero
        count += ok
    v0 = total / np.float32(count) if count >= 2 else np.float32(np.nan)
    # 90 deg: the three columns'
    total, count = zero, 0
    for k in range(3):
        jj = j + k - 1
        a, b, d = _px(z, i - 1, jj), _px(z, i, jj), _px(z, i + 1, jj)
        part = _part((a - two * b) + d, _broken(pairs, use_pairs, 2, i - 1, jj)
                     or _broken(pairs, use_pairs, 2, i, jj))
        ok = part == part
        total += part if ok else zero
        count += ok
    v90 = total / np.float32(count) if count >= 2 else np.float32(np.nan)
    c2 = two * c
    s4 = ((no + we) + ea) + so
    # 45 deg: the centre diagonal nw-se and the two L's through ne and sw
    centre = _part((nw - c2) + se, _broken(pairs, use_pairs, 1, i - 1, j - 1)
                   or _broken(pairs, use_pairs, 1, i, j))
    ell = _part(s4 - two * (ne + sw), _broken(pairs, use_pairs, 0, i - 1, j)
                or _broken(pairs, use_pairs, 2, i - 1, j + 1) or _broken(pairs, use_pairs, 2, i, j - 1)
                or _broken(pairs, use_pairs, 0, i + 1, j - 1))
    v45 = _diagonal(centre, ell, sq2)
    # 135 deg: the centre diagonal ne-sw and the two L's through nw and se
    centre = _part((ne - c2) + sw, _broken(pairs, use_pairs, 3, i - 1, j + 1)
                   or _broken(pairs, use_pairs, 3, i, j))
    ell = _part(s4 - two * (nw + se), _broken(pairs, use_pairs, 0, i - 1, j - 1)
                or _broken(pairs, use_pairs, 2, i - 1, j - 1) or _broken(pairs, use_pairs, 2, i, j + 1)
                or _broken(pairs, use_pairs, 0, i + 1, j))
    v135 = _diagonal(centre, ell, sq2)
    return v0, v45, v90, v135


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _diagonal(centre, ell, sq2):  # pragma: no cover - compiled
    """A diagonal operator from its two parts (step sqrt 2 each), NaN if neither is valid:
    ``(0 + parts) / (count * sqrt 2)``, as the array form."""
    zero = np.float32(0)
    total = zero
    count = 0
    if centre == centre:
        total += centre
        count += 1
    else:
        total += zero
    if ell == ell:
        total += ell
        count += 1
    else:
        total += zero
    if count == 0:
        return np.float32(np.nan)
    return total / (np.float32(count) * sq2)


#: the strided operators' half-width over the block matcher's window (see :func:`matching_stride`)
MATCHING_STRIDE_WINDOWS = 1.0


#: grid (px) of the smoothing candidates :func:`crease_sigma` tries below the noise rule's sigma
SIGMA_STEP = 0.25
#: a smaller smoothing must find creases this much gentler (relative) to be chosen: the
#: noise medians it compares scatter by a few percent from scan to scan
SIGMA_MARGIN = 0.05


@functools.lru_cache(maxsize=64)
def smoothing_gain(sigma: float) -> float:
    """The share of a crease's slope change that the operators' ridge sees after smoothing.

    A roof whose slope changes by ``D`` (per pixel, across it), smoothed by the detector's
    own kernel of standard deviation ``sigma`` (:func:`_nan_gaussian`: 5 taps up to
    :data:`SMALL_SIGMA`, else a Gaussian truncated at 3 sigma), turns its slope over about
    4 sigma pixels, so the 3-tap second difference at the crease plus its larger neighbour
    across it (the ridge :func:`gradient` sums) see only part of ``D``. Measured on a
    sampled 1-D roof at crease offsets 0, 1/4, 1/2 and 3/4 px from a pixel centre (mean);
    as :func:`~rangesim.edges._matching_scale.rounding_gain` for a block matcher's box.

    Parameters
    ----------
    sigma : float
        Smoothing standard deviation, pixels (0 or less: none, gain 1).

    Returns
    -------
    float
        Gain, dimensionless, in (0, 1].

    Examples
    --------
    >>> round(smoothing_gain(0.0), 3), round(smoothing_gain(1.0), 3), round(smoothing_gain(3.0), 3)
    (1.0, 0.625, 0.259)
    """
    if sigma <= 0:
        return 1.0
    x = np.arange(-40, 41, dtype=np.float64)
    rows = 2 * int(np.ceil(3 * sigma)) + 3           # the kernel's reach either side of the middle row
    seen = []
    for c in (0.0, 0.25, 0.5, 0.75):
        z = np.maximum(x - c, 0.0)                     # a roof of slope change 1 per pixel
        # smoothed by the detector's own kernel (constant down the columns: the middle row
        # is the 1-D smoothing; the roof's ends lie beyond the kernel's reach of its crease)
        zs = _nan_gaussian(np.tile(z.astype(np.float32), (rows, 1)), sigma)[rows // 2].astype(np.float64)
        d = zs[:-2] - 2 * zs[1:-1] + zs[2:]
        i = int(np.argmax(d))
        seen.append(d[i] + max(d[i - 1], d[i + 1]))    # the ridge: peak and larger neighbour
    return float(np.mean(seen))


def _near_jump(touching: np.ndarray, sigma: float) -> np.ndarray:
    """Pixels within ``ceil(2 sigma)`` px (4-connected steps) of a discontinuity's pixels:
    smoothing drags a step's slope out by ~2 sigma, so no responses that close to one."""
    near = touching
    for _ in range(int(np.ceil(2 * sigma))):
        near = near | shift(near, 1, 0, False) | shift(near, -1, 0, False)
        near = near | shift(near, 0, 1, False) | shift(near, 0, -1, False)
    return near


def _noise_bends(z: np.ndarray, pairs: np.ndarray, touching: np.ndarray, inv_fp: np.ndarray,
                 valid: np.ndarray, sigma: float) -> np.ndarray:
    """The noise's bend ``2 atan(response)`` (degrees of bend estimate) at smoothing ``sigma``
    on every 4th row and column of valid pixels, the responses as :func:`gradient` has them
    (NaN within ``ceil(2 sigma)`` px of a jump, dropped here)."""
    zs = _nan_gaussian(z, sigma) if sigma > 0 else z
    near = _near_jump(touching, sigma)
    # the operators at the sampled pixels only (the dense responses' [::4, ::4] to the bit)
    resp = sampled_second_differences(zs, pairs, near, 4)
    mag = np.abs(resp[0])
    for r in resp[1:]:
        np.fmax(mag, np.abs(r), out=mag)
    mag *= np.where(near[::4, ::4], np.float32(np.nan), inv_fp[::4, ::4])
    bend = np.degrees(2 * np.arctan(mag))
    return bend[valid[::4, ::4] & np.isfinite(bend)]


#: images larger than this (pixels) search their smoothing on tiles (:func:`_search_tiles`)
SEARCH_PIXELS = 512 * 512
#: side and spacing (pixels) of those tiles: a quarter of the image, every other tile
SEARCH_TILE, SEARCH_SPACING = 128, 256


def _search_tiles(shape: tuple[int, int]) -> list[tuple[slice, slice]]:
    """Where :func:`crease_sigma` measures the noise: the whole image up to
    :data:`SEARCH_PIXELS`, else :data:`SEARCH_TILE`-px tiles every :data:`SEARCH_SPACING` px
    (a quarter of the pixels: the noise median is a scan-wide figure, and the candidates'
    smoothing is what a search costs)."""
    h, w = shape
    if h * w <= SEARCH_PIXELS:
        return [(slice(0, h), slice(0, w))]
    return [(slice(i, i + SEARCH_TILE), slice(j, j + SEARCH_TILE))
            for i in range(0, h, SEARCH_SPACING) for j in range(0, w, SEARCH_SPACING)]


#: blank pixels (multiple of 4: the noise is sampled on every 4th row and column) between the
#: search tiles in their mosaic, more than the reach of any candidate's smoothing (3 sigma
#: <= 9 px), of the jump margin (2 sigma) and of the operators (1 px)
MOSAIC_GAP = 16


def _search_mosaic(tiles: list[tuple[slice, slice]], *images: tuple[np.ndarray, object]) -> list[np.ndarray]:
    """The search tiles of each ``(image, blank)`` packed into one image, tile after tile
    with :data:`MOSAIC_GAP` blank pixels (NaN depth, no pair, invalid) between them.

    Every step of :func:`_noise_bends` treats a blank pixel as it treats the outside of an
    image (smoothing: zero weight, renormalised; operators: a missing part; the jump
    margin: no jump), so each tile's samples come out as on the tile alone, to the bit, in
    one call instead of one per tile (a 1024^2 scan's 16 tiles cost about 0.6 ms each in
    per-call overhead). A single tile is returned as it is.
    """
    if len(tiles) == 1:
        return [a[(slice(None),) * (a.ndim - 2) + tiles[0]] for a, _ in images]
    rows = sorted({t[0].start for t in tiles})
    cols = sorted({t[1].start for t in tiles})
    cell = SEARCH_TILE + MOSAIC_GAP
    shape = (len(rows) * cell - MOSAIC_GAP, len(cols) * cell - MOSAIC_GAP)
    out = []
    for a, blank in images:
        m = np.full(a.shape[:-2] + shape, blank, a.dtype)
        for rs, cs in tiles:
            part = a[..., rs, cs]
            r0, c0 = rows.index(rs.start) * cell, cols.index(cs.start) * cell
            m[..., r0:r0 + part.shape[-2], c0:c0 + part.shape[-1]] = part
        out.append(m)
    return out


def crease_sigma(z: np.ndarray, pairs: np.ndarray, touching: np.ndarray, footprint: np.ndarray,
                 valid: np.ndarray, noise: float, floor: float = 15.0) -> float:
    """The pre-smoothing (pixels) whose crease test finds the gentlest creases on a noisy scan.

    The noise rule ``clip(4 noise, 1, 3)`` px brings the operators' noise under the noise-free
    threshold, and on noisy scans (the INRIA preset's 0.8 footprints: 3 px) far under it:
    the noise-raised threshold falls to the 15-degree floor while smoothing rounds a crease
    over ~4 sigma px, so the ridge keeps only :func:`smoothing_gain` of its bend (26 % at
    3 px: the floor then means a 58-degree crease), and the responses within 2 sigma px of
    every jump and shadow are dropped (6 px at 3 px: the creases of narrow chamfers and
    faces beside an outline). So the scale is chosen from the measured noise: at each
    candidate sigma the threshold :func:`gradient` would set (``max(floor, k * median)``
    of the noise's bend, :func:`_noise_bends`; on tiles of large images, :func:`_search_tiles`, packed
    into one image, :func:`_search_mosaic`) over that gain is the least true bend a
    crease needs; from the rule's sigma down in steps of :data:`SIGMA_STEP` to 1 px, a smaller
    sigma is taken where that bend is lower by more than :data:`SIGMA_MARGIN` (a sigma whose
    gain cannot beat that even at the threshold's floor is not measured). At the White
    Scanner preset's noise the rule's ~1 px stays; the INRIA preset's 0.8 gets ~1.75 px.

    The noise is measured with the plain normalised smoothing and no response within ``ceil(2
    sigma)`` px of a jump, as :func:`gradient` smoothed before its step-preserving smoothing
    (:func:`~rangesim.edges._gradient_steps.step_smooth`); away from steps the two agree, and
    the search was kept so that the chosen sigma did not move.

    Parameters
    ----------
    z : (H, W) float32
        Depth, mm, NaN where invalid.
    pairs : (4, H, W) bool
        Discontinuity pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`).
    touching : (H, W) bool
        Pixels of a discontinuity pair.
    footprint : (H, W) float
        Pixel footprint, mm.
    valid : (H, W) bool
    noise : float
        Depth noise, pixel footprints (:func:`~rangesim.edges._noise.estimate_depth_noise`).
    floor : float
        The noise-free threshold, degrees.

    Returns
    -------
    float
        Smoothing standard deviation, pixels, in ``[1, clip(4 noise, 1, 3)]``.
    """
    top = float(np.clip(4 * noise, 1.0, 3.0))
    if top <= 1.0:
        return top                      # nothing smaller to try
    inv_fp = np.float32(1) / np.asarray(footprint, np.float32)
    zm, pm, tm, fm, vm = _search_mosaic(_search_tiles(z.shape), (np.asarray(z, np.float32), np.nan), (pairs, False),
                                        (touching, False), (inv_fp, np.nan), (valid, False))
    best, best_bend = top, None
    for sigma in [top, *np.arange(np.ceil(top / SIGMA_STEP - 1) * SIGMA_STEP, 1.0 - 1e-9, -SIGMA_STEP)]:
        sigma = float(sigma)
        # the threshold is never under the floor: a sigma whose gain cannot bring even the
        # floor's bend under the margin cannot win, and its noise need not be measured
        if best_bend is not None and floor / smoothing_gain(sigma) >= (1 - SIGMA_MARGIN) * best_bend:
            continue
        noise_bend = _noise_bends(zm, pm, tm, fm, vm, sigma)
        # the threshold gradient would set at this sigma, over the share of a bend it sees
        threshold = noise_threshold(noise_bend[None], np.ones((1, noise_bend.size), bool), floor, NOISE_K_GRADIENT,
                                    stride=1)
        bend = threshold / smoothing_gain(sigma)
        if best_bend is None:
            best_bend = bend
        elif bend < (1 - SIGMA_MARGIN) * best_bend:
            best, best_bend = sigma, bend
    return best


#: the distances (px from a broken pair) :func:`step_noise_gain` raises the threshold at
#: are those of the smoothing's reach, ``ceil(3 sigma)``; measured on this many rows and draws
GAIN_ROWS, GAIN_DRAWS = 64, 64


@functools.lru_cache(maxsize=32)
def step_gain_profile(sigma: float) -> np.ndarray:
    """The operators' response noise ``d`` px from a step (index d = 0, 1, ...), over an open
    face's, after :func:`~rangesim.edges._gradient_steps.step_smooth` of ``sigma`` px (>= 1).

    Beside a broken pair the step-preserving smoothing continues each run by the point
    reflection ``2 z(e) - z(e - m)`` of its own pixels: the run's end pixel is not smoothed
    across the step (its reflected taps cancel its neighbours'), and the pixels next to it
    average few independent depths, so their responses are several times noisier than an open
    face's, whose noise sets the threshold. Measured once per sigma (seeded) on a straight
    step across :data:`GAIN_ROWS` rows of unit white noise, :data:`GAIN_DRAWS` times: the RMS
    of the largest |response| per distance over the RMS far from the step.
    """
    from rangesim.edges._gradient_steps import step_smooth

    reach = int(np.ceil(3 * sigma)) + 2
    w = 2 * (2 * reach + 8)
    c = w // 2 - 1                                     # the break between columns c and c + 1
    pairs = np.zeros((4, GAIN_ROWS, w), bool)
    pairs[0][:, c] = True
    rng = np.random.default_rng(20261205)
    acc = np.zeros(w, np.float64)
    for _ in range(GAIN_DRAWS):
        n = rng.standard_normal((GAIN_ROWS, w)).astype(np.float32)
        resp = second_differences(step_smooth(n, pairs, sigma), pairs)
        mag = np.abs(resp[0])
        for r in resp[1:]:
            np.fmax(mag, np.abs(r), out=mag)
        acc += (np.nan_to_num(mag[4:-4].astype(np.float64)) ** 2).sum(axis=0)
    rms = np.sqrt(acc)
    far = float(np.mean(rms[6:c - reach]))
    left = rms[c::-1][:reach + 1] / far                # d = 0 at the pair's own pixel
    right = rms[c + 1:][:reach + 1] / far
    profile = np.maximum(np.maximum(left, right), 1.0).astype(np.float32)
    profile.setflags(write=False)  # cached: shared by every caller
    return profile


def step_noise_gain(touching: np.ndarray, sigma: float) -> np.ndarray:
    """Per pixel, :func:`step_gain_profile` at its chessboard distance ``d`` from the nearest
    pixel of a jump (``touching``: :func:`gradient` passes the jumps' occluding and occluded
    pixels, the set its ``jump_clearance`` is measured from) for ``d <= ceil(sigma)``, where the
    reflected taps carry a third or more of the kernel (1.7-9 times the noise at 1.75 px); 1
    beyond (1.2 times at 3 px, 1.75: raised there, a 45-degree crease 3 px from a step at
    the INRIA preset's noise is lost in most rows)."""
    prof = step_gain_profile(float(sigma))[:int(np.ceil(sigma)) + 1]
    gain = np.ones(touching.shape, np.float32)
    ring = np.asarray(touching, bool)
    seen = ring.copy()
    gain[ring] = prof[0]
    for d in range(1, prof.size):
        grown = _near(ring, 1, border=False)
        new = grown & ~seen
        gain[new] = prof[d]
        seen |= new
        ring = new
    return gain


def matching_stride(window: int | None) -> int:
    """Default half-width (pixels) of the crease operators for a block matcher's ``window``.

    1 (the 3 x 3 operators) without a matcher. With one, ``round(MATCHING_STRIDE_WINDOWS *
    window)``: the chords from a crease's centre then reach past the ``window / 2`` pixels the
    matcher rounded and see 1 - 1 / 4 of its bend at one window
    (:func:`~rangesim.edges._matching_scale.rounding_gain`), while their ends stay on the faces.

    Examples
    --------
    >>> matching_stride(None), matching_stride(9)
    (1, 9)
    """
    if window is None:
        return 1
    return max(1, int(round(MATCHING_STRIDE_WINDOWS * window)))


def gradient(
    scan: Any,
    threshold: float | None = None,
    jump_threshold: float = JUMP_THRESHOLD,
    nms: bool = True,
    sigma: float | None = None,
    max_search: int = 50,
    jump_clearance: int | None = None,
    stride: int | None = None,
) -> EdgeMap:
    """Roof (crease) and jump edges from the paper's four 3x3 second-derivative operators.

    Technique 1 of the founding paper (after Sugihara): the operators of
    :data:`OPERATORS` at 0, 45, 90 and 135 degrees are applied to the depth image (NaN-aware,
    see :func:`second_differences`); the response magnitude is the largest absolute
    response over the four. Divided by the pixel footprint ``z / f`` (mm per pixel) it is
    range-independent: the change of the surface's depth slope ``tan(phi)`` (phi the angle
    to the image plane, across the edge), since a face at slant phi changes depth by
    ``footprint * tan(phi)`` per pixel. A crease between a face seen frontally and one bent
    by theta therefore responds with ``tan(theta)``; one between pixel centres splits that
    between the two pixels beside it. The reported ``strength`` converts the response to
    the bend angle: with ``d`` the response summed over the two pixels of the edge's ridge
    and ``t`` the mean slope across it (central first difference), the slopes on either
    side are ``t -+ d / 2`` and the bend is ``atan(t + d/2) - atan(t - d/2)`` degrees, so the
    threshold means the same at every range and viewing angle (a fixed slope change would
    fire on faint facet edges of surfaces seen at grazing angles). On noise-free roofs the
    estimate is 0.75-1 times the true bend (median 0.93) at any orientation.

    Direction and type come from the second-derivative (Hessian) tensor that the four
    responses sample (``Dxx`` from the 0 degree operator, ``Dyy`` from 90, ``Dxy`` from the
    difference of the diagonals), summed over 3x3: ``direction`` is its dominant
    eigenvector (across the edge, within ~2 degrees on straight creases; a quantised
    operator direction would be off by up to 22.5) and the sign of its dominant eigenvalue
    is the type. The sign of the single strongest operator is not used: on oblique creases
    the diagonal operators respond with the opposite sign as strongly.

    Sign convention (camera looking along +z): at a convex crease (a roof, material angle
    below 180 degrees) the edge is nearer the camera than the average of its neighbours
    across it, so the depth's second difference ``z(-1) - 2 z(0) + z(1)`` is positive
    (equivalently, the height towards the camera, -z, has a negative second derivative, as
    the mean curvature H < 0 of :mod:`rangesim.curvature`); concave creases are negative.

    Jump edges: depth discontinuities by :func:`~rangesim.edges._discontinuities.find_discontinuities`
    (neighbours more than ``jump_threshold`` pixel footprints apart, PCL's rule scaled to
    the footprint, also searched across NaN gaps up to ``max_search`` pixels), labelled
    JUMP on the near (occluding) side. A step is not a roof: stencil parts that cross a
    discontinuity are dropped, and the smoothing never averages across one
    (:func:`~rangesim.edges._gradient_steps.step_smooth`: each side continued by its own
    surface, so a step is not smeared into a slope change and creases beside it keep their
    response; on tuning seeds 20-29, inria_laser with noise, F1 0.848 -> 0.879; before, every
    response within ceil(2 sigma) px of a jump was dropped, as it still is for an explicit
    sigma with ``stride > 1``).
    Pixels next to NaN gaps that the search cannot resolve are not labelled.

    Parameters
    ----------
    scan : RangeScan
        Uses ``depth``, ``valid`` and ``meta["K"]`` for the footprint (without it the
        footprint is estimated from the points, see
        :func:`~rangesim.edges._scan_access.pixel_geometry`).
    threshold : float, optional
        Least bend of a crease pixel, degrees in (0, 180) (estimated as above). Noise-free default 15:
        finds creases of 20 degrees and more (the ground truth's ``crease_deg``) at any
        orientation and sub-pixel position. Default (None) on scans with measurable noise
        (depth noise from :func:`~rangesim.edges._noise.estimate_depth_noise` above
        :data:`~rangesim.edges._noise.NOISE_MEASURABLE` footprints, quantisation included):
        ``max(15, k * median)`` of
        ``2 atan(response)`` over valid pixels (the noise's bend, as if the neighbour
        across responded as much), ``k`` = :data:`~rangesim.edges._noise.NOISE_K_GRADIENT`
        = 3 (~4 sigma of the bend estimate; 20 degrees at the preset noise). On smoothed
        noisy scans the crease test (not the thinning's candidates) raises it further within
        the smoothing's reach of a broken pair by :func:`step_noise_gain` (the
        step-preserving smoothing leaves the pixels beside a step barely smoothed: 2.2 / 1.7 /
        1.2 times an open face's response noise 1 / 2 / 3 px from it at 1.75 px).
    jump_threshold : float
        Depth-discontinuity threshold in pixel footprints (finite, > 0): neighbours whose depths differ by
        more than this many footprints (``z / f`` mm) are a jump. Default
        :data:`~rangesim.edges._discontinuities.JUMP_THRESHOLD` = cot(15 deg) = 3.73, the ground
        truth's rule (a continuous surface jumps only beyond 75 degrees slant); for a pinhole
        camera it is ``jump_threshold / f`` times the depth (PCL's 0.02 z is 0.02 f).
    nms : bool
        Thin creases by non-maximum suppression across the edge direction (1 px wide),
        then drop the inner corners of the staircases it leaves on diagonal edges
        (:func:`~rangesim.edges._thinning.thin_staircases`: 8-connected, 1 px diagonals).
        Either way no crease is kept within ``jump_clearance`` px of a jump
        (occluding or occluded side): the crest beside a jump is the jump itself.
    sigma : float, optional
        Gaussian pre-smoothing of the depth, pixels, 0 to 42.5 (0: none). Noisy scans need it: the
        response's noise is ~1.4 sigma_z / footprint unsmoothed. Default (None): 0 on
        noise-free scans, else ``clip(4 * noise, 1, 3)`` px for a depth noise of ``noise``
        footprints (1 px at the White Scanner preset's 0.25; also under
        :data:`~rangesim.edges._noise.NOISE_FLOOR` where the noise, unsmoothed, would raise the
        threshold above 15 degrees: the 0.04 footprints of its peak quantisation alone), or less where the default
        threshold then lets gentler creases through (:func:`crease_sigma`: ~1.75 px
        instead of 3 at the INRIA preset's 0.8, where 3 px kept a quarter of a crease's
        bend and dropped every crease within 6 px of a jump or shadow; on the machined
        parts' tuning seeds 20-29, inria_laser, gradient F1 0.78 -> 0.85); up to
        :data:`SMALL_SIGMA` a 5-tap kernel of the same variance, beyond it a Gaussian. 0 on
        block-matched scans (structured light): the matcher has smoothed over its window.
    max_search : int
        Pixels searched across NaN gaps for the jump rule, >= 0 (0: only direct neighbours).
    jump_clearance : int, optional
        No crease is kept within this many pixels (an integer >= 0) of a jump (the crest beside an occluding
        edge is the jump itself); 0 keeps them, e.g. for fitting circles to whole rims. Default
        (None): :func:`~rangesim.edges._thinning.stripe_clearance`, the pixels a laser stripe of
        the scan's width rounds a step over, plus the operator's reach (2 px for the White
        Scanner and Cyberware presets at their own resolutions, 1 px for the INRIA preset, whose
        stripe images under a pixel wide, and for a White Scanner scan at a quarter of its
        resolution); :data:`JUMP_CLEARANCE` (2) where the scan does not say (recordings read
        without a laser sensor, block-matched scans). On noisy scans the crease threshold beside
        a jump is raised (above) whatever the clearance, 0 included.
    stride : int, optional
        Half-width of the operators, pixels (an integer from 1 to 255): 1 is the paper's 3 x 3; ``s`` dilates them (a
        trous: second differences between pixels ``s`` apart, parts across a jump or a gap
        dropped, :func:`~rangesim.edges._matching_scale.strided_responses`), so they compare
        the slopes of chords ``s`` pixels long. Default (None): 1, or the block matcher's
        window where the scan's ``meta["sensor"]`` says its depth comes from block matching
        (``mode = "structured_light"``, :func:`matching_stride`; 9 px for the presets). Such a
        matcher reports about the mean disparity over its window, so it rounds a crease over
        ``w`` pixels: the 3 x 3 operators see a ninth of the bend per pixel under its noise,
        while chords one window long reach the faces beside the rounding. There the
        response is divided by the share of the bend the chords see
        (:func:`~rangesim.edges._matching_scale.rounding_gain`, 3/4 at one window), so the
        threshold keeps meaning the crease's bend, and the ridge is thinned on the response
        smoothed over the window (:func:`~rangesim.edges._matching_scale.ridge_sigma`). On the
        machined parts' tuning seeds 0-15 (kinect_v1, structured_light_bench) gradient F1 rose
        from 0.53-0.63 to 0.62-0.71, most of it crease recall; laser-stripe scans keep 1.

    Returns
    -------
    EdgeMap
        ``method="gradient"``; ``strength`` is the bend estimate in degrees (NaN where no
        operator has a response: invalid pixels, stencils cut by gaps or jumps);
        ``direction`` is the angle in [0, pi) of the (x, y) vector across the edge, for
        every pixel with a response (and across the discontinuity at jump pixels); on a
        block-matched scan, at the edge pixels, the mean of the edge pixels' directions
        over the matcher's window (:func:`~rangesim.edges._matching_scale.window_directions`:
        its contours are ragged by a pixel or two, and the circle and ellipse finders vote
        and grow along these directions);
        ``labels`` CONVEX/CONCAVE on creases, JUMP on the near side of jumps.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> edges = rs.edges.gradient(scan)
    >>> edges.method, edges.mask.shape, bool(edges.mask.any())
    ('gradient', (120, 128), True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    """
    threshold = P.number(threshold, "threshold", 0, 180, lo_open=True, hi_open=True, what="angle", unit="degrees",
                         none=True)
    jump_threshold, max_search = P.jump_rule(jump_threshold, max_search)
    nms = P.flag(nms, "nms")
    # the kernel reaches 3 sigma: no wider than the largest window a detector takes
    sigma = P.number(sigma, "sigma", 0, P.MAX_WINDOW_PX / 6, unit="pixels", none=True)
    jump_clearance = P.whole(jump_clearance, "jump_clearance", 0, unit="pixels", none=True)
    stride = P.whole(stride, "stride", 1, P.MAX_WINDOW_PX, unit="pixels", none=True)
    z, valid = scan_depth(scan)
    disc, geo = discontinuities(scan, z, jump_threshold, max_search)
    window = matching_window(scan)
    if stride is None:
        stride = matching_stride(window)
    stride = int(stride)
    noise = None
    if sigma is None or threshold is None:
        noise = estimate_depth_noise(scan, z=z, fp=geo.footprint, quantum=disc.quantum)
    noisy = noise is not None and noise >= NOISE_FLOOR
    auto_threshold = threshold is None
    if (not noisy and auto_threshold and sigma is None and window is None and noise is not None
            and noise >= NOISE_MEASURABLE):
        # noise under NOISE_FLOOR that would still raise the threshold unsmoothed (a laser scan's
        # 1/16 px peak quantisation alone: 0.04 footprints, 29-34 degrees) gets the noisy path's
        # smoothing and per-pixel threshold: raising the threshold alone lost every 20-29 degree
        # crease that the full preset noise keeps (a 25 degree roof: recall 0.03 against 0.68)
        bends = _noise_bends(z, disc.pairs, disc.touching, np.float32(1) / geo.footprint, valid, 0.0)
        noisy = bends.size > 0 and NOISE_K_GRADIENT * float(np.median(bends)) > 15.0
    if sigma is None:
        # a block matcher has smoothed over its window already: more would round creases further
        if not noisy or window is not None:
            sigma = 0.0
        elif auto_threshold:
            # the scale whose noise-raised threshold lets the gentlest creases through
            sigma = crease_sigma(z, disc.pairs, disc.touching, geo.footprint, valid, noise)
        else:
            sigma = float(np.clip(4 * noise, 1.0, 3.0))
    if auto_threshold:
        threshold = 15.0
    fp = geo.footprint
    if jump_clearance is None:
        jump_clearance = stripe_clearance(scan, fp, valid)
    inv_fp = np.float32(1) / fp
    near_jump = None
    if sigma > 0 and stride == 1:
        # smoothed without averaging across a broken pair (rangesim.edges._gradient_steps): a
        # step is not smeared into a slope change, so no response near it need be dropped
        zs = step_smooth(z, disc.pairs, sigma)
    elif sigma > 0:
        # (an explicit sigma on strided operators) smoothing drags a step's slope out by ~2
        # sigma: no responses that close to one
        zs = _nan_gaussian(z, sigma)
        near_jump = _near_jump(disc.touching, sigma)
        np.copyto(inv_fp, np.nan, where=near_jump)
    else:
        zs = z
    # a depth step is not a roof: no stencil part may cross a discontinuity. The responses
    # scaled in place to slope changes per footprint; the largest |response|, where an
    # undefined operator does not veto (NumPy's fmax); the Hessian from the operators (0 ->
    # Dxx, 90 -> Dyy, 45/135 -> +-(6 / 2 sqrt 2) Dxy), its dominant eigenvector's angle
    # (compiled arc tangents, rangesim.edges._trig: NumPy's are scalar C-library calls on
    # CPUs without AVX-512; the same but for last bits) and the sign of its eigenvalue
    h, w = z.shape
    if stride == 1 and near_jump is None and h >= 3 and w >= 3:
        # all in one compiled pass, a row at a time (the responses never made as images)
        mag, theta, dominant_positive = _streamed_responses(
            np.ascontiguousarray(zs, np.float32), *_pairs_arg(disc.pairs),
            np.ascontiguousarray(np.broadcast_to(inv_fp, z.shape), np.float32))
    else:
        if stride > 1:
            # the operators dilated to the matcher's scale: chords beside the rounding, divided
            # by the share of the bend they see after the window's box (1 without a matcher)
            resp = strided_responses(zs, disc.pairs, stride, second_differences)
            scale = inv_fp / np.float32(rounding_gain(window or 1, stride))
        else:
            resp = second_differences(zs, disc.pairs, skip=near_jump)
            scale = inv_fp
        mag = _scale_and_magnitude(*resp, np.ascontiguousarray(np.broadcast_to(scale, z.shape), np.float32))
        theta, dominant_positive = _hessian_direction(*resp, mag)
        # (the responses' 16 MB freed here, for the images below to reuse: fresh pages cost
        # about as much as the arithmetic on them)
        del resp
    direction = theta

    # the noise's threshold wherever noise is measurable, under NOISE_FLOOR too: a laser scan with
    # only its 1/16 px peak quantisation (0.04 footprints) marked its quantisation steps as creases
    # at the fixed 15 degrees (machined parts' tuning / check seeds: F1 0.34 / 0.39 -> 0.95 / 0.92)
    if auto_threshold and noise is not None and noise >= NOISE_MEASURABLE:
        # the median is taken on every 4th row and column: the bend only there
        # (the noise's bend as the crease rule below would estimate it: at stride 1 as if the
        # neighbour across responded as much, d = 2 mag; a strided response is not shared)
        noise_bend = np.degrees(2 * np.arctan(mag[::4, ::4] if stride == 1 else mag[::4, ::4] / 2))
        threshold = noise_threshold(noise_bend, valid[::4, ::4], threshold, NOISE_K_GRADIENT, stride=1)
    # per pixel: raised where the noise model predicts more noise than at the median pixel
    pixel_threshold: float | np.ndarray = threshold
    if auto_threshold and noisy:
        pixel_threshold = raised_noise_threshold(scan, valid, fp, threshold, 89.0, disc.noise)

    # bend angle: the slopes on either side are t -+ d / 2 around the mean slope t across
    # the edge (central first difference, which straddles a crease at the centre); d is
    # the response summed over the edge's ridge: a crease between two pixel centres splits
    # its response between them (the larger neighbour across the edge holds the rest)
    if np.ndim(pixel_threshold):
        candidates = above_tan_half(mag, np.ascontiguousarray(pixel_threshold, np.float32))
    else:
        with np.errstate(invalid="ignore"):
            candidates = mag > np.tan(np.radians(pixel_threshold) / 2)
    ridge = mag
    if stride > 1:
        # a strided response peaks broadly (at the crease it falls by 2 / w of itself per
        # pixel aside, under the matcher's noise): thinned as it is, it leaves parallel
        # ridges a few pixels apart. Its ridge is found on it smoothed over the matcher's
        # own support, a Gaussian of the box's variance (w^2 / 12), which keeps the peak
        ridge = _nan_gaussian(mag, ridge_sigma(window, stride))
    thin, ti, beside = nonmax_suppress(ridge, direction, candidates, return_sides=True)
    gx = central_difference(zs, 0, disc.pairs)
    gy = central_difference(zs, 2, disc.pairs)
    del zs
    # t = gx cos + gy sin in gx's and gy's own memory (fresh images cost more than their
    # arithmetic; NumPy's cos and sin give the same bits whichever buffer they fill)
    trig = np.cos(theta)
    t = np.multiply(gx, trig, out=gx)
    t += np.multiply(gy, np.sin(theta, out=trig), out=gy)
    del trig, gy
    t *= inv_fp
    np.copyto(t, 0, where=np.isnan(t))
    # half the response summed over the ridge: the side's share only at NMS survivors
    # (sparse; (mag + 0) / 2 elsewhere is mag / 2 to the bit)
    half = mag * np.float32(0.5)
    if stride == 1:
        half.ravel()[ti] = (mag.ravel()[ti] + np.fmax(beside, 0)) / 2
    # (a strided response is not split between two pixels: a crease between centres gives
    # both (s - 1/2) / s of it, and the neighbour's share would count it twice)
    bend = bend_degrees(t, half)
    # (the crease test only, not the NMS candidates: a jump's own pixels keep thinning their
    # neighbours as before) raised beside broken pairs, where the step-preserving smoothing
    # leaves the depth barely smoothed and the responses noisier than the threshold's median
    crease_threshold = pixel_threshold
    if auto_threshold and noisy and sigma > 0 and stride == 1 and near_jump is None:
        gain = step_noise_gain(disc.occluding | disc.occluded, sigma)
        crease_threshold = np.minimum(np.asarray(pixel_threshold, np.float32) * gain, np.float32(89.0))
    with np.errstate(invalid="ignore"):
        crease = bend > crease_threshold
    if nms:
        crease &= thin
    jump = disc.occluding
    rim = disc.rim
    jump_or_rim = jump | rim
    beside_jumps = jump_or_rim | disc.occluded
    # the crest beside an occluding jump (or a rim) is the jump itself (a mixed or
    # half-seen pixel next to it): no crease within JUMP_CLEARANCE px of one
    if jump_clearance > 0:
        crease &= ~near_mask(crease, beside_jumps, jump_clearance)
    if nms:
        # 1 px diagonals: NMS leaves 4-connected staircases, the truth is 8-connected
        crease = thin_staircases(crease | jump_or_rim, crease)
    # the type from the sign of the Hessian's dominant eigenvalue, needed on creases only
    labels = np.zeros(z.shape, np.uint8)
    ci = np.flatnonzero(crease)
    labels.ravel()[ci] = np.where(dominant_positive.ravel()[ci], EdgeLabel.CONVEX, EdgeLabel.CONCAVE)
    labels[rim] = RIM
    labels[jump] = EdgeLabel.JUMP
    # a crease between pixel centres: the kept pixel moved along the crease's normal to the
    # vertex of the ridge it was thinned on (its own direction, before jumps overwrite it)
    offset = disc.offsets_at(jump_or_rim)
    if nms:
        # unsmoothed, a roof's response is a 2-sample triangle (a parabola goes half the way)
        peak = "parabola" if sigma > 0 or stride > 1 else "triangle"
        # (none within JUMP_CLEARANCE px of a discontinuity: the neighbour across is the
        # step's own slope there, not the roof's, whatever jump_clearance kept)
        placed = crease & ~jump_or_rim
        placed &= ~near_mask(placed, beside_jumps, JUMP_CLEARANCE)
        # added in place at the placed pixels (0 elsewhere); at the jump and rim pixels the
        # sum with those zeros that it replaces (x + 0: -0 becomes +0)
        ridge_offsets(ridge, direction, placed, peak=peak, out=offset)
        offset.reshape(-1, 2)[np.flatnonzero(jump_or_rim)] += np.float32(0)
    np.copyto(direction, disc.direction, where=np.isfinite(disc.direction))
    params = {
        "threshold": float(threshold), "jump_threshold": float(jump_threshold), "nms": bool(nms),
        "sigma": float(sigma), "max_search": int(max_search), "stride": stride,
        "jump_clearance": int(jump_clearance),
        "noise": None if noise is None else float(noise),
    }
    mask = with_gap_creases(crease | jump | rim, labels, disc, offset) & valid
    if window is not None:
        # a block matcher resolves a contour's direction only at its window's scale
        direction = window_directions(direction, mask, window)
    return EdgeMap(mask=mask, labels=labels, strength=bend, direction=direction, offset=offset,
                   method="gradient", params=params)
