"""Compiled inner loops of the circle finder (Numba): casting the directional votes, listing the
voters of each centre candidate, and refining each hypothesis on the edge pixels of its ring.

They run the same arithmetic as the array code they replace, but in one pass over the data
with no temporaries, so the finder's cost follows the edge pixels and the rings' areas rather
than the thousand NumPy calls a batched formulation needs (about 3x faster at 512^2). Image
coordinates: x = column, y = row, integers at pixel centres; all lengths in pixels.
"""
from __future__ import annotations

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _norm(x, y):  # pragma: no cover - compiled
    """|(x, y)| by sqrt (libm's hypot guards against overflow that pixel offsets never reach,
    at several times the cost)."""
    return np.sqrt(x * x + y * y)


@_jit
def accumulate(x, y, ct, st, rc, rs, col_band, inv, pad, cols, off, total):  # pragma: no cover - compiled
    """Votes per accumulator cell (int64, ``total`` cells, all bands back to back), and the
    cell of every vote, (N, M, 2) int32 (point, column, sense).

    Point i votes at ``u +- (rc ct - rs st, rc st + rs ct)`` for every column j, with
    ``u = (x + 0.5) / cell + pad`` in its band's padded grid of cells (truncation is the
    floor there, the padding keeping every vote inside).
    """
    acc = np.zeros(total, np.int64)
    flat = np.empty((len(x), len(rc), 2), np.int32)
    for i in range(len(x)):
        b = -1
        u = v = 0.0
        for j in range(len(rc)):
            if col_band[j] != b:  # the columns come band by band
                b = col_band[j]
                u = (x[i] + 0.5) * inv[b] + pad[b]
                v = (y[i] + 0.5) * inv[b] + pad[b]
            dx = rc[j] * ct[i] - rs[j] * st[i]
            dy = rc[j] * st[i] + rs[j] * ct[i]
            f0 = off[b] + int(v + dy) * cols[b] + int(u + dx)
            f1 = off[b] + int(v - dy) * cols[b] + int(u - dx)
            acc[f0] += 1
            acc[f1] += 1
            flat[i, j, 0] = f0
            flat[i, j, 1] = f1
    return acc, flat


@_jit
def block_voters(flat, lookup, n_cand, bound):  # pragma: no cover - compiled
    """(candidate, point) pairs, once each, in point order: the points with a vote in the
    candidate's block. ``lookup`` maps each accumulator cell to its candidate (-1 elsewhere);
    ``bound`` is the votes in all the blocks together (an upper bound on the pairs)."""
    last = np.full(n_cand, -1, np.int64)
    ks = np.empty(bound, np.int64)
    ps = np.empty(bound, np.int64)
    n = 0
    N, M, _ = flat.shape
    for i in range(N):
        for j in range(M):
            for s in range(2):
                k = lookup[flat[i, j, s]]
                if k >= 0 and last[k] != i:
                    last[k] = i
                    ks[n] = k
                    ps[n] = i
                    n += 1
    return ks[:n], ps[:n]


@_jit
def block_peaks(acc, off, rows, cols, pad, y1, x1, t):  # pragma: no cover - compiled
    """Centre blocks: 2 x 2 cell sums of at least ``t[b]`` that no neighbouring block (3 x 3)
    beats (ties: the first in scan order wins), among the blocks holding a cell of at least
    a quarter of that, whose top-left cell lies in rows ``pad - 1 .. y1 - 1`` and columns
    ``pad - 1 .. x1 - 1`` of its band (the corner in the image).

    Returns
    -------
    blk : (K,) int64
        Flat index of each block's top-left cell, by band then scan order.
    band : (K,) int64
    votes : (K,) int64
    """
    # mark the blocks holding a hot cell, then list the marked ones in scan order
    seen = np.zeros(len(acc), np.bool_)
    n = 0
    for b in range(len(off)):
        C, base = cols[b], off[b]
        t4 = (t[b] + 3) // 4
        for q in range(base + C + 1, base + rows[b] * C):
            if acc[q] >= t4:
                seen[q] = seen[q - 1] = seen[q - C] = seen[q - C - 1] = True
                n += 4
    blk = np.empty(n, np.int64)
    bnd = np.empty(n, np.int64)
    n = 0
    for b in range(len(off)):
        C, base = cols[b], off[b]
        for row in range(pad[b] - 1, y1[b]):
            for q in range(base + row * C + pad[b] - 1, base + row * C + x1[b]):
                if seen[q]:
                    blk[n] = q
                    bnd[n] = b
                    n += 1
    out = np.empty(n, np.int64)
    votes = np.empty(n, np.int64)
    m = 0
    for q in range(n):
        f, C = blk[q], cols[bnd[q]]
        v = acc[f] + acc[f + 1] + acc[f + C] + acc[f + C + 1]
        if v < t[bnd[q]]:
            continue
        peak = True
        for oy in range(-1, 2):
            for ox in range(-1, 2):
                if oy == 0 and ox == 0:
                    continue
                g = f + oy * C + ox
                w = acc[g] + acc[g + 1] + acc[g + C] + acc[g + C + 1]
                if (oy < 0 or (oy == 0 and ox < 0)) and not v > w:
                    peak = False
                elif not (oy < 0 or (oy == 0 and ox < 0)) and not v >= w:
                    peak = False
        if peak:
            out[m] = f
            bnd[m] = bnd[q]
            votes[m] = v
            m += 1
    return out[:m], bnd[:m].copy(), votes[:m]


@_jit
def centres_and_radii(x, y, ct, st, k, i, cen, cell, lo, hi, threshold, step,
                      nb):  # pragma: no cover - compiled
    """Circle hypotheses of the centre candidates from their voters ``(k, i)``.

    Centre: the least-squares intersection of the voters' normal lines (no radius needed),
    kept at the block's corner ``cen`` when singular or more than 1.5 cells from it (a clutter
    of unrelated voters can pull it away). Radii: peaks of the histogram of voter distances
    (``step`` px bins; a bin plus its larger neighbour at least ``threshold * 2 pi r``) within
    the band ``lo - 1 .. hi + 1``, at the centroid of the three bins.

    Returns
    -------
    c0 : (K, 2) float
        Candidate centres.
    hk : (P,) int64, r0 : (P,) float
        Candidate and radius of each hypothesis, by candidate then radius.
    """
    K = len(cen)
    a = np.zeros((K, 6))
    for q in range(len(k)):
        p, kk = i[q], k[q]
        tx, ty = -st[p], ct[p]
        a[kk, 0] += tx * tx
        a[kk, 1] += tx * ty
        a[kk, 2] += ty * ty
        a[kk, 3] += tx * tx * x[p] + tx * ty * y[p]
        a[kk, 4] += tx * ty * x[p] + ty * ty * y[p]
        a[kk, 5] += 1.0
    c0 = np.empty((K, 2))
    for kk in range(K):
        det = a[kk, 0] * a[kk, 2] - a[kk, 1] * a[kk, 1]
        ok = abs(det) > 1e-6 * max(a[kk, 5], 1.0) ** 2
        cx = cy = 0.0
        if ok:
            cx = (a[kk, 2] * a[kk, 3] - a[kk, 1] * a[kk, 4]) / det
            cy = (a[kk, 0] * a[kk, 4] - a[kk, 1] * a[kk, 3]) / det
            ok = np.isfinite(cx) and np.isfinite(cy) and max(abs(cx - cen[kk, 0]), abs(cy - cen[kk, 1])) <= 1.5 * cell[kk]
        c0[kk, 0] = cx if ok else cen[kk, 0]
        c0[kk, 1] = cy if ok else cen[kk, 1]
    hist = np.zeros((K, nb))
    for q in range(len(k)):
        p, kk = i[q], k[q]
        b = min(int(_norm(x[p] - c0[kk, 0], y[p] - c0[kk, 1]) / step), nb - 1)
        hist[kk, b] += 1.0
    hk = np.empty(K * nb, np.int64)
    r0 = np.empty(K * nb)
    m = 0
    for kk in range(K):
        for b in range(nb):
            rb = (b + 0.5) * step
            if rb < lo[kk] - 1 or rb > hi[kk] + 1:
                continue
            h = hist[kk, b]
            left = hist[kk, b - 1] if b > 0 else -1.0
            right = hist[kk, b + 1] if b < nb - 1 else -1.0
            if h > left and h >= right and h + max(left, right) >= threshold * 2 * np.pi * rb:
                w0, w2 = max(left, 0.0), max(right, 0.0)
                hk[m] = kk
                r0[m] = rb + step * (w2 - w0) / max(w0 + h + w2, 1.0)
                m += 1
    return c0, hk[:m], r0[:m]


@_jit
def _gather(cx, cy, r, width, index, H, W, out):  # pragma: no cover - compiled
    """Edge points on the pixels whose offset (dx, dy) from the rounded centre has a length
    within ``width`` (+1.25: the rounding of the centre, 0.71 px, and the points' offsets
    from their pixels, at most 0.5 px) of ``r``, row by row (in memory order); written to
    ``out``, their number returned."""
    lo = max(r - width - 1.25, 0.0)
    hi = r + width + 1.25
    ix, iy = int(np.rint(cx)), int(np.rint(cy))
    R = int(hi)
    n = 0
    for dy in range(max(-R, -iy), min(R, H - 1 - iy) + 1):
        row = (iy + dy) * W
        outer = int(np.sqrt(max(hi * hi - dy * dy, 0.0))) + 1
        inner = int(np.sqrt(max(lo * lo - dy * dy, 0.0))) - 1  # |dx| below it is inside the hole
        # the row crosses the annulus in [-outer, -inner] and [inner, outer], or in one run
        # [-outer, outer] where it misses the hole
        for side in range(2 if inner > 0 else 1):
            a, b = (-outer, outer) if inner <= 0 else ((-outer, -inner) if side == 0 else (inner, outer))
            for dx in range(max(a, -ix), min(b, W - 1 - ix) + 1):
                p = index[row + ix + dx]
                if p >= 0:
                    d = np.sqrt(dx * dx + dy * dy)
                    if lo <= d <= hi:
                        out[n] = p
                        n += 1
    return n


@_jit
def _gauss_newton(px, py, pts, n, cx, cy, r, iterations, max_step):  # pragma: no cover - compiled
    """Geometric least-squares circle through ``px/py[pts[:n]]`` from (cx, cy, r), as
    :func:`rangesim.core.conics.fit_circles_batched` (at least 5 points, a non-singular
    system, steps of at most ``max_step``; otherwise the start is kept)."""
    if n < 5:
        return cx, cy, r
    for _ in range(iterations):
        sxx = syy = sxy = sx = sy = ex = ey = se = 0.0
        for q in range(n):
            dx, dy = px[pts[q]] - cx, py[pts[q]] - cy
            rho = max(_norm(dx, dy), 1e-9)
            ux, uy = dx / rho, dy / rho
            e = rho - r
            sxx += ux * ux
            syy += uy * uy
            sxy += ux * uy
            sx += ux
            sy += uy
            ex += e * ux
            ey += e * uy
            se += e
        # the symmetric 3 x 3 normal equations [[sxx sxy sx] [sxy syy sy] [sx sy n]] by Cramer
        nn = float(n)
        c00, c01, c02 = syy * nn - sy * sy, sy * sx - sxy * nn, sxy * sy - syy * sx
        det = sxx * c00 + sxy * c01 + sx * c02
        if not abs(det) > 1e-9 * nn ** 3:
            break
        c11, c12, c22 = sxx * nn - sx * sx, sxy * sx - sxx * sy, sxx * syy - sxy * sxy
        s0 = (c00 * ex + c01 * ey + c02 * se) / det
        s1 = (c01 * ex + c11 * ey + c12 * se) / det
        s2 = (c02 * ex + c12 * ey + c22 * se) / det
        if max(abs(s0), abs(s1), abs(s2)) > max_step:
            break
        cx += s0
        cy += s1
        r += s2
    return cx, cy, r


@_jit
def _select(px, py, ct, st, ring, n, cx, cy, r, width, cos_tol, out):  # pragma: no cover - compiled
    """Ring points whose edge normal is radial within ``acos(cos_tol)`` and whose distance to
    the circle is at most ``width``; written to ``out``, their number returned."""
    m = 0
    for q in range(n):
        p = ring[q]
        dx, dy = px[p] - cx, py[p] - cy
        dist = max(_norm(dx, dy), 1e-9)
        if abs(dx * ct[p] + dy * st[p]) >= cos_tol * dist and abs(dist - r) <= width:
            out[m] = p
            m += 1
    return m


@_jit
def refine(px, py, ct, st, index, H, W, c, r, reach, band_px, cos_tol, max_step, labels, split, concave,
           none):  # pragma: no cover - compiled
    """Refine every hypothesis on its ring, then list its inliers.

    Per hypothesis: the ring of ``reach`` px is looked up once; three Gauss-Newton fits on
    its radially oriented points within ``reach``, then ``band_px + 0.5`` twice (1, 2, 2
    steps); a refit on the stretches of arc where the ring is one edge thick
    (:func:`_thin_fit`); with ``split``, a hypothesis whose ring holds two edges is replaced
    by the two circles they lie on (:func:`_two_edges`; ``labels`` (N,) uint8 the points'
    edge kinds, or empty; ``concave`` and ``none`` the label values of
    :func:`rangesim.features._edge_points.one_edge`); and the inliers: radial ring points
    within ``band_px``.

    Returns
    -------
    c : (K', 2) float, r : (K',) float
        K' >= K circles: a split hypothesis gives two, next to each other.
    hyp, point : (P,) int64
        The inliers, grouped by circle.
    parent : (K',) int64
        The hypothesis each circle comes from.
    sibling : (K',) int64
        The other circle of a split hypothesis, -1 for the others.
    """
    K = len(r)
    cap_k = 2 * K if split else K
    c_out = np.empty((cap_k, 2))
    r_out = np.empty(cap_k)
    parent = np.empty(cap_k, np.int64)
    sibling = np.full(cap_k, -1, np.int64)
    ring = np.empty(len(px), np.int64)  # a ring holds each edge point once at most
    sel = np.empty(len(px), np.int64)
    aux = np.empty(len(px) if split else 0, np.int64)
    cap = 1024
    hyp = np.empty(cap, np.int64)
    pnt = np.empty(cap, np.int64)
    total = 0
    k_out = 0
    two = np.empty((2, 3))
    for k in range(K):
        cx, cy, rk = c[k, 0], c[k, 1], r[k]
        n = _gather(cx, cy, rk, reach[k], index, H, W, ring)
        for p in range(3):
            width = reach[k] if p == 0 else band_px + 0.5
            m = _select(px, py, ct, st, ring, n, cx, cy, rk, width, cos_tol, sel)
            cx, cy, rk = _gauss_newton(px, py, sel, m, cx, cy, rk, 1 if p == 0 else 2, max_step)
        cx, cy, rk, thick = _thin_fit(px, py, ct, st, index, H, W, cx, cy, rk, cos_tol, ring, sel)
        n_new = 1
        two[0, 0], two[0, 1], two[0, 2] = cx, cy, rk
        # a ring with two edges is thick over much of its arc already within _thin_fit's 3 px
        # (half of _two_edges' threshold there, as its ring is narrower): the others are not
        # looked at again
        if split and thick >= 0.5 * SPLIT_MIN_THICK and _two_edges(px, py, ct, st, labels, index, H, W, cx, cy, rk, cos_tol, ring, sel, aux,
                                concave, none, two):
            n_new = 2
            sibling[k_out] = k_out + 1
            sibling[k_out + 1] = k_out
        for q in range(n_new):
            cx, cy, rk = two[q, 0], two[q, 1], two[q, 2]
            c_out[k_out, 0], c_out[k_out, 1], r_out[k_out] = cx, cy, rk
            parent[k_out] = k
            n = _gather(cx, cy, rk, band_px + 0.5, index, H, W, ring)
            m = _select(px, py, ct, st, ring, n, cx, cy, rk, band_px, cos_tol, sel)
            if total + m > cap:
                while total + m > cap:
                    cap *= 2
                hyp2 = np.empty(cap, np.int64)
                pnt2 = np.empty(cap, np.int64)
                hyp2[:total] = hyp[:total]
                pnt2[:total] = pnt[:total]
                hyp, pnt = hyp2, pnt2
            hyp[total:total + m] = k_out
            pnt[total:total + m] = sel[:m]
            total += m
            k_out += 1
    return (c_out[:k_out].copy(), r_out[:k_out].copy(), hyp[:total], pnt[:total], parent[:k_out].copy(),
            sibling[:k_out].copy())


@_jit
def _thin_fit(px, py, ct, st, index, H, W, cx, cy, r, cos_tol, ring, sel,
              reach=3.0, thick=1.5):  # pragma: no cover - compiled
    """Refit a circle on the stretches of arc where its ring is one edge thick.

    Where a second edge runs beside the circle (the wall seen inside a hole's rim, a crescent
    of edge pixels), the radially oriented pixels within ``reach`` px of it, per 2 px of arc,
    spread over more than ``thick`` px: those stretches are left out, so the fit follows the
    thin rim rather than the middle of the band. The refit (3 steps) is kept when at least a
    quarter of the circle is thin (a short arc alone is ill-conditioned). Returns the circle
    and the fraction of its bins that were thick (:func:`refine` looks for two edges only
    in rings with enough of them).
    """
    n = _gather(cx, cy, r, reach, index, H, W, ring)
    nb = max(int(np.rint(np.pi * r)), 8)  # bins of about 2 px of arc
    lo = np.full(nb, np.inf)
    hi = np.full(nb, -np.inf)
    m = 0
    for q in range(n):
        p = ring[q]
        dx, dy = px[p] - cx, py[p] - cy
        dist = max(_norm(dx, dy), 1e-9)
        e = dist - r
        if abs(dx * ct[p] + dy * st[p]) >= cos_tol * dist and abs(e) <= reach:
            ang = np.arctan2(dy, dx) % (2 * np.pi)
            b = min(int(ang / (2 * np.pi) * nb), nb - 1)
            lo[b] = min(lo[b], e)
            hi[b] = max(hi[b], e)
            ring[m] = p
            sel[m] = b
            m += 1
    n_thick = 0
    for b in range(nb):
        if hi[b] - lo[b] > thick:
            n_thick += 1
    kept = 0
    for q in range(m):
        p = ring[q]
        b = sel[q]
        if hi[b] - lo[b] <= thick:
            e = _norm(px[p] - cx, py[p] - cy) - r
            if abs(e) <= 2.0:
                ring[kept] = p
                kept += 1
    if kept < 0.25 * 2 * np.pi * r:
        return cx, cy, r, n_thick / nb
    cx, cy, r = _gauss_newton(px, py, ring, kept, cx, cy, r, 3, 3.0)
    return cx, cy, r, n_thick / nb


#: :func:`_two_edges`: half-width of the ring searched for a second edge, px (two edges nearer
#: than the refinement's bands, 1.5-4.5 px, are averaged by it)
SPLIT_REACH_PX = 4.0
#: an arc bin holds two edges when its points spread over more than this, px (as _thin_fit)
SPLIT_THICK_PX = 1.5
#: least fraction of the circle's arc bins holding two edges for a split
SPLIT_MIN_THICK = 0.15
#: each edge's seed points: within this of the bin's outermost / innermost point, px (the
#: points' jitter and pixel rounding, about +-0.5 px)
SPLIT_CLUSTER_PX = 0.75
#: the two circles must differ by at least this in radius or centre, px
SPLIT_MIN_APART_PX = 0.75
#: least fraction of the ring's points within 1 px of one of the two circles
SPLIT_EXPLAINED = 0.8


@_jit
def _kind_flags(labels, pts, concave, none):  # pragma: no cover - compiled
    """The one_edge rule's flags for the points ``pts`` (indices into ``labels``): (drop
    concave, drop other), the minority kind of concave against other labelled points, as
    :func:`rangesim.features._edge_points.one_edge`; neither where one kind is absent."""
    n_c = 0
    n_o = 0
    for p in pts:
        lab = labels[p]
        if lab == concave:
            n_c += 1
        elif lab != none:
            n_o += 1
    both = n_c > 0 and n_o > 0
    return both and n_c <= n_o, both and n_c > n_o


@_jit
def _kind_filter(labels, pts, n, concave, none):  # pragma: no cover - compiled
    """Keep (in place, first ``n`` of ``pts``) the points of one edge kind
    (:func:`_kind_flags`; unlabelled kept; ``labels`` empty: all); their number returned,
    and the rule's two flags (drop concave, drop other) for later rings of the same circle."""
    if len(labels) == 0:
        return n, False, False
    drop_c, drop_o = _kind_flags(labels, pts[:n], concave, none)
    return _apply_kind(labels, pts, n, drop_c, drop_o, concave, none), drop_c, drop_o


@_jit
def _apply_kind(labels, pts, n, drop_c, drop_o, concave, none):  # pragma: no cover - compiled
    """Drop (in place) the points of ``pts[:n]`` that the flags of :func:`_kind_flags` leave out."""
    if len(labels) == 0 or not (drop_c or drop_o):
        return n
    m = 0
    for q in range(n):
        if not _dropped(labels[pts[q]], drop_c, drop_o, concave, none):
            pts[m] = pts[q]
            m += 1
    return m


@_jit
def _trimmed(px, py, pts, n, cx, cy, r, passes=2):  # pragma: no cover - compiled
    """Refit ``pts[:n]`` without the points farther from the circle than 2.5 times their
    median distance (at least ``SPLIT_CLUSTER_PX``), ``passes`` times: a seed whose bins
    caught a third edge (a crease beside the rim) is pulled back onto the one most of it
    lies on. Reorders ``pts[:n]``."""
    dist = np.empty(n)
    for _ in range(passes):
        for q in range(n):
            dist[q] = abs(_norm(px[pts[q]] - cx, py[pts[q]] - cy) - r)
        tol = max(2.5 * np.median(dist[:n]), SPLIT_CLUSTER_PX)
        m = 0
        for q in range(n):
            if dist[q] <= tol:
                pts[m], pts[q] = pts[q], pts[m]
                m += 1
        if m < 5 or m == n:
            break
        cx, cy, r = _gauss_newton(px, py, pts, m, cx, cy, r, 3, 3.0)
        n = m
    return cx, cy, r


@_jit
def _two_edges(px, py, ct, st, labels, index, H, W, cx, cy, r, cos_tol, ring, sel, aux, concave, none,
               out):  # pragma: no cover - compiled
    """Whether a refined circle averages two near-concentric edges; if so, the two circles.

    Two circles nearly concentric, or internally nearly tangent (a tapped hole's rim and its
    crests seen down the hole, a counterbore's step), lie within the refinement's bands of
    each other over much of their arc, so a fit to the ring lands between them. The ring of
    ``SPLIT_REACH_PX`` around the circle (radial points of its own edge kind) is cut into
    bins of about 2 px of arc; a bin holds two edges when its points spread over more than
    ``SPLIT_THICK_PX``. With at least ``SPLIT_MIN_THICK`` of the bins so, the outermost and
    innermost points of those bins (within ``SPLIT_CLUSTER_PX``) seed two circles, each then
    refitted on the whole ring in bands narrowing to 1 and 0.75 px, so each locks onto its
    own edge (where they coincide, both keep those points). Written to ``out`` (2, 3): (cx,
    cy, r) of the outer and the inner circle; False (``out`` untouched) when the ring has one
    edge, a seed is too small or the two circles come out within ``SPLIT_MIN_APART_PX``.
    """
    reach = SPLIT_REACH_PX
    n = _gather(cx, cy, r, reach, index, H, W, ring)
    m = _select(px, py, ct, st, ring, n, cx, cy, r, reach, cos_tol, sel)
    m, drop_c, drop_o = _kind_filter(labels, sel, m, concave, none)
    nb = max(int(np.rint(np.pi * r)), 8)  # bins of about 2 px of arc
    lo = np.full(nb, np.inf)
    hi = np.full(nb, -np.inf)
    for q in range(m):
        p = sel[q]
        dx, dy = px[p] - cx, py[p] - cy
        e = _norm(dx, dy) - r
        b = min(int((np.arctan2(dy, dx) % (2 * np.pi)) / (2 * np.pi) * nb), nb - 1)
        ring[q] = b  # the bin of each selected point (the ring is gathered again below)
        lo[b] = min(lo[b], e)
        hi[b] = max(hi[b], e)
    n_thick = 0
    for b in range(nb):
        if hi[b] - lo[b] > SPLIT_THICK_PX:
            n_thick += 1
    if n_thick < SPLIT_MIN_THICK * nb:
        return False
    for side in range(2):  # 0: outer, 1: inner
        k = 0
        for q in range(m):
            p = sel[q]
            b = ring[q]
            if hi[b] - lo[b] > SPLIT_THICK_PX:
                e = _norm(px[p] - cx, py[p] - cy) - r
                if (side == 0 and e >= hi[b] - SPLIT_CLUSTER_PX) or (side == 1 and e <= lo[b] + SPLIT_CLUSTER_PX):
                    aux[k] = p
                    k += 1
        if k < 5:
            return False
        ox, oy, orr = _gauss_newton(px, py, aux, k, cx, cy, r, 3, 3.0)
        ox, oy, orr = _trimmed(px, py, aux, k, ox, oy, orr)
        out[side, 0], out[side, 1], out[side, 2] = ox, oy, orr
    for side in range(2):  # locked refits, each on the whole ring about its own circle
        ox, oy, orr = out[side, 0], out[side, 1], out[side, 2]
        n2 = _gather(ox, oy, orr, 2.0, index, H, W, aux)
        n2 = _apply_kind(labels, aux, n2, drop_c, drop_o, concave, none)
        for width in (1.0, 0.75):
            k = _select(px, py, ct, st, aux, n2, ox, oy, orr, width, cos_tol, ring)
            ox, oy, orr = _gauss_newton(px, py, ring, k, ox, oy, orr, 2, 3.0)
        out[side, 0], out[side, 1], out[side, 2] = ox, oy, orr
    apart = max(abs(out[0, 2] - out[1, 2]), _norm(out[0, 0] - out[1, 0], out[0, 1] - out[1, 1]))
    if not apart >= SPLIT_MIN_APART_PX:
        out[0, 0], out[0, 1], out[0, 2] = cx, cy, r
        return False
    # the ring must be those two edges: where a third runs between or beside them (a crease
    # beside a rim), the two circles are not the ring's edges and the averaged one is kept
    # (sel[:m] still holds the ring's radial points of the edge kind, as found above)
    near = 0
    for q in range(m):
        p = sel[q]
        d0 = abs(_norm(px[p] - out[0, 0], py[p] - out[0, 1]) - out[0, 2])
        d1 = abs(_norm(px[p] - out[1, 0], py[p] - out[1, 1]) - out[1, 2])
        if min(d0, d1) <= 1.0:
            near += 1
    if near < SPLIT_EXPLAINED * m:
        out[0, 0], out[0, 1], out[0, 2] = cx, cy, r
        return False
    return True


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _dropped(lab, drop_concave, drop_other, concave, none):  # pragma: no cover - compiled
    """Whether :func:`claim`'s one_edge rule leaves out a point labelled ``lab``."""
    return (drop_concave and lab == concave) or (drop_other and lab != concave and lab != none)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def claim(order, starts, points, labels, x, y, cx, cy, r, min_support, concave, none):  # pragma: no cover - compiled
    """The circles' claim loop of :func:`rangesim.features.circles`: each edge point supports
    one circle, strongest first.

    Candidate ``j`` (in ``order``) has the points ``points[starts[j]:starts[j + 1]]``. It keeps
    those of its own edge (:func:`rangesim.features._edge_points.one_edge`: the majority of
    concave against other labelled points, unlabelled ones kept; ``labels`` empty: all), and
    is kept when all of them are free or the free ones still cover ``min_support`` of
    ``max(round(2 pi r), 8)`` equal angular bins; a kept candidate takes its points.
    Returns the kept candidates, in ``order``'s order. (:func:`claim_pairs` with no pairs.)
    """
    return claim_pairs(order, starts, points, labels, x, y, cx, cy, r, min_support, concave, none,
                       np.full(len(r), -1, np.int64))


#: :func:`_tangent_inside`: two circles meet when the gap between them at their nearest is at
#: most this, px (the inliers' band, ``band_px`` of :func:`refine`: a point there lies on both;
#: from the geometry, not tuned)
TANGENT_MEET_PX = 1.0
#: ... and are two edges, not one found twice, when the gap at their farthest is at least this,
#: px (two bands: there the two circles' inliers are disjoint; from the geometry, not tuned)
TANGENT_APART_PX = 2.0


#: ... and the larger circle keeps the shared points only when the points no tangent circle
#: took cover at least this share of ``min_support`` of its perimeter: a circle of one ring
#: drawn 0.9 px off it with 1.2 px more radius passes the tangency test and was covered by
#: the ring's own pixels alone (a review's probe)
TANGENT_OWN_SHARE = 0.25


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _tangent_inside(ax, ay, ar, bx, by, br):  # pragma: no cover - compiled
    """Whether two circles are internally nearly tangent: one inside the other, meeting within
    ``TANGENT_MEET_PX`` on one side (nearest gap ``|ra - rb| - d``, d the centres' distance)
    and ``TANGENT_APART_PX`` or more apart on the other (``|ra - rb| + d``): a tapped hole's
    rim and the crest outline seen inside it, a counterbore's step. Where they meet both
    edges run through the same pixels, so those points support both circles."""
    d = _norm(ax - bx, ay - by)
    dr = abs(ar - br)
    return abs(dr - d) <= TANGENT_MEET_PX and dr + d >= TANGENT_APART_PX


@numba.njit(cache=True, nogil=True, error_model="numpy")
def claim_pairs(order, starts, points, labels, x, y, cx, cy, r, min_support, concave, none,
                sibling):  # pragma: no cover - compiled
    """:func:`claim`, where the two circles of a split hypothesis (``sibling[j]``, -1 for
    none) share their points: two edges that meet (a rim and the circle tangent inside it)
    both run through the pixels where they meet, so a point taken by the sibling still covers
    its bin. So does a point taken by a smaller circle internally tangent to candidate ``j``
    (:func:`_tangent_inside`: a tapped hole's crest outline kept before its rim, which meets
    it on one side). Only the larger circle shares: a circle averaging two such edges lies
    inside the outer one and meets it as well, and letting it share kept it beside the true
    inner circle (tangent pairs drawn as ``benchmarks/bench_hough.py``'s, seeds 10-15:
    precision 1.00 -> 0.93 sharing both ways, 1.00 with the larger only; recall 0.69 -> 0.75).
    Points taken by any other circle do not count (a ghost across two rims, a duplicate).
    """
    owner = np.full(len(x), -1, np.int64)
    kept = np.empty(len(order), np.int64)
    n_kept = 0
    two_pi = 2 * np.pi
    for j in order:
        a, b = starts[j], starts[j + 1]
        drop_concave = False
        drop_other = False
        if len(labels) > 0:
            drop_concave, drop_other = _kind_flags(labels, points[a:b], concave, none)
        n_bins = max(int(np.rint(two_pi * r[j])), 8)
        occ = np.zeros(n_bins, np.bool_)
        own = np.zeros(n_bins, np.bool_)  # bins covered by points no tangent circle took
        all_free = True
        tangent_shared = False
        for k in range(a, b):
            p = points[k]
            if len(labels) > 0 and _dropped(labels[p], drop_concave, drop_other, concave, none):
                all_free = False  # one_edge dropped it: the candidate lost points
                continue
            mine = True
            if owner[p] >= 0:
                all_free = False
                o = owner[p]
                if o == sibling[j] and sibling[j] >= 0:
                    pass
                elif r[j] > r[o] and _tangent_inside(cx[j], cy[j], r[j], cx[o], cy[o], r[o]):
                    mine = False
                    tangent_shared = True
                else:
                    continue
            ang = np.arctan2(y[p] - cy[j], x[p] - cx[j]) % two_pi
            bin_ = int(np.floor(ang / two_pi * n_bins)) % n_bins
            occ[bin_] = True
            if mine:
                own[bin_] = True
        if not all_free:
            if np.count_nonzero(occ) / n_bins < min_support:
                continue
            # a second edge, not one edge found twice: where the two circles are apart it
            # has points of its own
            if tangent_shared and np.count_nonzero(own) / n_bins < TANGENT_OWN_SHARE * min_support:
                continue
        for k in range(a, b):
            p = points[k]
            if owner[p] < 0 and not (len(labels) > 0 and _dropped(labels[p], drop_concave, drop_other, concave, none)):
                owner[p] = j
        kept[n_kept] = j
        n_kept += 1
    return kept[:n_kept]
