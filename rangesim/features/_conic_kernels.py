"""Compiled inner loop of the conic refits (Numba): the edge points near each conic whose normal
agrees with the conic's, and the moments of each conic's points that its direct fit needs, in
one pass per band (the batched array version costs about a hundred NumPy calls per band)."""
from __future__ import annotations

import numba
import numpy as np

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
