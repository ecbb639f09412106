"""Pre-smoothing that does not smear depth steps: :func:`gradient`'s noisy-scan smoothing.

Smoothing a depth image across a step of height ``H`` turns the step into a ramp ``~4 sigma``
wide, whose second difference at a distance ``d`` from the step is about
``H g(d / sigma) / sigma^2`` (``g`` the Gaussian's derivative): a 4-footprint step (the jump
threshold) smoothed by 1.75 px still answers the crease operators with ~0.28 footprints a pixel
at 1 px, ~0.13 at 3 px, more than a 20-degree crease gives. So :func:`step_smooth` never
averages across a broken neighbour pair: each pass (rows, then columns) smooths the run of
pixels between two breaks on its own, and a tap that would fall across a break is replaced
by the run's own surface continued past its last pixel, the point reflection
``2 z(e) - z(e - m)`` of the tap ``m`` px past the run's end ``e``. That continuation is exact
for a plane (a constant and a ramp stay as they are, so a face beside a step gets no
response of its own, however steep it is) and mirrors a crease ``d`` px from the end into
one of the opposite sign ``2 d`` px from it, whose effect on the crease's own response falls
as ``exp(-(2 d)^2 / (2 sigma^2))`` (under 2 % from ``2 d >= 2.8 sigma``). Pixels ``d`` px from
the end average fewer independent depths, so their responses are noisier, at most ~1.8
times (``d`` = 1-3 px at 1.75 px) and as the plain smoothing's from ``d >= 2 sigma``.

Ends at invalid pixels and at the image border keep the normalised convolution of
:func:`~rangesim.edges._gradient._nan_gaussian` (taps dropped, weights renormalised; beside
gaps and away from breaks with its joint 2-D weights, :func:`_joint_beside_gaps`), unless
``reflect_open``.
"""
from __future__ import annotations

import functools

import numba
import numpy as np

__all__ = ["step_smooth", "smoothing_weights"]


@functools.lru_cache(maxsize=32)
def smoothing_weights(sigma: float) -> np.ndarray:
    """The one-sided taps ``w[0..R]`` (float32, ``w0 + 2 sum w[1:]`` = 1) of the kernel
    :func:`~rangesim.edges._gradient._nan_gaussian` uses for ``sigma``: 5 taps of the same
    variance up to :data:`~rangesim.edges._gradient.SMALL_SIGMA`, else the sampled Gaussian to
    ``int(3 sigma + 0.5)`` px (scipy's ``gaussian_filter`` at ``truncate=3``)."""
    from rangesim.edges._gradient import SMALL_SIGMA, _taps5

    if sigma <= SMALL_SIGMA:
        w = np.array(_taps5(sigma), np.float64)
    else:
        r = int(3.0 * sigma + 0.5)
        w = np.exp(-0.5 * (np.arange(r + 1) / sigma) ** 2)
    w /= w[0] + 2 * w[1:].sum()
    return w.astype(np.float32)


def step_smooth(z: np.ndarray, pairs: np.ndarray, sigma: float, reflect_open: bool = False) -> np.ndarray:
    """Separable smoothing of the depth ``z`` that never averages across a broken pair.

    Parameters
    ----------
    z : (H, W) float32
        Depth, NaN where invalid (stays NaN).
    pairs : (4, H, W) bool
        Discontinuity pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`);
        ``pairs[0]`` breaks the row links ``(i, j)-(i, j+1)``, ``pairs[2]`` the column links
        ``(i, j)-(i+1, j)``.
    sigma : float
        Standard deviation of the kernel, pixels (:func:`smoothing_weights`).
    reflect_open : bool
        Continue the surface past invalid pixels and the border too (else their taps are
        dropped and the rest renormalised).

    Returns
    -------
    (H, W) float32
    """
    w = smoothing_weights(float(sigma))
    a = np.ascontiguousarray(z, np.float32)
    rows = _row_pass(a, np.ascontiguousarray(pairs[0]), w, reflect_open)
    out = _col_pass(rows, np.ascontiguousarray(pairs[2]), w, reflect_open)
    if not reflect_open:
        _joint_beside_gaps(out, a, pairs, float(sigma))
    return out


def _joint_beside_gaps(zs: np.ndarray, z: np.ndarray, pairs: np.ndarray, sigma: float) -> None:
    """In place: beside gaps (invalid pixels) and away from every broken pair, the 2-D
    normalised convolution of :func:`~rangesim.edges._gradient._nan_gaussian` instead of the
    separable passes'.

    :func:`step_smooth`'s passes renormalise each on its own at
    an open end; on a slanted face the row pass's one-sided means are biased along x, and the
    column pass mixes biased and unbiased rows at a gap's corners: false creases (18-21
    degrees at the corners of a 7 x 7 dropout on a plate at the White Scanner's noise), where
    the joint 2-D weights leave none. Within the kernel's reach of a broken pair the
    step-aware values stay. One compiled pass for the 5-tap kernel (the same bits as
    ``_nan_gaussian``'s), else from the full Gaussian.
    """
    from rangesim.edges._gradient import SMALL_SIGMA, _nan_gaussian, _near, _taps5

    r = 2 if sigma <= SMALL_SIGMA else int(3.0 * sigma + 0.5)
    broken = pairs[0] | pairs[1]
    broken |= pairs[2]
    broken |= pairs[3]
    z = np.ascontiguousarray(z, np.float32)
    bad = np.isnan(z)
    if not bad.any():
        return
    # a pair is broken at its first pixel: its second lies within 1 px, so r + 1 covers both
    redo = _near(bad, r, border=False)
    redo &= ~bad
    redo &= ~_near(broken, r + 1, border=False)
    if sigma <= SMALL_SIGMA:
        w0, w1, w2 = _taps5(sigma)
        _gap_smooth5(zs, z, bad, redo, w0, w1, w2)
        return
    idx = np.flatnonzero(redo)
    if idx.size:
        zs.ravel()[idx] = _nan_gaussian(z, sigma).ravel()[idx]


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def tap5_sum(a, w0, w1, w2):  # pragma: no cover - compiled
    """The symmetric 5-tap sum ``((a0 + a4) w2 + (a1 + a3) w1) + w0 a2`` of ``a[0..4]`` in the
    order every smoothing kernel of the gradient detector uses (so all agree to the bit)."""
    r = (a[0] + a[4]) * w2
    r += (a[1] + a[3]) * w1
    r += w0 * a[2]
    return r


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _gap_smooth5(zs, z, bad, redo, w0, w1, w2):  # pragma: no cover - compiled
    """:func:`_joint_beside_gaps` for the 5-tap kernel: at the ``redo`` pixels the normalised
    5-tap smoothing ``num / den`` with ``_gradient._smooth5_at``'s operations in its order (zeros
    outside the image and at the ``bad`` pixels; ``den`` the same sums of the validity)."""
    h, w = z.shape
    zero, one = np.float32(0), np.float32(1)
    nums = np.empty(5, np.float32)
    dens = np.empty(5, np.float32)
    vals = np.empty(5, np.float32)
    oks = np.empty(5, np.float32)
    for i in range(h):
        # rows without a pixel to redo skipped by a vectorised count (a branch per pixel of
        # the image cost more than the pixels redone)
        rr = redo[i]
        n = 0
        for j in range(w):
            n += rr[j]
        if n == 0:
            continue
        for j in range(w):
            if not rr[j]:
                continue
            for k in range(5):
                ii = i + k - 2
                for m in range(5):
                    vals[m] = zero
                    oks[m] = zero
                if ii >= 0 and ii < h:          # (no chained comparisons: Numba is slow on them)
                    for m in range(5):
                        jj = j + m - 2
                        if jj >= 0 and jj < w and not bad[ii, jj]:
                            vals[m] = z[ii, jj]
                            oks[m] = one
                nums[k] = tap5_sum(vals, w0, w1, w2)
                dens[k] = tap5_sum(oks, w0, w1, w2)
            num = tap5_sum(nums, w0, w1, w2)
            den = tap5_sum(dens, w0, w1, w2)
            zs[i, j] = num / den if den != zero else np.float32(np.nan)
    return zs


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _taps(v, j, s, e, sb, eb, wts, reflect_open):  # pragma: no cover - compiled
    """The smoothed value at ``j`` of the run ``v[s..e]`` (``sb`` / ``eb``: its ends are
    breaks), taps past a break continued by point reflection about the run's end, taps past
    an open end dropped (unless ``reflect_open``) and the rest renormalised."""
    r = wts.shape[0] - 1
    two = np.float32(2)
    acc = wts[0] * v[j]
    norm = wts[0]
    for k in range(1, r + 1):
        wk = wts[k]
        p = j + k
        if p <= e:
            acc += wk * v[p]
            norm += wk
        elif eb or reflect_open:
            m = 2 * e - p
            if m < s:
                m = s
            acc += wk * (two * v[e] - v[m])
            norm += wk
        p = j - k
        if p >= s:
            acc += wk * v[p]
            norm += wk
        elif sb or reflect_open:
            m = 2 * s - p
            if m > e:
                m = e
            acc += wk * (two * v[s] - v[m])
            norm += wk
    return acc / norm


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _flagged(f, j, n, words):  # pragma: no cover - compiled
    """The first ``k >= j`` with ``f[k]`` set (``n`` if none), skipping clear 8-byte words
    (``words``: ``f`` viewed as uint64; ``f`` padded to a multiple of 8)."""
    while j < n:
        if j & 7 == 0 and words[j >> 3] == 0:
            j += 8
            continue
        if f[j]:
            return j
        j += 1
    return n


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _row_pass(a, cut, wts, reflect_open):  # pragma: no cover - compiled
    """Smooth each row over its runs (between invalid pixels and ``cut`` links): the plain
    taps everywhere, then the pixels within reach of a run's end redone by :func:`_taps`."""
    h, w = a.shape
    r = wts.shape[0] - 1
    out = np.empty((h, w), np.float32)
    n8 = (w + 7) // 8 * 8
    f = np.zeros(n8, np.uint8)             # run ends: invalid, or the link to the right cut
    words = f.view(np.uint64)
    for i in range(h):
        v = a[i]
        c = cut[i]
        o = out[i]
        w0 = wts[0]
        for j in range(w):
            o[j] = w0 * v[j]
        for k in range(1, r + 1):
            # views, so that the compiler vectorises the shifted sums
            wk, m = wts[k], w - 2 * k
            x, y, b = v[:m], v[2 * k:], o[k:w - k]
            for j in range(m):
                b[j] += wk * (x[j] + y[j])
        # flags on the valid pixels that start or end a run (an invalid pixel's plain value
        # is NaN already: its own tap)
        f[0] = v[0] == v[0]
        for j in range(1, w):
            f[j] = (v[j] == v[j]) & ((v[j - 1] != v[j - 1]) | c[j - 1])
        for j in range(w - 1):
            f[j] |= (v[j] == v[j]) & ((v[j + 1] != v[j + 1]) | c[j])
        f[w - 1] = v[w - 1] == v[w - 1]
        p = _flagged(f, 0, w, words)
        while p < w:
            s = p
            sb = s > 0 and c[s - 1]
            if s == w - 1 or c[s] or v[s + 1] != v[s + 1]:
                e = s
            else:
                e = _flagged(f, s + 1, w, words)
            eb = e + 1 < w and c[e]
            for q in range(s, min(s + r, e + 1)):
                o[q] = _taps(v, q, s, e, sb, eb, wts, reflect_open)
            for q in range(max(e - r + 1, s + r), e + 1):
                o[q] = _taps(v, q, s, e, sb, eb, wts, reflect_open)
            p = _flagged(f, e + 1, w, words)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _col_pass(a, cut, wts, reflect_open):  # pragma: no cover - compiled
    """Smooth each column over its runs (between invalid pixels and ``cut`` links), a row of
    output at a time: the plain taps, then the pixels within reach of a run's end (a set
    link flag in the ``2 r`` links around them, or the border) redone by :func:`_taps`."""
    h, w = a.shape
    r = wts.shape[0] - 1
    out = np.empty((h, w), np.float32)
    n8 = (w + 7) // 8 * 8
    nw = n8 // 8
    # link flags: the link from (i, j) down to (i + 1, j) ends a run (either pixel invalid,
    # or cut); the last row's links end every run
    g = np.ones((h, n8), np.uint8)
    for i in range(h - 1):
        v, vn, c, gi = a[i], a[i + 1], cut[i], g[i]
        for j in range(w):
            gi[j] = (v[j] != v[j]) | c[j] | (vn[j] != vn[j])
    gw = g.view(np.uint64)
    f = np.zeros(n8, np.uint8)
    fw = f.view(np.uint64)
    col = np.empty(h, np.float32)
    for i in range(h):
        o = out[i]
        v = a[i]
        w0 = wts[0]
        for j in range(w):
            o[j] = w0 * v[j]
        if r <= i < h - r:
            for k in range(1, r + 1):
                au, ad, wk = a[i - k], a[i + k], wts[k]
                for j in range(w):
                    o[j] += wk * (au[j] + ad[j])
            for q in range(nw):
                fw[q] = gw[i - r, q]
            for m in range(i - r + 1, i + r):
                for q in range(nw):
                    fw[q] |= gw[m, q]
        else:
            for q in range(nw):
                fw[q] = ~np.uint64(0)
        # (an invalid pixel's plain value is NaN already: its own tap)
        for j in range(w):
            f[j] &= v[j] == v[j]
        j = _flagged(f, 0, w, fw)
        while j < w:
            lo = i
            while lo > 0 and lo > i - r and not g[lo - 1, j]:
                lo -= 1
            sb = lo > 0 and lo > i - r and cut[lo - 1, j]
            hi = i
            while hi < h - 1 and hi < i + r and not g[hi, j]:
                hi += 1
            eb = hi < h - 1 and hi < i + r and cut[hi, j]
            for q in range(lo, hi + 1):
                col[q] = a[q, j]
            o[j] = _taps(col, i, lo, hi, sb, eb, wts, reflect_open)
            j = _flagged(f, j + 1, w, fw)
    return out
