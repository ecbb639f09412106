"""Shared helpers of the feature finders: edge points with their edge-normal directions, and
the angular coverage of a circle by points (image coordinates: x = column, y = row, integers
at pixel centres). The circle and conic fits are in :mod:`rangesim.core.conics`."""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage


def edge_points(edge_map: Any, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Edge pixels and their edge-normal directions.

    Parameters
    ----------
    edge_map : EdgeMap or (H, W) bool array
    keep : (H, W) bool, optional
        Extra mask of the pixels to use.

    Returns
    -------
    xy : (N, 2) float64
        (x = column, y = row) of the edge pixels, pixels.
    theta : (N,) float64
        Direction across the edge, radians: ``edge_map.direction`` where given, else the
        direction of the gradient of the Gaussian-smoothed mask (sigma 1.5 px).
    """
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    if keep is not None:
        mask = mask & keep
    rows, cols = np.nonzero(mask)
    direction = getattr(edge_map, "direction", None)
    if direction is not None:
        theta = np.asarray(direction, np.float64)[rows, cols]
    else:
        theta = np.full(len(rows), np.nan)
    bad = ~np.isfinite(theta)
    if bad.any():
        # structure-tensor orientation of the mask: the normal to the local line of edge pixels
        m = np.asarray(getattr(edge_map, "mask", edge_map), np.float64)
        gx = ndimage.sobel(m, axis=1)
        gy = ndimage.sobel(m, axis=0)
        jxx, jyy, jxy = (ndimage.gaussian_filter(a, 1.5) for a in (gx * gx, gy * gy, gx * gy))
        orient = 0.5 * np.arctan2(2 * jxy, jxx - jyy)  # dominant gradient orientation
        theta[bad] = orient[rows[bad], cols[bad]]
    return np.column_stack([cols, rows]).astype(np.float64), theta


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
        Fraction of bins holding a point, 0..1.
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
