"""Shared helpers of the feature finders: edge points with their edge-normal directions, and
the angular coverage of a circle by points (image coordinates: x = column, y = row, integers
at pixel centres). The circle and conic fits are in :mod:`rangesim.core.conics`."""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.edges.edgemap import check_offsets


def edge_mask(edge_map: Any, keep: np.ndarray | None = None) -> np.ndarray:
    """The (H, W) bool mask of an edge map (an EdgeMap or a bare mask), times ``keep``.

    Raises :class:`RangesimError` for anything that is not a 2-D image, and for a ``keep``
    of another shape.
    """
    mask = np.asarray(getattr(edge_map, "mask", edge_map))
    if mask.ndim != 2 or mask.dtype.kind not in "biuf":
        raise RangesimError(f"must be an EdgeMap or an (H, W) bool mask, got {type(edge_map).__name__} of shape "
                            f"{mask.shape}" + ("" if mask.dtype.kind in "biufO" else f" and dtype {mask.dtype}"),
                            "edge_map")
    if mask.dtype.kind == "f":
        mask = np.nan_to_num(mask, nan=0.0)  # NaN is no value, so no edge
    mask = mask.astype(bool, copy=False)
    if keep is not None:
        keep = np.asarray(keep)
        if keep.shape != mask.shape:
            raise RangesimError(f"has shape {keep.shape}, the edge map {mask.shape}", "keep")
        mask = mask & keep.astype(bool, copy=False)
    return mask


def check_scan_shape(scan: Any, mask: np.ndarray) -> None:
    """A scan passed with an edge map must be the one it was detected on (same H x W)."""
    shape = tuple(np.shape(getattr(scan, "depth", None)))
    if shape != mask.shape:
        raise RangesimError(f"is {'x'.join(map(str, shape)) or 'no RangeScan'}, the edge map "
                            f"{mask.shape[0]}x{mask.shape[1]}: pass the scan the edges were found on", "scan")


def check_range(values: Any, name: str, what: str = "pixels") -> tuple[float, float]:
    """``(min, max)`` of a range parameter (radii, axes) as two finite floats, 0 <= min <= max."""
    try:
        if isinstance(values, (str, bytes)):
            raise TypeError("not numbers")
        values = tuple(values)  # (a generator is read once)
        if any(isinstance(v, (bool, np.bool_)) for v in values):
            raise TypeError("not numbers")  # (True would pass as 1.0)
        lo, hi = (float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"must be two numbers (min, max), {what}; got {values!r}", name) from exc
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo <= hi):
        raise RangesimError(f"must be two finite numbers 0 <= min <= max, {what}; got {values!r}", name)
    return lo, hi


def edge_points(edge_map: Any, keep: np.ndarray | None = None, *,
                return_pixels: bool = False) -> tuple[np.ndarray, ...]:
    """Edge points (where the edges lie, to a fraction of a pixel) and their edge-normal directions.

    Parameters
    ----------
    edge_map : EdgeMap or (H, W) bool array
    keep : (H, W) bool, optional
        Extra mask of the pixels to use.
    return_pixels : bool
        Also return the edge pixels themselves.

    Returns
    -------
    xy : (N, 2) float64
        (x = column, y = row) of the edge points, pixels: the edge pixels' centres moved by
        ``edge_map.offset`` where the detector gives one (half a pixel spacing towards the
        far side at jumps), else the centres.
    theta : (N,) float64
        Direction across the edge, radians: ``edge_map.direction`` where given, else the
        normal to the local line of edge pixels (:func:`mask_normals`).
    pixels : (N, 2) int64
        (column, row) of each point's pixel; only with ``return_pixels``.
    """
    mask = edge_mask(edge_map, keep)
    flat = np.flatnonzero(mask)
    rows, cols = np.divmod(flat, mask.shape[1])  # 5x faster than 2D np.nonzero
    direction = getattr(edge_map, "direction", None)
    if direction is not None:
        theta = np.asarray(direction, np.float64)[rows, cols]
    else:
        theta = np.full(len(rows), np.nan)
    bad = ~np.isfinite(theta)
    if bad.any():
        full = mask if keep is None else edge_mask(edge_map)
        theta[bad] = mask_normals(full, rows[bad], cols[bad])
    pixels = np.column_stack([cols, rows])
    xy = pixels.astype(np.float64)
    offset = getattr(edge_map, "offset", None)
    if offset is not None:
        moved = np.asarray(offset).reshape(-1, 2)[flat]
        check_offsets(moved)  # again: the map may have been changed since it was made
        xy += moved
    return (xy, theta, pixels) if return_pixels else (xy, theta)


def point_labels(edge_map: Any, pixels: np.ndarray) -> np.ndarray | None:
    """(N,) uint8 :class:`~rangesim.core.constants.EdgeLabel` of the edge points at ``pixels``
    (N, 2) (column, row); None for a bare mask, which has none."""
    labels = getattr(edge_map, "labels", None)
    if labels is None:
        return None
    return np.asarray(labels)[pixels[:, 1], pixels[:, 0]]


def one_edge(labels: np.ndarray | None, points: np.ndarray) -> np.ndarray:
    """The points (indices into ``labels``) of a round feature's own edge.

    A rim is one edge all round: concave (a blind hole's floor, a boss's foot), or convex and
    occluding (a hole's top, a boss's top; where it is an occluding contour, its jump pixels).
    A concave edge never occludes: the material on either side stands in front of whatever
    lies beyond. So the supporting points of one circle or ellipse that are of the other
    kind than most of its labelled ones (jump, convex, concave or rim) belong to another
    edge: a rim's neighbour within a pixel or two (a hole's wall meeting the floor below its
    top), or the other half of a ghost made of two rims (a boss top's far arc and its
    foot's near arc). Those are left out; untyped points (label 0) are kept. Without labels
    (a bare mask) all points are kept. (The circle finder's claim loop applies the same rule
    inside its compiled kernel, :func:`rangesim.features._circle_kernels.claim`.)
    """
    if labels is None or len(points) == 0:
        return points
    lab = np.asarray(labels)[points]
    concave = lab == EdgeLabel.CONCAVE
    other = (lab != EdgeLabel.NONE) & ~concave
    n_concave, n_other = np.count_nonzero(concave), np.count_nonzero(other)
    if n_concave == 0 or n_other == 0:
        return points
    return points[~other] if n_concave > n_other else points[~concave]


def angular_coverage(angles: np.ndarray, n_bins: int) -> tuple[float, float, float]:
    """Coverage of a circle by point angles, and the longest covered run.

    Parameters
    ----------
    angles : (N,) float, radians
    n_bins : int
        Bins around the circle (about one per pixel of circumference).

    Returns
    -------
    coverage : float
        Fraction of bins holding a point, 0..1 (the circles' support: a thin 8-connected
        circle, whose pixels lie up to sqrt(2) px apart along it, covers 0.86-0.94).
    start, end : float
        Start and end angles (radians, counter-clockwise in image x-y, i.e. from +x towards
        +y) of the longest run of occupied bins.
    """
    n_bins = max(int(n_bins), 8)
    idx = np.floor((np.mod(angles, 2 * np.pi)) / (2 * np.pi) * n_bins).astype(int) % n_bins
    occ = np.zeros(n_bins, bool)
    occ[idx] = True
    cov = float(occ.mean())
    if occ.all():
        return 1.0, 0.0, 2 * np.pi
    if not occ.any():
        return 0.0, 0.0, 0.0
    # longest circular run of True: rotate so that the array starts at an empty bin
    shift = int(np.argmin(occ))
    r = np.roll(occ, -shift)
    padded = np.concatenate([[False], r, [False]]).astype(np.int8)
    dif = np.diff(padded)
    starts, ends = np.nonzero(dif == 1)[0], np.nonzero(dif == -1)[0]
    k = int(np.argmax(ends - starts))
    step = 2 * np.pi / n_bins
    s = ((starts[k] + shift) % n_bins) * step
    e = s + (ends[k] - starts[k]) * step
    return cov, float(s), float(e)


_R = 2  # half-width of the mask_normals window, px


def mask_normals(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Edge normals of mask pixels from the spread of their neighbouring edge pixels.

    The second moments of the edge pixels in the 5 x 5 window around each pixel (Gaussian
    weights, sigma 1.5 px) give the local line's direction (principal axis); the normal is
    perpendicular to it. Only the given pixels are visited (work proportional to their
    number, not to the image), unlike a dense structure tensor.

    Parameters
    ----------
    mask : (H, W) bool
    rows, cols : (N,) int
        Pixels to evaluate.

    Returns
    -------
    (N,) float64
        Normal angles, radians in [-pi/2, pi/2) (the sense is undetermined); isolated
        pixels get 0.
    """
    g = np.arange(-_R, _R + 1, dtype=np.float64)
    dy, dx = np.meshgrid(g, g, indexing="ij")
    w = np.exp(-(dx ** 2 + dy ** 2) / (2 * 1.5 ** 2))
    return _mask_normals(np.ascontiguousarray(mask, np.bool_).view(np.uint8), np.asarray(rows, np.int64),
                         np.asarray(cols, np.int64), w * dx * dx, w * dy * dy, w * dx * dy)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _mask_normals(mask, rows, cols, wxx, wyy, wxy):  # pragma: no cover - compiled
    H, W = mask.shape
    out = np.empty(len(rows))
    for n in range(len(rows)):
        r, c = rows[n], cols[n]
        sxx = syy = sxy = 0.0
        if _R <= r < H - _R and _R <= c < W - _R:  # no bounds tests inside the image
            for i in range(2 * _R + 1):
                for j in range(2 * _R + 1):
                    m = mask[r + i - _R, c + j - _R]
                    sxx += m * wxx[i, j]
                    syy += m * wyy[i, j]
                    sxy += m * wxy[i, j]
        else:
            for i in range(2 * _R + 1):
                for j in range(2 * _R + 1):
                    y, x = r + i - _R, c + j - _R
                    if 0 <= y < H and 0 <= x < W and mask[y, x]:
                        sxx += wxx[i, j]
                        syy += wyy[i, j]
                        sxy += wxy[i, j]
        # (tangent + pi) mod pi - pi / 2, with the modulo as one exact subtraction (Sterbenz)
        v = 0.5 * np.arctan2(2 * sxy, sxx - syy) + np.pi
        out[n] = (v - np.pi if v >= np.pi else v) - np.pi / 2
    return out
