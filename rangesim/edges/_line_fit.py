"""Technique 2 of the founding paper: edges of unorganized point lists by straight lines
through each point's nearest neighbours."""
from __future__ import annotations

from typing import Any

import numba
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from skimage.morphology import thin as skeleton_thin

from rangesim.core import params as P
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.edges._discontinuities import JUMP_THRESHOLD, discontinuities, with_gap_creases
from rangesim.edges._grid import NEIGHBOURS
from rangesim.edges._line_fit_sl import sl_creases
from rangesim.edges._line_rings import ring_edges, ring_strides
from rangesim.edges._matching_scale import matching_window
from rangesim.edges._noise import NOISE_FLOOR, estimate_depth_noise, noise_in_footprints, stride_gain
from rangesim.edges._scan_access import scan_arrays
from rangesim.edges._thinning import near_mask
from rangesim.edges.edgemap import RIM, EdgeMap

__all__ = ["line_fit", "line_fit_points"]

#: creases kept clear of a jump's far side, pixels (:func:`line_fit`'s ``jump_clearance``): a
#: depth step seen through a stripe of finite width is rounded over a pixel or two on either
#: side (on the White Scanner preset's noise-free scans 0.04 and 0.2 mm over the 0.27 mm
#: footprints beside a 6.7 mm step), which bends the nearest-neighbour lines of the pixel
#: beside the jump's pair by 20-40 degrees: a false crease along the step's foot and one along
#: its shoulder. Only the foot is cleared: beside the near side a real crease can lie (the flat
#: machined target's 0.5 mm chamfers run one pixel inside its jumps: clearing both sides took
#: its F1 0.77 -> 0.745, the far side alone 0.77 -> 0.87). Chosen on the machined parts'
#: tuning seeds 0-7 (inria_laser 20-29; 2 px cost inria_laser's small features 0.01), checked
#: on 8-15 (30-39): noise-free F1 white_scanner 0.84 -> 0.85, cyberware_3030 0.81 -> 0.84,
#: inria_laser unchanged; with noise unchanged (its strides and wider tolerance already stop
#: short of a jump)
LINE_FIT_CLEARANCE = 1

#: centres per batch: bounds the (chunk, k, k) temporaries (~4 MB each at k = 8)
_CHUNK = 1 << 16
#: most neighbours of the line test: past a few dozen the neighbourhood is no longer local
#: (the paper's is 8), and a k-d query holds _CHUNK x k indices (a k of 10^6 asked for 500 TB)
MAX_K = 64


def line_fit_points(
    points: np.ndarray,
    k: int = 8,
    angle_tol_deg: float | np.ndarray = 15.0,
    line_sep_deg: float = 30.0,
    workers: int = -1,
) -> np.ndarray:
    """Edge points of an (N, 3) point list; see :func:`line_fit`.

    ``angle_tol_deg`` may be one tolerance for all points or an (N,) array, one per point.

    Returns
    -------
    (N,) bool
        True at edge points; False at non-finite rows (which are ignored as neighbours).
    """
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        pts = np.asarray(points, dtype=object)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.dtype == object:
        raise RangesimError(f"line_fit takes a RangeScan or an (N, 3) point array, got {type(points).__name__} "
                            f"of shape {pts.shape}")
    k, line_sep_deg, workers = _line_test_params(k, line_sep_deg, workers)
    tol = np.asarray(angle_tol_deg)
    if tol.ndim and tol.shape != (len(pts),):
        raise RangesimError(f"angle_tol_deg must be a number or one per point ({len(pts)}), got shape {tol.shape}")
    if tol.ndim:
        if tol.dtype.kind not in "iuf" or not (np.isfinite(tol).all() and (tol > 0).all() and (tol < 90).all()):
            raise RangesimError("angle_tol_deg must be finite angles in (0, 90) degrees at every point")
    else:
        P.number(angle_tol_deg, "angle_tol_deg", 0, 90, lo_open=True, hi_open=True, what="angle", unit="degrees")
    tol = tol.astype(np.float64)
    out = np.zeros(len(pts), bool)
    finite = np.isfinite(pts).all(axis=1)
    p = pts[finite]
    n = len(p)
    if n == 0:
        return out
    if n <= k:
        out[finite] = True                         # too few points for any line pair
        return out
    cos_opp = np.cos(np.radians(tol if tol.ndim == 0 else tol[finite]))
    out[finite] = _line_edges(p, np.arange(n), k, cos_opp, float(np.cos(np.radians(line_sep_deg))), workers)
    return out


def _line_test_params(k: Any, line_sep_deg: Any, workers: Any) -> tuple[int, Any, int]:
    """The line test's parameters checked (scans and point lists alike)."""
    k = P.whole(k, "k", 2, MAX_K)
    line_sep_deg = P.number(line_sep_deg, "line_sep_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    workers = P.whole(workers, "workers", 1, also=(-1,), unit="threads; -1: all cores")
    return k, line_sep_deg, workers


def _line_edges(p: np.ndarray, centres: np.ndarray, k: int, cos_opp: float | np.ndarray, cos_sep: float,
                workers: int) -> np.ndarray:
    """The test of :func:`line_fit_points` at the points ``centres`` (M,) of the finite
    points ``p`` (N, 3), N > k, with the cosine of the opposite-pair tolerance (one, or (N,)
    per point); all points are neighbours. (M,) bool."""
    n = len(p)
    cos_opp = np.broadcast_to(np.asarray(cos_opp, np.float64), (n,))
    tree = cKDTree(p)
    edge = np.empty(len(centres), bool)
    for i0 in range(0, len(centres), _CHUNK):
        i1 = min(i0 + _CHUNK, len(centres))
        centre = centres[i0:i1]
        _, idx = tree.query(p[centre], k=k + 1, workers=workers)
        # drop the centre itself (the last neighbour if duplicates pushed it out)
        is_self = idx == centre[:, None]
        no_self = ~is_self.any(axis=1)
        is_self[no_self, -1] = True
        is_self &= np.cumsum(is_self, axis=1) == 1
        idx = idx[~is_self].reshape(i1 - i0, k)
        # the tolerances stay float64 (the float32 cosines are compared in float64)
        edge[i0:i1] = ~_planar(p, idx, np.ascontiguousarray(centre, np.int64),
                               np.ascontiguousarray(cos_opp[centre]), cos_sep)
    return edge


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _planar(p, idx, centre, cos_opp, cos_sep):  # pragma: no cover - compiled
    """Whether each centre ``centre[m]`` has two distinct lines through it among its neighbours
    ``idx[m]``: unit vectors to them (float32; coincident points give NaN, on no line),
    neighbour j on a line when some neighbour is opposite it (cosine below ``-cos_opp``),
    two lines distinct when their directions' |cosine| is below ``cos_sep``."""
    m_all, k = idx.shape
    out = np.zeros(m_all, np.bool_)
    u = np.empty((k, 3), np.float32)
    on = np.empty(k, np.bool_)
    for m in range(m_all):
        ci = centre[m]
        for j in range(k):
            d0 = np.float32(p[idx[m, j], 0] - p[ci, 0])
            d1 = np.float32(p[idx[m, j], 1] - p[ci, 1])
            d2 = np.float32(p[idx[m, j], 2] - p[ci, 2])
            nrm = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            u[j, 0], u[j, 1], u[j, 2] = d0 / nrm, d1 / nrm, d2 / nrm
        lim = -cos_opp[m]
        for j in range(k):
            on[j] = False
            for l in range(k):
                if (u[j, 0] * u[l, 0] + u[j, 1] * u[l, 1]) + u[j, 2] * u[l, 2] < lim:
                    on[j] = True
                    break
        found = False
        for j in range(k):
            if not on[j]:
                continue
            for l in range(k):
                if on[l] and abs((u[j, 0] * u[l, 0] + u[j, 1] * u[l, 1]) + u[j, 2] * u[l, 2]) < cos_sep:
                    found = True
                    break
            if found:
                break
        out[m] = found
    return out


#: noisy scans: the opposite-pair tolerance is ``atan(NOISE_K_LINE * sqrt(2) * noise)``
#: (the angle noise of a unit vector to a neighbour one footprint away is ~sqrt(2) noise
#: radians), at least 15 and at most :data:`MAX_TOL_DEG` degrees
NOISE_K_LINE = 3.0
#: the same per pixel, where the scan's predicted noise says how noisy each pixel is: the
#: margin the scan-wide figure needs for its noisiest faces is not needed (chosen on the
#: machined parts' seeds 0-7: F1 with noise 0.69 / 0.67 -> 0.73 / 0.74 on white_scanner /
#: cyberware_3030)
NOISE_K_LINE_LOCAL = 2.25
#: noisy scans: each pixel's lines reach as many pixels out as bring its tolerance down to
#: this, the noise-free default (:mod:`~rangesim.edges._line_rings`), at most ``max_stride``
RING_TOL_DEG = 15.0


def _pixel_noise(scan: Any, valid: np.ndarray, footprint: np.ndarray, noise: float,
                 sigma: np.ndarray | None = None) -> tuple[float | np.ndarray, float | np.ndarray]:
    """``(k, noise_p)``: the noise multiple of the opposite-pair tolerance and the depth noise
    (footprints) of each pixel, numbers or (H, W).

    ``noise`` is the scan's depth noise in footprints; where the scan carries its noise
    model's ``sigma`` (:func:`~rangesim.edges._noise.predicted_noise`) each pixel's noise is
    ``noise`` times its predicted noise in footprints over the median of that, with
    :data:`NOISE_K_LINE_LOCAL`; elsewhere the scan-wide figure with :data:`NOISE_K_LINE`.
    """
    relative = noise_in_footprints(scan, valid, footprint, sigma)
    if relative is None:
        return NOISE_K_LINE, noise
    ok, sigma_fp = relative
    # pixels without a usable sigma keep the scan-wide figure and its margin
    k = np.where(ok, NOISE_K_LINE_LOCAL, NOISE_K_LINE)
    return k, noise * np.where(ok, sigma_fp / np.median(sigma_fp[ok]), 1.0)


#: the largest opposite-pair tolerance, degrees (beyond it the test would pass any bend). A
#: pixel whose predicted noise (the scan's ``sigma``) asks for more (a face at grazing
#: incidence, 10-20 footprints of noise) can tell no crease from its noise and marks none:
#: its noise would otherwise be a salt of creases where the jump rule's false-alarm floor
#: leaves no jumps (:data:`~rangesim.edges._discontinuities.FALSE_JUMP_Z`)
MAX_TOL_DEG = 60.0


def _noise_tolerance(k: float | np.ndarray, noise_p: float | np.ndarray, gain: np.ndarray | float = 1.0) -> float | np.ndarray:
    """The opposite-pair tolerance (degrees) of a noisy scan, ``atan(k sqrt(2) noise_p gain)``
    clipped to 15..60: a number, or (H, W) float32 per pixel (see :func:`_pixel_noise`; ``gain``
    the bend noise of the pixel's stride over that of stride 1, :mod:`~rangesim.edges._line_rings`)."""
    tolerance = np.clip(np.degrees(np.arctan(k * np.sqrt(2) * noise_p * gain)), 15.0, MAX_TOL_DEG)
    return float(tolerance) if np.ndim(tolerance) == 0 else tolerance.astype(np.float32)


def line_fit(
    points_or_scan: Any,
    k: int = 8,
    angle_tol_deg: float | None = None,
    line_sep_deg: float = 30.0,
    jump_threshold: float = JUMP_THRESHOLD,
    max_search: int = 50,
    workers: int = -1,
    thin: bool = True,
    min_crease_px: int = 5,
    label_creases: bool = True,
    max_stride: int = 8,
    jump_clearance: int | None = None,
) -> np.ndarray | EdgeMap:
    """Edge points by line fitting through nearest neighbours (the paper's technique 2).

    For unorganized, non-uniformly spaced (x, y, z) lists: each point's ``k`` nearest
    neighbours in 3D (``scipy.spatial.cKDTree``), unit vectors from the point to them, and
    pairs of neighbours in opposite directions (within ``angle_tol_deg`` of 180 degrees)
    form straight lines through the point. Two or more distinct lines (directions more
    than ``line_sep_deg`` apart) span a plane: not an edge; one line or none: an edge
    point. Vectorised over all points (``(N, k, k)`` cosines, in chunks).

    What it finds: creases whose faces bend by more than ``angle_tol_deg`` (no neighbour
    pair straddling the crease is straight any more, only the line along it is), and the
    boundaries of the point set (silhouettes, holes): there the neighbourhood is one-sided.
    The least bend found depends on where the crease crosses the pixel grid: through pixel
    centres ``angle_tol_deg``; midway between two centres each pixel beside it sees half the
    bend on one side, so about twice that (a noise-free 40 degree roof between centres was
    missed at the default 15, found 0.2 mm aside). On a plane sampled anisotropically the
    k nearest neighbours crowd along one direction and points turn into false creases: from
    a slant of about 65 degrees (spacing ratio 2.4) with the default k = 8, most of a plane at
    75 degrees, worst on noise-free quantised depth; ``k = 12`` kept planes up to 80 degrees
    clean (on the machined parts it cost F1, so 8 stays the default).

    For a scan, the valid pixels' points are the list and the answer is mapped back to
    pixels. Pixels whose neighbourhood is one-sided only because of the image, not the
    surface (next to invalid pixels, at the image border, or either side of a depth
    jump) are decided by the jump rule instead
    (:func:`~rangesim.edges._discontinuities.find_discontinuities`, steps deeper than
    ``jump_threshold`` pixel footprints, searched across NaN gaps): an edge, labelled JUMP,
    on the near side of a jump, else none, so a hole in a flat face or the image border is
    not an edge. The technique itself cannot tell convex from concave; on a scan, with
    ``label_creases``, a crease pixel is CONVEX where it lies nearer the camera than the
    mean depth of the valid pixels of its 5 x 5 neighbourhood (on a noisy scan, ``2 s + 1``
    square where its stride ``s`` is larger) that are not across a depth jump (a roof: the
    faces fall away on both sides), else CONCAVE (label 0 without).

    On a noisy scan the tolerance that keeps noise from being an edge hides the creases
    (46 degrees at the White Scanner preset's noise, 60 at the INRIA one's), so there each
    pixel's lines are drawn ``s`` pixels out instead of to its nearest neighbours: the
    opposite pairs of its 8-neighbourhood stretched ``s`` times
    (:mod:`~rangesim.edges._line_rings`). For independent errors their angle noise is
    ``1 / s`` of the nearest neighbours'; how fast it really falls is measured on the scan
    (:func:`~rangesim.edges._noise.stride_gain`, the second differences of depth at each
    lag: block matching's correlated, heavy-tailed errors fall far more slowly). ``s`` is
    the least stride that brings the pixel's tolerance down to 15 degrees
    (:data:`RING_TOL_DEG`), at most ``max_stride`` and only as far as its window holds no
    invalid pixel and no depth jump; pixels whose window allows only 1 keep the
    nearest-neighbour test with the wider tolerance. A crease then marks a band about
    ``s`` px wide, thinned below, and its label is read over the stride's window. On the
    machined parts of ``benchmarks/bench_detectors.py`` (tuning seeds 0-19, with the
    presets' noise) F1 rose from 0.68 / 0.70 / 0.65 to 0.88 / 0.85 / 0.78 on white_scanner /
    cyberware_3030 / inria_laser, the creases' recall from 0.00-0.15 to 0.47-0.89.

    On a block-matched scan (structured light: the scan's sensor metadata names the matcher's
    ``window``, :func:`~rangesim.edges._matching_scale.matching_window`) with the default
    tolerance, the test runs at the matcher's scale instead (:mod:`~rangesim.edges._line_fit_sl`):
    each pixel's four compass lines reach one window out (chords skip invalid pixels, stop at
    depth jumps, at least half a window), their bends are divided by the share of a
    box-rounded crease they see (:func:`~rangesim.edges._matching_scale.rounding_gain`), a pixel
    with at least 3 lines is a crease where its second least bend exceeds 1.5 times the bend
    noise measured on the scan at that stride (over the same gain; at least 15 degrees), and
    the bands are thinned by non-maximum suppression of that strength smoothed over the
    window; ``k``, ``max_stride`` and ``workers`` are not used there. On tuning seeds 0-7 of
    the machined parts F1 rose from 0.66 / 0.61 to 0.73 / 0.71 (kinect_v1, noise-free / preset
    noise) and from 0.59 / 0.58 to 0.71 / 0.71 (structured_light_bench).

    On a scan the crease points form bands 2-3 px wide (every point within a neighbour's
    reach of the crease sees no straight line across it): with ``thin`` they are thinned to
    1 px lines (``skimage.morphology.thin`` of the crease pixels; jump pixels stay as the
    jump rule marks them), and crease pieces of fewer than ``min_crease_px`` 8-connected
    pixels are dropped: single noisy points whose neighbours happen not to line up, or
    mixed pixels beside a jump. That also drops a real crease shorter than that (a small
    chamfer seen in pieces beside a jump; on the flat machined target F1 0.79 -> 0.77),
    and gains 0.04-0.07 F1 on the machined parts of ``benchmarks/bench_detectors.py``.

    Parameters
    ----------
    points_or_scan : (N, 3) array or RangeScan
        Points (mm; non-finite rows ignored), or a scan (``xyz``, ``depth``, ``valid``).
    k : int
        Neighbours per point, an integer from 2 to :data:`MAX_K` (64; 8-12 suit: the paper's
        8-neighbourhood).
    angle_tol_deg : float, optional
        Two neighbours are opposite if the angle between their directions is within this
        many degrees of 180, in (0, 90); hence the least crease bend detected. Default (None): 15;
        for a scan whose depth noise (:func:`~rangesim.edges._noise.estimate_depth_noise`,
        ``noise`` footprints) is above :data:`~rangesim.edges._noise.NOISE_FLOOR`,
        ``atan(3 sqrt(2) noise)`` clipped to 15..60 degrees (46 at the White Scanner
        preset's 0.25: creases below that are not found, but noise is not an edge); where
        the scan carries its noise model's ``sigma``, per pixel, ``atan(2.25 sqrt(2)
        noise_p)`` with ``noise_p`` the scan's noise times the pixel's predicted noise over
        the median pixel's (:data:`NOISE_K_LINE_LOCAL`), and a pixel whose tolerance would
        exceed :data:`MAX_TOL_DEG` (60) marks no crease.
    line_sep_deg : float
        Least angle between two lines for them to count as distinct, degrees in (0, 90] (default 30; lines of
        a square grid are 45 degrees apart).
    jump_threshold : float
        The jump rule for scans, in pixel footprints, > 0 (default
        :data:`~rangesim.edges._discontinuities.JUMP_THRESHOLD` = 3.73, as the ground truth).
    max_search : int
        Pixels searched across NaN gaps for the jump rule, >= 0 (0: only direct neighbours).
    workers : int
        Threads for the k-d tree queries, >= 1 (-1: all cores).
    thin : bool
        Scans only: thin crease bands to 1 px and drop crease pieces under
        ``min_crease_px`` pixels (above).
    min_crease_px : int
        Scans only, with ``thin``: least size of a kept crease piece, pixels, >= 1 (8-connected;
        1 keeps all).
    label_creases : bool
        Scans only: label creases convex or concave by the depth of their neighbourhood
        (above); False leaves them 0, "type unknown".
    max_stride : int
        Scans only, noisy ones with the default tolerance: the longest stride of the line
        test, pixels, 1 to 255 (above; 1 tests only the nearest neighbours).
    jump_clearance : int, optional
        Scans only: no crease is kept within this many pixels (chessboard; an integer >= 0) of a jump's far
        side (the step's foot, rounded by the stripe's width), beyond the pixels that touch
        the jump (those never are).
        Default: :data:`LINE_FIT_CLEARANCE` (1), 0 on block-matched scans, whose lines skip
        gaps and stop at jumps.

    Returns
    -------
    (N,) bool array for a point list; EdgeMap for a scan
        ``method="line_fit"``; ``strength`` 1.0 at edge pixels, 0 at other valid pixels,
        NaN at invalid ones; ``direction`` None.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> edges = rs.edges.line_fit(scan)
    >>> edges.method, bool(edges.mask.any())
    ('line_fit', True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    """
    if not hasattr(points_or_scan, "xyz"):
        tol = 15.0 if angle_tol_deg is None else angle_tol_deg
        return line_fit_points(points_or_scan, k, tol, line_sep_deg, workers)
    k, line_sep_deg, workers = _line_test_params(k, line_sep_deg, workers)
    angle_tol_deg = P.number(angle_tol_deg, "angle_tol_deg", 0, 90, lo_open=True, hi_open=True, what="angle",
                             unit="degrees", none=True)
    jump_threshold, max_search = P.jump_rule(jump_threshold, max_search)
    thin = P.flag(thin, "thin")
    min_crease_px = P.whole(min_crease_px, "min_crease_px", 1, unit="pixels")
    label_creases = P.flag(label_creases, "label_creases")
    max_stride = P.whole(max_stride, "max_stride", 1, P.MAX_WINDOW_PX, unit="pixels")
    jump_clearance = P.whole(jump_clearance, "jump_clearance", 0, unit="pixels", none=True)
    scan = points_or_scan
    xyz, z, valid = scan_arrays(scan)
    noise = None
    disc, geo = discontinuities(scan, z, jump_threshold, max_search)
    tolerance: float | np.ndarray = 15.0 if angle_tol_deg is None else float(angle_tol_deg)
    stride = None
    saturated = None
    window = matching_window(scan) if angle_tol_deg is None else None
    sl_info: dict = {}
    if window is not None:
        # block-matched: the line test one matching window out (rangesim.edges._line_fit_sl)
        edge, sl_info = sl_creases(xyz, z, valid, disc.pairs, geo.footprint,
                                   geo.footprint * np.float32(jump_threshold), window)
        stride = np.where(valid, sl_info["stride"], 0).astype(np.int64)
        tolerance = sl_info["tolerance_deg"]
    elif angle_tol_deg is None:
        noise = estimate_depth_noise(scan, z, fp=geo.footprint, quantum=disc.quantum)
        if noise >= NOISE_FLOOR:
            k_noise, noise_p = _pixel_noise(scan, valid, geo.footprint, noise, disc.noise)
            gain: np.ndarray | float = 1.0
            if int(max_stride) > 1:
                gains = stride_gain(z, geo.footprint, int(max_stride), quantum=disc.quantum)
                stride = ring_strides(np.broadcast_to(noise_p, z.shape), k_noise, ~valid | disc.touching,
                                      RING_TOL_DEG, gains)
                gain = gains[np.maximum(stride, 1)]
            tolerance = _noise_tolerance(k_noise, noise_p, gain)
            if np.ndim(k_noise):  # per pixel, where the scan's sigma says how noisy each one is
                saturated = (k_noise == NOISE_K_LINE_LOCAL) & (
                    k_noise * np.sqrt(2) * noise_p * gain > np.tan(np.radians(MAX_TOL_DEG)))
    if window is None:
        edge = _point_edges(xyz, z, valid, stride, tolerance, k, line_sep_deg, workers)
        if saturated is not None:  # noise past the largest tolerance: no crease can be told from it
            edge &= ~(saturated & ~(disc.occluding | disc.rim))
    # one-sided neighbourhoods that are the image's doing: an invalid or missing neighbour
    vpad = np.pad(valid, 1, constant_values=False)
    h, w = z.shape
    cut = disc.touching.copy()
    for dr, dc in NEIGHBOURS:
        cut |= ~vpad[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
    cut &= valid
    fixed = disc.occluding | disc.rim
    if window is None:
        edge[cut] = fixed[cut]
    else:
        # the matcher's lines skip gaps and stop at jumps, so a pixel beside a gap keeps its
        # crease; jumps and rims stay the jump rule's
        edge = (edge & ~fixed) | (cut & fixed)
    if jump_clearance is None:
        # block-matched scans (whatever the tolerance): their lines skip gaps and stop at jumps
        clearance = 0 if matching_window(scan) is not None else LINE_FIT_CLEARANCE
    else:
        clearance = int(jump_clearance)
    if clearance > 0:
        # a step's rounded foot (the stripe's width spread over the step) bends the lines of
        # the pixels just beyond its far side: the jump itself, not a crease
        crease = edge & ~fixed
        edge &= ~near_mask(crease, disc.occluded, clearance)
    if thin:
        edge = _thin_creases(edge, disc.occluding | disc.rim, int(min_crease_px))
    labels = np.where(disc.occluding, EdgeLabel.JUMP, EdgeLabel.NONE).astype(np.uint8)
    if label_creases:
        crease = edge & ~disc.occluding & ~disc.rim
        labels[crease] = _crease_type(z, valid, crease, geo.footprint * np.float32(jump_threshold), stride)
    labels[disc.rim & ~disc.occluding] = RIM
    strength = np.where(valid, edge.astype(np.float32), np.float32(np.nan))
    params = {
        "k": int(k), "angle_tol_deg": float(np.median(tolerance[valid]) if np.ndim(tolerance) else tolerance), "line_sep_deg": float(line_sep_deg),
        "jump_threshold": float(jump_threshold), "max_search": int(max_search),
        "noise": None if noise is None else float(noise), "thin": bool(thin),
        "min_crease_px": int(min_crease_px), "label_creases": bool(label_creases),
        "max_stride": int(max_stride), "jump_clearance": clearance,
        "median_stride": 1.0 if stride is None else float(np.median(stride[valid])) if valid.any() else 1.0,
    }
    if window is not None:
        params.update(matching_window=int(window), bend_noise=float(sl_info["bend_noise"]))
    offset = disc.offsets_at(disc.occluding | disc.rim)
    edge = with_gap_creases(edge, labels, disc, offset)
    strength[edge & valid] = 1.0
    return EdgeMap(mask=edge & valid, labels=labels, strength=strength, method="line_fit",
                   params=params, offset=offset)


def _point_edges(xyz: np.ndarray, z: np.ndarray, valid: np.ndarray, stride: np.ndarray | None,
                 tolerance: float | np.ndarray, k: int, line_sep_deg: float, workers: int) -> np.ndarray:
    """The paper's test on a scan's pixels (H, W) bool: on the ``k`` nearest neighbours in 3D, or
    on the compass rings of pixels with a ``stride`` of 2 or more (:mod:`~._line_rings`)."""
    edge = np.zeros(z.shape, bool)
    ring = np.zeros(z.shape, bool) if stride is None else stride >= 2
    near = valid & ~ring                    # pixels tested on their nearest neighbours
    if near.any():
        p = xyz[valid].astype(np.float64)
        cos_opp = np.cos(np.radians(tolerance if np.ndim(tolerance) == 0 else tolerance[valid]))
        if len(p) > k:
            centres = np.flatnonzero(near[valid])
            edge[near] = _line_edges(p, centres, k, cos_opp, float(np.cos(np.radians(line_sep_deg))), workers)
        else:
            edge[near] = True               # too few points for any line pair
    if ring.any():
        cos_ring = np.broadcast_to(np.cos(np.radians(tolerance)), z.shape).astype(np.float32)
        edge |= ring_edges(xyz, stride, cos_ring, float(np.cos(np.radians(line_sep_deg))))
    return edge


def _thin_creases(edge: np.ndarray, fixed: np.ndarray, min_px: int) -> np.ndarray:
    """Crease bands of ``edge`` (H, W) bool thinned to 1 px, pieces under ``min_px`` dropped.

    Only the crease pixels are thinned (a crease running beside a jump, such as a small
    chamfer, is not eaten by the jump's band); ``fixed`` pixels (jumps, rims) stay as
    they are.
    """
    crease = skeleton_thin(edge & ~fixed)
    if min_px > 1 and crease.any():
        lab, n = ndimage.label(crease, structure=np.ones((3, 3), bool))
        size = np.bincount(lab.ravel(), minlength=n + 1)
        small = size < min_px
        small[0] = False
        crease &= ~small[lab]
    return crease | (edge & fixed)


def _crease_type(z: np.ndarray, valid: np.ndarray, crease: np.ndarray, jump_mm: np.ndarray,
                 radius: np.ndarray | None = None) -> np.ndarray:
    """CONVEX or CONCAVE (uint8) for each ``crease`` pixel, in ``np.flatnonzero`` order.

    Convex where the pixel's depth is below the mean depth of the valid pixels of its
    neighbourhood, ``2 r + 1`` pixels square (``r`` = 2, or the pixel's ``radius`` (H, W)
    where larger: the stride of its line test, so the depth noise averages down as the
    lines lengthen): across a roof both faces fall away from the camera, so their mean lies
    farther than the crest (a plane gives the pixel's own depth to first order).
    Neighbours farther in depth than the jump rule allows over their distance (``jump_mm``
    per pixel step, the pixel's jump threshold) lie across a depth jump and are left out.
    """
    ii, jj = np.nonzero(crease)
    r_px = np.full(ii.size, 2, np.int64) if radius is None else np.maximum(radius[ii, jj], 2).astype(np.int64)
    r = int(r_px.max()) if r_px.size else 2
    zp = np.pad(np.where(valid, z, 0.0), r)
    vp = np.pad(valid, r)
    zc, limit = z[ii, jj], jump_mm[ii, jj]
    total = np.zeros(ii.size)
    count = np.zeros(ii.size)
    for dr in range(-r, r + 1):
        for dc in range(-r, r + 1):
            ring = max(abs(dr), abs(dc))
            near = r_px >= ring
            zq = zp[ii + r + dr, jj + r + dc]
            use = near & vp[ii + r + dr, jj + r + dc] & (np.abs(zq - zc) <= ring * limit)
            total += np.where(use, zq, 0.0)
            count += use
    farther = total / np.maximum(count, 1) > zc
    return np.where(farther, EdgeLabel.CONVEX, EdgeLabel.CONCAVE).astype(np.uint8)
