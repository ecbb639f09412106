"""Circles from edge directions (the paper's section 5): a Hough transform in which every edge
point votes only along its edge normal, both senses, at each radius."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.conics import ellipse_params
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.core.memory import check_memory
from rangesim.features._arc_ellipses import DIRECTION_TOL_DEG as GROW_DIRECTION_TOL_DEG
from rangesim.features._arc_ellipses import GROW_MARGIN_PX
from rangesim.features._arc_ellipses import coverage as ellipse_coverage
from rangesim.features._circle_kernels import centres_and_radii, claim_pairs, refine
from rangesim.features._circle_votes import cast_votes, n_cells, peaks, radius_bands, voters
from rangesim.features._conic_kernels import grow_few
from rangesim.features._edge_points import angular_coverage, check_range, edge_points, point_labels

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
        Fraction of the circumference with an edge pixel within 1 px of the circle, 0..1, in
        1 px bins of arc (a thin 8-connected circle, whose pixels lie up to sqrt(2) px apart
        along it, covers 0.86-0.94 of them).
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
    hypothesis, so concentric rims each get one). Only centres inside the image (within half a
    pixel of it) are candidates, so radii beyond the image's diagonal are not searched, and
    the arc of a rim whose centre lies outside the frame is not found. The centre of a candidate starts at the
    least-squares intersection of its voters' normal lines; each hypothesis is refined by
    geometric (Gauss-Newton) fits on the edge points of a ring around it (its pixels looked up
    row by row) whose direction is radial within ``DIRECTION_TOL_DEG`` (15), the ring
    narrowing to ``band_px`` (+0.5) over three passes, then once more on the stretches where
    the ring is one edge thick. The work follows the edge pixels and the rings' areas, with no
    dense 3D accumulator; the loops over votes, blocks and rings are compiled
    (:mod:`~._circle_kernels`, Numba), which makes the finder as fast as OpenCV's
    HOUGH_GRADIENT at 512^2 and about twice as fast at 1024^2 (``benchmarks/bench_hough.py``).

    Returns
    -------
    list of (center (2,), radius, votes, inlier indices into the edge points), best first
    (largest fraction of 2 pi r in inliers).
    """
    radii = check_range(radii, "radii")
    P.number(angle_tol_deg, "angle_tol_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    P.number(threshold, "threshold", 0, lo_open=True)
    P.number(band_px, "band_px", 0, lo_open=True, unit="pixels")
    max_hypotheses = P.whole(max_hypotheses, "max_hypotheses", 1)
    # a centre cell wider than the largest radius sought (or than its band's smallest radius)
    # resolves no circle, and its radius bins ran into terabytes
    cell_px = P.number(cell_px, "cell_px", 0, lo_open=True, unit="pixels")
    if radii[1] < cell_px:
        raise RangesimError(f"radii: the largest radius sought, {radii[1]:g} px, is under the centre cell "
                            f"(cell_px = {cell_px:g} px): no circle that small is resolved; got {radii!r}")
    P.number(radius_step, "radius_step", 0, lo_open=True, unit="pixels")
    P.number(rel_cell, "rel_cell", 0, 1, lo_open=True, none=True)
    xy, theta, pixels = edge_points(edge_map, keep, return_pixels=True)
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    h = _hypotheses(xy, theta, pixels, mask.shape, radii, angle_tol_deg, threshold, band_px,
                    max_hypotheses, cell_px, radius_step, REL_CELL if rel_cell is None else rel_cell)
    if h is None:
        return []
    c, r, votes, ph, pp, _ = h
    n_in = np.bincount(ph, minlength=len(r))
    order = np.argsort(-n_in / (2 * np.pi * r), kind="stable")
    by_h = np.split(pp[np.argsort(ph, kind="stable")], np.cumsum(n_in)[:-1])
    return [(c[j], float(r[j]), int(votes[j]), by_h[j]) for j in order if n_in[j] >= 6]


def _hypotheses(xy: np.ndarray, theta: np.ndarray, pixels: np.ndarray, shape: tuple[int, int], radii,
                angle_tol_deg: float, threshold: float, band_px: float, max_hypotheses: int, cell_px: float,
                radius_step: float, rel_cell: float, labels: np.ndarray | None = None, split: bool = False):
    """Refined circle hypotheses as arrays: centres (K, 2), radii (K,), votes (K,), the
    (hypothesis, point) pairs of their inliers, and each one's sibling (K,) (the other circle
    of a hypothesis split in two, -1 for none); None when there are none. ``xy`` (N, 2): the
    edge points, ``pixels`` (N, 2) int: their pixels (column, row); ``labels`` (N,) uint8:
    their edge kinds (None: a bare mask); ``split``: replace a hypothesis whose ring holds two
    near-concentric edges by the two circles (:func:`~._circle_kernels._two_edges`)."""
    if len(xy) < 5:
        return None
    # a circle centred in the image through an edge pixel is at most the diagonal wide: larger
    # radii asked for cost accumulator memory and find nothing
    radii = (radii[0], min(radii[1], float(np.hypot(*shape)) + 1.0))
    if radii[0] > radii[1]:
        return None
    bands = radius_bands(shape, radii, cell_px, rel_cell)
    tol = np.deg2rad(angle_tol_deg)
    _check_accumulator(n_cells(bands), len(xy) * 2 * sum(
        np.ceil((b.hi - b.lo) / b.cell) * (2 * np.floor(tol * b.hi / b.cell) + 1) for b in bands),
        max_hypotheses * ((bands[-1].hi + bands[-1].cell) / radius_step + 3), radii)
    acc, flat = cast_votes(xy, theta, bands, tol)
    cen, band, votes, cells = peaks(acc, bands, shape, threshold)
    if len(cen) == 0:
        return None
    lo = np.array([b.lo for b in bands])[band]
    cap = np.argsort(-votes / lo, kind="stable")[:max_hypotheses]
    cen, band, votes, cells, lo = cen[cap], band[cap], votes[cap], cells[cap], lo[cap]
    cell = np.array([b.cell for b in bands])[band]
    hi = np.array([b.hi for b in bands])[band]
    k, i = voters(flat, acc, cells)
    del flat
    ct, st = np.cos(theta), np.sin(theta)
    px, py = xy[:, 0].copy(), xy[:, 1].copy()
    # centres (the voters' normal lines' intersection) and radii (peaks of the histogram of
    # voter distances within the band +- 1 px: the band's voters are the points at that range,
    # so a concentric rim of another band, a hole's wall inside its rim, is left to that band)
    nb = int(np.ceil((hi.max() + cell.max()) / radius_step)) + 3
    c0, hk, r = centres_and_radii(px, py, ct, st, k, i, cen, cell, lo, hi, float(threshold), float(radius_step), nb)
    if len(hk) == 0:
        return None
    c, votes = c0[hk], votes[hk]
    # refinement on a ring of edge points around each hypothesis, narrowing; the first ring is
    # as wide as the candidate's cell (its centre is known to about that)
    index = np.full(shape[0] * shape[1], -1, np.int32)  # int32: half the cache lines of int64
    index[pixels[:, 1] * shape[1] + pixels[:, 0]] = np.arange(len(xy), dtype=np.int32)
    hcell = cell[hk]
    reach = concentric_reach(hk, r, band_px + 1.0 + 0.5 * hcell, band_px + 0.5)
    labels = np.zeros(0, np.uint8) if labels is None else np.ascontiguousarray(labels, np.uint8)
    c, r, ph, pp, parent, sibling = refine(px, py, ct, st, index, shape[0], shape[1], c, r, reach, float(band_px),
                                           float(np.cos(np.deg2rad(DIRECTION_TOL_DEG))), float(hcell.max()) + 3.0,
                                           labels, bool(split), int(EdgeLabel.CONCAVE), int(EdgeLabel.NONE))
    return c, r, votes[parent], ph, pp, sibling


def concentric_reach(candidate: np.ndarray, r: np.ndarray, reach: np.ndarray, least: float) -> np.ndarray:
    """The first refinement ring's half-width of each hypothesis (px), at most half the gap to
    the nearest other radius of the same centre candidate (and at least ``least``).

    The first ring is as wide as the candidate's cell, since the centre is known to about that;
    but where one candidate's voter distances peak at two radii a few pixels apart (two
    concentric rims: a counterbore, a hole's two rims head-on, 5-6 px apart at r = 44-70), a
    ring that wide holds both, the fit averages them and the narrowed rings around the mean
    hold neither (both were lost). ``candidate`` (K,): each hypothesis's candidate; ``r`` (K,):
    its radius; ``reach`` (K,): the cell's half-width ring.
    """
    reach = np.asarray(reach, float).copy()
    o = np.lexsort((r, candidate))
    same = candidate[o][1:] == candidate[o][:-1]
    gap = np.where(same, np.diff(r[o]), np.inf)
    nearest = np.minimum(np.concatenate([[np.inf], gap]), np.concatenate([gap, [np.inf]]))
    reach[o] = np.minimum(reach[o], np.maximum(0.5 * nearest, least))
    return reach


def _support(xy: np.ndarray, c: np.ndarray, r: float) -> tuple[np.ndarray, float, float, float, float]:
    """Edge points within 1 px of the circle, coverage, start/end angles of the longest run, RMS."""
    d = xy - c
    rho = np.hypot(d[:, 0], d[:, 1])
    on = np.abs(rho - r) <= 1.0
    ang = np.arctan2(d[on, 1], d[on, 0])
    n_bins = round(2 * np.pi * r)
    cov, start, end = angular_coverage(ang, n_bins)
    if len(ang) > 1:
        # the run goes on across the gap between two neighbouring pixels (8-adjacent): a thin
        # curve's diagonal steps put them sqrt(2) px apart, leaving an empty 1 px bin every few
        # pixels (a clean 180 degree arc of radius 30 px ran 61 degrees); a missing pixel
        # (neighbours 2 px apart) still breaks it, so clutter near a circle is not joined up
        o = np.argsort(ang)
        a, p = ang[o], xy[on][o]
        nxt = np.roll(np.arange(len(a)), -1)
        adjacent = np.abs(p[nxt] - p).max(axis=1) <= 1.0 + 1e-6
        gap = np.mod(a[nxt] - a, 2 * np.pi)
        mid = a[adjacent] + gap[adjacent] / 2
        _, start, end = angular_coverage(np.concatenate([ang, mid]), n_bins)
    rms = float(np.sqrt(np.mean((rho[on] - r) ** 2))) if on.any() else np.inf
    return on, cov, start, end, rms


def _dedupe(items: list, key_c, key_r, dist_px: float) -> list:
    kept = []
    for it in items:
        if all(np.hypot(*(key_c(it) - key_c(k))) > dist_px or abs(key_r(it) - key_r(k)) > dist_px for k in kept):
            kept.append(it)
    return kept


def _check_accumulator(cells: int, n_votes: float, hist_bins: float, radii) -> None:
    """Refuse (one line, naming the radius range) a Hough accumulator that would not fit in memory.

    ``cells``: the bands' centre cells (int64 counts, an int32 candidate lookup, a bool mark);
    ``n_votes``: the votes (an int32 cell each, and at most one (candidate, point) pair of
    two int64 per vote); ``hist_bins``: the candidates' radius histograms (float, plus a
    hypothesis index and radius per bin).
    """
    estimate = float(cells) * 13 + n_votes * 20 + hist_bins * 24
    check_memory(estimate, f"circle radii {radii[0]:g}..{radii[1]:g} px (--rmin/--rmax, a Hough accumulator of "
                           f"{cells:,.0f} cells, {n_votes:,.0f} votes and {hist_bins:,.0f} radius bins)")


def circles(
    edge_map: Any,
    radii: tuple[float, float] = (5, 80),
    *,
    min_support: float = 0.5,
    threshold: float = 0.25,
    angle_tol_deg: float = 4.0,
    max_residual: float = 0.8,
    keep: np.ndarray | None = None,
    split_tangent: bool = False,
) -> list[Circle]:
    """Circles in an edge map, by the direction-guided Hough transform.

    Parameters
    ----------
    edge_map : EdgeMap or (H, W) bool
        Edge pixels; ``direction`` (radians, across the edge) is used when present, else it
        is estimated from the mask.
    radii : (rmin, rmax)
        Radius range, pixels; every circle returned has its (refined) radius in it.
    min_support : float
        Least fraction of the circumference (bins of about 1 px) with an edge pixel within
        1 px of the circle whose edge normal is radial within 15 degrees; each edge pixel
        supports one circle (strongest first; but a circle keeps the pixels where a smaller
        one internally tangent to it meets it, a tapped hole's rim around its crest outline,
        :func:`~._circle_kernels.claim_pairs`), so a candidate left below this once the pixels
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
    split_tangent : bool
        Also separate two near-concentric circles whose edges lie within a few pixels of each
        other (internally nearly tangent: a rim and an outline seen inside it), which the
        refinement otherwise averages into one circle 0.5-1.5 px off both: a hypothesis whose
        ring (4 px) holds two edges over at least 15 % of its arc, and nothing else, becomes
        the two circles, each refitted on a narrowing band so that it locks onto its own edge
        (:func:`~._circle_kernels._two_edges`); the two share the points where they meet in
        the support test. Off by default: on the Green Piece's tapped holes, where a third
        edge (a crease beside the rim) runs between them, it finds the crest outlines but no
        more rims, and it costs about 20 % more time (``benchmarks/bench_hough.py``).

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
    radii = check_range(radii, "radii")
    P.number(min_support, "min_support", 0, 1, what="share")
    P.number(threshold, "threshold", 0, lo_open=True)
    P.number(angle_tol_deg, "angle_tol_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    P.number(max_residual, "max_residual", 0, lo_open=True, unit="pixels")
    split_tangent = P.flag(split_tangent, "split_tangent")
    xy, theta, pixels = edge_points(edge_map, keep, return_pixels=True)
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    labels = point_labels(edge_map, pixels)
    labels = np.zeros(0, np.uint8) if labels is None else np.ascontiguousarray(labels, np.uint8)
    # split_tangent: a hypothesis averaging two near-concentric edges (a rim and a circle
    # nearly tangent inside it) becomes both circles, which then share the points where they meet
    h = _hypotheses(xy, theta, pixels, mask.shape, radii, angle_tol_deg, threshold, 1.0, 200, 1.0, 1.0, REL_CELL,
                    labels, split=split_tangent)
    if h is None:
        return []
    c, r, votes, ph, pp, sibling = h
    cov, rms = _coverage(xy, c, r, ph, pp)
    order = np.argsort(-cov, kind="stable")
    # refinement may move a hypothesis out of the radii searched: those are not returned
    inside = (r[order] >= radii[0]) & (r[order] <= radii[1])
    order = order[(cov[order] >= min_support) & (rms[order] <= max_residual) & inside]
    # each edge point supports one circle: a candidate that is left with too little support
    # once the points of stronger circles are taken (a ghost made of two rims, a crescent
    # inside a rim) is dropped; this also removes near-duplicates
    # (compiled: one_edge and the angular coverage of the free points, per candidate)
    points = pp[np.argsort(ph, kind="stable")]
    starts = np.concatenate([[0], np.cumsum(np.bincount(ph, minlength=len(r)))])
    kept = claim_pairs(order.astype(np.int64), starts, points.astype(np.int64), labels, xy[:, 0].copy(),
                       xy[:, 1].copy(), c[:, 0].copy(), c[:, 1].copy(), np.asarray(r, np.float64), float(min_support),
                       int(EdgeLabel.CONCAVE), int(EdgeLabel.NONE), sibling)
    found = [Circle((float(c[j, 0]), float(c[j, 1])), float(r[j]), int(votes[j]), float(cov[j]), float(rms[j]))
             for j in kept]
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
    # as _arc_ellipses.grow (bands 3, 1.5, 1 px), compiled whole for these few conics
    grown, ok, hyp, pt = grow_few(conics, xy, np.cos(theta), np.sin(theta), np.array([3.0, 1.5, 1.0]),
                                  float(np.cos(np.deg2rad(GROW_DIRECTION_TOL_DEG))), GROW_MARGIN_PX)
    _, axes, _, real = ellipse_params(grown)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = axes[:, 1] / axes[:, 0]
    thin = ok & real & (ratio < max_ratio)
    if thin.any():  # the coverage only of the conics that grew thin (most stay circles)
        keep = thin[hyp]
        remap = np.cumsum(thin) - 1
        cov, _, _ = ellipse_coverage(grown[thin], xy, remap[hyp[keep]], pt[keep])
        support = np.array([f.support for f in found])[thin]
        thin[thin] = cov > support
    out[ask] = thin
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
