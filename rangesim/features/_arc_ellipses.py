"""Model-free ellipses: conics fitted to short arcs of edge pixels, then grown along the edges.

Hypotheses come (by default, :data:`HYPOTHESES` "tilings") from the pieces of smooth edge
curves inside square tiles of several sizes (tiles that shift by half their size, so that
every arc lies whole in some tile at some scale) and from the outer outlines of the groups of
edge pixels; or ("chains") from the edge pixels traced into ordered chains and cut into arc
pieces (:mod:`._ellipse_chains`), with the outlines; or ("outlines") from the outlines alone,
one fit per group of edge pixels as ``cv2.fitEllipse`` on a contour. Each hypothesis that is a good ellipse
on its piece is grown over all the edge points near it whose edge direction agrees,
refitted, and kept when it covers enough of its own perimeter. Each edge point is claimed by
one ellipse (strongest first): a candidate left with too little unclaimed support is
dropped. Each stage is one compiled pass (:mod:`._ellipse_kernels`,
:mod:`._ellipse_chains_kernels`): the work follows the edge pixels and the number of
hypotheses.
"""
from __future__ import annotations

import numpy as np

from rangesim.core.conics import ellipse_params
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.features._conic_kernels import sampson_pairs
from rangesim.features._ellipse_chains import chain_hypotheses
from rangesim.features._ellipse_kernels import (
    DISTINCT_MAX_PX,
    arc_pieces,
    claim,
    coverage_rows,
    curve_labels,
    distinct_conics,
    grow_conics,
    outline_fits,
    outline_points,
)

#: the hypothesis generator of :func:`free_ellipses` (and so of ``rs.features.ellipses``
#: without a model): "tilings" (:func:`arc_hypotheses` and :func:`outline_hypotheses`) or
#: "chains" (:func:`~._ellipse_chains.chain_hypotheses` and :func:`outline_hypotheses`). The
#: chains are 1.3-1.5x faster on the tilted Green Piece (CPU time 2.7-3.3x cv2.fitEllipse's,
#: the tilings 3.9-4.4x) and find far more large partial ellipses (55 of 80 against 25 on
#: held-out synthetic maps), but lost a rim and gained a false one on the machined parts' check
#: seeds, and find ghost ellipses in dense random clutter (half the pixels of a mask set) where
#: the tilings find none, so they are not the default (``rs.features.ellipses(...,
#: hypotheses="chains")`` asks for them). "outlines": only :func:`outline_hypotheses`, the
#: outlines of the groups of edge pixels and of the regions they enclose (``cv2.findContours``
#: with ``RETR_LIST`` and ``cv2.fitEllipse`` on each contour; :data:`OUTLINE_PASSES`): on the
#: tilted Green Piece the tilings' recall (0.92 / 1.00) at 1.4-1.5x cv2.fitEllipse's CPU time
#: (the tilings 3.9-4.4x), precision 0.92 / 1.00 (fitEllipse 0.33 / 0.44); on the machined
#: parts' report seeds the same hole rims as the tilings on the laser-stripe presets but fewer
#: boss and cylinder tops (all round features 0.80-1.00 against 0.95-1.00), and far fewer
#: rims on the block-matched ones. It needs outlines: a rim broken by gaps over 2 px (a
#: dashed ellipse: 9 of 99 found, the tilings 93) or whose inside an edge splits in two
#: (neither region is the ellipse) is missed, and two crossing ellipses' lens is an enclosed
#: region that can be fitted as a ghost
HYPOTHESES = "tilings"
#: the "outlines" generator's passes, (dilation px every way, with the inner outlines): dilated
#: by 1 px, the outlines bridge a broken rim's gaps and the regions a group encloses give the
#: rims whose group's outer outline is something else (a boss top with its sides, a rim with
#: a floor's edge); undilated, the outer outlines keep apart what a dilation joins (a rim and
#: a line a pixel or two beside it). (Undilated inner outlines found no rim more on the
#: machined parts' tuning and check seeds nor on the tilted Green Piece.)
OUTLINE_PASSES = ((1, True), (0, False))
#: the chain hypotheses' claims go by coverage less this times the RMS residual (px): two grown
#: copies of one rim, one pulled 1-3 px towards a thread's crests, cover alike, and the closer
#: fit goes first
CLAIM_RMS_WEIGHT = 1.0
#: the chain hypotheses are joined by the outlines' (:func:`outline_hypotheses`), which go first
#: (a threaded hole's rim around its crests: its arcs join the crests' and grow towards them)
CHAIN_OUTLINES = True
#: the growth bands of :func:`free_ellipses`, px
BANDS = (3.0, 2.0, 1.5, 1.0)
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
#: sines and cosines of the 65 parametric angles of :func:`coverage`'s arc-length table
_T = np.linspace(0.0, 2 * np.pi, 65)
_SIN_T, _COS_T = np.sin(_T), np.cos(_T)


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
        Component labels, numbered by their first point: a corner (normals turning by more
        than ``link_deg`` between two neighbours) or a crossing edge of another direction
        ends a curve.
    """
    if len(xy) == 0:
        return np.zeros(0, np.int64)
    x, y = xy[:, 0].astype(np.int64), xy[:, 1].astype(np.int64)
    x, y = x - x.min(), y - y.min()  # the index image covers the points' box only
    return curve_labels(x, y, np.asarray(theta, np.float64), int(gap_px) + 1, float(np.cos(np.deg2rad(link_deg))),
                        float(np.sin(np.deg2rad(link_deg))), float(np.cos(np.deg2rad(ADJACENT_DEG))))[0]


def arc_hypotheses(xy: np.ndarray, curve: np.ndarray, *, min_points: int = 10, tiles_px=TILES_PX,
                   max_rms: float = 0.5, min_inliers: float = 0.6, min_arc_deg: float = 60.0,
                   axes_range: tuple[float, float] = (4.0, 200.0), min_ratio: float = 0.2,
                   pairs_per_tile: int = 3):
    """Ellipses fitted to the pieces of each smooth curve inside square tiles.

    The pieces are the points of one curve in one tile, for every tiling (the sizes
    ``tiles_px``, each also shifted by half a tile diagonally); each tile is its pieces'
    fitting frame. A piece that recurs in several tilings (the same curve, count and sum of
    point indices) is fitted once. Pairs of curved pieces (a fit that is a real ellipse,
    whatever its residual) sharing a tile, the ``pairs_per_tile`` largest of each tile, are
    fitted too: the arcs of one rim that a gap or a corner split (their moments, in one
    frame, add up). Each fit is checked on its points after one trimmed refit (the points
    within 1 px of the first fit: a piece of a rim with some clutter linked to it). All of it
    is one compiled pass (:func:`~._ellipse_kernels.arc_pieces`).

    Parameters
    ----------
    xy : (N, 2) float
    curve : (N,) int
        :func:`smooth_curves` labels.
    min_points : int
        Least points of a fitted piece or pair (pieces of fewer than ``max(5, min_points //
        3)`` are not used at all).
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
    if len(xy) < min_points:
        return np.zeros((0, 6)), np.zeros(0, np.int64)
    curve = np.asarray(curve, np.int64)
    return arc_pieces(np.ascontiguousarray(xy, np.float64), curve, int(curve.max()) + 1,
                      np.asarray(tiles_px, np.int64), int(min_points), int(pairs_per_tile), float(max_rms),
                      float(min_inliers), float(axes_range[0]), float(axes_range[1]), float(min_ratio),
                      float(min_arc_deg))


def _parametric_angle(p: np.ndarray, c: np.ndarray, axes: np.ndarray, ang: np.ndarray) -> np.ndarray:
    """(N,) parametric angle in [0, 2 pi) of points about their ellipses (rows)."""
    d = p - c
    ca, sa = np.cos(ang), np.sin(ang)
    u = (d[:, 0] * ca + d[:, 1] * sa) / np.maximum(axes[:, 0], 1e-9)
    v = (-d[:, 0] * sa + d[:, 1] * ca) / np.maximum(axes[:, 1], 1e-9)
    return np.mod(np.arctan2(v, u), 2 * np.pi)


def distinct(conics: np.ndarray, center_px: float = 2.0, rel_size: float = 0.2,
             max_px: float = DISTINCT_MAX_PX) -> np.ndarray:
    """Indices of the conics (in order) that repeat no earlier kept one (centre within
    ``center_px`` and both semi-axes within ``rel_size`` of the later one's and within
    ``max_px``)."""
    if len(conics) == 0:
        return np.zeros(0, np.int64)
    return distinct_conics(np.ascontiguousarray(conics, np.float64), float(center_px), float(rel_size), float(max_px))


def grow(conics: np.ndarray, xy: np.ndarray, theta: np.ndarray, *, bands=(3.0, 2.0, 1.5, 1.0),
         direction_tol_deg: float = DIRECTION_TOL_DEG):
    """Refit each conic on the edge points near it whose edge normal agrees, narrowing.

    The candidates, once: the points within ``bands[0] + GROW_MARGIN_PX`` px of the first
    conic (a refit moves an ellipse by less), found through its bounding box and a grid of
    32 px cells (the work follows the boxes' areas, not the image); then, per band, the
    agreeing candidates within it are refitted (one compiled call,
    :func:`~._ellipse_kernels.grow_conics`).

    Returns
    -------
    conics : (K, 6) float
    ok : (K,) bool
        Real ellipses after the last pass.
    hyp, point : (P,) int
        (ellipse, edge point) pairs of the inliers (by ellipse): within the last band and
        agreeing.
    """
    return grow_conics(np.ascontiguousarray(conics, np.float64).reshape(-1, 6), np.ascontiguousarray(xy, np.float64),
                       np.ascontiguousarray(theta, np.float64), np.asarray(bands, np.float64),
                       float(np.cos(np.deg2rad(direction_tol_deg))), float(GROW_MARGIN_PX), 32.0)


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


def outline_hypotheses(xy: np.ndarray, *, min_points: int = 10, max_rms: float = 0.5, min_inliers: float = 0.6,
                       min_arc_deg: float = 60.0, axes_range: tuple[float, float] = (4.0, 200.0),
                       min_ratio: float = 0.2, gap_px: int = 1, pixels: np.ndarray | None = None,
                       inner: bool = False):
    """Ellipses fitted to the outer outline of each group of edge pixels (as ``cv2.fitEllipse``
    on a contour): the rim around a hole's clutter (thread crests, a floor's edges) that links
    to the rim's arcs and spoils their pieces. With ``inner``, the outlines of the regions each
    group encloses too (``cv2.findContours``' ``RETR_LIST``): a boss top or a hole's rim whose
    group also holds the boss's sides or a floor's edges, so that its outer outline is not it.

    The edge pixels, dilated by ``gap_px`` every way (bridging gaps of up to twice that), are
    grouped (8-connected); a group's
    outline is its points with a 4-neighbour in the group's outer background (the background
    region left of its leftmost pixel; not the regions it encloses, and not the region of a
    group it lies in). Each outline is fitted and checked as the pieces of
    :func:`arc_hypotheses`. ``pixels`` (N, 2) int: the points' pixels (default: ``xy``
    truncated), which make the groups; the fits are to ``xy``. The groups and regions are
    found on the rows' runs (:func:`~._ellipse_kernels.outline_points`), not pixel by pixel.

    Returns
    -------
    conics : (K, 6) float
    n_points : (K,) int
    """
    if len(xy) < min_points:
        return np.zeros((0, 6)), np.zeros(0, np.int64)
    pix = np.ascontiguousarray(xy if pixels is None else pixels).astype(np.int64)
    idx, _, n = outline_points(pix, max(int(gap_px), 0), bool(inner))
    return outline_fits(np.ascontiguousarray(xy, np.float64), idx, n, int(min_points), float(max_rms),
                        float(min_inliers), float(axes_range[0]), float(axes_range[1]), float(min_ratio),
                        float(min_arc_deg))


def free_ellipses(xy: np.ndarray, theta: np.ndarray, *, min_points: int = 20, min_support: float = 0.5,
                  max_residual: float = 0.8, axes_range: tuple[float, float] = (4.0, 200.0),
                  min_ratio: float = 0.2, pixels: np.ndarray | None = None, labels: np.ndarray | None = None,
                  hypotheses: str | None = None, outlines: bool | None = None, bands: tuple | None = None
                  ) -> list[tuple[np.ndarray, np.ndarray, float, float, int]]:
    """Ellipses of edge points without a model: arc hypotheses, grown, one claim per point
    (a candidate whose unclaimed inliers cover less than ``min_support`` is dropped; the
    returned inliers of an accepted ellipse are all of them, claimed before or not).

    ``hypotheses``: "tilings", "chains" or "outlines" (default :data:`HYPOTHESES`);
    ``outlines``: add the outline hypotheses (default: always with the tilings and, being all
    there is, with "outlines"; with the chains when :data:`CHAIN_OUTLINES`); ``bands``: the
    growth bands, px (default :data:`BANDS`).

    ``pixels`` (N, 2) int: the points' pixels (default ``xy``), which link the points into
    curves and groups; the conics are fitted to ``xy`` (edge points to a fraction of a pixel).
    ``labels`` (N,) uint8, optional: the points' edge labels; a candidate keeps only the
    inliers of its own edge (:func:`~._edge_points.one_edge`), and is dropped when those cover
    too little.

    Returns
    -------
    list of (conic (6,), inlier point indices, coverage, RMS Sampson distance px, n inliers),
    in the claims' order (the largest coverage first; with the chains, the largest coverage
    less :data:`CLAIM_RMS_WEIGHT` times the RMS distance).
    """
    if len(xy) < min_points:
        return []
    xy = np.ascontiguousarray(xy, np.float64)
    hypotheses = HYPOTHESES if hypotheses is None else hypotheses
    if hypotheses == "chains":
        conics, n = chain_hypotheses(xy, theta, pixels, axes_range=axes_range, min_ratio=min_ratio)
    elif hypotheses == "tilings":
        curve = smooth_curves(xy if pixels is None else pixels, theta)
        conics, n = arc_hypotheses(xy, curve, axes_range=axes_range, min_ratio=min_ratio)
    elif hypotheses == "outlines":
        if outlines is False:
            raise RangesimError("hypotheses='outlines' fits the outlines only: outlines=False leaves nothing to fit")
        conics, n = np.zeros((0, 6)), np.zeros(0, np.int64)
        outlines = True
    else:
        raise RangesimError(f"hypotheses must be 'tilings', 'chains' or 'outlines', not {hypotheses!r}")
    if (hypotheses == "tilings" or CHAIN_OUTLINES) if outlines is None else outlines:
        if hypotheses == "outlines":  # outer and inner outlines, pixels dilated and not (OUTLINE_PASSES)
            fits = [outline_hypotheses(xy, axes_range=axes_range, min_ratio=min_ratio, pixels=pixels, gap_px=g,
                                       inner=inner) for g, inner in OUTLINE_PASSES]
            c2, n2 = np.concatenate([f[0] for f in fits]), np.concatenate([f[1] for f in fits])
        else:
            c2, n2 = outline_hypotheses(xy, axes_range=axes_range, min_ratio=min_ratio, pixels=pixels)
        if hypotheses == "chains":  # the outlines first: a rim's outline beats its arcs joined to crests
            n2 = n2 + (n.max() if len(n) else 0) + 1
        conics, n = np.concatenate([conics, c2]), np.concatenate([n, n2])
    conics = conics[np.argsort(-n, kind="stable")]
    conics = conics[distinct(conics)]
    if len(conics) == 0:
        return []
    conics, ok, hyp, pt = grow(conics, xy, theta, bands=BANDS if bands is None else bands)
    cov, rms, _ = coverage_rows(conics, xy, hyp, pt, _SIN_T, _COS_T, MAX_PERIMETER_PX)
    _, axes, _, real = ellipse_params(conics)
    n_in = np.bincount(hyp, minlength=len(conics))
    good = ok & real & (cov >= min_support) & (rms <= max_residual) & (n_in >= min_points)
    good &= (axes[:, 1] >= axes_range[0]) & (axes[:, 0] <= axes_range[1]) & (axes[:, 1] >= min_ratio * axes[:, 0])
    order = np.nonzero(good)[0]
    # the claims' order: the largest coverage first; with the chains, less the RMS residual
    # times CLAIM_RMS_WEIGHT (two grown copies of one rim, one pulled 1-3 px towards a crest,
    # cover alike: the closer fit goes first)
    key = cov[order] - (CLAIM_RMS_WEIGHT * rms[order] if hypotheses == "chains" else 0.0)
    order = order[np.argsort(-key, kind="stable")]
    # the claims (one compiled pass): a candidate keeps its own edge's inliers; one left with
    # too little of its perimeter once stronger ellipses took their points (a near-duplicate,
    # a ghost across two rims) is dropped
    has_labels = labels is not None
    lab = np.asarray(labels, np.uint8) if has_labels else np.zeros(1, np.uint8)
    acc, start, pts = claim(conics, order, hyp, pt, xy, lab, has_labels, int(EdgeLabel.CONCAVE), int(EdgeLabel.NONE),
                            int(min_points), float(min_support), _SIN_T, _COS_T, MAX_PERIMETER_PX)
    return [(conics[j], pts[start[k]:start[k + 1]], float(cov[j]), float(rms[j]), int(start[k + 1] - start[k]))
            for k, j in enumerate(acc)]
