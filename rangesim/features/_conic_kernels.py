"""Compiled inner loop of the conic refits (Numba): the edge points near each conic whose normal
agrees with the conic's, and the moments of each conic's points that its direct fit needs, in
one pass per band (the batched array version costs about a hundred NumPy calls per band)."""
from __future__ import annotations

import numba
import numpy as np

from rangesim.core._conic_kernels import direct_fit, ellipse_row
from rangesim.features._circle_kernels import _norm


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _add_moments(mom, x, y):  # pragma: no cover - compiled
    """Add :func:`rangesim.core.conics.conic_monomials` of (x, y) (x^i y^j, i + j <= 4, in the
    order of ``MOMENT_POWERS``) to the float64 moments ``mom`` (15,).

    Every moment of the model-free ellipse finder is summed this way, point by point in
    float64: more exact than the float32 rows NumPy's batched form summed, and without a
    scratch buffer and a pass per column (summed that way, they took a quarter of the finder's
    time)."""
    x2, y2 = x * x, y * y
    x3, y3 = x2 * x, y2 * y
    mom[0] += 1.0
    mom[1] += y
    mom[2] += y2
    mom[3] += y3
    mom[4] += y3 * y
    mom[5] += x
    mom[6] += x * y
    mom[7] += x * y2
    mom[8] += x * y3
    mom[9] += x2
    mom[10] += x2 * y
    mom[11] += x2 * y2
    mom[12] += x3
    mom[13] += x3 * y
    mom[14] += x3 * x


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
            _add_moments(mom[h], (px[k] - m[h, 0]) / s[h], (py[k] - m[h, 1]) / s[h])
    return sel, m, s, mom


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
def grouped_frames(xy, pt, keep, group, G):  # pragma: no cover - compiled
    """Frames and moments of :func:`rangesim.core.conics.fit_conics_grouped`, compiled.

    The points ``xy[pt[r]]`` of the rows ``r`` with ``keep[r]``, in groups ``group[r]``
    (0 <= group < G). Returns the centroids m (G, 2), scales s (G,) (the largest coordinate
    offset from m, at least 1e-9; 1 for an empty group) and the (G, 15) float64 sums of the
    monomials of ``(p - m) / s`` (:func:`_add_moments`).
    """
    m = np.zeros((G, 2))
    n = np.zeros(G, np.int64)
    for r in range(len(pt)):
        if keep[r]:
            g = group[r]
            m[g, 0] += xy[pt[r], 0]
            m[g, 1] += xy[pt[r], 1]
            n[g] += 1
    for g in range(G):
        c = max(n[g], 1)
        m[g, 0] /= c
        m[g, 1] /= c
    s = np.full(G, -np.inf)
    for r in range(len(pt)):
        if keep[r]:
            g = group[r]
            s[g] = max(s[g], abs(xy[pt[r], 0] - m[g, 0]), abs(xy[pt[r], 1] - m[g, 1]))
    for g in range(G):
        s[g] = max(s[g], 1e-9) if n[g] > 0 else 1.0
    mom = np.zeros((G, 15))
    for r in range(len(pt)):
        if keep[r]:
            g = group[r]
            _add_moments(mom[g], (xy[pt[r], 0] - m[g, 0]) / s[g], (xy[pt[r], 1] - m[g, 1]) / s[g])
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
