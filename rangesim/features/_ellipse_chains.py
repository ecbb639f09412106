"""Chain hypotheses of the model-free ellipse finder (``free_ellipses(...,
hypotheses="chains")``): the edge pixels traced into ordered chains, cut into arc pieces at
corners, inflections, jumps of curvature and where one conic no longer fits, each piece and
its nearest neighbours fitted, and each good fit grown over the whole pieces that lie on it
(:mod:`._ellipse_chains_kernels`).

A point belongs to one piece, so it is fitted a few times (alone, in its piece's pairs and
triples, in the unions it is grown into) instead of once per tiling
(:func:`~._arc_ellipses.arc_hypotheses`): about 330 fits per tilted Green Piece map instead
of about 1,150, and pieces as long as the arcs themselves, joined across gaps (a large partial
ellipse's arcs are fitted whole, not cut at tile borders).
"""
from __future__ import annotations

import numpy as np

from rangesim.features._ellipse_chains_kernels import (
    cluster_groups,
    cut_chains,
    fit_ranges,
    grow_pieces,
    link_groups,
    piece_fits,
    trace_chains,
)
from rangesim.features._ellipse_kernels import DISTINCT_MAX_PX, distinct_conics

#: edge normals of linked 8-neighbours agree within this, degrees (as the curves of
#: :func:`~._arc_ellipses.smooth_curves`)
LINK_DEG = 35.0
#: 8-neighbours are linked only when their step is at least this far off their normals, degrees
ADJACENT_DEG = 30.0
#: a chain's walk jumps gaps of up to this, px, along the tangent where no link goes on (1: none;
#: 2 and 3 cost recall, precision and time on the tilted Green Piece)
GAP_PX = 1
#: the chains' polylines (Douglas-Peucker) keep every point within this, px
POLY_TOL_PX = 0.75
#: a chain is cut where its polyline turns by more than this, degrees (a corner)
MAX_TURN_DEG = 75.0
#: ... and where it turns one way then the other by more than this, degrees (an inflection)
INFLECTION_DEG = 10.0
#: ... and where a segment is over this many times the next two on the other side of a vertex
#: (the curvature jumps)
MAX_SEGMENT_RATIO = 3.0
#: ... the longer of them at least this long, px
MIN_LONG_PX = 20.0
#: ... and where the direct fit of the piece grown by one more segment passes farther than
#: this from one of its polyline's vertices or segment middles, px
CUT_DIST_PX = 1.5
#: ... once the piece has turned by this much, degrees
MIN_TURNED_DEG = 45.0
#: ... and only once its fit is an ellipse of semi-minor axis this many px or more (and over 0.2
#: of the major): a flatter piece's fit is ill-determined
MIN_THICK_PX = 4.0
#: the growing piece's fit runs in a frame at its first point with this many px per unit (the
#: moments' monomials stay near 1 for pieces of tens of pixels)
FIT_SCALE_PX = 16.0
#: a fit is good when the RMS Sampson distance of its points (after one trimmed refit) is at
#: most this, px
MAX_RMS_PX = 0.5
#: pieces of fewer points are not fitted alone nor in pairs, ...
MIN_PIECE_POINTS = 8
#: ... but pieces of this many join the pairs and clusters (shorter chains are dropped)
MIN_FRAGMENT_POINTS = 2
#: the fragments join the pieces' pairs (else only the clusters), of pieces of at most
#: FRAGMENT_PIECE_MAX points
FRAGMENT_PAIRS = True
FRAGMENT_PIECE_MAX = 15
#: pieces whose ends lie within this of each other (px) make a cluster, fitted whole when it holds
#: at most CLUSTER_MAX_POINTS points (a small rim broken into fragments); 0: no clusters
CLUSTER_GAP_PX = 3.0
CLUSTER_MAX_POINTS = 150
#: a piece lies on a hypothesis when its points are within this of it, px, ...
PIECE_BAND_PX = 3.0
#: ... and their normals within this of the conic's, degrees
PIECE_DIRECTION_DEG = 25.0
#: pairs of pieces: each piece with its nearest others whose ends are within this, px, ...
PAIR_GAP_PX = 12.0
#: ... this many at most
PAIR_NEAREST = 3
#: each piece with the nearest piece at either end, within PAIR_GAP_PX or this fraction of its
#: length (points), and with both
GAP_FRACTION = 0.5
#: the pieces are linked end to end (their ends facing each other, the step between them within
#: LINK_TURN_DEG of both ends' directions, within PAIR_GAP_PX or GAP_FRACTION of the shorter
#: piece's points), and runs of LINK_WINDOWS pieces and whole paths fitted
LINKS = True
LINK_TURN_DEG = 30.0
#: a piece end's outward direction is taken from the point this many points back along it
END_DIRECTION_PX = 8
LINK_WINDOWS = (3,)
#: only the distinct good fits (centres 2 px apart, or a semi-axis 20 %) are grown over pieces
SEED_DISTINCT = True
#: rounds of the pieces' growth (each around the last union's fit)
PIECE_GROW_ITER = 2


def chains(pixels: np.ndarray, theta: np.ndarray, min_len: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Ordered chains of edge pixels (:func:`~._ellipse_chains_kernels.trace_chains`).

    8-neighbours are linked when their normals agree within :data:`LINK_DEG` and their step
    runs at least :data:`ADJACENT_DEG` off both normals; a diagonal link is dropped where a
    4-neighbour linked to both carries the chain. Walks start at the chains' ends, then at
    the points left (loops), and go on along the straightest link; at a junction the other
    branches become chains of their own (the walk itself goes on through it: where the
    straightest branch is not the same curve, the pieces' cuts end the arc there). A staircase
    pixel whose step to its neighbour runs along the normal is not linked, and a walk may
    pass it by: about one pixel in eight of a rasterised ellipse stays out of the chains.

    Parameters
    ----------
    pixels : (N, 2) int
        (column, row) of the edge pixels, distinct.
    theta : (N,) float
        Edge-normal angles, radians.
    min_len : int
        Chains of fewer points are left out.

    Returns
    -------
    order : (M,) int
        Point indices, chain after chain, each in its order along the chain.
    start : (C + 1,) int
        Chain c is ``order[start[c]:start[c + 1]]``.
    """
    pixels = np.asarray(pixels)
    if len(pixels) == 0:
        return np.zeros(0, np.int64), np.zeros(1, np.int64)
    x, y = pixels[:, 0].astype(np.int64), pixels[:, 1].astype(np.int64)
    x, y = x - x.min(), y - y.min()
    theta = np.asarray(theta, np.float64)
    return trace_chains(x, y, np.cos(theta), np.sin(theta), float(np.cos(np.deg2rad(LINK_DEG))),
                        float(np.cos(np.deg2rad(ADJACENT_DEG))), int(min_len), int(GAP_PX),
                        float(np.sin(np.deg2rad(LINK_DEG))))


def pieces(xy: np.ndarray, order: np.ndarray, start: np.ndarray, *, tol_px: float | None = None,
           max_turn_deg: float | None = None, cut_dist: float | None = None,
           min_points: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arc pieces of :func:`chains`: each chain's polyline cut at corners, inflections
    and where a conic no longer fits it (:func:`~._ellipse_chains_kernels.cut_chains`).

    ``tol_px``, ``max_turn_deg``, ``cut_dist`` and ``min_points`` default to
    :data:`POLY_TOL_PX`, :data:`MAX_TURN_DEG`, :data:`CUT_DIST_PX` and :data:`MIN_PIECE_POINTS`.

    Returns
    -------
    p_start, p_cnt, p_chain : (P,) int
        Piece p is ``order[p_start[p]:p_start[p] + p_cnt[p]]``, on chain ``p_chain[p]``.
    """
    tol_px = POLY_TOL_PX if tol_px is None else tol_px
    max_turn_deg = MAX_TURN_DEG if max_turn_deg is None else max_turn_deg
    cut_dist = CUT_DIST_PX if cut_dist is None else cut_dist
    min_points = MIN_PIECE_POINTS if min_points is None else min_points
    return cut_chains(np.ascontiguousarray(xy, np.float64), np.asarray(order, np.int64), np.asarray(start, np.int64),
                      float(tol_px), float(np.deg2rad(max_turn_deg)), float(np.deg2rad(INFLECTION_DEG)),
                      float(MAX_SEGMENT_RATIO), float(MIN_LONG_PX), float(cut_dist),
                      float(np.deg2rad(MIN_TURNED_DEG)), float(MIN_THICK_PX), int(min_points), float(FIT_SCALE_PX))


def chain_hypotheses(xy: np.ndarray, theta: np.ndarray, pixels: np.ndarray | None = None, *,
                     max_rms: float | None = None,
                     min_inliers: float = 0.6, min_arc_deg: float = 60.0,
                     axes_range: tuple[float, float] = (4.0, 200.0), min_ratio: float = 0.2,
                     skip_explained: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Ellipse hypotheses from the arc pieces of the edge chains.

    The chains (:func:`chains`) are cut into pieces (:func:`pieces`); pieces of
    :data:`MIN_PIECE_POINTS` or more are fitted alone, with their :data:`PAIR_NEAREST`
    nearest pieces (ends within :data:`PAIR_GAP_PX`), with the nearest piece at either end
    (within :data:`PAIR_GAP_PX` or :data:`GAP_FRACTION` of their length) and with both; the
    small ones (at most :data:`FRAGMENT_PIECE_MAX` points) also with the nearest fragment at
    either end and both, and pieces and fragments joined end to end (within
    :data:`CLUSTER_GAP_PX`, at most :data:`CLUSTER_MAX_POINTS` points) as one cluster: a
    small rim that the links broke into short chains
    (:func:`~._ellipse_chains_kernels.piece_fits`,
    :func:`~._ellipse_chains_kernels.cluster_groups`). With :data:`LINKS` the pieces are
    also linked end to end where one continues another across a gap (ends facing, the step
    within :data:`LINK_TURN_DEG` of both ends' directions, mutual nearest), and each run of
    :data:`LINK_WINDOWS` linked pieces and each whole path is fitted: the arcs of a large
    ellipse whose chain the links broke in several places, each too short for an unbiased fit
    (:func:`~._ellipse_chains_kernels.link_groups`). Each fit (direct least squares, one
    trimmed refit) is checked as :func:`~._arc_ellipses.arc_hypotheses` checks its pieces
    (RMS Sampson distance <= ``max_rms``, ``min_inliers`` within 1 px, over ``min_arc_deg``
    of the ellipse, within ``axes_range``); each distinct good one, the most points first, is
    grown over the pieces lying on it (4 of 5 of their points spread along them, the middle
    one included, within :data:`PIECE_BAND_PX` with agreeing normals: the other arcs of the
    same rim, across gaps and junctions) and refitted on their union, :data:`PIECE_GROW_ITER`
    times. With ``skip_explained`` a fit whose first piece is in an earlier good union is not
    grown again.

    Parameters
    ----------
    xy : (N, 2) float
        Edge points, pixels (fitted).
    theta : (N,) float
        Edge-normal angles, radians.
    pixels : (N, 2) int, optional
        The points' pixels, which are traced (default ``xy`` truncated).

    max_rms : float, optional
        Default :data:`MAX_RMS_PX`.

    Returns
    -------
    conics : (K, 6) float
        The good fits: the grown unions, then the pieces' groups, then the clusters.
    n_points : (K,) int
    """
    max_rms = MAX_RMS_PX if max_rms is None else max_rms
    xy = np.ascontiguousarray(xy, np.float64)
    theta = np.asarray(theta, np.float64)
    pix = xy.astype(np.int64) if pixels is None else np.asarray(pixels, np.int64)
    order, start = chains(pix, theta, MIN_FRAGMENT_POINTS)
    f_start, f_cnt, _ = pieces(xy, order, start, min_points=MIN_FRAGMENT_POINTS)
    big = f_cnt >= MIN_PIECE_POINTS  # the pieces; the shorter fragments only join pairs and clusters
    p_start, p_cnt = f_start[big], f_cnt[big]
    lo, hi = float(axes_range[0]), float(axes_range[1])
    pf_start, pf_cnt = (f_start, f_cnt) if FRAGMENT_PAIRS else (p_start, p_cnt)
    conics, good, first, n = piece_fits(xy, order, pf_start, pf_cnt, int(MIN_PIECE_POINTS), int(FRAGMENT_PIECE_MAX),
                                        float(PAIR_GAP_PX), float(GAP_FRACTION), int(PAIR_NEAREST), float(max_rms),
                                        float(min_inliers), lo, hi, float(min_ratio), float(min_arc_deg))
    if FRAGMENT_PAIRS:
        first = (np.cumsum(big) - 1)[first]  # the groups' first pieces among the pieces
    if LINKS:  # the pieces linked end to end across gaps: windows of them, and whole paths
        l_pts, l_lo, l_n, l_first = link_groups(xy, order, p_start, p_cnt, float(GAP_FRACTION), float(PAIR_GAP_PX),
                                                float(np.cos(np.deg2rad(LINK_TURN_DEG))), int(END_DIRECTION_PX),
                                                np.asarray(LINK_WINDOWS, np.int64))
        l_conics, l_good = fit_ranges(xy, l_pts, l_lo, l_n, float(max_rms), float(min_inliers), lo, hi,
                                      float(min_ratio), float(min_arc_deg))
        conics, good = np.concatenate([conics, l_conics]), np.concatenate([good, l_good])
        first, n = np.concatenate([first, l_first]), np.concatenate([n, l_n])
    if CLUSTER_GAP_PX > 0:
        c_pts, c_lo, c_n, _ = cluster_groups(xy, order, f_start, f_cnt, float(CLUSTER_GAP_PX),
                                             int(MIN_PIECE_POINTS), int(CLUSTER_MAX_POINTS))
        c_conics, c_good = fit_ranges(xy, c_pts, c_lo, c_n, float(max_rms), float(min_inliers), lo, hi,
                                      float(min_ratio), float(min_arc_deg))
        c_sel = np.nonzero(c_good)[0]
        c_conics, c_n = c_conics[c_sel], c_n[c_sel]
    else:
        c_conics, c_n = np.zeros((0, 6)), np.zeros(0, np.int64)
    sel = np.nonzero(good)[0]
    sel = sel[np.argsort(-n[sel], kind="stable")]
    if SEED_DISTINCT and len(sel):  # seeds that repeat a larger one grow into the same union
        sel = sel[distinct_conics(np.ascontiguousarray(conics[sel]), 2.0, 0.2, DISTINCT_MAX_PX)]
    if PIECE_GROW_ITER == 0:
        return np.concatenate([conics[sel], c_conics]), np.concatenate([n[sel], c_n])
    ct, st = np.cos(theta), np.sin(theta)
    u_c, u_good, u_n = grow_pieces(conics[sel], first[sel], xy, order, p_start, p_cnt, ct, st, float(PIECE_BAND_PX),
                                   float(np.cos(np.deg2rad(PIECE_DIRECTION_DEG))), float(max_rms),
                                   float(min_inliers), lo, hi, float(min_ratio), float(min_arc_deg),
                                   bool(skip_explained), int(PIECE_GROW_ITER))
    return (np.concatenate([u_c[u_good], conics[sel], c_conics]),
            np.concatenate([u_n[u_good], n[sel], c_n]))
