"""Shared helpers of the feature finders: edge points with their edge-normal directions, and
the angular coverage of a circle by points (image coordinates: x = column, y = row, integers
at pixel centres). The circle and conic fits are in :mod:`rangesim.core.conics`."""
from __future__ import annotations

from typing import Any

import numpy as np


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
        normal to the local line of edge pixels (:func:`mask_normals`).
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
        full = np.asarray(getattr(edge_map, "mask", edge_map), bool)
        theta[bad] = mask_normals(full, rows[bad], cols[bad])
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


_R = 2  # half-width of the mask_normals window, px
_OFF = [(dy, dx) for dy in range(-_R, _R + 1) for dx in range(-_R, _R + 1) if (dy, dx) != (0, 0)]


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
    H, W = mask.shape
    Wp = W + 2 * _R
    pm = np.zeros((H + 2 * _R, Wp), np.float32)
    pm[_R:_R + H, _R:_R + W] = mask
    flat = pm.ravel()
    base = (rows + _R) * Wp + cols + _R
    sxx = np.zeros(len(rows), np.float32)
    syy = np.zeros(len(rows), np.float32)
    sxy = np.zeros(len(rows), np.float32)
    for dy, dx in _OFF:
        m = flat[base + (dy * Wp + dx)]
        w = np.float32(np.exp(-(dx * dx + dy * dy) / (2 * 1.5 ** 2)))
        m *= w
        sxx += m * np.float32(dx * dx)
        syy += m * np.float32(dy * dy)
        sxy += m * np.float32(dx * dy)
    tangent = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    return (tangent.astype(np.float64) + np.pi / 2 + np.pi / 2) % np.pi - np.pi / 2
