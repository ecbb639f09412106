"""Model-free ellipses: conics fitted to short arcs of edge pixels, then grown along the edges.

Hypotheses come from the pieces of smooth edge curves inside square tiles of several sizes
(tiles that shift by half their size, so that every arc lies whole in some tile at some scale);
each hypothesis that is a good ellipse on its piece is grown over all the edge points near it
whose edge direction agrees, refitted, and kept when it covers enough of its own perimeter.
Each edge point is claimed by one ellipse (strongest first): a candidate left with too little
unclaimed support is dropped. All of it is batched: the work follows
the edge pixels and the number of hypotheses, with no per-curve loop and no tracing.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from rangesim.core.conics import (
    ellipse_params,
    fit_conics_moments,
    real_ellipses,
)
from rangesim.features._conic_kernels import band_moments, curve_links, grouped_frames, piece_moments, sampson_pairs
from rangesim.features._edge_points import one_edge

#: tile sizes (px) of the arc pieces; each tiling also shifted by half a tile (diagonally)
TILES_PX = (16, 32, 64, 128, 256)
#: neighbouring edge pixels belong to one smooth curve when their edge normals agree within this
LINK_DEG = 35.0
#: neighbouring edge pixels are linked only when their step is at least this far off their normals
ADJACENT_DEG = 30.0
#: ellipses longer than this (px of perimeter) are not scored: conics of straight runs
MAX_PERIMETER_PX = 20000.0
#: a grown point's edge normal must agree with the ellipse's normal within this, degrees
DIRECTION_TOL_DEG = 25.0
#: :func:`grow` looks for its points within its first band plus this, px (a refit moves an
#: ellipse by less)
GROW_MARGIN_PX = 3.0


def smooth_curves(xy: np.ndarray, theta: np.ndarray, link_deg: float = LINK_DEG, gap_px: int = 2) -> np.ndarray:
    """Curve label of every edge point: nearby edge pixels whose normals agree.

    Two edge pixels are linked when they are 8-neighbours, or up to ``gap_px`` + 1 px apart
    along their common tangent (the step within ``link_deg`` of the tangent: gaps of up to
    ``gap_px`` missing pixels are bridged, parallel edges are not), and their normals agree
    within ``link_deg`` (the sense ignored).

    Parameters
    ----------
    xy : (N, 2) float, pixels (integer pixel positions)
    theta : (N,) float
        Edge-normal angles, radians.

    Returns
    -------
    (N,) int
        Component labels: a corner (normals turning by more than ``link_deg`` between two
        neighbours) or a crossing edge of another direction ends a curve.
    """
    n = len(xy)
    if n == 0:
        return np.zeros(0, int)
    x, y = xy[:, 0].astype(np.int64), xy[:, 1].astype(np.int64)
    x, y = x - x.min(), y - y.min()  # the index image covers the points' box only
    r, c = curve_links(x, y, np.asarray(theta, np.float64), int(gap_px) + 1, float(np.cos(np.deg2rad(link_deg))),
                       float(np.sin(np.deg2rad(link_deg))), float(np.cos(np.deg2rad(ADJACENT_DEG))))
    g = coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(n, n))
    return connected_components(g, directed=False)[1]


def arc_hypotheses(xy: np.ndarray, curve: np.ndarray, *, min_points: int = 10, tiles_px=TILES_PX,
                   max_rms: float = 0.5, min_inliers: float = 0.6, min_arc_deg: float = 60.0,
                   axes_range: tuple[float, float] = (4.0, 200.0), min_ratio: float = 0.2,
                   pairs_per_tile: int = 3):
    """Ellipses fitted to the pieces of each smooth curve inside square tiles.

    Parameters
    ----------
    xy : (N, 2) float
    curve : (N,) int
        :func:`smooth_curves` labels.
    min_points : int
        Least points of a piece.
    max_rms, min_inliers : float
        A piece's fit is kept when the RMS Sampson distance of its points is at most
        ``max_rms`` px and ``min_inliers`` of them lie within 1 px.
    min_arc_deg : float
        Least angle of the ellipse (parametric, in 10 degree bins) the piece covers: shorter
        arcs leave the ellipse ill-determined.

    Returns
    -------
    conics : (K, 6) float
        Unit-norm conics of the kept pieces, the longest pieces first.
    n_points : (K,) int
    """
    n = len(xy)
    if n < min_points:
        return np.zeros((0, 6)), np.zeros(0, int)
    # pieces: the points of one curve in one tile (every tiling: sizes x 2 shifts); each
    # tile is the frame of its pieces' moments (origin its centre, scale half its size)
    tiles, frames, x, y = [], [], xy[:, 0], xy[:, 1]
    for s in tiles_px:
        for ox, oy in ((0, 0), (s // 2, s // 2)):
            # floor of a true quotient (the tiles are powers of two: exact) is 3x np.floor_divide's speed
            tx, ty = np.floor((x + ox) / s).astype(np.int64), np.floor((y + oy) / s).astype(np.int64)
            tiles.append((len(tiles) * 4096 + ty) * 4096 + tx)
            frames.append(np.column_stack([(tx + 0.5) * s - ox, (ty + 0.5) * s - oy, np.full(n, s / 2)]))
    n_curves = int(curve.max()) + 1
    uk, first_row, piece, cnt = np.unique(np.concatenate(tiles) * n_curves + np.tile(curve, len(tiles)),
                                          return_index=True, return_inverse=True, return_counts=True)
    frame = np.concatenate(frames)[first_row]  # (P, 3): origin x, y and scale of each piece
    piece_tile, piece_curve = uk // n_curves, uk % n_curves
    small = max(5, min_points // 3)
    use = cnt >= small
    rows = np.nonzero(use[piece])[0]
    pt, pc = np.tile(np.arange(n), len(tiles))[rows], piece[rows]
    o = np.argsort(pc, kind="stable")
    pt, pc = pt[o], pc[o]
    mom = np.zeros((len(cnt), 15))
    starts = np.searchsorted(pc, np.nonzero(use)[0])
    # float32 suffices for hypotheses (grow refits in float64); one compiled pass
    sums = np.empty((len(starts), 15), np.float32)
    piece_moments(xy, pt, pc, frame, starts, sums)
    mom[use] = sums
    points = _Pieces(pt, np.where(use, cnt, 0))
    # a piece that recurs in several tilings (a curve whole inside tiles of several shifts and
    # sizes) is fitted once: the same curve, count and sum of point indices
    psum = np.bincount(pc, weights=pt, minlength=len(cnt)).astype(np.int64)
    same_as, first = _first_copies(piece_curve, cnt, psum)  # the first copy of each piece
    quality = dict(max_rms=max_rms, min_inliers=min_inliers, axes_range=axes_range, min_ratio=min_ratio,
                   min_arc_deg=min_arc_deg)
    single = first[use[first]]
    conics, curved, good = _fit_pieces(xy, points, mom[single], frame[single], [single], **quality)
    good &= cnt[single] >= min_points
    out_c, out_n = [conics[good]], [cnt[single][good]]
    # pairs of curved pieces (a fit that is a real ellipse, whatever its residual) sharing a
    # tile, the largest few per tile: the arcs of one rim that a gap or a corner split; their
    # moments (one frame per tile) add up
    is_curved = np.zeros(len(cnt), bool)
    is_curved[single[curved]] = True
    cand = np.nonzero(is_curved[same_as] & use)[0]
    cand = cand[np.lexsort((-cnt[cand], piece_tile[cand]))]  # by tile, largest first
    ct = piece_tile[cand]
    rank = np.arange(len(cand)) - np.searchsorted(ct, ct, "left")
    cand, ct = cand[rank < pairs_per_tile], ct[rank < pairs_per_tile]
    pa, pb = [], []
    for k in range(1, pairs_per_tile):
        same = np.nonzero(ct[:-k] == ct[k:])[0] if len(ct) > k else np.zeros(0, int)
        pa.append(cand[same])
        pb.append(cand[same + k])
    pa = np.concatenate(pa) if pa else np.zeros(0, np.int64)
    pb = np.concatenate(pb) if pb else np.zeros(0, np.int64)
    fa, fb = same_as[pa], same_as[pb]
    _, once = np.unique(np.minimum(fa, fb) * len(cnt) + np.maximum(fa, fb), return_index=True)
    pa, pb = pa[once], pb[once]
    big = cnt[pa] + cnt[pb] >= min_points
    pa, pb = pa[big], pb[big]
    if len(pa):
        conics, _, good = _fit_pieces(xy, points, mom[pa] + mom[pb], frame[pa], [pa, pb], **quality)
        out_c.append(conics[good])
        out_n.append((cnt[pa] + cnt[pb])[good])
    conics, npts = np.concatenate(out_c), np.concatenate(out_n)
    o = np.argsort(-npts, kind="stable")
    return conics[o], npts[o]


def _first_copies(*columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For rows made of the (P,) int ``columns``: the index of the first row equal to each
    row (P,), and those first rows in the rows' sorted order (U,): ``first[inverse]`` and
    ``first`` of ``np.unique(np.column_stack(columns), axis=0, return_index=True,
    return_inverse=True)``, through one stable lexsort (about 10x faster)."""
    o = np.lexsort(columns[::-1])
    new = np.zeros(len(o), bool)
    new[:1] = True
    for c in columns:
        cs = c[o]
        new[1:] |= cs[1:] != cs[:-1]
    run = np.cumsum(new) - 1
    first = o[new]  # stable: the first row of each run has the smallest index
    same = np.empty(len(o), np.int64)
    same[o] = first[run]
    return same, first


class _Pieces:
    """Point indices of the pieces: piece ``k`` holds ``points[start[k]:start[k] + count[k]]``."""

    def __init__(self, points: np.ndarray, count: np.ndarray):
        self.points, self.count = points, count
        self.start = np.concatenate([[0], np.cumsum(count)[:-1]])

    def rows(self, groups: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(group, point) rows, sorted by group, of groups made of one piece from each array
        of ``groups`` (group g = the pieces ``groups[0][g], groups[1][g], ...``)."""
        gid, pts = [], []
        for members in groups:
            owner, at = ranges(self.start[members], self.count[members])
            gid.append(owner)
            pts.append(self.points[at])
        gid, pts = np.concatenate(gid), np.concatenate(pts)
        o = np.argsort(gid, kind="stable")
        return gid[o], pts[o]


def _fit_pieces(xy, pieces: _Pieces, mom: np.ndarray, frame: np.ndarray, groups: list[np.ndarray], *,
                max_rms, min_inliers, axes_range, min_ratio, min_arc_deg, trim_rms=3.0):
    """Direct fits of groups of pieces from their moments ``mom`` (G, 15) in the frames
    ``frame`` (G, 3), then checked on their points.

    Returns
    -------
    conics : (G, 6)
    curved : (G,) bool
        The fit is a real ellipse within the largest axis (not a straight run).
    good : (G,) bool
        Also a close fit (RMS Sampson distance <= ``max_rms``, ``min_inliers`` within 1 px),
        within the axes range and covering ``min_arc_deg`` of its ellipse.
    """
    conics, ok, rms_est = fit_conics_moments(mom, frame[:, :2], frame[:, 2])
    c, axes, ang, real = ellipse_params(conics)
    curved = ok & real & (axes[:, 0] <= axes_range[1])
    good = curved & (rms_est <= trim_rms) & (axes[:, 1] >= 0.5 * axes_range[0])
    # the exact checks, on the points of the groups left, after one trimmed refit (the points
    # within 1 px of the first fit: a piece of a rim with some clutter linked to it)
    idx = np.nonzero(good)[0]
    gid, pt = pieces.rows([g[idx] for g in groups])
    hyp = idx[gid]
    inl = sampson_pairs(conics, hyp, xy, pt) <= 1.0
    m = np.bincount(gid, minlength=len(idx))
    # fit_conics_grouped(xy[pt[inl]], gid[inl], len(idx)), its frames and moments compiled
    m_in, s_in, mom_in = grouped_frames(xy, pt, inl, gid, len(idx))
    new, nok, _ = fit_conics_moments(mom_in, m_in, s_in)
    nok &= real_ellipses(new) & (np.bincount(gid[inl], minlength=len(idx)) >= 6)
    conics[idx[nok]] = new[nok]
    c, axes, ang, real = ellipse_params(conics)
    d = sampson_pairs(conics, hyp, xy, pt)
    inl = d <= 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.bincount(gid, weights=np.where(inl, d * d, 0), minlength=len(idx))
                      / np.bincount(gid, weights=inl, minlength=len(idx)))
        frac = np.bincount(gid, weights=inl, minlength=len(idx)) / m
    # arc covered by the inliers: parametric angle in the ellipse's frame, 36 bins
    k = idx[gid[inl]]
    t = _parametric_angle(xy[pt[inl]], c[k], axes[k], ang[k])
    occ = np.zeros(len(idx) * 36, bool)
    occ[gid[inl] * 36 + np.minimum((t / (2 * np.pi) * 36).astype(np.int64), 35)] = True
    arc = occ.reshape(len(idx), 36).sum(1) * 10.0
    good[idx] = (rms <= max_rms) & (frac >= min_inliers) & (arc >= min_arc_deg) & real[idx] \
        & (axes[idx, 1] >= axes_range[0]) & (axes[idx, 0] <= axes_range[1]) & (axes[idx, 1] >= min_ratio * axes[idx, 0])
    return conics, curved, good


def _parametric_angle(p: np.ndarray, c: np.ndarray, axes: np.ndarray, ang: np.ndarray) -> np.ndarray:
    """(N,) parametric angle in [0, 2 pi) of points about their ellipses (rows)."""
    d = p - c
    ca, sa = np.cos(ang), np.sin(ang)
    u = (d[:, 0] * ca + d[:, 1] * sa) / np.maximum(axes[:, 0], 1e-9)
    v = (-d[:, 0] * sa + d[:, 1] * ca) / np.maximum(axes[:, 1], 1e-9)
    return np.mod(np.arctan2(v, u), 2 * np.pi)


def distinct(conics: np.ndarray, center_px: float = 2.0, rel_size: float = 0.2) -> np.ndarray:
    """Indices of the conics (in order) that repeat no earlier kept one (centre within
    ``center_px`` and both semi-axes within ``rel_size``)."""
    c, axes, _, _ = ellipse_params(conics)
    K = len(c)
    if K == 0:
        return np.zeros(0, int)
    # pairs of near centres (a k-d tree: no K x K arrays), then the greedy pass over them
    pairs = cKDTree(np.nan_to_num(c, nan=1e12, posinf=1e12, neginf=-1e12)).query_pairs(center_px, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.abs(axes[i] - axes[j])
    fwd, back = (d <= rel_size * axes[j]).all(1), (d <= rel_size * axes[i]).all(1)  # k takes j: within j's size
    i, j = np.concatenate([i[fwd], j[back]]), np.concatenate([j[fwd], i[back]])
    o = np.argsort(i, kind="stable")
    i, j = i[o], j[o]
    start = np.searchsorted(i, np.arange(K + 1))
    taken = np.zeros(K, bool)
    kept = []
    for k in range(K):
        if not taken[k]:
            kept.append(k)
            taken[j[start[k]:start[k + 1]]] = True
    return np.array(kept, int)


def ranges(start: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, index) of the concatenated ranges ``start[k] .. start[k] + count[k]``."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count - start, count)


def box_candidates(center: np.ndarray, reach: np.ndarray, xy: np.ndarray,
                   cell_px: float = 32.0) -> tuple[np.ndarray, np.ndarray]:
    """(box, point) pairs: the points within ``reach`` px (Chebyshev) of each centre.

    Through a grid of ``cell_px`` cells (points sorted by cell), so the pairs looked at are
    those of the cells each box overlaps: proportional to the boxes' areas, not to the image.
    A box with a non-finite centre or reach gets none.
    """
    K = len(center)
    if K == 0 or len(xy) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    gx, gy = (xy[:, 0] // cell_px).astype(np.int64), (xy[:, 1] // cell_px).astype(np.int64)
    nx, ny = int(gx.max()) + 1, int(gy.max()) + 1
    key = gy * nx + gx
    order = np.argsort(key, kind="stable")
    cell_start = np.searchsorted(key[order], np.arange(nx * ny + 1))
    good = np.isfinite(center).all(1) & np.isfinite(reach)
    cx, cy = np.where(good, center[:, 0], 0.0), np.where(good, center[:, 1], 0.0)
    r = np.where(good, reach, -1.0)
    x0 = np.clip(np.floor((cx - r) / cell_px), 0, nx).astype(np.int64)
    x1 = np.clip(np.floor((cx + r) / cell_px), -1, nx - 1).astype(np.int64)
    y0 = np.clip(np.floor((cy - r) / cell_px), 0, ny).astype(np.int64)
    y1 = np.clip(np.floor((cy + r) / cell_px), -1, ny - 1).astype(np.int64)
    wx, wy = np.maximum(x1 - x0 + 1, 0), np.maximum(y1 - y0 + 1, 0)
    box, local = ranges(np.zeros(K, np.int64), np.where(good, wx * wy, 0))
    cell = (y0[box] + local // np.maximum(wx[box], 1)) * nx + x0[box] + local % np.maximum(wx[box], 1)
    first, count = cell_start[cell], cell_start[cell + 1] - cell_start[cell]
    which, at = ranges(first, count)
    hyp, pt = box[which], order[at]
    inside = (np.abs(xy[pt, 0] - cx[hyp]) <= r[hyp]) & (np.abs(xy[pt, 1] - cy[hyp]) <= r[hyp])
    return hyp[inside], pt[inside]


def grow(conics: np.ndarray, xy: np.ndarray, theta: np.ndarray, *, bands=(3.0, 2.0, 1.5, 1.0),
         direction_tol_deg: float = DIRECTION_TOL_DEG):
    """Refit each conic on the edge points near it whose edge normal agrees, narrowing.

    Returns
    -------
    conics : (K, 6) float
    ok : (K,) bool
        Real ellipses after the last pass.
    hyp, point : (P,) int
        (ellipse, edge point) pairs of the inliers: within the last band and agreeing.
    """
    conics = conics.copy()
    cos_tol = np.cos(np.deg2rad(direction_tol_deg))
    # candidates, once: the points within ``bands[0] + margin`` px of the first conic (a
    # refit moves an ellipse by less), found through its bounding box (points sorted by x)
    c, axes, _, ok = ellipse_params(conics)
    margin = GROW_MARGIN_PX
    reach = axes[:, 0] + bands[0] + margin + 1
    hyp, pt = box_candidates(np.where(ok[:, None], c, np.inf), np.where(ok, reach, 0.0), xy)
    near = sampson_pairs(conics, hyp, xy, pt) <= bands[0] + margin
    hyp, pt = hyp[near], pt[near]
    px, py = xy[pt, 0].copy(), xy[pt, 1].copy()
    ct, st = np.cos(theta[pt]), np.sin(theta[pt])
    for band in bands:
        # the agreeing points within the band and the moments of their direct fit, in one pass
        sel, m, s, mom = band_moments(conics, hyp, px, py, ct, st, float(band), float(cos_tol))
        if band == bands[-1]:
            break
        new, nok, _ = fit_conics_moments(mom, m, s)
        nok &= (mom[:, 0] >= 6) & real_ellipses(new)
        conics[nok & ok] = new[nok & ok]
    ok &= real_ellipses(conics)
    return conics, ok, hyp[sel], pt[sel]


def coverage(conics: np.ndarray, xy: np.ndarray, hyp: np.ndarray, pt: np.ndarray):
    """Fraction of each ellipse's perimeter holding an inlier, and the RMS Sampson distance of
    the inliers.

    The bins are 1 px of arc each, ``round(perimeter)`` of them (as a circle's ``round(2 pi r)``
    in :func:`~rangesim.features.circles`): a point's bin is its arc length from the major
    axis's end, interpolated in a table of the arc length at 64 steps of the parametric angle.
    Equal steps of the parametric angle instead would be up to a / b px of arc long, so a thin
    ellipse (b of 2-4 px) would be "covered" by a few points.

    Returns
    -------
    cov, rms, perimeter : (K,) float
    """
    K = len(conics)
    if K == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    c, axes, ang, real = ellipse_params(conics)
    c, axes = np.where(real[:, None], c, 0.0), np.where(real[:, None], axes, 1.0)  # not counted below
    a, b = axes[:, 0], axes[:, 1]
    # arc length at t_j = 2 pi j / 64: trapezoids of |d(x, y)/dt| = sqrt(a^2 sin^2 t + b^2 cos^2 t)
    steps = 64
    tj = np.linspace(0.0, 2 * np.pi, steps + 1)
    speed = np.sqrt((a[:, None] * np.sin(tj)) ** 2 + (b[:, None] * np.cos(tj)) ** 2)
    arc = np.concatenate([np.zeros((K, 1)), np.cumsum(0.5 * (speed[:, 1:] + speed[:, :-1]), 1) * (2 * np.pi / steps)], 1)
    perim = arc[:, -1]
    huge = ~(perim <= MAX_PERIMETER_PX)  # (NaN too) a straight run's conic: not an ellipse to score (cov 0)
    n_bins = np.where(huge, 8, np.maximum(np.nan_to_num(np.rint(perim)), 8)).astype(np.int64)
    start = np.concatenate([[0], np.cumsum(n_bins)[:-1]])
    u = _parametric_angle(xy[pt], c[hyp], axes[hyp], ang[hyp]) * (steps / (2 * np.pi))
    j = np.minimum(u.astype(np.int64), steps - 1)
    s_pt = arc[hyp, j] + (u - j) * (arc[hyp, j + 1] - arc[hyp, j])
    bins = np.minimum((s_pt / perim[hyp] * n_bins[hyp]).astype(np.int64), n_bins[hyp] - 1)
    occ = np.zeros(int(n_bins.sum()), bool)
    occ[start[hyp] + bins] = True
    cov = np.add.reduceat(occ, start) / n_bins
    d = sampson_pairs(conics, hyp, xy, pt)
    cnt = np.bincount(hyp, minlength=K)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.bincount(hyp, weights=d * d, minlength=K) / cnt)
    rms[(cnt == 0) | ~real | huge] = np.inf
    cov[(cnt == 0) | ~real | huge] = 0.0
    return cov, rms, perim


def _square_dilation(m: np.ndarray, g: int) -> np.ndarray:
    """``ndimage.binary_dilation(m, np.ones((2 g + 1, 2 g + 1)))`` (outside the image False)
    as separable slice ORs, rows then columns: the same array, ~10x faster."""
    rows = m.copy()
    for s in range(1, g + 1):
        rows[:, s:] |= m[:, :-s]
        rows[:, :-s] |= m[:, s:]
    out = rows.copy()
    for s in range(1, g + 1):
        out[s:] |= rows[:-s]
        out[:-s] |= rows[s:]
    return out


def outline_hypotheses(xy: np.ndarray, *, min_points: int = 10, max_rms: float = 0.5, min_inliers: float = 0.6,
                       min_arc_deg: float = 60.0, axes_range: tuple[float, float] = (4.0, 200.0),
                       min_ratio: float = 0.2, gap_px: int = 1, pixels: np.ndarray | None = None):
    """Ellipses fitted to the outer outline of each group of edge pixels (as ``cv2.fitEllipse``
    on a contour): the rim around a hole's clutter (thread crests, a floor's edges) that links
    to the rim's arcs and spoils their pieces.

    The edge pixels, dilated by ``gap_px`` every way (bridging gaps of up to twice that), are
    grouped (8-connected); a group's
    outline is its points with a 4-neighbour in the group's outer background (the background
    region left of its leftmost pixel; not the regions it encloses, and not the region of a
    group it lies in). Each outline is fitted and checked as the pieces of
    :func:`arc_hypotheses`. ``pixels`` (N, 2) int: the points' pixels (default: ``xy``
    truncated), which make the groups; the fits are to ``xy``.

    Returns
    -------
    conics : (K, 6) float
    n_points : (K,) int
    """
    none = np.zeros((0, 6)), np.zeros(0, int)
    if len(xy) < min_points:
        return none
    g = max(int(gap_px), 0)
    pad = g + 1  # room for the dilation (g px every way) and the neighbour tests beyond it
    pix = (xy if pixels is None else pixels).astype(np.int64)
    x, y = pix[:, 0] + pad, pix[:, 1] + pad
    m = np.zeros((int(y.max()) + pad + 1, int(x.max()) + pad + 1), bool)
    m[y, x] = True
    # a symmetric (2 g + 1)-square dilation: gaps of up to 2 g missing pixels are bridged
    grown = _square_dilation(m, g)
    groups, G = ndimage.label(grown, np.ones((3, 3), bool))
    spaces = ndimage.label(~grown)[0]  # 4-connected background regions
    # each group's outer background: the region left of its leftmost pixel (not enclosed by it)
    gy, gx = np.nonzero(grown)
    gl = groups[gy, gx]
    first = np.full(G + 1, np.iinfo(np.int64).max)
    np.minimum.at(first, gl, gx * grown.shape[0] + gy)
    fx, fy = first[1:] // grown.shape[0], first[1:] % grown.shape[0]
    outer = np.concatenate([[-1], spaces[fy, fx - 1]])
    lab = groups[y, x]
    on = np.zeros(len(xy), bool)
    # the 4-neighbours of a point's dilated footprint (y - g .. y + g, x - g .. x + g)
    for dy, dx in ((-g - 1, 0), (g + 1, 0), (0, -g - 1), (0, g + 1)):
        on |= spaces[y + dy, x + dx] == outer[lab]
    idx = np.nonzero(on)[0]
    idx = idx[np.argsort(lab[idx], kind="stable")]
    g, cnt = np.unique(lab[idx], return_counts=True)
    group = np.repeat(np.arange(len(g)), cnt)
    n = np.bincount(group, minlength=len(g))
    centre = np.column_stack([np.bincount(group, weights=xy[idx, k], minlength=len(g)) / n for k in (0, 1)])
    scale = np.maximum(np.maximum.reduceat(np.abs(xy[idx] - centre[group]).max(1), np.cumsum(n) - n), 1.0)
    frame = np.column_stack([centre, scale])
    mom = np.empty((len(n), 15), np.float32)
    piece_moments(xy, idx, group, frame, np.cumsum(n) - n, mom)  # float32, as the arc pieces'
    mom = mom.astype(np.float64)
    big = np.nonzero(n >= min_points)[0]
    if len(big) == 0:
        return none
    pieces = _Pieces(idx, n)
    conics, _, good = _fit_pieces(xy, pieces, mom[big], frame[big], [big],
                                  max_rms=max_rms, min_inliers=min_inliers, axes_range=axes_range,
                                  min_ratio=min_ratio, min_arc_deg=min_arc_deg)
    return conics[good], n[big][good]


def free_ellipses(xy: np.ndarray, theta: np.ndarray, *, min_points: int = 20, min_support: float = 0.5,
                  max_residual: float = 0.8, axes_range: tuple[float, float] = (4.0, 200.0),
                  min_ratio: float = 0.2, pixels: np.ndarray | None = None, labels: np.ndarray | None = None
                  ) -> list[tuple[np.ndarray, np.ndarray, float, float, int]]:
    """Ellipses of edge points without a model: arc hypotheses, grown, one claim per point
    (a candidate whose unclaimed inliers cover less than ``min_support`` is dropped; the
    returned inliers of an accepted ellipse are all of them, claimed before or not).

    ``pixels`` (N, 2) int: the points' pixels (default ``xy``), which link the points into
    curves and groups; the conics are fitted to ``xy`` (edge points to a fraction of a pixel).
    ``labels`` (N,) uint8, optional: the points' edge labels; a candidate keeps only the
    inliers of its own edge (:func:`~._edge_points.one_edge`), and is dropped when those cover
    too little.

    Returns
    -------
    list of (conic (6,), inlier point indices, coverage, RMS Sampson distance px, n inliers),
    largest coverage first.
    """
    if len(xy) < min_points:
        return []
    curve = smooth_curves(xy if pixels is None else pixels, theta)
    conics, n = arc_hypotheses(xy, curve, axes_range=axes_range, min_ratio=min_ratio)
    c2, n2 = outline_hypotheses(xy, axes_range=axes_range, min_ratio=min_ratio, pixels=pixels)
    conics, n = np.concatenate([conics, c2]), np.concatenate([n, n2])
    conics = conics[np.argsort(-n, kind="stable")]
    conics = conics[distinct(conics)]
    if len(conics) == 0:
        return []
    conics, ok, hyp, pt = grow(conics, xy, theta)
    cov, rms, _ = coverage(conics, xy, hyp, pt)
    _, axes, _, real = ellipse_params(conics)
    n_in = np.bincount(hyp, minlength=len(conics))
    good = ok & real & (cov >= min_support) & (rms <= max_residual) & (n_in >= min_points)
    good &= (axes[:, 1] >= axes_range[0]) & (axes[:, 0] <= axes_range[1]) & (axes[:, 1] >= min_ratio * axes[:, 0])
    order = np.nonzero(good)[0]
    order = order[np.argsort(-cov[order], kind="stable")]
    by_h = np.split(pt[np.argsort(hyp, kind="stable")], np.cumsum(n_in)[:-1])
    used = np.zeros(len(xy), bool)
    out = []
    for j in order:
        pts = one_edge(labels, by_h[j])  # the candidate's own edge's points
        free = pts[~used[pts]]
        if len(free) < len(by_h[j]):
            # a candidate left with too little of its perimeter once stronger ellipses took
            # their points (a near-duplicate, a ghost across two rims) is dropped
            if len(free) < min_points or coverage(conics[j:j + 1], xy, np.zeros(len(free), int), free)[0][0] < min_support:
                continue
        used[pts] = True
        out.append((conics[j], pts, float(cov[j]), float(rms[j]), len(pts)))
    return out
