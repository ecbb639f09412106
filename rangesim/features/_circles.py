"""Circles from edge directions (the paper's section 5): a Hough transform in which every edge
point votes only along its edge normal, both senses, at each radius."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from rangesim.core.conics import ellipse_params, fit_circles_batched
from rangesim.core.memory import check_memory
from rangesim.features._arc_ellipses import coverage as ellipse_coverage
from rangesim.features._arc_ellipses import grow, ranges
from rangesim.features._circle_votes import cast_votes, n_cells, peaks, radius_bands, voters
from rangesim.features._edge_points import angular_coverage, edge_points

DIRECTION_TOL_DEG = 15.0  # an inlier's edge normal is radial within this, degrees
REL_CELL = 1 / 4  # accumulator cell over the band's smallest radius (radius_bands)
ELLIPSE_PIECE_RATIO = 0.85  # a circle that grows into an ellipse thinner than this is its end
PIECE_MAX_SUPPORT = 0.75  # circles supported over more of their perimeter are not checked


@dataclass(frozen=True)
class Circle:
    """A circle in the image.

    Attributes
    ----------
    center : (x, y) float, pixels (x = column, y = row, integers at pixel centres)
    radius : float, pixels
    votes : int
        Accumulator votes at the peak.
    support : float
        Fraction of the circumference with an edge pixel within 1 px of the circle, 0..1.
    residual : float
        RMS distance of those edge pixels to the circle, pixels.
    """

    center: tuple[float, float]
    radius: float
    votes: int
    support: float
    residual: float


def circle_hypotheses(
    edge_map: Any,
    radii: tuple[float, float] = (5, 80),
    *,
    angle_tol_deg: float = 4.0,
    threshold: float = 0.25,
    band_px: float = 1.0,
    keep: np.ndarray | None = None,
    max_hypotheses: int = 200,
    cell_px: float = 1.0,
    radius_step: float = 1.0,
    rel_cell: float | None = None,
) -> list[tuple[np.ndarray, float, int, np.ndarray]]:
    """Directional Hough accumulator, peaks and least-squares refinement (no support test).

    The paper's transform, made sparse: each edge point p with edge-normal angle t votes at
    p +- r (cos a, sin a), a = t + k c / r, |k c / r| <= ``angle_tol_deg``, for radius samples
    r every c px: the angular step is c / r (prop. to 1 / r, one vote per cell of arc). The
    radii are cut into octave bands, each with its own 2D centre accumulator of cells
    c = max(``cell_px``, ``rel_cell`` * r_lo) px (:func:`~._circle_votes.radius_bands`), so
    the work is proportional to the edge pixels times the octaves, with no dense 3D array.
    A circle of radius r collects about 2 pi r votes, so the thresholds are ``threshold *
    2 pi r`` (proportional to r), first on 2 x 2 cell sums (centre candidates), then on each
    candidate's histogram of voter distances (``radius_step`` px bins; every peak is a
    hypothesis, so concentric rims each get one). The centre of a candidate starts at the
    least-squares intersection of its voters' normal lines; each hypothesis is refined by
    batched geometric fits (:func:`~rangesim.core.conics.fit_circles_batched`) on the edge
    points of a ring around it (looked up pixel by pixel, :func:`ring_points`) whose direction
    is radial within ``DIRECTION_TOL_DEG`` (15), the ring narrowing to ``band_px`` (+0.5) over
    three passes, then once more on the stretches where the ring is one edge thick
    (:func:`_thin_ring_fit`). All of it is batched over the hypotheses: the work follows the
    edge pixels and the rings' areas, with no dense 3D accumulator and no per-candidate loop.

    Returns
    -------
    list of (center (2,), radius, votes, inlier indices into the edge points), best first
    (largest fraction of 2 pi r in inliers).
    """
    xy, theta = edge_points(edge_map, keep)
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    h = _hypotheses(xy, theta, mask.shape, radii, angle_tol_deg, threshold, band_px,
                    max_hypotheses, cell_px, radius_step, REL_CELL if rel_cell is None else rel_cell)
    if h is None:
        return []
    c, r, votes, ph, pp = h
    n_in = np.bincount(ph, minlength=len(r))
    order = np.argsort(-n_in / (2 * np.pi * r), kind="stable")
    by_h = np.split(pp[np.argsort(ph, kind="stable")], np.cumsum(n_in)[:-1])
    return [(c[j], float(r[j]), int(votes[j]), by_h[j]) for j in order if n_in[j] >= 6]


def _hypotheses(xy: np.ndarray, theta: np.ndarray, shape: tuple[int, int], radii, angle_tol_deg: float,
                threshold: float, band_px: float, max_hypotheses: int, cell_px: float,
                radius_step: float, rel_cell: float):
    """Refined circle hypotheses as arrays: centres (K, 2), radii (K,), votes (K,), and the
    (hypothesis, point) pairs of their inliers; None when there are none."""
    if len(xy) < 5:
        return None
    bands = radius_bands(shape, radii, cell_px, rel_cell)
    tol = np.deg2rad(angle_tol_deg)
    _check_accumulator(n_cells(bands), len(xy) * 2 * sum(
        np.ceil((b.hi - b.lo) / b.cell) * (2 * np.floor(tol * b.hi / b.cell) + 1) for b in bands), radii)
    flat, acc, m = cast_votes(xy, theta, bands, tol)
    cen, band, votes, cells = peaks(acc, bands, shape, threshold)
    if len(cen) == 0:
        return None
    lo = np.array([b.lo for b in bands])[band]
    cap = np.argsort(-votes / lo, kind="stable")[:max_hypotheses]
    cen, band, votes, cells, lo = cen[cap], band[cap], votes[cap], cells[cap], lo[cap]
    cell = np.array([b.cell for b in bands])[band]
    hi = np.array([b.hi for b in bands])[band]
    k, i = voters(flat, cells, len(acc), len(xy), m)
    del flat
    K = len(cen)
    # centre: least-squares intersection of the voters' normal lines (t = tangent), which
    # needs no radius; kept near the block (a clutter of unrelated voters can pull it away)
    tx, ty = -np.sin(theta[i]), np.cos(theta[i])
    px, py = xy[i, 0], xy[i, 1]

    def s(w):
        return np.bincount(k, weights=w, minlength=K)

    a11, a12, a22 = s(tx * tx), s(tx * ty), s(ty * ty)
    b1 = s(tx * tx * px + tx * ty * py)
    b2 = s(tx * ty * px + ty * ty * py)
    det = a11 * a22 - a12 * a12
    with np.errstate(invalid="ignore", divide="ignore"):
        c0 = np.column_stack([(a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det])
    bad = ~(np.abs(det) > 1e-6 * np.maximum(s(np.ones(len(k))), 1) ** 2)
    bad |= ~np.isfinite(c0).all(1) | (np.abs(c0 - cen).max(1) > 1.5 * cell)
    c0[bad] = cen[bad]
    # radius: peaks of each candidate's histogram of voter distances (1 px bins; a bin plus
    # its larger neighbour at least threshold * 2 pi r), within the band (+- 1 px): the
    # band's voters are the points at that range, so a concentric rim of another band (a
    # hole's wall inside its rim) is left to that band
    step = float(radius_step)
    rho = np.hypot(px - c0[k, 0], py - c0[k, 1])
    nb = int(np.ceil((hi.max() + cell.max()) / step)) + 3
    b = np.minimum((rho / step).astype(np.int64), nb - 1)
    hist = np.bincount(k * nb + b, minlength=K * nb).reshape(K, nb).astype(float)
    rb = (np.arange(nb) + 0.5) * step
    left = np.concatenate([np.full((K, 1), -1.0), hist[:, :-1]], 1)
    right = np.concatenate([hist[:, 1:], np.full((K, 1), -1.0)], 1)
    pair = hist + np.maximum(left, right)
    ok = (hist > left) & (hist >= right) & (pair >= threshold * 2 * np.pi * rb[None])
    ok &= (rb[None] >= (lo - 1)[:, None]) & (rb[None] <= (hi + 1)[:, None])
    hk, hb = np.nonzero(ok)
    if len(hk) == 0:
        return None
    # sub-bin radius: centroid of the 3 bins
    w0, w1, w2 = np.maximum(left[hk, hb], 0), hist[hk, hb], np.maximum(right[hk, hb], 0)
    r0 = rb[hb] + step * (w2 - w0) / np.maximum(w0 + w1 + w2, 1)
    c, r, votes = c0[hk].copy(), r0, votes[hk]
    # refinement on a ring of edge points around each hypothesis, narrowing
    index = np.full(shape[0] * shape[1], -1, np.int32)
    index[xy[:, 1].astype(np.int64) * shape[1] + xy[:, 0].astype(np.int64)] = np.arange(len(xy), dtype=np.int32)
    # the first ring is as wide as the candidate's cell (its centre is known to about that)
    hcell = cell[hk]
    reach = band_px + 1.0 + 0.5 * hcell
    ph, pp = ring_points(c, r, reach, index, shape)
    cos_tol = np.cos(np.deg2rad(DIRECTION_TOL_DEG))
    ct, st = np.cos(theta[pp]), np.sin(theta[pp])
    for width in (reach, np.full(len(r), band_px + 0.5), np.full(len(r), band_px + 0.5)):
        d = xy[pp] - c[ph]
        dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        radial = np.abs(d[:, 0] * ct + d[:, 1] * st) >= cos_tol * dist
        sel = radial & (np.abs(dist - r[ph]) <= width[ph])
        c, r, _ = fit_circles_batched(xy[pp[sel]], ph[sel], len(r), c, r, iterations=1 + (width is not reach),
                                      max_step=float(hcell.max()) + 3.0)
    c, r = _thin_ring_fit(xy, theta, c, r, index, shape, cos_tol)
    ph, pp = ring_points(c, r, band_px + 0.5, index, shape)
    ct, st = np.cos(theta[pp]), np.sin(theta[pp])
    d = xy[pp] - c[ph]
    dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    sel = (np.abs(d[:, 0] * ct + d[:, 1] * st) >= cos_tol * dist) & (np.abs(dist - r[ph]) <= band_px)
    return c, r, votes, ph[sel], pp[sel]


def _thin_ring_fit(xy, theta, c, r, index, shape, cos_tol, reach: float = 3.0, thick: float = 1.5):
    """Refit each circle on the stretches of arc where its ring is one edge thick.

    Where a second edge runs beside the circle (the wall seen inside a hole's rim, a
    crescent of edge pixels), the radially oriented pixels within ``reach`` px of it, per
    2 px of arc, spread over more than ``thick`` px: those stretches are left out, so the
    fit follows the thin rim rather than the middle of the band.
    """
    ph, pp = ring_points(c, r, reach, index, shape)
    d = xy[pp] - c[ph]
    dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    e = dist - r[ph]
    radial = np.abs(d[:, 0] * np.cos(theta[pp]) + d[:, 1] * np.sin(theta[pp])) >= cos_tol * dist
    keep = radial & (np.abs(e) <= reach)
    ph, pp, d, e = ph[keep], pp[keep], d[keep], e[keep]
    if len(ph) == 0:
        return c, r
    nb = np.maximum(np.rint(np.pi * r).astype(np.int64), 8)  # bins of about 2 px of arc
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    key = ph * int(nb.max()) + np.minimum((ang / (2 * np.pi) * nb[ph]).astype(np.int64), nb[ph] - 1)
    o = np.argsort(key, kind="stable")
    ks, es = key[o], e[o]
    first = np.concatenate([[0], np.nonzero(np.diff(ks))[0] + 1])
    spread = np.maximum.reduceat(es, first) - np.minimum.reduceat(es, first)
    thin = np.repeat(spread <= thick, np.diff(np.concatenate([first, [len(ks)]])))
    sel = o[thin]
    sel = sel[np.abs(e[sel]) <= 2.0]
    c2, r2, _ = fit_circles_batched(xy[pp[sel]], ph[sel], len(r), c, r, iterations=3, max_step=3.0)
    # keep the thin fit only where enough of the circle is thin
    n_thin = np.bincount(ph[sel], minlength=len(r))
    use = n_thin >= 0.25 * 2 * np.pi * r  # circles, not arcs (a short arc alone is ill-conditioned)
    c[use], r[use] = c2[use], r2[use]
    return c, r


@lru_cache(maxsize=4)
def _offsets(r_max: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer pixel offsets within ``r_max`` px, sorted by length: (length, dx, dy)."""
    g = np.arange(-r_max, r_max + 1)
    dx, dy = np.meshgrid(g, g)
    d = np.hypot(dx, dy).ravel()
    o = np.argsort(d, kind="stable")
    out = d[o], dx.ravel()[o].astype(np.int64), dy.ravel()[o].astype(np.int64)
    for a in out:
        a.flags.writeable = False
    return out


def ring_points(c: np.ndarray, r: np.ndarray, width: float | np.ndarray, index: np.ndarray,
                shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Edge points within ``width`` px of each circle, by looking up the pixels of its ring.

    Parameters
    ----------
    c : (K, 2) float, r : (K,) float
        Circles, pixels.
    width : float or (K,) float, pixels
    index : (H * W,) int32
        Edge point number of each pixel (row-major), -1 off the edges.
    shape : (H, W)

    Returns
    -------
    hyp, point : (P,) int
        (circle, edge point) pairs; work proportional to the rings' areas, not the image's.
    """
    H, W = shape
    if len(r) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    width = np.broadcast_to(np.asarray(width, float), r.shape)
    reach = int(np.ceil(max(float((r + width).max()), 0) + 2))
    d, ox, oy = _offsets(-(-reach // 32) * 32)  # a few table sizes, so the cache hits
    ci = np.rint(c).astype(np.int64)
    s0 = np.searchsorted(d, np.maximum(r - width - 0.75, 0), "left")  # 0.75: the rounding of c
    s1 = np.searchsorted(d, r + width + 0.75, "right")
    hyp, j = ranges(s0, s1 - s0)
    x = ci[hyp, 0] + ox[j]
    y = ci[hyp, 1] + oy[j]
    inside = (x >= 0) & (x < W) & (y >= 0) & (y < H)
    hyp, x, y = hyp[inside], x[inside], y[inside]
    pt = index[y * W + x]
    on = pt >= 0
    return hyp[on], pt[on].astype(np.int64)


def _support(xy: np.ndarray, c: np.ndarray, r: float) -> tuple[np.ndarray, float, float, float, float]:
    """Edge points within 1 px of the circle, coverage, start/end angles of the longest run, RMS."""
    d = xy - c
    rho = np.hypot(d[:, 0], d[:, 1])
    on = np.abs(rho - r) <= 1.0
    ang = np.arctan2(d[on, 1], d[on, 0])
    cov, start, end = angular_coverage(ang, round(2 * np.pi * r))
    rms = float(np.sqrt(np.mean((rho[on] - r) ** 2))) if on.any() else np.inf
    return on, cov, start, end, rms


def _dedupe(items: list, key_c, key_r, dist_px: float) -> list:
    kept = []
    for it in items:
        if all(np.hypot(*(key_c(it) - key_c(k))) > dist_px or abs(key_r(it) - key_r(k)) > dist_px for k in kept):
            kept.append(it)
    return kept


def _check_accumulator(cells: int, n_votes: float, radii) -> None:
    """Refuse (one line, naming the radius range) a Hough accumulator that would not fit in memory."""
    ring = (2 * float(radii[1]) + 7) ** 2  # the ring lookup's offset table (ring_points)
    estimate = float(cells) * 8 + n_votes * 16 + ring * 24  # int64 counts; int32 cells + lookups
    check_memory(estimate, f"circle radii {radii[0]:g}..{radii[1]:g} px (--rmin/--rmax, a Hough accumulator of "
                           f"{cells:,.0f} cells and {n_votes:,.0f} votes)")

def circles(
    edge_map: Any,
    radii: tuple[float, float] = (5, 80),
    *,
    min_support: float = 0.5,
    threshold: float = 0.25,
    angle_tol_deg: float = 4.0,
    max_residual: float = 0.8,
    keep: np.ndarray | None = None,
) -> list[Circle]:
    """Circles in an edge map, by the direction-guided Hough transform.

    Parameters
    ----------
    edge_map : EdgeMap or (H, W) bool
        Edge pixels; ``direction`` (radians, across the edge) is used when present, else it
        is estimated from the mask.
    radii : (rmin, rmax)
        Radius range, pixels.
    min_support : float
        Least fraction of the circumference (bins of about 1 px) with an edge pixel within
        1 px of the circle whose edge normal is radial within 15 degrees; each edge pixel
        supports one circle (strongest first), so a candidate left below this once the pixels
        of stronger circles are taken (a near-duplicate, a ghost across two rims) is dropped;
        so is a circle that is the end of an elongated ellipse (:func:`_ellipse_pieces`).
    threshold : float
        Accumulator threshold as a fraction of the 2 pi r votes of a complete circle.
    angle_tol_deg : float
        Half-width of the voting window around the edge normal, degrees (angle offsets k c / r;
        below one step, as by default for r / c < 14, each point votes on its normal only).
    max_residual : float
        Largest RMS distance of the supporting edge pixels to the circle, pixels.
    keep : (H, W) bool, optional
        Only these pixels vote.

    Returns
    -------
    list of Circle
        Strongest (largest support) first.

    Examples
    --------
    >>> import rangesim as rs
    >>> quiet = {"noise.sigma_px": 0, "noise.speckle_contrast": 0}
    >>> scan = rs.datasets.plate_scan(quiet)   # a plate with a hole, on a table, 128 x 120, noise-free

    >>> found = rs.features.circles(rs.edges.gradient(scan), radii=(5, 30))
    >>> len(found), round(found[0].radius)                  # the hole's rim, radius in pixels
    (1, 9)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5 (the
       gradient-directed Hough transform).
    .. [2] R. O. Duda, P. E. Hart, "Use of the Hough transformation to detect lines and curves
       in pictures", Communications of the ACM 15(1), 11-15 (1972), doi:10.1145/361237.361242.
    """
    xy, theta = edge_points(edge_map, keep)
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    h = _hypotheses(xy, theta, mask.shape, radii, angle_tol_deg, threshold, 1.0, 200, 1.0, 1.0, REL_CELL)
    if h is None:
        return []
    c, r, votes, ph, pp = h
    cov, rms = _coverage(xy, c, r, ph, pp)
    order = np.argsort(-cov, kind="stable")
    order = order[(cov[order] >= min_support) & (rms[order] <= max_residual)]
    # each edge point supports one circle: a candidate that is left with too little support
    # once the points of stronger circles are taken (a ghost made of two rims, a crescent
    # inside a rim) is dropped; this also removes near-duplicates
    by_h = np.split(pp[np.argsort(ph, kind="stable")], np.cumsum(np.bincount(ph, minlength=len(r)))[:-1])
    used = np.zeros(len(xy), bool)
    found = []
    for j in order:
        pts = by_h[j]
        free = pts[~used[pts]]
        if len(free) < len(pts):
            d = xy[free] - c[j]
            if angular_coverage(np.arctan2(d[:, 1], d[:, 0]), round(2 * np.pi * r[j]))[0] < min_support:
                continue
        used[pts] = True
        found.append(Circle((float(c[j, 0]), float(c[j, 1])), float(r[j]), int(votes[j]), float(cov[j]),
                            float(rms[j])))
    return [f for f, piece in zip(found, _ellipse_pieces(found, xy, theta)) if not piece]


def _ellipse_pieces(found: list[Circle], xy: np.ndarray, theta: np.ndarray,
                    max_ratio: float = ELLIPSE_PIECE_RATIO) -> np.ndarray:
    """(len(found),) bool: circles that are the end of an elongated ellipse.

    Near the ends of its major axis an ellipse is close to a circle of radius b^2 / a over half
    or more of that circle's perimeter. Each circle supported over less than
    ``PIECE_MAX_SUPPORT`` (0.75) of its perimeter is grown as a general conic over the edge
    points within 3, 1.5 then 1 px whose normal agrees (:func:`~._arc_ellipses.grow`); when
    that conic is an ellipse of axis ratio below ``max_ratio`` that covers more of its own
    perimeter than the circle did, the edge is that ellipse and the circle is dropped.
    """
    out = np.zeros(len(found), bool)
    # a circle supported over most of its perimeter is no ellipse's end (an ellipse of axis
    # ratio 0.85 leaves its osculating circle well before that): only the others are grown
    ask = np.array([f.support < PIECE_MAX_SUPPORT for f in found], bool)
    if not ask.any():
        return out
    found = [f for f, a in zip(found, ask) if a]
    c = np.array([f.center for f in found], float)
    r = np.array([f.radius for f in found], float)
    one = np.ones(len(r))
    conics = np.column_stack([one, 0 * one, one, -2 * c[:, 0], -2 * c[:, 1], (c ** 2).sum(1) - r ** 2])
    conics /= np.linalg.norm(conics, axis=1, keepdims=True)
    grown, ok, hyp, pt = grow(conics, xy, theta, bands=(3.0, 1.5, 1.0))
    cov, _, _ = ellipse_coverage(grown, xy, hyp, pt)
    _, axes, _, real = ellipse_params(grown)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = axes[:, 1] / axes[:, 0]
    support = np.array([f.support for f in found])
    out[ask] = ok & real & (ratio < max_ratio) & (cov > support)
    return out


def _coverage(xy: np.ndarray, c: np.ndarray, r: np.ndarray, ph: np.ndarray,
              pp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coverage (fraction of about 2 pi r angular bins holding an inlier) and RMS distance of
    the inliers, of many circles at once; inliers are the (circle, point) pairs ``ph, pp``."""
    K = len(r)
    n_bins = np.maximum(np.rint(2 * np.pi * r).astype(np.int64), 8)
    start = np.concatenate([[0], np.cumsum(n_bins)[:-1]])
    d = xy[pp] - c[ph]
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    b = np.minimum((ang / (2 * np.pi) * n_bins[ph]).astype(np.int64), n_bins[ph] - 1)
    occ = np.zeros(int(n_bins.sum()), bool)
    occ[start[ph] + b] = True
    cov = np.add.reduceat(occ, start) / n_bins
    e = np.hypot(d[:, 0], d[:, 1]) - r[ph]
    n = np.bincount(ph, minlength=K)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.bincount(ph, weights=e * e, minlength=K) / n)
    rms[n == 0] = np.inf
    return cov, rms
