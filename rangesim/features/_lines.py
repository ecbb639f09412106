"""Straight line segments: Hough transform for lines, then segments along each line."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from skimage.transform import hough_line

from rangesim.core import params as P
from rangesim.features._edge_points import check_scan_shape, edge_mask, edge_points, mask_normals
from rangesim.features._feature_lists import feature_list
from rangesim.features._line_kernels import suppress_near, window_maxima

#: along a line, neighbouring pixels lie up to sqrt(2) px apart: a smaller ``max_gap`` still
#: never cuts between them
NEIGHBOUR_PX = 1.5
#: default ``max_gap`` of :func:`lines`, px: 3 until the machined parts' benchmark, whose
#: laser-stripe outlines at 25-40 degrees leave a pixel unaligned at every step of their
#: staircase, 4-5 px apart (tuning seeds 0-7, inria_laser 20-29: 3 / 4 / 5 / 6 px found 0.485 /
#: 0.522 / 0.535 / 0.549 of the segments of 30 px or more with both ends within 5 px; the
#: least gap that bridges the staircase's 4-5 px was taken, as a longer one joins more pieces
#: of different edges that share a line)
MAX_GAP_PX = 5.0


@dataclass(frozen=True)
class Segment:
    """A straight segment in the image.

    Attributes
    ----------
    start, end : (x, y) float, pixels (x = column, y = row)
    length : float, pixels
    length_mm : float or None
        3D distance between the back-projected end points (nearest valid pixel of
        ``scan.xyz``), mm; None without a scan.
    n_points : int
        Edge pixels supporting it.
    residual : float
        RMS distance of those pixels to the line, pixels.
    """

    start: tuple[float, float]
    end: tuple[float, float]
    length: float
    length_mm: float | None
    n_points: int
    residual: float


def back_project(scan: Any, xy: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points (mm) of image positions, from the nearest valid pixel of
    ``scan.xyz``; NaN when the scan has no valid pixel."""
    valid = np.asarray(scan.valid, bool) & np.isfinite(np.asarray(scan.xyz)).all(-1)
    if not valid.any():
        return np.full((len(xy), 3), np.nan)
    _, (ri, ci) = ndimage.distance_transform_edt(~valid, return_indices=True)
    H, W = valid.shape
    r = np.clip(np.rint(xy[:, 1]).astype(int), 0, H - 1)
    c = np.clip(np.rint(xy[:, 0]).astype(int), 0, W - 1)
    return np.asarray(scan.xyz, float)[ri[r, c], ci[r, c]]


def lines(
    edge_map: Any,
    scan: Any = None,
    *,
    min_length: float = 30.0,
    max_gap: float = MAX_GAP_PX,
    band_px: float = 1.5,
    angle_tol_deg: float = 15.0,
    threshold: int | None = None,
    max_lines: int = 200,
    keep: np.ndarray | None = None,
) -> list[Segment]:
    """Line segments of an edge map.

    Steps: Hough transform of the edge pixels (``skimage.transform.hough_line``, 0.5 degree
    steps), peaks (:func:`_line_peaks`: local maxima, strongest first, 3 bins apart); for each line, strongest first, the unused edge
    pixels within ``band_px`` of it that are aligned with it are split at gaps longer than
    ``max_gap`` pixels (never between neighbouring pixels, up to sqrt(2) px apart); runs at least ``min_length`` long are refitted (total least squares)
    and become segments; their pixels are used up. A pixel is aligned when its edge direction
    or the direction of the local line of edge pixels around it
    (:func:`~rangesim.features._edge_points.mask_normals`, 5 x 5) is within ``angle_tol_deg``
    of the line's normal: a detector's direction is that of a 3 x 3 neighbourhood (on
    block-matched scans averaged over the matcher's window), which on
    a digital line at 30 degrees swings by 15-30 degrees at each step of the staircase (the
    line would break every 4-5 px), while the local line follows it within a few degrees;
    where the 5 x 5 window holds a corner or a crossing, the detector's direction still can.

    Parameters
    ----------
    edge_map : EdgeMap or (H, W) bool
    scan : RangeScan, optional
        For the lengths in mm.
    min_length : float, pixels
    max_gap : float, pixels
    band_px : float, pixels
        At least 0.5 (a digitised line's pixels lie up to half a pixel about it).
    angle_tol_deg : float, degrees
    threshold : int, optional
        Least Hough votes of a line (default ``min_length / 2``).
    max_lines : int
    keep : (H, W) bool, optional
        Only these edge pixels are used.

    Returns
    -------
    list of Segment, longest first.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> segments = rs.features.lines(rs.edges.gradient(scan), scan)
    >>> len(segments) >= 4, all(s.length_mm > 20 for s in segments)    # the plate's outline
    (True, True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    .. [2] R. O. Duda, P. E. Hart, "Use of the Hough transformation to detect lines and curves
       in pictures", Communications of the ACM 15(1), 11-15 (1972), doi:10.1145/361237.361242.
    """
    for name, value in (("min_length", min_length), ("max_gap", max_gap)):
        P.number(value, name, 0, unit="pixels")
    # a digitised line's pixels lie up to half a pixel about it: a narrower band holds none
    P.number(band_px, "band_px", 0.5, unit="pixels")
    P.number(angle_tol_deg, "angle_tol_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    P.whole(max_lines, "max_lines", 1)
    P.number(threshold, "threshold", 0, none=True)  # 0 or None: min_length / 2
    mask = edge_mask(edge_map, keep)
    if scan is not None:
        check_scan_shape(scan, mask)
    xy, theta, pixels = edge_points(edge_map, keep, return_pixels=True)
    if len(xy) < 2:
        return []
    # the local line of edge pixels, the second opinion where the map has directions of its
    # own (where it has none, edge_points gave that already)
    has_direction = getattr(edge_map, "direction", None) is not None
    local = mask_normals(mask, pixels[:, 1], pixels[:, 0]) if has_direction else theta
    angles = np.deg2rad(np.arange(-90, 90, 0.5))
    acc, ang, dist = hough_line(mask, angles)
    # a line has at least one vote: a threshold of 0 (min_length=0) would make every empty cell a peak
    pa, pd = _line_peaks(acc, ang, dist, 3, 3, max(threshold or min_length / 2, 1), max_lines)
    used = np.zeros(len(xy), bool)
    cos_tol = np.cos(np.deg2rad(angle_tol_deg))
    # (start, end, points, rms, its two end pixels)
    out: list[tuple[np.ndarray, np.ndarray, int, float, np.ndarray]] = []
    for a, d in zip(pa, pd):
        n = np.array([np.cos(a), np.sin(a)])  # skimage: d = x cos a + y sin a
        off = pixels @ n - d  # the band about the peak, of the pixels it was voted by; fits to xy
        idx = np.nonzero((np.abs(off) <= band_px) & ~used)[0]
        idx = idx[(np.abs(np.cos(theta[idx] - a)) >= cos_tol) | (np.abs(np.cos(local[idx] - a)) >= cos_tol)]
        if len(idx) < min_length / 2:
            continue
        t = xy[idx] @ np.array([-n[1], n[0]])
        o = np.argsort(t)
        idx, t = idx[o], t[o]
        cuts = np.nonzero(np.diff(t) > max(max_gap, NEIGHBOUR_PX))[0] + 1
        for run in np.split(np.arange(len(idx)), cuts):
            if len(run) < 2 or t[run[-1]] - t[run[0]] < min_length - 1e-9:  # (a 30.0 px run projects to 29.999...)
                continue
            p = xy[idx[run]]
            m = p.mean(0)
            _, _, vt = np.linalg.svd(p - m, full_matrices=False)
            u = vt[0]
            s = (p - m) @ u
            res = (p - m) @ vt[1]
            rms = float(np.sqrt(np.mean(res ** 2)))
            if rms > band_px:
                continue
            # with its own end pixels, where its length in mm is measured: an edge pixel lies on the
            # surface the edge bounds (a jump's near side), a fitted end point may round beyond it
            out.append((m + s.min() * u, m + s.max() * u, len(run), rms, p[[np.argmin(s), np.argmax(s)]]))
            used[idx[run]] = True
    mm = None
    if scan is not None and len(out):
        ends3d = back_project(scan, np.concatenate([e for *_, e in out])).reshape(-1, 2, 3)
        mm = np.linalg.norm(ends3d[:, 1] - ends3d[:, 0], axis=1)
    segs = [
        Segment((float(a[0]), float(a[1])), (float(b[0]), float(b[1])), float(np.hypot(*(b - a))),
                None if mm is None or not np.isfinite(mm[k]) else float(mm[k]), n, rms)
        for k, (a, b, n, rms, _) in enumerate(out)
    ]
    segs.sort(key=lambda s: -s.length)
    return segs


def _line_peaks(acc: np.ndarray, angles: np.ndarray, dists: np.ndarray, min_distance: int, min_angle: int,
                threshold: float, num_peaks: int) -> tuple[np.ndarray, np.ndarray]:
    """Peaks of a (distance, angle) line accumulator: local maxima over (2 min_distance + 1) x
    (2 min_angle + 1) bins at least ``threshold``, strongest first, each at least that many bins
    from a stronger one; at most ``num_peaks``. Returns their angles and distances.

    Takes the place of ``skimage.transform.hough_line_peaks``, which labels every region above
    the threshold (most of the run time on an edge map of a part).
    """
    di, ai = window_maxima(acc, float(threshold), int(min_distance), int(min_angle))
    order = np.argsort(-acc[di, ai].astype(np.int64), kind="stable")  # hough_line's counts are unsigned
    di, ai = di[order], ai[order]
    k = suppress_near(di, ai, int(min_distance), int(min_angle), int(num_peaks))
    return angles[ai[k]], dists[di[k]]


def segment_pairs(segments: list[Segment]) -> tuple[np.ndarray, np.ndarray]:
    """Minimum distance and angle between every pair of segments, vectorised.

    Returns
    -------
    distance : (N, N) float, pixels
        0 where two segments cross.
    angle : (N, N) float, degrees in [0, 90]
        Angle between the lines.
    """
    segments = feature_list(segments, "segments", ("start", "end"), "segment_pairs")
    if not segments:
        return np.zeros((0, 0)), np.zeros((0, 0))
    A = np.array([s.start for s in segments], float)
    B = np.array([s.end for s in segments], float)

    def point_seg(P, a, b):  # P (N,2) against segments a,b (M,2) -> (N, M)
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(1), 1e-12)
        t = np.clip(((P[:, None] - a[None]) * ab[None]).sum(-1) / L2[None], 0, 1)
        return np.linalg.norm(P[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1)

    d = np.minimum.reduce([point_seg(A, A, B), point_seg(B, A, B), point_seg(A, A, B).T, point_seg(B, A, B).T])

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    r, s_ = B - A, B - A
    den = cross(r[:, None], s_[None])
    qp = A[None] - A[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(qp, s_[None]) / den
        u = cross(qp, r[:, None]) / den
    crossing = (np.abs(den) > 1e-12) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    d[crossing] = 0.0
    ang = np.arctan2(r[:, 1], r[:, 0])
    diff = np.abs(ang[:, None] - ang[None]) % np.pi
    return d, np.rad2deg(np.minimum(diff, np.pi - diff))
