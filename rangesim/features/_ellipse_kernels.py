"""Compiled stages of the model-free ellipse finder (Numba): curve linking, the arc pieces of
the tilings and their fits, the outer outlines, the distinct hypotheses, their growth, the
coverage and the claims (:mod:`._arc_ellipses`).

Each stage is one compiled call whose loops follow the edge points and the hypotheses: the
batched NumPy form it replaces cost a few hundred array calls per map (sorts, uniques,
bincounts, fancy indexing), most of the finder's time on maps of a few thousand points. The
orders are the NumPy form's (the same stable orders of pieces and hypotheses); the moments of
the fits are summed point by point in float64 (:func:`~._conic_kernels._add_moments`), not as
the NumPy form's float32 rows and pairwise sums, which moves a fit by round-off only.
"""
from __future__ import annotations

import numba
import numpy as np

from rangesim.core._conic_kernels import direct_fit, ellipse_row
from rangesim.features._conic_kernels import _add_moments, grouped_frames

_JIT = dict(cache=True, nogil=True, error_model="numpy")
TWO_PI = 2 * np.pi
#: two ellipse hypotheses are one (:func:`distinct_conics`) only when their semi-axes differ by
#: at most this, px, besides 20 % (and their centres by 2 px): the first growth band's width, so
#: that hypotheses farther apart, which would grow onto different edges (concentric rims a
#: few pixels apart: a counterbore, a chamfer, a hole's two rims head-on), are both grown
DISTINCT_MAX_PX = 3.0


# -- helpers ------------------------------------------------------------------------------------

@numba.njit(**_JIT)
def _find(parent, i):  # pragma: no cover - compiled
    """Root of ``i`` in a union-find forest (path halving)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(**_JIT)
def _union(parent, i, k):  # pragma: no cover - compiled
    """Join the trees of ``i`` and ``k`` (the smaller root becomes the root)."""
    ri, rk = _find(parent, i), _find(parent, k)
    if ri < rk:
        parent[rk] = ri
    elif rk < ri:
        parent[ri] = rk


@numba.njit(**_JIT)
def _sampson(q, x, y):  # pragma: no cover - compiled
    """Sampson distance of (x, y) to the conic ``q``: :func:`~._conic_kernels.sampson_pairs`,
    with the gradient's norm by sqrt (libm's hypot, several times the cost, guards against an
    overflow that pixel coordinates never reach; the two differ by an ulp at most)."""
    a, b, c, d, e, f = q[0], q[1], q[2], q[3], q[4], q[5]
    v = a * x * x + b * x * y + c * y * y + d * x + e * y + f
    gx = 2 * a * x + b * y + d
    gy = b * x + 2 * c * y + e
    return abs(v) / max(np.sqrt(gx * gx + gy * gy), 1e-12)


@numba.njit(**_JIT)
def _angle(px, py, cx, cy, ca, sa, a, b):  # pragma: no cover - compiled
    """Parametric angle in [0, 2 pi) of (px, py) about an ellipse (centre, cos and sin of its
    angle, semi-axes): :func:`~._arc_ellipses._parametric_angle`'s arithmetic."""
    dx, dy = px - cx, py - cy
    u = (dx * ca + dy * sa) / max(a, 1e-9)
    v = (-dx * sa + dy * ca) / max(b, 1e-9)
    t = np.arctan2(v, u)
    if t < 0:
        t += TWO_PI
    return t


@numba.njit(**_JIT)
def _stable_argsort(key):  # pragma: no cover - compiled
    """``np.argsort(key, kind="stable")`` (merge sort: equal keys keep their order)."""
    return np.argsort(key, kind="mergesort")


@numba.njit(**_JIT)
def pixel_index(x, y, margin):  # pragma: no cover - compiled
    """The index image of points at int pixels ``x, y`` (N,) (distinct, >= 0): the point at
    pixel (x, y) is at ``[y + margin, x + margin]``, -1 elsewhere, with ``margin`` pixels of
    -1 around the points' box (so neighbour lookups up to ``margin`` away need no bounds test)."""
    W = 0
    H = 0
    for i in range(len(x)):
        W = max(W, x[i])
        H = max(H, y[i])
    index = np.full((H + 2 * margin + 1, W + 2 * margin + 1), -1, np.int32)
    for i in range(len(x)):
        index[y[i] + margin, x[i] + margin] = i
    return index


# -- curves -------------------------------------------------------------------------------------

@numba.njit(**_JIT)
def curve_labels(x, y, theta, R, cos_link, sin_link, cos_adjacent):  # pragma: no cover - compiled
    """Labels of the smooth curves: the connected components of the links of
    :func:`~._arc_ellipses.smooth_curves`, numbered by their first point as
    ``scipy.sparse.csgraph.connected_components`` numbers them.

    Each point looks at the pixels of half the (2R+1)^2 window (dy > 0, or dy == 0 and
    dx > 0, so a pair is seen once) through an index image: linked when the normals agree
    within ``cos_link`` (the cosine of their difference from the normals' cosines and sines)
    and the step runs along both tangents (within ``sin_link`` of the tangent across a
    bridged gap, at least ``cos_adjacent`` off the normal between 8-neighbours).

    ``x, y`` (N,) int pixels (distinct, >= 0), ``theta`` (N,) normals. Returns (labels (N,),
    number of curves).
    """
    n = len(x)
    index = pixel_index(x, y, R)
    ct, st = np.empty(n), np.empty(n)
    for i in range(n):
        ct[i], st[i] = np.cos(theta[i]), np.sin(theta[i])
    # the half window's offsets: the 8-neighbours (always looked at), and the farther ones
    # by the direction of the normal, in NB bins of theta mod pi: only those within the link
    # angle of the bin's tangent (plus half a bin and a degree: a superset of the offsets the
    # test below can pass, so the same links; the components do not depend on the order in
    # which links are joined)
    NB = 64
    far_dx = np.empty(2 * R * R + 2 * R, np.int64)
    far_dy = np.empty(2 * R * R + 2 * R, np.int64)
    F = 0
    for dy in range(0, R + 1):
        for dx in range(-R, R + 1):
            if (dy == 0 and dx <= 0) or max(abs(dx), abs(dy)) <= 1:
                continue
            far_dx[F], far_dy[F] = dx, dy
            F += 1
    cone = np.arcsin(min(sin_link, 1.0)) + np.pi / NB / 2 + np.pi / 180
    tab = np.empty((NB + 1, F), np.int64)
    tcount = np.zeros(NB + 1, np.int64)
    for f in range(F):  # row NB: every offset (a normal that is not finite)
        tab[NB, f] = f
    tcount[NB] = F
    for bn in range(NB):
        tangent = (bn + 0.5) * np.pi / NB + np.pi / 2  # the bin's normal, turned
        for f in range(F):
            phi = np.arctan2(far_dy[f], far_dx[f]) - tangent
            phi = abs(phi - np.pi * np.floor(phi / np.pi + 0.5))  # angle to the tangent line, 0 .. pi / 2
            if phi <= cone:
                tab[bn, tcount[bn]] = f
                tcount[bn] += 1
    parent = np.arange(n)
    for i in range(n):
        ci, si = ct[i], st[i]
        bn = NB
        if np.isfinite(theta[i]):
            bn = min(max(int((theta[i] % np.pi) / np.pi * NB), 0), NB - 1)
        for f in range(-4, tcount[bn]):
            if f < 0:  # the 8-neighbours of the half window
                dx, dy = (1, -1, 0, 1)[f + 4], (0, 1, 1, 1)[f + 4]
            else:
                dx, dy = far_dx[tab[bn, f]], far_dy[tab[bn, f]]
            if R < 1 and f < 0:
                continue
            k = index[y[i] + R + dy, x[i] + R + dx]
            if k < 0:
                continue
            if abs(ci * ct[k] + si * st[k]) < cos_link:  # cos(theta_i - theta_k)
                continue
            step = np.sqrt(dx * dx + dy * dy)
            lim = sin_link if max(abs(dx), abs(dy)) > 1 else cos_adjacent
            if abs(dx * ci + dy * si) > lim * step:
                continue
            if abs(dx * ct[k] + dy * st[k]) > lim * step:
                continue
            _union(parent, i, k)
    lab = np.full(n, -1, np.int64)
    out = np.empty(n, np.int64)
    m = 0
    for i in range(n):
        r = _find(parent, i)
        if lab[r] < 0:
            lab[r] = m
            m += 1
        out[i] = lab[r]
    return out, m


# -- fits of groups of pieces -------------------------------------------------------------------

@numba.njit(**_JIT)
def fit_groups(xy, pts, sa, na, sb, nb, mom, frame, max_rms, min_inliers, ax_lo, ax_hi, min_ratio,
               min_arc_deg, trim_rms):  # pragma: no cover - compiled
    """:func:`~._arc_ellipses._fit_pieces`: direct fits of groups from their moments, checked
    on their points after one trimmed refit.

    Group g is the points ``pts[sa[g]:sa[g] + na[g]]`` then ``pts[sb[g]:sb[g] + nb[g]]``;
    ``mom`` (G, 15) their moments in the frames ``frame`` (G, 3) (origin x, y, scale).

    Returns conics (G, 6), curved (G,) (the first fit is a real ellipse within the largest
    axis) and good (G,) (after the refit: a close fit over ``min_arc_deg`` of its ellipse,
    within the axes range).
    """
    G = len(sa)
    conics = np.zeros((G, 6))
    curved = np.zeros(G, np.bool_)
    good = np.zeros(G, np.bool_)
    v = np.empty(6)
    idx = np.empty(G, np.int64)
    L = 0
    R = 0
    for g in range(G):
        r = direct_fit(mom[g], frame[g, 0], frame[g, 1], frame[g, 2], conics[g], v)
        if r < 0:
            conics[g] = 0.0
            continue
        real, _, _, A, B, _ = ellipse_row(conics[g])
        curved[g] = real and A <= ax_hi
        if curved[g] and r <= trim_rms and B >= 0.5 * ax_lo:
            idx[L] = g
            L += 1
            R += na[g] + nb[g]
    if L == 0:
        return conics, curved, good
    # the points of the groups left, group by group (a's then b's)
    gid = np.empty(R, np.int64)
    pt = np.empty(R, np.int64)
    j = 0
    for li in range(L):
        g = idx[li]
        for k in range(na[g]):
            gid[j] = li
            pt[j] = pts[sa[g] + k]
            j += 1
        for k in range(nb[g]):
            gid[j] = li
            pt[j] = pts[sb[g] + k]
            j += 1
    inl = np.empty(R, np.bool_)
    n_in = np.zeros(L, np.int64)
    for j in range(R):
        inl[j] = _sampson(conics[idx[gid[j]]], xy[pt[j], 0], xy[pt[j], 1]) <= 1.0
        if inl[j]:
            n_in[gid[j]] += 1
    # one trimmed refit: the points within 1 px of the first fit
    m_in, s_in, mom_in = grouped_frames(xy, pt, inl, gid, L)
    new = np.empty(6)
    for li in range(L):
        if direct_fit(mom_in[li], m_in[li, 0], m_in[li, 1], s_in[li], new, v) >= 0 and n_in[li] >= 6:
            if ellipse_row(new)[0]:
                conics[idx[li]] = new
    # the checks on the points: the residual and inlier share first, the arc (an atan2 per
    # inlier) only of the fits that pass them
    occ = np.zeros(36, np.bool_)
    j = 0
    for li in range(L):
        g = idx[li]
        q = conics[g]
        j0 = j
        m = 0
        cnt = 0
        s2 = 0.0
        while j < R and gid[j] == li:
            d = _sampson(q, xy[pt[j], 0], xy[pt[j], 1])
            m += 1
            if d <= 1.0:
                cnt += 1
                s2 += d * d
            j += 1
        rms = np.sqrt(s2 / cnt)
        frac = cnt / m
        real, cx, cy, A, B, ang = ellipse_row(q)
        if not (rms <= max_rms and frac >= min_inliers and real and B >= ax_lo and A <= ax_hi and B >= min_ratio * A):
            continue
        ca, sa_ = np.cos(ang), np.sin(ang)
        occ[:] = False
        for r in range(j0, j):
            x, y = xy[pt[r], 0], xy[pt[r], 1]
            if _sampson(q, x, y) <= 1.0:
                t = _angle(x, y, cx, cy, ca, sa_, A, B)
                occ[min(int(t / TWO_PI * 36), 35)] = True
        arc = 0.0
        for k in range(36):
            if occ[k]:
                arc += 1.0
        good[g] = arc * 10.0 >= min_arc_deg
    return conics, curved, good


@numba.njit(**_JIT)
def _piece_moments(xy, pts, start, cnt, frame, out):  # pragma: no cover - compiled
    """Float64 moments of the points ``pts[start:start + cnt]`` in ``frame`` (x, y, scale)
    into ``out`` (15,)."""
    out[:] = 0.0
    f0, f1, f2 = frame[0], frame[1], frame[2]
    for r in range(cnt):
        p = pts[start + r]
        _add_moments(out, (xy[p, 0] - f0) / f2, (xy[p, 1] - f1) / f2)


@numba.njit(**_JIT)
def frame_moments(xy, pts, lo, n, frame, mom):  # pragma: no cover - compiled
    """The frame (centroid, largest coordinate offset, at least 1 px) and float64 moments
    (:func:`~._conic_kernels._add_moments`) of the points ``pts[lo:lo + n]``."""
    sx, sy = 0.0, 0.0
    for r in range(lo, lo + n):
        sx += xy[pts[r], 0]
        sy += xy[pts[r], 1]
    cx, cy = sx / n, sy / n
    s = 0.0
    for r in range(lo, lo + n):
        s = max(s, max(abs(xy[pts[r], 0] - cx), abs(xy[pts[r], 1] - cy)))
    s = max(s, 1.0)
    frame[0], frame[1], frame[2] = cx, cy, s
    mom[:] = 0.0
    for r in range(lo, lo + n):
        _add_moments(mom, (xy[pts[r], 0] - cx) / s, (xy[pts[r], 1] - cy) / s)


@numba.njit(**_JIT)
def _counting_sort(key, n, n_keys):  # pragma: no cover - compiled
    """The indices ``0 .. n - 1`` ordered by ``key`` (stable counting sort; keys in
    ``0 .. n_keys - 1``) and each key's start in that order, (n_keys + 1,)."""
    start = np.zeros(n_keys + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for c in range(n_keys):
        start[c + 1] += start[c]
    order = np.empty(n, np.int64)
    fill = start[:-1].copy()
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    return order, start


@numba.njit(**_JIT)
def _by_curve_count_sum(curve, cnt, psum, P, n_curves):  # pragma: no cover - compiled
    """The order of the pieces ``0 .. P - 1`` by (curve, count, sum), stable: a counting sort by
    curve, then each curve's pieces by (count, sum) (insertion sort; two stable merge sorts
    for a curve of many pieces)."""
    o, start = _counting_sort(curve, P, n_curves)
    for c in range(n_curves):
        lo, hi = start[c], start[c + 1]
        if hi - lo <= 64:
            for r in range(lo + 1, hi):
                v = o[r]
                j = r - 1
                while j >= lo and (cnt[o[j]] > cnt[v] or (cnt[o[j]] == cnt[v] and psum[o[j]] > psum[v])):
                    o[j + 1] = o[j]
                    j -= 1
                o[j + 1] = v
        else:
            seg = o[lo:hi].copy()
            seg = seg[_stable_argsort(psum[seg])]
            seg = seg[_stable_argsort(cnt[seg])]
            o[lo:hi] = seg
    return o


@numba.njit(**_JIT)
def _moments_of(xy, pts, p, start, cnt, frame, mom, have):  # pragma: no cover - compiled
    """The moments of piece ``p`` into ``mom[p]``, once (``have``)."""
    if have[p]:
        return
    _piece_moments(xy, pts, start[p], cnt[p], frame[p], mom[p])
    have[p] = True


# -- arc pieces -----------------------------------------------------------------------------------

@numba.njit(**_JIT)
def arc_pieces(xy, curve, n_curves, tiles, min_points, pairs_per_tile, max_rms, min_inliers, ax_lo, ax_hi,
               min_ratio, min_arc_deg):  # pragma: no cover - compiled
    """:func:`~._arc_ellipses.arc_hypotheses`: the pieces of each curve in the tiles of every
    tiling, the good fits of single pieces (fitted once when a piece recurs in several
    tilings) and of pairs of curved pieces sharing a tile, the most points first.

    Returns conics (K, 6) and their points (K,).
    """
    N = len(xy)
    T = 2 * len(tiles)
    # points by curve (stable): each tiling's counting sort by tile then keeps (tile, curve, index)
    by_curve, cstart = _counting_sort(curve, N, n_curves)
    pts = np.empty(T * N, np.int64)  # the pieces' points, piece after piece
    p_start = np.empty(T * N, np.int64)
    p_cnt = np.empty(T * N, np.int64)
    p_tile = np.empty(T * N, np.int64)
    p_curve = np.empty(T * N, np.int64)
    p_sum = np.empty(T * N, np.int64)
    p_frame = np.empty((T * N, 3))
    tx = np.empty(N, np.int64)
    ty = np.empty(N, np.int64)
    tb = np.empty(N, np.int64)
    P = 0
    at = 0
    n_tiles = 0
    for t in range(T):
        s = tiles[t // 2]
        o = 0 if t % 2 == 0 else s // 2
        x0, x1, y0, y1 = 1 << 62, -(1 << 62), 1 << 62, -(1 << 62)
        if s > 0 and (s & (s - 1)) == 0:  # a power of two: (x + o) / s is (x + o) * (1 / s) to the bit
            inv = 1.0 / s
            for i in range(N):
                tx[i] = np.int64(np.floor((xy[i, 0] + o) * inv))
                ty[i] = np.int64(np.floor((xy[i, 1] + o) * inv))
        else:
            for i in range(N):
                tx[i] = np.int64(np.floor((xy[i, 0] + o) / s))
                ty[i] = np.int64(np.floor((xy[i, 1] + o) / s))
        for i in range(N):
            x0, x1, y0, y1 = min(x0, tx[i]), max(x1, tx[i]), min(y0, ty[i]), max(y1, ty[i])
        nx = x1 - x0 + 1
        nb = nx * (y1 - y0 + 1)
        bstart = np.zeros(nb + 1, np.int64)
        for i in range(N):
            tb[i] = (ty[i] - y0) * nx + tx[i] - x0  # the point's tile
            bstart[tb[i] + 1] += 1
        for b in range(nb):
            bstart[b + 1] += bstart[b]
        for r in range(N):
            i = by_curve[r]
            b = tb[i]
            pts[at + bstart[b]] = i
            bstart[b] += 1
        # runs of (tile, curve) in that order: the pieces
        prev_b = -1
        for r in range(N):
            i = pts[at + r]
            b = tb[i]
            if b != prev_b:
                n_tiles += 1
            if b != prev_b or curve[i] != p_curve[P - 1]:
                p_start[P] = at + r
                p_cnt[P] = 0
                p_tile[P] = n_tiles - 1
                p_curve[P] = curve[i]
                p_sum[P] = 0
                p_frame[P, 0] = (tx[i] + 0.5) * s - o
                p_frame[P, 1] = (ty[i] + 0.5) * s - o
                p_frame[P, 2] = s / 2
                P += 1
            p_cnt[P - 1] += 1
            p_sum[P - 1] += i
            prev_b = b
        at += N
    small = max(5, min_points // 3)
    # moments of the pieces fitted only: the first copies, then the pieces of pairs
    mom = np.zeros((P, 15))
    have = np.zeros(P, np.bool_)
    # first copies: pieces of the same curve, count and sum of point indices, by those keys
    o3 = _by_curve_count_sum(p_curve, p_cnt, p_sum, P, n_curves)
    same_as = np.empty(P, np.int64)
    first = np.empty(P, np.int64)
    U = 0
    for r in range(P):
        p = o3[r]
        if r == 0 or p_curve[p] != p_curve[o3[r - 1]] or p_cnt[p] != p_cnt[o3[r - 1]] or p_sum[p] != p_sum[o3[r - 1]]:
            first[U] = p
            U += 1
        same_as[p] = first[U - 1]
    single = np.empty(U, np.int64)
    S = 0
    for u in range(U):
        if p_cnt[first[u]] >= small:
            single[S] = first[u]
            S += 1
    single = single[:S]
    for p in single:
        _moments_of(xy, pts, p, p_start, p_cnt, p_frame, mom, have)
    zero = np.zeros(S, np.int64)
    conics1, curved1, good1 = fit_groups(xy, pts, p_start[single], p_cnt[single], zero, zero, mom[single],
                                         p_frame[single], max_rms, min_inliers, ax_lo, ax_hi, min_ratio,
                                         min_arc_deg, 3.0)
    is_curved = np.zeros(P, np.bool_)
    for k in range(S):
        if curved1[k]:
            is_curved[single[k]] = True
    # pairs: the largest few curved pieces of each tile (pieces are in tile order already)
    cand = np.empty(P, np.int64)
    C = 0
    for p in range(P):
        if is_curved[same_as[p]] and p_cnt[p] >= small:
            cand[C] = p
            C += 1
    cand = cand[:C]
    r0 = 0
    while r0 < C:  # within a tile: the most points first (stable insertion sort)
        r1 = r0 + 1
        while r1 < C and p_tile[cand[r1]] == p_tile[cand[r0]]:
            r1 += 1
        for r in range(r0 + 1, r1):
            v = cand[r]
            j = r - 1
            while j >= r0 and p_cnt[cand[j]] < p_cnt[v]:
                cand[j + 1] = cand[j]
                j -= 1
            cand[j + 1] = v
        r0 = r1
    keep = np.empty(C, np.int64)
    Ck = 0
    rank = 0
    for r in range(C):
        rank = rank + 1 if r > 0 and p_tile[cand[r]] == p_tile[cand[r - 1]] else 0
        if rank < pairs_per_tile:
            keep[Ck] = cand[r]
            Ck += 1
    cand = keep[:Ck]
    pa = np.empty(Ck * pairs_per_tile, np.int64)
    pb = np.empty(Ck * pairs_per_tile, np.int64)
    Q = 0
    for k in range(1, pairs_per_tile):
        for r in range(Ck - k):
            if p_tile[cand[r]] == p_tile[cand[r + k]]:
                pa[Q] = cand[r]
                pb[Q] = cand[r + k]
                Q += 1
    key = np.empty(Q, np.int64)
    for q in range(Q):
        fa, fb = same_as[pa[q]], same_as[pb[q]]
        key[q] = min(fa, fb) * P + max(fa, fb)
    ok = _stable_argsort(key)
    qa = np.empty(Q, np.int64)
    qb = np.empty(Q, np.int64)
    M = 0
    for r in range(Q):
        q = ok[r]
        if r > 0 and key[q] == key[ok[r - 1]]:
            continue
        if p_cnt[pa[q]] + p_cnt[pb[q]] >= min_points:
            qa[M] = pa[q]
            qb[M] = pb[q]
            M += 1
    qa, qb = qa[:M], qb[:M]
    mom2 = np.empty((M, 15))
    for q in range(M):
        _moments_of(xy, pts, qa[q], p_start, p_cnt, p_frame, mom, have)
        _moments_of(xy, pts, qb[q], p_start, p_cnt, p_frame, mom, have)
        for k in range(15):
            mom2[q, k] = mom[qa[q], k] + mom[qb[q], k]
    conics2, _, good2 = fit_groups(xy, pts, p_start[qa], p_cnt[qa], p_start[qb], p_cnt[qb], mom2, p_frame[qa],
                                   max_rms, min_inliers, ax_lo, ax_hi, min_ratio, min_arc_deg, 3.0)
    # the good ones: singles then pairs, the most points first (stable)
    K = 0
    for k in range(S):
        good1[k] = good1[k] and p_cnt[single[k]] >= min_points
        K += good1[k]
    for q in range(M):
        K += good2[q]
    out = np.empty((K, 6))
    npts = np.empty(K, np.int64)
    j = 0
    for k in range(S):
        if good1[k]:
            out[j] = conics1[k]
            npts[j] = p_cnt[single[k]]
            j += 1
    for q in range(M):
        if good2[q]:
            out[j] = conics2[q]
            npts[j] = p_cnt[qa[q]] + p_cnt[qb[q]]
            j += 1
    o = _stable_argsort(-npts)
    return out[o], npts[o]


# -- outer outlines -----------------------------------------------------------------------------

@numba.njit(**_JIT)
def outline_points(pix, g, inner=False):  # pragma: no cover - compiled
    """The points of :func:`~._arc_ellipses.outline_hypotheses`' outlines.

    The pixels dilated by a (2 g + 1) square make groups (8-connected) amid background
    regions (4-connected), both found on the rows' runs; a point is on its group's outline
    when a 4-neighbour of its footprint lies in the group's outer region (that of the pixel
    left of the group's leftmost pixel).

    With ``inner``, the inner outlines follow: for each background region that a group
    encloses (every region a point's footprint touches but its group's outer region), the
    group's points with a 4-neighbour of their footprint in it (what ``cv2.findContours`` with
    ``RETR_LIST`` adds to the outer contours: a rim's inside when its group also holds the
    sides of a boss or the edges of a floor, which spoil the group's outer outline). Regions
    are numbered after the groups, in raster order of the first point that touches them.

    Returns the outline points (indices, by group), their group (0 .. n_groups - 1, groups
    numbered in raster order of their first pixel, as ``ndimage.label`` numbers them; then
    the inner regions) and the number of points of each group.
    """
    N = len(pix)
    pad = g + 1
    # the points' box, with a margin of pad px: the background ring round it joins every
    # region that reaches it, as the rest of the image would (the same regions, groups, and
    # raster order of the groups)
    x0, y0, x1, y1 = pix[0, 0], pix[0, 1], pix[0, 0], pix[0, 1]
    for i in range(N):
        x0, x1 = min(x0, pix[i, 0]), max(x1, pix[i, 0])
        y0, y1 = min(y0, pix[i, 1]), max(y1, pix[i, 1])
    ox, oy = pad - x0, pad - y0
    W = x1 + ox + pad + 1
    H = y1 + oy + pad + 1
    # runs of each row, background and foreground alternating (the first and the last are
    # background: the margin), from the points' footprints [x - g, x + g] on the rows y - g ..
    # y + g merged, row by row: the work follows the points, not the box's pixels
    key = (pix[:, 1] + oy) * W + (pix[:, 0] + ox)
    o = np.arange(N)
    in_order = True  # edge_points gives the points in raster order: no sort then
    for i in range(1, N):
        if key[i] < key[i - 1]:
            in_order = False
            break
    if not in_order:  # (an argsort inside the loop's branch cost a sort's time on every call)
        o = np.argsort(key)
    pstart = np.zeros(H + 1, np.int64)
    for i in range(N):
        pstart[pix[i, 1] + oy + 1] += 1
    for y in range(H):
        pstart[y + 1] += pstart[y]
    # room for every run at once (arrays that grow and are rebound inside the loop cost
    # reference counting on every access): a row holds a first background run, then a
    # foreground and a background run per point of its 2 g + 1 rows at most, and at most one
    # per 2 g + 2 columns (a dilated run is 2 g + 1 wide, with a gap after it)
    per_row = W // (2 * g + 2) + 1
    cap = 1
    for y in range(H):
        cap += 1 + 2 * min(pstart[min(y + g + 1, H)] - pstart[max(y - g, 0)], per_row)
    rs = np.empty(cap, np.int64)
    re = np.empty(cap, np.int64)
    rf = np.empty(cap, np.bool_)
    row0 = np.empty(H + 1, np.int64)
    heads = np.empty(2 * g + 1, np.int64)
    ends = np.empty(2 * g + 1, np.int64)
    xs = np.empty(N, np.int64)  # the points' columns in raster order
    for k in range(N):
        xs[k] = pix[o[k], 0] + ox
    n_runs = 0
    for y in range(H):
        row0[y] = n_runs
        # a (2 g + 1)-way merge of the rows' points by x
        for k in range(2 * g + 1):
            yy = y - g + k
            heads[k] = pstart[yy] if 0 <= yy < H else 0
            ends[k] = pstart[yy + 1] if 0 <= yy < H else 0
        x_end = -1  # the last foreground column so far (-1: none yet)
        x_beg = 0
        bg_end = -1
        while True:
            best, bx = -1, 0
            for k in range(2 * g + 1):
                if heads[k] < ends[k]:
                    xk = xs[heads[k]]
                    if best < 0 or xk < bx:
                        best, bx = k, xk
            if best >= 0:
                heads[best] += 1
            if best >= 0 and x_end >= 0 and bx - g <= x_end + 1:
                x_end = max(x_end, bx + g)  # extends the current foreground run
                continue
            # close the current foreground run (and the background before it), start another
            if x_end >= 0:
                rs[n_runs], re[n_runs], rf[n_runs] = x_beg, bg_end, False
                rs[n_runs + 1], re[n_runs + 1], rf[n_runs + 1] = bg_end + 1, x_end, True
                n_runs += 2
                x_beg = x_end + 1
            if best < 0:
                break
            bg_end = bx - g - 1
            x_end = bx + g
        rs[n_runs], re[n_runs], rf[n_runs] = x_beg, W - 1, False
        n_runs += 1
    row0[H] = n_runs
    # components over the runs: foreground 8-connected, background 4-connected
    parent = np.arange(n_runs)
    for y in range(1, H):
        a, a1 = row0[y - 1], row0[y]
        for r in range(row0[y], row0[y + 1]):
            grow_ = 1 if rf[r] else 0
            while a < a1 and re[a] < rs[r] - grow_:
                a += 1
            b = a
            while b < a1 and rs[b] <= re[r] + grow_:
                if rf[b] == rf[r]:
                    _union(parent, r, b)
                b += 1
    # each run's root, once; group numbers in raster order of the first run; each group's
    # leftmost pixel
    rroot = np.empty(n_runs, np.int64)
    for r in range(n_runs):
        rroot[r] = _find(parent, r)
    gnum = np.full(n_runs, -1, np.int64)
    n_groups = 0
    for r in range(n_runs):
        if rf[r]:
            root = rroot[r]
            if gnum[root] < 0:
                gnum[root] = n_groups
                n_groups += 1
    left = np.full(n_groups, 1 << 62, np.int64)
    left_run = np.zeros(n_groups, np.int64)
    for y in range(H):
        for r in range(row0[y], row0[y + 1]):
            if rf[r]:
                k = gnum[rroot[r]]
                key = rs[r] * H + y
                if key < left[k]:
                    left[k] = key
                    left_run[k] = r
    outer = np.empty(n_groups, np.int64)  # root of the background run left of the leftmost pixel
    for k in range(n_groups):
        outer[k] = rroot[left_run[k] - 1]
    lab = np.empty(N, np.int64)
    on = np.zeros(N, np.bool_)
    count = np.zeros(n_groups, np.int64)
    # the inner outlines' (point, region) pairs, in raster order of the points
    pair_i = np.empty(4 * N if inner else 0, np.int64)
    pair_r = np.empty(4 * N if inner else 0, np.int64)
    n_pairs = 0
    region = np.full(n_runs if inner else 0, -1, np.int64)  # region number by root run
    n_regions = 0
    # the points in raster order (o): the runs holding a point and its 4-neighbours g + 1 px
    # away, by pointers that only move right along the rows y - g - 1, y and y + g + 1 (the
    # margin keeps those rows inside the box for every row that holds a point)
    for y in range(H):
        if pstart[y] == pstart[y + 1]:
            continue  # no point on this row (the margin rows among them: their neighbours lie outside)
        a, u, d = row0[y], row0[y - g - 1], row0[y + g + 1]
        for k in range(pstart[y], pstart[y + 1]):
            i, x = o[k], xs[k]
            while re[a] < x:
                a += 1
            while re[u] < x:
                u += 1
            while re[d] < x:
                d += 1
            lab[i] = gnum[rroot[a]]
            root = outer[lab[i]]
            # x - g - 1 lies in the point's own run or the background run before it (the run
            # starts at x - g at the latest); x + g + 1 likewise after it
            left = a if rs[a] <= x - g - 1 else a - 1
            right = a if re[a] >= x + g + 1 else a + 1
            for r in (u, d, left, right):
                if not rf[r] and rroot[r] == root:
                    on[i] = True
                    break
            if on[i]:
                count[lab[i]] += 1
            if inner:
                first = n_pairs
                for r in (u, d, left, right):
                    if rf[r] or rroot[r] == root:
                        continue
                    if region[rroot[r]] < 0:
                        region[rroot[r]] = n_regions
                        n_regions += 1
                    q = region[rroot[r]]
                    new = True
                    for p in range(first, n_pairs):  # a region met on two sides counts once
                        new = new and pair_r[p] != q
                    if new:
                        pair_i[n_pairs], pair_r[n_pairs] = i, q
                        n_pairs += 1
    # by group (stable), groups without outline points left out
    gid = np.full(n_groups, -1, np.int64)
    G = 0
    for k in range(n_groups):
        if count[k] > 0:
            gid[k] = G
            G += 1
    T = G + n_regions
    n = np.zeros(T, np.int64)
    start = np.zeros(T + 1, np.int64)
    for k in range(n_groups):
        if count[k] > 0:
            n[gid[k]] = count[k]
    for p in range(n_pairs):
        n[G + pair_r[p]] += 1
    for k in range(T):
        start[k + 1] = start[k] + n[k]
    idx = np.empty(start[T], np.int64)
    group = np.empty(start[T], np.int64)
    fill = start[:T].copy()
    for i in range(N):
        if on[i]:
            k = gid[lab[i]]
            idx[fill[k]] = i
            group[fill[k]] = k
            fill[k] += 1
    for p in range(n_pairs):  # stable: each region's points stay in raster order
        k = G + pair_r[p]
        idx[fill[k]] = pair_i[p]
        group[fill[k]] = k
        fill[k] += 1
    return idx, group, n


@numba.njit(**_JIT)
def outline_fits(xy, idx, n, min_points, max_rms, min_inliers, ax_lo, ax_hi, min_ratio,
                 min_arc_deg):  # pragma: no cover - compiled
    """Fits of the outlines (points ``idx`` by group, ``n`` per group): frames (centroid,
    largest offset, at least 1 px), moments, :func:`fit_groups` of those with
    ``min_points``. Returns the good conics and their points."""
    G = len(n)
    start = np.zeros(G, np.int64)
    for k in range(1, G):
        start[k] = start[k - 1] + n[k - 1]
    sel = np.nonzero(n >= min_points)[0]
    B = len(sel)
    frame = np.empty((B, 3))
    mom = np.empty((B, 15))
    for j in range(B):
        frame_moments(xy, idx, start[sel[j]], n[sel[j]], frame[j], mom[j])
    zero = np.zeros(B, np.int64)
    conics, _, good = fit_groups(xy, idx, start[sel], n[sel], zero, zero, mom, frame, max_rms, min_inliers,
                                 ax_lo, ax_hi, min_ratio, min_arc_deg, 3.0)
    keep = np.nonzero(good)[0]
    return conics[keep], n[sel][keep]


# -- distinct hypotheses ------------------------------------------------------------------------

@numba.njit(**_JIT)
def distinct_conics(conics, center_px, rel_size, max_px):  # pragma: no cover - compiled
    """:func:`~._arc_ellipses.distinct`: indices of the conics (in order) that repeat no
    earlier kept one (centres within ``center_px``, both semi-axes within ``rel_size`` of
    the later one's and within ``max_px``)."""
    K = len(conics)
    cx, cy = np.empty(K), np.empty(K)
    a, b = np.empty(K), np.empty(K)
    for k in range(K):
        _, x, y, a[k], b[k], _ = ellipse_row(conics[k])
        # as np.nan_to_num(nan=1e12, posinf=1e12, neginf=-1e12)
        cx[k] = 1e12 if np.isnan(x) else min(max(x, -1e12), 1e12) if np.isinf(x) else x
        cy[k] = 1e12 if np.isnan(y) else min(max(y, -1e12), 1e12) if np.isinf(y) else y
    o = _stable_argsort(cx)
    pos = np.empty(K, np.int64)
    for r in range(K):
        pos[o[r]] = r
    taken = np.zeros(K, np.bool_)
    kept = np.empty(K, np.int64)
    n_kept = 0
    r2 = center_px * center_px
    for j in range(K):
        if taken[j]:
            continue
        kept[n_kept] = j
        n_kept += 1
        # the later conics near it (by x, then the distance and the sizes)
        for step in (-1, 1):
            r = pos[j] + step
            while 0 <= r < K and abs(cx[o[r]] - cx[j]) <= center_px:
                k = o[r]
                if k > j and not taken[k]:
                    dx, dy = cx[k] - cx[j], cy[k] - cy[j]
                    if dx * dx + dy * dy <= r2 and abs(a[j] - a[k]) <= min(rel_size * a[k], max_px) \
                            and abs(b[j] - b[k]) <= min(rel_size * b[k], max_px):
                        taken[k] = True
                r += step
    return kept[:n_kept]


# -- growth -------------------------------------------------------------------------------------

@numba.njit(**_JIT)
def _band_pass(conics, seg, px, py, ct, st, band, cos_tol, last):  # pragma: no cover - compiled
    """:func:`~._conic_kernels.band_moments` of pairs sorted by conic (conic k's pairs are
    ``seg[k]:seg[k + 1]``): the same inliers, centroids, scales and moments to the bit (the
    same arithmetic, summed in the same order), with each conic's coefficients held over its
    run (a loop without gathers or branches, which the compiler vectorises) and, for the
    ``last`` band, the inliers only."""
    K, P = len(conics), len(px)
    sel = np.zeros(P, np.bool_)
    m = np.zeros((K, 2))
    n = np.zeros(K)
    for h in range(K):
        a, b, c, d, e, f = conics[h, 0], conics[h, 1], conics[h, 2], conics[h, 3], conics[h, 4], conics[h, 5]
        for k in range(seg[h], seg[h + 1]):
            x, y = px[k], py[k]
            gx = 2 * a * x + b * y + d
            gy = b * x + 2 * c * y + e
            val = a * x * x + b * x * y + c * y * y + d * x + e * y + f
            gn = max(np.sqrt(gx * gx + gy * gy), 1e-12)
            sel[k] = (abs(gx * ct[k] + gy * st[k]) >= cos_tol * gn) & (abs(val) <= band * gn)
    s = np.zeros(K)
    mom = np.zeros((K, 15))
    if last:
        return sel, m, s, mom
    for h in range(K):
        sx, sy, cnt = 0.0, 0.0, 0.0
        for k in range(seg[h], seg[h + 1]):
            if sel[k]:
                sx += px[k]
                sy += py[k]
                cnt += 1.0
        n[h] = cnt
        m[h, 0], m[h, 1] = sx / max(cnt, 1.0), sy / max(cnt, 1.0)
        sh = 0.0
        for k in range(seg[h], seg[h + 1]):
            if sel[k]:
                sh = max(sh, abs(px[k] - m[h, 0]), abs(py[k] - m[h, 1]))
        s[h] = max(sh, 1e-9) if cnt > 0 else 1.0
        for k in range(seg[h], seg[h + 1]):
            if sel[k]:
                _add_moments(mom[h], (px[k] - m[h, 0]) / s[h], (py[k] - m[h, 1]) / s[h])
    return sel, m, s, mom


@numba.njit(**_JIT)
def grow_conics(conics, xy, theta, bands, cos_tol, margin, cell_px):  # pragma: no cover - compiled
    """:func:`~._arc_ellipses.grow`: each conic refitted on the edge points near it whose
    normal agrees, over narrowing bands.

    The candidates (once, as :func:`~._arc_ellipses.box_candidates` finds them, in its order:
    by conic, then by grid cell, then by point) are the points within each conic's box
    (semi-major axis + ``bands[0]`` + ``margin`` + 1 px) and ``bands[0] + margin`` px of it.

    ``theta`` (N,): the points' edge normals, radians (their cosines and sines are taken for
    the candidates only).

    Returns conics (K, 6), ok (K,) and the (conic, point) pairs of the last band's inliers.
    """
    K, N = len(conics), len(xy)
    conics = conics.copy()
    ok = np.zeros(K, np.bool_)
    cx, cy, reach = np.empty(K), np.empty(K), np.empty(K)
    for k in range(K):
        ok[k], cx[k], cy[k], a, _, _ = ellipse_row(conics[k])
        reach[k] = a + bands[0] + margin + 1
    if K == 0 or N == 0:
        return conics, ok, np.zeros(0, np.int64), np.zeros(0, np.int64)
    # points by grid cell (stable)
    gx, gy = np.empty(N, np.int64), np.empty(N, np.int64)
    nx, ny = 0, 0
    for i in range(N):
        gx[i] = np.int64(np.floor(xy[i, 0] / cell_px))
        gy[i] = np.int64(np.floor(xy[i, 1] / cell_px))
        nx, ny = max(nx, gx[i] + 1), max(ny, gy[i] + 1)
    cstart = np.zeros(nx * ny + 1, np.int64)
    for i in range(N):
        key = gy[i] * nx + gx[i]
        if key >= 0:
            cstart[key + 1] += 1
    for c in range(nx * ny):
        cstart[c + 1] += cstart[c]
    order = np.empty(cstart[nx * ny], np.int64)
    fill = cstart[:-1].copy()
    for i in range(N):
        key = gy[i] * nx + gx[i]
        if key >= 0:
            order[fill[key]] = i
            fill[key] += 1
    lim = bands[0] + margin
    # one pass: room for every point of every conic's cells (a bound read off the cell
    # counts, without visiting the points), then the candidates in order
    box = np.zeros((K, 4), np.int64)
    cap = 0
    for k in range(K):
        if not ok[k] or not (np.isfinite(cx[k]) and np.isfinite(cy[k]) and np.isfinite(reach[k])):
            box[k, 0], box[k, 1], box[k, 2], box[k, 3] = 0, -1, 0, -1
            continue
        r = reach[k]
        box[k, 0] = int(min(max(np.floor((cx[k] - r) / cell_px), 0), nx))
        box[k, 1] = int(min(max(np.floor((cx[k] + r) / cell_px), -1), nx - 1))
        box[k, 2] = int(min(max(np.floor((cy[k] - r) / cell_px), 0), ny))
        box[k, 3] = int(min(max(np.floor((cy[k] + r) / cell_px), -1), ny - 1))
        for yc in range(box[k, 2], box[k, 3] + 1):
            if box[k, 1] >= box[k, 0]:
                cap += cstart[yc * nx + box[k, 1] + 1] - cstart[yc * nx + box[k, 0]]
    hyp = np.empty(cap, np.int64)
    pt = np.empty(cap, np.int64)
    P = 0
    for k in range(K):
        r = reach[k]
        for yc in range(box[k, 2], box[k, 3] + 1):
            for xc in range(box[k, 0], box[k, 1] + 1):
                c = yc * nx + xc
                for at in range(cstart[c], cstart[c + 1]):
                    i = order[at]
                    x, y = xy[i, 0], xy[i, 1]
                    if abs(x - cx[k]) <= r and abs(y - cy[k]) <= r and _sampson(conics[k], x, y) <= lim:
                        hyp[P] = k
                        pt[P] = i
                        P += 1
    hyp, pt = hyp[:P], pt[:P]
    # each conic's run of pairs (the pairs are by conic)
    seg = np.zeros(K + 1, np.int64)
    for j in range(P):
        seg[hyp[j] + 1] += 1
    for k in range(K):
        seg[k + 1] += seg[k]
    # the normals' cosines and sines once per point (the same values as per pair)
    ct_pt, st_pt = np.empty(N), np.empty(N)
    done = np.zeros(N, np.bool_)
    px, py = np.empty(len(pt)), np.empty(len(pt))
    ct, st = np.empty(len(pt)), np.empty(len(pt))
    for j in range(len(pt)):
        i = pt[j]
        if not done[i]:
            ct_pt[i], st_pt[i] = np.cos(theta[i]), np.sin(theta[i])
            done[i] = True
        px[j], py[j], ct[j], st[j] = xy[i, 0], xy[i, 1], ct_pt[i], st_pt[i]
    new, v = np.empty(6), np.empty(6)
    sel = np.zeros(len(pt), np.bool_)
    for b in range(len(bands)):
        last = b == len(bands) - 1
        sel, m, s, mom = _band_pass(conics, seg, px, py, ct, st, bands[b], cos_tol, last)
        if last:
            break
        for k in range(K):
            if ok[k] and direct_fit(mom[k], m[k, 0], m[k, 1], s[k], new, v) >= 0 and mom[k, 0] >= 6:
                if ellipse_row(new)[0]:
                    conics[k] = new
    for k in range(K):
        ok[k] = ok[k] and ellipse_row(conics[k])[0]
    return conics, ok, hyp[sel], pt[sel]


# -- coverage and claims ------------------------------------------------------------------------

@numba.njit(**_JIT)
def _arc_table(a, b, sin_t, cos_t, arc):  # pragma: no cover - compiled
    """Arc length of the ellipse (semi-axes a, b) at the 65 parametric angles whose sines and
    cosines are ``sin_t``, ``cos_t`` (trapezoids, as :func:`~._arc_ellipses.coverage`) into
    ``arc``; returns the perimeter."""
    steps = len(sin_t) - 1
    prev = np.sqrt((a * sin_t[0]) ** 2 + (b * cos_t[0]) ** 2)
    arc[0] = 0.0
    acc = 0.0
    for j in range(steps):
        sp = np.sqrt((a * sin_t[j + 1]) ** 2 + (b * cos_t[j + 1]) ** 2)
        acc += 0.5 * (sp + prev)
        arc[j + 1] = acc * (TWO_PI / steps)
        prev = sp
    return arc[steps]


@numba.njit(**_JIT)
def _cover_one(q, xy, pts, lo, hi, sin_t, cos_t, max_perimeter, arc, occ):  # pragma: no cover - compiled
    """Coverage, RMS Sampson distance and perimeter of the conic ``q`` by the points
    ``pts[lo:hi]``: one row of :func:`~._arc_ellipses.coverage`."""
    steps = len(sin_t) - 1
    real, cx, cy, A, B, ang = ellipse_row(q)
    if not real:
        cx, cy, A, B = 0.0, 0.0, 1.0, 1.0
    perim = _arc_table(A, B, sin_t, cos_t, arc)
    huge = not (perim <= max_perimeter)
    if huge:
        n_bins = 8
    else:
        r = np.rint(perim)
        n_bins = max(int(r) if np.isfinite(r) else 0, 8)
    occ[:n_bins] = False
    ca, sa = np.cos(ang), np.sin(ang)
    s2 = 0.0
    for j in range(lo, hi):
        x, y = xy[pts[j], 0], xy[pts[j], 1]
        u = _angle(x, y, cx, cy, ca, sa, A, B) * (steps / TWO_PI)
        i = min(int(u), steps - 1)
        s_pt = arc[i] + (u - i) * (arc[i + 1] - arc[i])
        occ[min(int(s_pt / perim * n_bins), n_bins - 1)] = True
        d = _sampson(q, x, y)
        s2 += d * d
    c = 0
    for k in range(n_bins):
        c += occ[k]
    cnt = hi - lo
    if cnt == 0 or not real or huge:
        return 0.0, np.inf, perim
    return c / n_bins, np.sqrt(s2 / cnt), perim


@numba.njit(**_JIT)
def coverage_rows(conics, xy, hyp, pt, sin_t, cos_t, max_perimeter):  # pragma: no cover - compiled
    """:func:`~._arc_ellipses.coverage` of pairs sorted by conic: cov, rms, perimeter (K,)."""
    K = len(conics)
    cov, rms, perim = np.zeros(K), np.full(K, np.inf), np.zeros(K)
    arc = np.empty(len(sin_t))
    occ = np.zeros(int(max_perimeter) + 2, np.bool_)
    j = 0
    for k in range(K):
        j1 = j
        while j1 < len(hyp) and hyp[j1] == k:
            j1 += 1
        cov[k], rms[k], perim[k] = _cover_one(conics[k], xy, pt, j, j1, sin_t, cos_t, max_perimeter, arc, occ)
        j = j1
    return cov, rms, perim


@numba.njit(**_JIT)
def claim(conics, order, hyp, pt, xy, labels, has_labels, concave, none, min_points, min_support, sin_t, cos_t,
          max_perimeter):  # pragma: no cover - compiled
    """The claims of :func:`~._arc_ellipses.free_ellipses`: in ``order``, each candidate keeps
    the inliers of its own edge (:func:`~._edge_points.one_edge`); one whose unclaimed ones
    no longer cover ``min_support`` (or are fewer than ``min_points``) is dropped, else it
    claims them all.

    ``hyp, pt``: the inlier pairs sorted by conic. Returns the accepted conics (indices, in
    order) and their points (concatenated, with the start of each).
    """
    K = len(conics)
    start = np.zeros(K + 1, np.int64)
    for j in range(len(hyp)):
        start[hyp[j] + 1] += 1
    for k in range(K):
        start[k + 1] += start[k]
    used = np.zeros(len(xy), np.bool_)
    arc = np.empty(len(sin_t))
    occ = np.zeros(int(max_perimeter) + 2, np.bool_)
    acc = np.empty(len(order), np.int64)
    out_start = np.zeros(len(order) + 1, np.int64)
    out_pts = np.empty(len(hyp), np.int64)
    free = np.empty(len(hyp), np.int64)
    A = 0
    for j in order:
        lo, hi = start[j], start[j + 1]
        n_all = hi - lo
        keep_concave, keep_other = True, True
        if has_labels:
            n_c, n_o = 0, 0
            for r in range(lo, hi):
                lab = labels[pt[r]]
                if lab == concave:
                    n_c += 1
                elif lab != none:
                    n_o += 1
            if n_c > 0 and n_o > 0:
                if n_c > n_o:
                    keep_other = False
                else:
                    keep_concave = False
        m = 0
        n_free = 0
        base = out_start[A]
        for r in range(lo, hi):
            p = pt[r]
            if has_labels:
                lab = labels[p]
                if (lab == concave and not keep_concave) or (lab != concave and lab != none and not keep_other):
                    continue
            out_pts[base + m] = p
            m += 1
            if not used[p]:
                free[n_free] = p
                n_free += 1
        if n_free < n_all:
            if n_free < min_points:
                continue
            if _cover_one(conics[j], xy, free, 0, n_free, sin_t, cos_t, max_perimeter, arc, occ)[0] < min_support:
                continue
        for r in range(base, base + m):
            used[out_pts[r]] = True
        acc[A] = j
        A += 1
        out_start[A] = base + m
    return acc[:A], out_start[:A + 1], out_pts[:out_start[A]]
