"""Compiled inner loop of the conic refits (Numba): the edge points near each conic whose normal
agrees with the conic's, and the moments of each conic's points that its direct fit needs, in
one pass per band (the batched array version costs about a hundred NumPy calls per band)."""
from __future__ import annotations

import numba
import numpy as np

from rangesim.core._conic_kernels import direct_fit, ellipse_row
from rangesim.features._circle_kernels import _norm


@numba.njit(cache=True, nogil=True, error_model="numpy")
def band_moments(conics, hyp, px, py, ct, st, band, cos_tol):  # pragma: no cover - compiled
    """Inliers of each conic within ``band`` px and their fitting moments.

    A candidate pair k (conic ``hyp[k]``, point with coordinates ``px[k], py[k]`` and edge
    normal ``(ct[k], st[k])``) is an inlier when ``|f| <= band |grad f|`` (the Sampson
    distance) and the normal is within ``acos(cos_tol)`` of the conic's gradient.

    Returns
    -------
    sel : (P,) bool
        Inlier pairs.
    m : (K, 2) float
        Centroid of each conic's inliers (the fitting frame's origin), pixels.
    s : (K,) float
        Frame scale: the largest coordinate offset from ``m`` (1 for no inliers), pixels.
    mom : (K, 15) float
        Sums of :func:`rangesim.core.conics.conic_monomials` of ``(p - m) / s`` (the powers
        x^i y^j, i + j <= 4, in the order of ``MOMENT_POWERS``).
    """
    K, P = len(conics), len(hyp)
    sel = np.zeros(P, np.bool_)
    m = np.zeros((K, 2))
    n = np.zeros(K)
    for k in range(P):
        q = conics[hyp[k]]
        a, b, c, d, e, f = q[0], q[1], q[2], q[3], q[4], q[5]
        x, y = px[k], py[k]
        gx = 2 * a * x + b * y + d
        gy = b * x + 2 * c * y + e
        val = a * x * x + b * x * y + c * y * y + d * x + e * y + f
        gn = max(_norm(gx, gy), 1e-12)
        if abs(gx * ct[k] + gy * st[k]) >= cos_tol * gn and abs(val) <= band * gn:
            sel[k] = True
            m[hyp[k], 0] += x
            m[hyp[k], 1] += y
            n[hyp[k]] += 1.0
    for h in range(K):
        m[h] /= max(n[h], 1.0)
    s = np.zeros(K)
    for k in range(P):
        if sel[k]:
            h = hyp[k]
            s[h] = max(s[h], abs(px[k] - m[h, 0]), abs(py[k] - m[h, 1]))
    for h in range(K):
        s[h] = max(s[h], 1e-9) if n[h] > 0 else 1.0
    mom = np.zeros((K, 15))
    for k in range(P):
        if sel[k]:
            h = hyp[k]
            x, y = (px[k] - m[h, 0]) / s[h], (py[k] - m[h, 1]) / s[h]
            col = 0
            xi = 1.0
            for i in range(5):
                v = xi
                for _ in range(5 - i):
                    mom[h, col] += v
                    v *= y
                    col += 1
                xi *= x
    return sel, m, s, mom


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pw_leaf(a, lo, n, col):  # pragma: no cover - compiled
    """NumPy's pairwise sum of ``a[lo:lo + n, col]`` for n <= 128 (8 running sums)."""
    if n < 8:
        res = a[lo, col]
        for i in range(1, n):
            res += a[lo + i, col]
        return res
    r0, r1, r2, r3 = a[lo, col], a[lo + 1, col], a[lo + 2, col], a[lo + 3, col]
    r4, r5, r6, r7 = a[lo + 4, col], a[lo + 5, col], a[lo + 6, col], a[lo + 7, col]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i, col]
        r1 += a[lo + i + 1, col]
        r2 += a[lo + i + 2, col]
        r3 += a[lo + i + 3, col]
        r4 += a[lo + i + 4, col]
        r5 += a[lo + i + 5, col]
        r6 += a[lo + i + 6, col]
        r7 += a[lo + i + 7, col]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i, col]
        i += 1
    return res


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pairwise(a, lo, n, col):  # pragma: no cover - compiled
    """NumPy's pairwise sum of ``a[lo:lo + n, col]``, n >= 1, in ``a``'s type (``pairwise_sum``
    of its loops: 8 running sums over blocks of at most 128, halves above), to the same bits.
    The halves are kept on an explicit stack: a recursive kernel cannot be called from
    another module's cached kernels (its symbol is not resolved there)."""
    if n <= 128:
        return _pw_leaf(a, lo, n, col)
    st_lo = np.empty(64, np.int64)
    st_n = np.empty(64, np.int64)
    st_k = np.zeros(64, np.int64)
    vals = np.empty(64, a.dtype)
    depth = 0
    st_lo[0], st_n[0] = lo, n
    ret = a[lo, col]
    while True:
        l, m = st_lo[depth], st_n[depth]
        if m > 128:  # split: the left half first
            st_k[depth] = 1
            h = m // 2
            h -= h % 8
            depth += 1
            st_lo[depth], st_n[depth], st_k[depth] = l, h, 0
            continue
        ret = _pw_leaf(a, l, m, col)
        depth -= 1
        while depth >= 0:
            if st_k[depth] == 1:  # a left half done: keep it, do the right half
                vals[depth] = ret
                st_k[depth] = 2
                h = st_n[depth] // 2
                h -= h % 8
                depth += 1
                st_lo[depth], st_n[depth], st_k[depth] = st_lo[depth - 1] + h, st_n[depth - 1] - h, 0
                break
            ret = vals[depth] + ret  # both halves done
            depth -= 1
        if depth < 0:
            return ret


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _reduce_rows(w, a, e, out):  # pragma: no cover - compiled
    """``np.add.reduceat``'s sum of the rows ``a .. e - 1`` of ``w`` into ``out``: the first
    row plus the pairwise sum of the others (``w[a]`` when ``e - a <= 1``)."""
    for k in range(w.shape[1]):
        out[k] = w[a, k] + _pairwise(w, a + 1, e - a - 1, k) if e - a > 1 else w[a, k]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _monomials(out, r, x, y):  # pragma: no cover - compiled
    """Row ``r`` of :func:`rangesim.core.conics.conic_monomials` at (x, y), in their type:
    x^i y^j, i + j <= 4, in the order of ``MOMENT_POWERS``, the powers multiplied up as
    NumPy's ``x * x * x`` does."""
    x2, y2 = x * x, y * y
    x3, y3 = x2 * x, y2 * y
    x4, y4 = x3 * x, y3 * y
    out[r, 0], out[r, 1], out[r, 2], out[r, 3], out[r, 4] = 1.0, y, y2, y3, y4
    out[r, 5], out[r, 6], out[r, 7], out[r, 8] = x, x * y, x * y2, x * y3
    out[r, 9], out[r, 10], out[r, 11] = x2, x2 * y, x2 * y2
    out[r, 12], out[r, 13], out[r, 14] = x3, x3 * y, x4


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _reduceat(w, starts, out):  # pragma: no cover - compiled
    """``out = np.add.reduceat(w, starts, axis=0)`` for ``starts`` in order, to the bits: a
    range's first row plus NumPy's pairwise sum of the others (:func:`_pairwise`); an empty
    range (``starts[g] == starts[g + 1]``) gives the row at ``starts[g]``."""
    G, R = len(starts), len(w)
    for g in range(G):
        _reduce_rows(w, starts[g], starts[g + 1] if g + 1 < G else R, out[g])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def sampson_pairs(conics, hyp, xy, pt):  # pragma: no cover - compiled
    """(P,) Sampson distance of point ``pt[k]`` to conic ``hyp[k]``:
    :func:`rangesim.core.conics.sampson_distance_rows` without gathering the rows."""
    out = np.empty(len(pt))
    for k in range(len(pt)):
        q = conics[hyp[k]]
        a, b, c, d, e, f = q[0], q[1], q[2], q[3], q[4], q[5]
        x, y = xy[pt[k], 0], xy[pt[k], 1]
        v = a * x * x + b * x * y + c * y * y + d * x + e * y + f
        gx = 2 * a * x + b * y + d
        gy = b * x + 2 * c * y + e
        out[k] = abs(v) / max(np.hypot(gx, gy), 1e-12)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _group_sums(w, starts, n, out):  # pragma: no cover - compiled
    """:func:`rangesim.core.conics._group_sums` of sorted groups: ``np.add.reduceat`` of ``w``
    with one zero row after it (the last group's range runs to it), 0 where ``n[g] == 0``."""
    padded = np.zeros((len(w) + 1, w.shape[1]))
    padded[:len(w)] = w
    _reduceat(padded, starts, out)
    for g in range(len(starts)):
        if n[g] == 0:
            out[g] = 0.0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def grouped_frames(xy, pt, keep, group, G):  # pragma: no cover - compiled
    """Frames and moments of :func:`rangesim.core.conics.fit_conics_grouped`, to the bits.

    The points ``xy[pt[r]]`` of the rows ``r`` with ``keep[r]``, in groups ``group[r]``
    (sorted, 0 <= group < G). Returns the centroids m (G, 2), scales s (G,) (the largest
    coordinate offset from m, at least 1e-9; 1 for an empty group) and the (G, 15) sums of
    the monomials of ``(p - m) / s``, all in float64 as NumPy sums them there.
    """
    R = 0
    for r in range(len(pt)):
        if keep[r]:
            R += 1
    p = np.empty((R, 2))
    gr = np.empty(R, np.int64)
    j = 0
    for r in range(len(pt)):
        if keep[r]:
            p[j, 0] = xy[pt[r], 0]
            p[j, 1] = xy[pt[r], 1]
            gr[j] = group[r]
            j += 1
    n = np.zeros(G, np.int64)
    for j in range(R):
        n[gr[j]] += 1
    starts = np.searchsorted(gr, np.arange(G))
    m = np.empty((G, 2))
    _group_sums(p, starts, n, m)
    for g in range(G):
        c = max(n[g], 1)
        m[g, 0] /= c
        m[g, 1] /= c
    s = np.full(G, -np.inf)
    q = np.empty((R, 2))
    for j in range(R):
        g = gr[j]
        q[j, 0] = p[j, 0] - m[g, 0]
        q[j, 1] = p[j, 1] - m[g, 1]
        s[g] = max(s[g], max(abs(q[j, 0]), abs(q[j, 1])))
    for g in range(G):
        s[g] = max(s[g], 1e-9) if n[g] > 0 else 1.0
    mono = np.empty((R, 15))
    for j in range(R):
        _monomials(mono, j, q[j, 0] / s[gr[j]], q[j, 1] / s[gr[j]])
    mom = np.empty((G, 15))
    _group_sums(mono, starts, n, mom)
    return m, s, mom


# -- growing few conics, all compiled (the circle finder's ellipse-end check) ---------------

@numba.njit(cache=True, nogil=True, error_model="numpy")
def _is_real_ellipse(q):  # pragma: no cover - compiled
    """:func:`rangesim.core.conics.ellipse_params`' test of one conic, with its centre and
    semi-major axis (px)."""
    ok, cx, cy, a, _, _ = ellipse_row(q)
    return ok, cx, cy, a


@numba.njit(cache=True, nogil=True, error_model="numpy")
def grow_few(conics, xy, ct_all, st_all, bands, cos_tol, margin):  # pragma: no cover - compiled
    """:func:`rangesim.features._arc_ellipses.grow` for a few conics, in one compiled call.

    The candidates of each conic are the points within its bounding box (semi-major axis +
    ``bands[0]`` + ``margin`` + 1 px, Chebyshev) and ``bands[0] + margin`` px (Sampson) of the
    first conic, looked at by one pass over all points per conic (work K x N: for the few
    circles the circle finder checks, not for the thousands of arc hypotheses).

    Returns conics (K, 6), ok (K,), and the (conic, point) pairs of the last band's inliers.
    """
    K = conics.shape[0]
    N = xy.shape[0]
    conics = conics.copy()
    ok = np.zeros(K, np.bool_)
    # two passes over the points, counting then filling: memory follows the candidates
    hyp = np.empty(0, np.int64)
    pt = np.empty(0, np.int64)
    for fill in range(2):
        count = 0
        for k in range(K):
            real, cx, cy, a = _is_real_ellipse(conics[k])
            ok[k] = real
            if not real:
                continue
            reach = a + bands[0] + margin + 1
            q = conics[k]
            for n in range(N):
                x, y = xy[n, 0], xy[n, 1]
                if abs(x - cx) > reach or abs(y - cy) > reach:
                    continue
                v = q[0] * x * x + q[1] * x * y + q[2] * y * y + q[3] * x + q[4] * y + q[5]
                gx = 2 * q[0] * x + q[1] * y + q[3]
                gy = q[1] * x + 2 * q[2] * y + q[4]
                if abs(v) / max(np.hypot(gx, gy), 1e-12) <= bands[0] + margin:
                    if fill == 1:
                        hyp[count] = k
                        pt[count] = n
                    count += 1
        if fill == 0:
            hyp = np.empty(count, np.int64)
            pt = np.empty(count, np.int64)
    px, py = xy[pt, 0].copy(), xy[pt, 1].copy()
    ct, st = ct_all[pt].copy(), st_all[pt].copy()
    new, v = np.empty(6), np.empty(6)
    sel = np.zeros(count, np.bool_)
    for b in range(len(bands)):
        sel, m, s, mom = band_moments(conics, hyp, px, py, ct, st, bands[b], cos_tol)
        if b == len(bands) - 1:
            break
        for k in range(K):
            if ok[k] and mom[k, 0] >= 6 and direct_fit(mom[k], m[k, 0], m[k, 1], s[k], new, v) >= 0:
                if _is_real_ellipse(new)[0]:
                    conics[k] = new
    for k in range(K):
        ok[k] = ok[k] and _is_real_ellipse(conics[k])[0]
    return conics, ok, hyp[sel], pt[sel]
