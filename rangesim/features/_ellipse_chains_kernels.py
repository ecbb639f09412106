"""Compiled stages of the chain hypotheses of the model-free ellipse finder (Numba;
:mod:`._ellipse_chains`): edge chains traced pixel to pixel, cut into arc pieces, the pieces
fitted, and each good fit grown over the whole pieces that lie on it.

The work follows the edge points (one pass to trace, one to cut) and the pieces (a few
hundred per map): unlike the tilings of :mod:`._ellipse_kernels`, a point belongs to one
piece, so it is fitted a few times (alone, in its piece's pairs and triples, in the unions
it is grown into) rather than once per tiling.
"""
from __future__ import annotations

import numba
import numpy as np

from rangesim.core._conic_kernels import direct_fit, ellipse_row
from rangesim.features._conic_kernels import _add_moments
from rangesim.features._ellipse_kernels import _find, _sampson, _union, fit_groups, frame_moments, pixel_index

_JIT = dict(cache=True, nogil=True, error_model="numpy")
#: fits whose residual estimate from the moments exceeds this (px) are not checked further (the
#: trimmed refit and the checks on the points; 3 px for the tilings' pieces: on the tilted
#: Green Piece 0.7 finds the same ellipses and saves about a tenth of the fits' time)
TRIM_RMS = 0.7

#: the 8 neighbour steps, 4-neighbours first (a walk prefers them at equal turn)
_DX = np.array([1, 0, -1, 0, 1, -1, -1, 1], np.int64)
_DY = np.array([0, 1, 0, -1, 1, 1, -1, -1], np.int64)
#: the opposite step of each
_OPP = np.array([2, 3, 0, 1, 6, 7, 4, 5], np.int64)
#: of a diagonal step (dx, dy): the steps (dx, 0) and (0, dy) (4-neighbour steps: themselves)
_H4 = np.array([0, 1, 2, 3, 0, 2, 2, 0], np.int64)
_V4 = np.array([0, 1, 2, 3, 1, 1, 3, 3], np.int64)


# -- chains -------------------------------------------------------------------------------------

@numba.njit(**_JIT)
def chain_links(x, y, ct, st, cos_link, cos_adjacent):  # pragma: no cover - compiled
    """The links of the chains: each point's linked 8-neighbours, with the diagonal links cut
    where a 4-neighbour linked to both ends carries the chain (a staircase's corner pixel).

    Two 8-neighbours are linked when their normals agree within ``cos_link`` (the sense
    ignored) and the step is at least ``cos_adjacent`` off both normals (as
    :func:`~._ellipse_kernels.curve_labels` links them).

    ``x, y`` (N,) int pixels (distinct, >= 0); ``ct, st`` (N,) the cosines and sines of the
    normals. Returns nb (N, 8) int (neighbour indices, -1 past the last), deg (N,) and the
    index image (the point at each pixel, -1 elsewhere; pixel (x, y) at [y + 1, x + 1]).
    """
    n = len(x)
    index = pixel_index(x, y, 1)
    # the links as bits (bit d: the neighbour at step d), each pair tested once
    bits = np.zeros(n, np.uint8)
    inv_sqrt2 = 1.0 / np.sqrt(2.0)
    for i in range(n):
        ci, si = ct[i], st[i]
        for d in range(8):
            if (d < 4 and (d == 0 or d == 1)) or d == 4 or d == 5:  # half the steps; the other half mirrors
                k = index[y[i] + 1 + _DY[d], x[i] + 1 + _DX[d]]
                if k < 0:
                    continue
                if abs(ci * ct[k] + si * st[k]) < cos_link:
                    continue
                ux, uy = _DX[d] * (inv_sqrt2 if d >= 4 else 1.0), _DY[d] * (inv_sqrt2 if d >= 4 else 1.0)
                if abs(ux * ci + uy * si) > cos_adjacent or abs(ux * ct[k] + uy * st[k]) > cos_adjacent:
                    continue
                bits[i] |= np.uint8(1 << d)
                bits[k] |= np.uint8(1 << _OPP[d])
    nb = np.full((n, 8), -1, np.int64)
    deg = np.zeros(n, np.int64)
    for i in range(n):
        b = bits[i]
        for d in range(8):
            if not (b >> d) & 1:
                continue
            if d >= 4:
                # the diagonal (dx, dy) is cut when the 4-neighbour (dx, 0) or (0, dy) is linked to
                # both ends: its step to the far end is (0, dy) or (dx, 0)
                cut = False
                for e in range(2):
                    d4 = _H4[d] if e == 0 else _V4[d]
                    if (b >> d4) & 1:
                        m = index[y[i] + 1 + _DY[d4], x[i] + 1 + _DX[d4]]
                        if (bits[m] >> (_V4[d] if e == 0 else _H4[d])) & 1:
                            cut = True
                if cut:
                    continue
            nb[i, deg[i]] = index[y[i] + 1 + _DY[d], x[i] + 1 + _DX[d]]
            deg[i] += 1
    return nb, deg, index


@numba.njit(**_JIT)
def _jump(cur, x, y, ct, st, index, visited, pdx, pdy, gap, cos_link, sin_link):  # pragma: no cover - compiled
    """The nearest unvisited point across a gap: 2 .. ``gap`` px from ``cur`` along both
    points' tangents (within ``sin_link`` of them), normals within ``cos_link``, ahead of the
    last step (``pdx, pdy``). -1 when there is none."""
    best = -1
    best_d = np.inf
    ci, si = ct[cur], st[cur]
    for dy in range(-gap, gap + 1):
        for dx in range(-gap, gap + 1):
            if max(abs(dx), abs(dy)) < 2:
                continue
            yy, xx = y[cur] + 1 + dy, x[cur] + 1 + dx
            if yy < 0 or xx < 0 or yy >= index.shape[0] or xx >= index.shape[1]:
                continue
            k = index[yy, xx]
            if k < 0 or visited[k]:
                continue
            if pdx * dx + pdy * dy <= 0 and (pdx != 0 or pdy != 0):
                continue
            step = np.sqrt(dx * dx + dy * dy)
            if step >= best_d or abs(ci * ct[k] + si * st[k]) < cos_link:
                continue
            if abs(dx * ci + dy * si) > sin_link * step or abs(dx * ct[k] + dy * st[k]) > sin_link * step:
                continue
            best, best_d = k, step
    return best


@numba.njit(**_JIT)
def _walk(start, x, y, nb, deg, visited, out, at, ct, st, index, gap, cos_link, sin_link):  # pragma: no cover
    """Walk from ``start`` (visited already) over unvisited links, the smallest turn first
    (the first step: a 4-neighbour first), across gaps of up to ``gap`` px where no link
    goes on (:func:`_jump`), writing the points to ``out[at:]``. Returns the new ``at``."""
    cur = start
    pdx, pdy = 0, 0
    while True:
        best = -1
        best_score = -np.inf
        for j in range(deg[cur]):
            k = nb[cur, j]
            if visited[k]:
                continue
            dx, dy = x[k] - x[cur], y[k] - y[cur]
            L = np.sqrt(dx * dx + dy * dy)
            score = (pdx * dx + pdy * dy) / L - 0.01 * L if (pdx != 0 or pdy != 0) else -L
            if score > best_score:
                best_score = score
                best = k
        if best < 0 and gap >= 2:
            best = _jump(cur, x, y, ct, st, index, visited, pdx, pdy, gap, cos_link, sin_link)
        if best < 0:
            return at
        visited[best] = True
        out[at] = best
        at += 1
        pdx, pdy = x[best] - x[cur], y[best] - y[cur]
        cur = best


@numba.njit(**_JIT)
def trace_chains(x, y, ct, st, cos_link, cos_adjacent, min_len, gap, sin_link):  # pragma: no cover - compiled
    """Ordered chains of linked edge pixels (:func:`chain_links`).

    Chains start at the ends (one link) in point order, then at the points left (loops and
    the rest of junctions), walked both ways; at a junction the walk goes on along the
    straightest branch and the others become chains of their own; where no link goes on, the
    walk jumps a gap of up to ``gap`` px along the tangent (:func:`_jump`, the bridged links
    of :func:`~._ellipse_kernels.curve_labels`). Chains of fewer than ``min_len`` points are
    dropped.

    Returns order (M,) (point indices, chain after chain) and start (C + 1,).
    """
    n = len(x)
    nb, deg, index = chain_links(x, y, ct, st, cos_link, cos_adjacent)
    visited = np.zeros(n, np.bool_)
    order = np.empty(n, np.int64)
    start = np.zeros(n + 1, np.int64)
    tmp = np.empty(n, np.int64)
    C = 0
    at = 0
    for pass_ in range(2):
        for s in range(n):
            if visited[s] or (pass_ == 0 and deg[s] != 1):
                continue
            visited[s] = True
            # one way into tmp, then the other way; the chain is the second part reversed,
            # then s, then the first
            e1 = _walk(s, x, y, nb, deg, visited, tmp, 0, ct, st, index, gap, cos_link, sin_link)
            e2 = _walk(s, x, y, nb, deg, visited, tmp, e1, ct, st, index, gap, cos_link, sin_link)
            m = e2 - e1 + 1 + e1
            if m < min_len:
                continue
            w = at
            for r in range(e2 - 1, e1 - 1, -1):
                order[w] = tmp[r]
                w += 1
            order[w] = s
            w += 1
            for r in range(e1):
                order[w] = tmp[r]
                w += 1
            at = w
            C += 1
            start[C] = at
    return order[:at], start[:C + 1]


# -- cuts -----------------------------------------------------------------------------------------

@numba.njit(**_JIT)
def _simplify(px, py, lo, hi, tol, keep, stack):  # pragma: no cover - compiled
    """Douglas-Peucker vertices of the polyline ``lo .. hi`` (inclusive) into ``keep``."""
    keep[lo] = True
    keep[hi] = True
    top = 0
    stack[0, 0], stack[0, 1] = lo, hi
    top = 1
    while top > 0:
        top -= 1
        a, b = stack[top, 0], stack[top, 1]
        if b - a < 2:
            continue
        ex, ey = px[b] - px[a], py[b] - py[a]
        L = np.sqrt(ex * ex + ey * ey)
        best, bi = -1.0, -1
        for i in range(a + 1, b):
            qx, qy = px[i] - px[a], py[i] - py[a]
            d = abs(qx * ey - qy * ex) / L if L > 1e-9 else np.sqrt(qx * qx + qy * qy)
            if d > best:
                best, bi = d, i
        if best > tol:
            keep[bi] = True
            stack[top, 0], stack[top, 1] = a, bi
            stack[top + 1, 0], stack[top + 1, 1] = bi, b
            top += 2


@numba.njit(**_JIT)
def _off_fit(conic, px, py, verts, j0, j, hi, cut_dist):  # pragma: no cover - compiled
    """Whether a vertex ``verts[j0 .. j]`` or a segment's middle point lies over ``cut_dist``
    px (Sampson distance) off ``conic``."""
    for jj in range(j0, j + 1):
        r = min(verts[jj], hi)
        if _sampson(conic, px[r], py[r]) > cut_dist:
            return True
        if jj < j:
            r = (verts[jj] + min(verts[jj + 1], hi)) // 2
            if _sampson(conic, px[r], py[r]) > cut_dist:
                return True
    return False


@numba.njit(**_JIT)
def _fits_thick(mom, ox, oy, scale, conic, v, min_thick):  # pragma: no cover - compiled
    """Direct fit of the moments into ``conic``; whether it is an ellipse of semi-minor axis
    ``min_thick`` px or more and over 0.2 of the major (the ellipse-specific fit of a flat arc
    hugs it with a thin ellipse whose ends lie off its points: no test)."""
    if direct_fit(mom, ox, oy, scale, conic, v) < 0:
        return False
    real, _, _, fa, fb, _ = ellipse_row(conic)
    return real and fb >= min_thick and fb >= 0.2 * fa


@numba.njit(**_JIT)
def cut_chains(xy, order, cstart, tol, max_turn, min_inflection, max_ratio, min_long, cut_dist, min_turned,
               min_thick, min_points, scale):  # pragma: no cover - compiled
    """The arc pieces of the chains.

    Each chain's polyline (Douglas-Peucker, ``tol`` px) is walked vertex by vertex; a piece
    grows segment by segment while the direct ellipse fit of its points (moments added up
    as it grows, in a frame at its first point with ``scale`` px units) passes within
    ``cut_dist`` px (Sampson distance) of its polyline's vertices and its segments' middle
    points (tested once the piece has turned by ``min_turned`` radians and its fit is an
    ellipse of semi-minor axis ``min_thick`` px or more and over 0.2 of the major: the fit
    of a flatter piece is ill-determined), and is cut at the last vertex before it does not (the fit's own residual
    estimate from the moments is no test: on a line joined to an arc it reads 0.34 px where
    the points' RMS distance is 1.4 px),
    or where the polyline turns by more than ``max_turn`` radians (a corner; turns next to a
    segment under 3 px count as none), where a
    segment of ``min_long`` px or more is over ``max_ratio`` times the next two on the other
    side of a vertex (the curvature jumps, as where a line meets an arc; a digital arc's
    polyline mixes long and very short segments, so one neighbour is no measure), or where the
    turn changes sign between two turns of over ``min_inflection`` radians, the turn before
    them of the first sign and the one after of the second (an inflection; one vertex whose
    turn flips is the pixels' noise).
    A circle meeting a tangent line is cut at the tangent point (the length rule).

    Returns the pieces' starts and counts in ``order`` (those of ``min_points`` or more) and
    their chains.
    """
    M = len(order)
    C = len(cstart) - 1
    px, py = np.empty(M), np.empty(M)
    for r in range(M):
        px[r], py[r] = xy[order[r], 0], xy[order[r], 1]
    keep = np.zeros(M, np.bool_)
    stack = np.empty((M + 2, 2), np.int64)
    p_start = np.empty(M, np.int64)
    p_cnt = np.empty(M, np.int64)
    p_chain = np.empty(M, np.int64)
    P = 0
    verts = np.empty(M, np.int64)
    turn = np.zeros(M + 1)
    ratio = np.ones(M + 1)
    seg = np.zeros(M + 1)
    mom = np.zeros(15)
    conic = np.empty(6)
    v = np.empty(6)
    small = min_inflection
    for c in range(C):
        lo, hi = cstart[c], cstart[c + 1] - 1
        _simplify(px, py, lo, hi, tol, keep, stack)
        V = 0
        for r in range(lo, hi + 1):
            if keep[r]:
                verts[V] = r
                V += 1
        verts[V - 1] = hi + 1  # the last segment takes the chain's last point
        # the turn at each inner vertex, and the jump of the segments' lengths there: the
        # longer of the segments on either side against the two next on the other side (a
        # digital arc's polyline mixes long and very short segments; a line does not turn)
        for j in range(V):
            a, e = min(verts[j], hi), min(verts[j + 1], hi) if j + 1 < V else hi
            seg[j] = np.sqrt((px[e] - px[a]) ** 2 + (py[e] - py[a]) ** 2) if j + 1 < V else 0.0
        for j in range(1, V - 1):
            a, b, e = verts[j - 1], verts[j], min(verts[j + 1], hi)
            ux, uy = px[b] - px[a], py[b] - py[a]
            vx, vy = px[e] - px[b], py[e] - py[b]
            turn[j] = np.arctan2(ux * vy - uy * vx, ux * vx + uy * vy)
            if min(seg[j - 1], seg[j]) < 3.0:  # a pixel's step: its direction is the pixels' noise
                turn[j] = 0.0
            before = seg[j - 1] + (seg[j - 2] if j >= 2 else 0.0)
            after = seg[j] + (seg[j + 1] if j + 1 < V - 1 else 0.0)
            if seg[j - 1] >= min_long and seg[j - 1] > max_ratio * after:
                ratio[j] = np.inf
            elif seg[j] >= min_long and seg[j] > max_ratio * before:
                ratio[j] = np.inf
            else:
                ratio[j] = 1.0
        first = lo
        j0 = 0  # the piece's first vertex
        ox, oy = px[lo], py[lo]
        mom[:] = 0.0
        turned = 0.0
        j = 1
        while j < V:
            # add segment j - 1 .. j
            for r in range(verts[j - 1], verts[j]):
                _add_moments(mom, (px[r] - ox) / scale, (py[r] - oy) / scale)
            cut = False
            k = j - 1  # the vertex a cut would be at
            at = k
            if k > j0:
                cut = abs(turn[k]) > max_turn or ratio[k] > max_ratio
                # an inflection: the turn changes sign, and keeps the old sign before it and
                # the new one after it (a lone flip is the pixels' noise)
                if not cut and k > j0 + 1 and turn[k - 1] * turn[k] < 0 and min(abs(turn[k - 1]), abs(turn[k])) > small:
                    cut = (k - 2 < 1 or turn[k - 2] * turn[k - 1] > 0) and (k + 1 > V - 2 or turn[k + 1] * turn[k] > 0)
            if k > j0:
                turned += abs(turn[k])
            if not cut and j - j0 >= 3 and mom[0] >= min_points and turned >= min_turned:
                if _fits_thick(mom, ox, oy, scale, conic, v, min_thick) and \
                        _off_fit(conic, px, py, verts, j0, j, hi, cut_dist):
                    cut = True
            if cut:
                # the piece ends at vertex ``at``; the next starts there
                b = verts[at]
                if b - first >= min_points:
                    p_start[P], p_cnt[P], p_chain[P] = first, b - first, c
                    P += 1
                first = b
                j0 = at
                ox, oy = px[b], py[b]
                mom[:] = 0.0
                turned = 0.0
                j = j0 + 1
                continue
            j += 1
        if hi + 1 - first >= min_points:
            p_start[P], p_cnt[P], p_chain[P] = first, hi + 1 - first, c
            P += 1
    return p_start[:P], p_cnt[:P], p_chain[:P]


# -- fits -----------------------------------------------------------------------------------------

@numba.njit(**_JIT)
def fit_ranges(xy, pts, lo, n, max_rms, min_inliers, ax_lo, ax_hi, min_ratio, min_arc_deg):  # pragma: no cover
    """:func:`~._ellipse_kernels.fit_groups` of the ranges ``pts[lo[g]:lo[g] + n[g]]``: conics
    (G, 6) and good (G,)."""
    G = len(lo)
    frame = np.empty((G, 3))
    mom = np.empty((G, 15))
    for g in range(G):
        frame_moments(xy, pts, lo[g], n[g], frame[g], mom[g])
    zero = np.zeros(G, np.int64)
    conics, _, good = fit_groups(xy, pts, lo, n, zero, zero, mom, frame, max_rms, min_inliers, ax_lo, ax_hi,
                                 min_ratio, min_arc_deg, TRIM_RMS)
    return conics, good


@numba.njit(**_JIT)
def _nearest_end(p, u, ex, ey, ends, ends_x, g2, cnt, lo, hi):  # pragma: no cover - compiled
    """The piece (and -1 for none) of ``lo`` .. ``hi - 1`` points (``cnt``) with an end nearest
    to end ``u`` of piece ``p``, within sqrt(``g2``) px (``ends``: the ends 2 q + w by x,
    ``ends_x`` their x)."""
    best, best_d = -1, g2
    x, y = ex[p, u], ey[p, u]
    r = np.sqrt(g2)
    at = np.searchsorted(ends_x, x - r)
    while at < len(ends) and ends_x[at] <= x + r:
        e = ends[at]
        at += 1
        q = e // 2
        if q == p or not lo <= cnt[q] < hi:
            continue
        dx, dy = x - ex[q, e % 2], y - ey[q, e % 2]
        d = dx * dx + dy * dy
        if d <= best_d:
            best, best_d = q, d
    return best


@numba.njit(**_JIT)
def piece_fits(xy, order, p_start, p_cnt, min_piece, max_small, max_gap, gap_frac, n_near, max_rms, min_inliers, ax_lo,
               ax_hi, min_ratio, min_arc_deg):  # pragma: no cover - compiled
    """Fits of each piece, of each piece with each of its ``n_near`` nearest others (the least
    distance between their ends, at most ``max_gap`` px: the arcs of one rim that a junction,
    a corner or a gap cut apart; consecutive pieces of a chain are 0 px apart), and of each
    piece with the pieces nearest to either of its ends (within ``max_gap`` px or
    ``gap_frac`` of its length in points, the larger: a large ellipse's arcs across wider
    gaps), the three together. Only pieces of ``min_piece`` points or more are fitted alone
    and make these groups; the shorter ones (fragments of a small rim) join them apart: each
    piece of at most ``max_small`` points with the fragment nearest to either end within
    ``max_gap`` px, and with both.

    Returns conics (G, 6), good (G,), the groups' first piece (G,) and their points (G,).
    """
    P = len(p_start)
    ex = np.empty((P, 2))
    ey = np.empty((P, 2))
    total = 0
    for p in range(P):
        i0, i1 = order[p_start[p]], order[p_start[p] + p_cnt[p] - 1]
        ex[p, 0], ey[p, 0], ex[p, 1], ey[p, 1] = xy[i0, 0], xy[i0, 1], xy[i1, 0], xy[i1, 1]
        total += p_cnt[p]
    Gmax = P * (7 + n_near)
    mem = np.full((Gmax, 3), -1, np.int64)
    first = np.empty(Gmax, np.int64)
    best_d = np.empty(n_near)
    best_q = np.empty(n_near, np.int64)
    g2 = max_gap * max_gap
    ends_x = np.empty(2 * P)
    for p in range(P):
        ends_x[2 * p], ends_x[2 * p + 1] = ex[p, 0], ex[p, 1]
    ends = np.argsort(ends_x)
    ends_x = ends_x[ends]
    G = 0
    for p in range(P):
        if p_cnt[p] < min_piece:
            continue
        mem[G, 0], first[G] = p, p
        G += 1
        # the n_near pieces with the least distance between ends (a sorted list; a piece seen
        # at both its ends keeps the nearer)
        best_d[:] = np.inf
        best_q[:] = -1
        for u in range(2):
            at = np.searchsorted(ends_x, ex[p, u] - max_gap)
            while at < 2 * P and ends_x[at] <= ex[p, u] + max_gap:
                e = ends[at]
                at += 1
                q = e // 2
                if q == p or p_cnt[q] < min_piece:
                    continue
                dx, dy = ex[p, u] - ex[q, e % 2], ey[p, u] - ey[q, e % 2]
                d = dx * dx + dy * dy
                if d > g2:
                    continue
                j = 0
                while j < n_near and best_q[j] != q:
                    j += 1
                if j < n_near:  # listed: keep the nearer, moved up
                    if d >= best_d[j]:
                        continue
                else:
                    if d >= best_d[n_near - 1]:
                        continue
                    j = n_near - 1
                while j > 0 and best_d[j - 1] > d:
                    best_d[j], best_q[j] = best_d[j - 1], best_q[j - 1]
                    j -= 1
                best_d[j], best_q[j] = d, q
        for j in range(n_near):
            q = best_q[j]
            if q < 0:
                break
            if q > p:  # each pair once
                mem[G, 0], mem[G, 1], first[G] = p, q, p
                G += 1
        # the nearest piece at each end, within a gap that grows with the piece
        gap = max(max_gap, gap_frac * p_cnt[p])
        q0 = _nearest_end(p, 0, ex, ey, ends, ends_x, gap * gap, p_cnt, min_piece, 1 << 62)
        q1 = _nearest_end(p, 1, ex, ey, ends, ends_x, gap * gap, p_cnt, min_piece, 1 << 62)
        for q in (q0, q1):
            if q < 0:
                continue
            dup = False
            for j in range(n_near):
                dup = dup or best_q[j] == q
            if not dup:
                mem[G, 0], mem[G, 1], first[G] = p, q, p
                G += 1
        if q0 >= 0 and q1 >= 0 and q0 != q1:
            mem[G, 0], mem[G, 1], mem[G, 2], first[G] = p, q0, q1, p
            G += 1
        # the nearest fragment at each end, and both (of small pieces only: a small rim's)
        if p_cnt[p] > max_small:
            continue
        f0 = _nearest_end(p, 0, ex, ey, ends, ends_x, g2, p_cnt, 0, min_piece)
        f1 = _nearest_end(p, 1, ex, ey, ends, ends_x, g2, p_cnt, 0, min_piece)
        for f in (f0, f1):
            if f >= 0:
                mem[G, 0], mem[G, 1], first[G] = p, f, p
                G += 1
        if f0 >= 0 and f1 >= 0 and f0 != f1:
            mem[G, 0], mem[G, 1], mem[G, 2], first[G] = p, f0, f1, p
            G += 1
    # the groups' points, group after group
    lo = np.empty(G, np.int64)
    n = np.zeros(G, np.int64)
    R = 0
    for g in range(G):
        for m in range(3):
            if mem[g, m] >= 0:
                R += p_cnt[mem[g, m]]
    pts = np.empty(R, np.int64)
    at = 0
    for g in range(G):
        lo[g] = at
        for m in range(3):
            q = mem[g, m]
            if q >= 0:
                for r in range(p_start[q], p_start[q] + p_cnt[q]):
                    pts[at] = order[r]
                    at += 1
        n[g] = at - lo[g]
    conics, good = fit_ranges(xy, pts, lo, n, max_rms, min_inliers, ax_lo, ax_hi, min_ratio, min_arc_deg)
    return conics, good, first[:G], n


@numba.njit(**_JIT)
def cluster_groups(xy, order, p_start, p_cnt, gap, min_points, max_points):  # pragma: no cover - compiled
    """The pieces joined end to end: the connected groups of pieces whose ends lie within
    ``gap`` px of another's (the ends sorted by x, each compared with those up to ``gap``
    px on), of 2 or
    more pieces and ``min_points`` .. ``max_points`` points in all (a small rim whose chain
    the links broke into fragments, each too short to fit).

    Returns pts (the groups' points, group after group), lo, n (each group's range) and
    first (its first piece).
    """
    P = len(p_start)
    parent = np.arange(P)
    if P == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    ex, ey = _piece_ends(xy, order, p_start, p_cnt)
    ends = np.argsort(ex)
    g2 = gap * gap
    for a in range(2 * P):
        e = ends[a]
        b = a + 1
        while b < 2 * P and ex[ends[b]] <= ex[e] + gap:
            f = ends[b]
            b += 1
            dx, dy = ex[e] - ex[f], ey[e] - ey[f]
            if f // 2 != e // 2 and dx * dx + dy * dy <= g2:
                _union(parent, e // 2, f // 2)
    root = np.empty(P, np.int64)
    size = np.zeros(P, np.int64)
    cnt = np.zeros(P, np.int64)
    for p in range(P):
        root[p] = _find(parent, p)
        size[root[p]] += p_cnt[p]
        cnt[root[p]] += 1
    gid = np.full(P, -1, np.int64)
    G = 0
    total = 0
    for p in range(P):
        r = root[p]
        if gid[r] < 0 and cnt[r] >= 2 and min_points <= size[r] <= max_points:
            gid[r] = G
            G += 1
            total += size[r]
    lo = np.zeros(G, np.int64)
    n = np.zeros(G, np.int64)
    first = np.full(G, -1, np.int64)
    for p in range(P):
        g = gid[root[p]]
        if g >= 0:
            n[g] += p_cnt[p]
            if first[g] < 0:
                first[g] = p
    for g in range(1, G):
        lo[g] = lo[g - 1] + n[g - 1]
    pts = np.empty(total, np.int64)
    fill = lo.copy()
    for p in range(P):
        g = gid[root[p]]
        if g >= 0:
            for r in range(p_start[p], p_start[p] + p_cnt[p]):
                pts[fill[g]] = order[r]
                fill[g] += 1
    return pts, lo, n, first


@numba.njit(**_JIT)
def _piece_ends(xy, order, p_start, p_cnt):  # pragma: no cover - compiled
    """The two end points of every piece ``order[p_start[p]:p_start[p] + p_cnt[p]]``: x and y
    (2 P,), end ``u`` (0 first, 1 last) of piece p at ``2 p + u``."""
    P = len(p_start)
    ex = np.empty(2 * P)
    ey = np.empty(2 * P)
    for p in range(P):
        for u in range(2):
            i = order[p_start[p] + (p_cnt[p] - 1 if u else 0)]
            ex[2 * p + u], ey[2 * p + u] = xy[i, 0], xy[i, 1]
    return ex, ey


@numba.njit(**_JIT)
def _end_dir(xy, order, s, m, u, back):  # pragma: no cover - compiled
    """Unit direction out of end ``u`` of the piece ``order[s:s + m]``: from the point ``back``
    points inside (or the far end) to the end."""
    k = min(back, m - 1)
    if u == 0:
        a, b = order[s + k], order[s]
    else:
        a, b = order[s + m - 1 - k], order[s + m - 1]
    dx, dy = xy[b, 0] - xy[a, 0], xy[b, 1] - xy[a, 1]
    L = np.sqrt(dx * dx + dy * dy)
    if L == 0:
        return 0.0, 0.0
    return dx / L, dy / L


@numba.njit(**_JIT)
def link_groups(xy, order, p_start, p_cnt, gap_frac, min_gap, cos_tol, back, windows):  # pragma: no cover
    """The pieces linked end to end into longer arcs across gaps: each piece end is linked
    to the end of another that is its nearest one continuing it (within ``gap_frac`` of the
    shorter piece's points or ``min_gap`` px, the larger; the step between the ends and both
    ends' outward directions within ``cos_tol`` of one line, the two ends facing each other),
    when that end chose it back. The links make paths (each end has one at most); each run
    of ``windows[k]`` consecutive pieces of a path is a group, and each whole path of 2 or
    more pieces (a large ellipse whose chain the links broke in several places).

    Returns pts, lo, n, first as :func:`cluster_groups`.
    """
    P = len(p_start)
    best = np.full(2 * P, -1, np.int64)
    dx_ = np.empty(2 * P)
    dy_ = np.empty(2 * P)
    ex, ey = _piece_ends(xy, order, p_start, p_cnt)
    for p in range(P):
        for u in range(2):
            dx_[2 * p + u], dy_[2 * p + u] = _end_dir(xy, order, p_start[p], p_cnt[p], u, back)
    ends = np.argsort(ex)
    ends_x = ex[ends]
    for e in range(2 * P):
        p = e // 2
        best_d = np.inf
        reach = max(min_gap, gap_frac * p_cnt[p])
        at = np.searchsorted(ends_x, ex[e] - reach)
        while at < 2 * P and ends_x[at] <= ex[e] + reach:
            f = ends[at]
            at += 1
            q = f // 2
            if q == p:
                continue
            g = max(min_gap, gap_frac * min(p_cnt[p], p_cnt[q]))
            sx, sy = ex[f] - ex[e], ey[f] - ey[e]
            d = np.sqrt(sx * sx + sy * sy)
            if d > g or d >= best_d:
                continue
            # facing each other, and (across a gap of over 2 px) the step along both
            if dx_[e] * dx_[f] + dy_[e] * dy_[f] > -cos_tol:
                continue
            if d > 2.0 and (sx * dx_[e] + sy * dy_[e] < cos_tol * d or -(sx * dx_[f] + sy * dy_[f]) < cos_tol * d):
                continue
            best_d = d
            best[e] = f
    link = np.full(2 * P, -1, np.int64)
    for e in range(2 * P):
        f = best[e]
        if f >= 0 and best[f] == e:
            link[e] = f
    # the paths: from each piece whose end 0 or end 1 is unlinked (or any piece of a cycle)
    seen = np.zeros(P, np.bool_)
    path = np.empty(P, np.int64)
    gs = np.empty(P + 1, np.int64)  # the paths' pieces, path after path
    gp = np.empty(P, np.int64)
    n_paths = 0
    n_at = 0
    gs[0] = 0
    for pass_ in range(2):
        for p in range(P):
            if seen[p]:
                continue
            if pass_ == 0 and link[2 * p] >= 0 and link[2 * p + 1] >= 0:
                continue  # not an end of a path (a cycle's pieces wait for the second pass)
            # walk out through the linked end (end 1 if end 0 is free, else end 0)
            u = 1 if link[2 * p] < 0 else 0
            L = 0
            q = p
            while q >= 0 and not seen[q]:
                seen[q] = True
                path[L] = q
                L += 1
                f = link[2 * q + u]
                if f < 0:
                    break
                q = f // 2
                u = 1 - f % 2  # leave the piece by its other end
            for k in range(L):
                gp[n_at + k] = path[k]
            n_at += L
            n_paths += 1
            gs[n_paths] = n_at
    # the groups: windows of consecutive pieces, and whole paths
    G = 0
    R = 0
    for k in range(n_paths):
        L = gs[k + 1] - gs[k]
        if L < 2:
            continue
        for w in windows:
            if w < L:
                for a in range(L - w + 1):
                    G += 1
                    for j in range(a, a + w):
                        R += p_cnt[gp[gs[k] + j]]
        G += 1
        for j in range(L):
            R += p_cnt[gp[gs[k] + j]]
    pts = np.empty(R, np.int64)
    lo = np.zeros(G, np.int64)
    n = np.zeros(G, np.int64)
    first = np.zeros(G, np.int64)
    g = 0
    at = 0
    for k in range(n_paths):
        L = gs[k + 1] - gs[k]
        if L < 2:
            continue
        for wi in range(len(windows) + 1):
            w = windows[wi] if wi < len(windows) else L
            if w > L or (wi < len(windows) and w == L):
                continue
            for a in range(L - w + 1):
                lo[g] = at
                first[g] = gp[gs[k] + a]
                for j in range(a, a + w):
                    q = gp[gs[k] + j]
                    for r in range(p_start[q], p_start[q] + p_cnt[q]):
                        pts[at] = order[r]
                        at += 1
                n[g] = at - lo[g]
                g += 1
    return pts[:at], lo[:g], n[:g], first[:g]


@numba.njit(**_JIT)
def _piece_on(q, cx, cy, reach, xy, order, s, m, ct, st, band, cos_tol):  # pragma: no cover - compiled
    """Whether the piece ``order[s:s + m]`` lies on the conic ``q``: at least 4 of 5 points
    spread along it within ``band`` px with agreeing normals (its middle one first)."""
    misses = 0
    for t in (2, 0, 1, 3, 4):
        i = order[s + (t * (m - 1)) // 4]
        x, y = xy[i, 0], xy[i, 1]
        ok = abs(x - cx) <= reach and abs(y - cy) <= reach and _sampson(q, x, y) <= band
        if ok:
            gx = 2 * q[0] * x + q[1] * y + q[3]
            gy = q[1] * x + 2 * q[2] * y + q[4]
            g = np.sqrt(gx * gx + gy * gy)
            ok = g > 0 and abs(gx * ct[i] + gy * st[i]) >= cos_tol * g
        if not ok:
            misses += 1
            if t == 2 or misses >= 2:  # the middle missed, or two points did
                return False
    return True


@numba.njit(**_JIT)
def grow_pieces(conics, seeds, xy, order, p_start, p_cnt, ct, st, band, cos_tol, max_rms, min_inliers, ax_lo,
                ax_hi, min_ratio, min_arc_deg, skip_explained, n_iter):  # pragma: no cover - compiled
    """Each seed conic grown over the whole pieces that lie on it (:func:`_piece_on`),
    refitted on their union (``n_iter`` rounds, each around the last union's fit) and checked
    as a piece (:func:`fit_ranges`).

    ``seeds`` (K,) the first piece of each conic's group; with ``skip_explained`` a conic
    whose seed piece is in an earlier good union is skipped. Returns the unions' conics
    (U, 6), good (U,) and points (U,).
    """
    K = len(conics)
    P = len(p_start)
    total = 0
    for p in range(P):
        total += p_cnt[p]
    explained = np.zeros(P, np.bool_)
    members = np.empty(P, np.int64)
    out_c = np.zeros((K, 6))
    out_good = np.zeros(K, np.bool_)
    out_n = np.zeros(K, np.int64)
    pts = np.empty(total, np.int64)
    one_lo = np.zeros(1, np.int64)
    one_n = np.zeros(1, np.int64)
    U = 0
    for k in range(K):
        if skip_explained and explained[seeds[k]]:
            continue
        q = conics[k]
        ok, cx, cy, A, _, _ = ellipse_row(q)
        if not ok:
            continue
        nm = 0
        m = 0
        for it in range(n_iter):
            if it > 0:  # again around the union's fit
                one_n[0] = m
                c, _ = fit_ranges(xy, pts, one_lo, one_n, np.inf, 0.0, 0.0, np.inf, 0.0, 0.0)
                ok, cx, cy, A, _, _ = ellipse_row(c[0])
                if not ok:
                    break
                q = c[0]
            reach = A + band + 1
            nm = 0
            m = 0
            for p in range(P):
                if _piece_on(q, cx, cy, reach, xy, order, p_start[p], p_cnt[p], ct, st, band, cos_tol):
                    members[nm] = p
                    nm += 1
                    for r in range(p_start[p], p_start[p] + p_cnt[p]):
                        pts[m] = order[r]
                        m += 1
            if m < 6:
                break
        if m < 6:
            continue
        one_n[0] = m
        c, g = fit_ranges(xy, pts, one_lo, one_n, max_rms, min_inliers, ax_lo, ax_hi, min_ratio, min_arc_deg)
        out_c[U] = c[0]
        out_good[U] = g[0]
        out_n[U] = m
        U += 1
        if g[0]:
            for j in range(nm):
                explained[members[j]] = True
    return out_c[:U], out_good[:U], out_n[:U]
