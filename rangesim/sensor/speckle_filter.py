"""The speckle filter of a block matcher: small islands of disparity are rejected.

A block matcher accepts some wrong matches (a window over a dim, shadowed or out-of-range
surface can correlate with the wrong stretch of the reference by chance). A wrong match is
not supported by its neighbours: their windows overlap it by all but one column, yet their
disparities jump to the right surface or to other chance matches. Device pipelines therefore
drop every connected region of the disparity image smaller than a set area, where two
4-neighbours belong to one region when their disparities differ by at most a set step: the
PrimeSense firmware of a Kinect v1, OpenCV's ``filterSpeckles`` (``speckleWindowSize``,
``speckleRange`` of ``StereoSGBM``), a RealSense's speckle filter. Recorded Kinect frames show
it: the 6 mOSD frames and the PCL table-top hold no region of 6-750 px at a 2 % depth step,
one region of the scene and a few 1-3 px specks each, while matching without the filter left
0.1-0.5 % of the valid pixels of the machined parts' scans in regions under 100 px.

The step must keep a real surface in one piece: along a row the disparity of a plane seen at
incidence theta changes by about (b / z) tan(theta) px per pixel (b the baseline, z the depth),
0.8 px at 75 degrees for a 100 mm baseline at 450 mm, so the default of 2 px splits faces only
beyond atan(2 z / b) = 83.7 degrees there (beyond 87.9 degrees for a Kinect's 75 mm baseline at 1 m).
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["speckle_regions", "filter_speckles"]


def speckle_regions(disparity: np.ndarray, max_diff: float) -> np.ndarray:
    """Area of the region each valid pixel belongs to (pixels); 0 at NaN pixels.

    Parameters
    ----------
    disparity : (H, W) float
        Disparity (px), NaN where no match was accepted.
    max_diff : float
        Two 4-neighbours belong to one region when their disparities differ by at most this (px).

    Returns
    -------
    area : (H, W) int64

    Examples
    --------
    >>> d = np.full((3, 4), 10.0); d[1, 1] = 30.0; d[2, 3] = np.nan
    >>> speckle_regions(d, 1.0).tolist()
    [[10, 10, 10, 10], [10, 1, 10, 10], [10, 10, 10, 0]]
    """
    d = np.ascontiguousarray(disparity, np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity must be an (H, W) image, got shape {d.shape}")
    return _region_areas(d, float(max_diff))


@numba.njit(cache=True, nogil=True)
def _find(parent, i):  # pragma: no cover - compiled
    """Root of ``i``, halving the path on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(cache=True, nogil=True)
def _region_areas(d, max_diff):  # pragma: no cover - compiled
    """Union-find over the 4-neighbour pairs within ``max_diff``, then each pixel's region area
    (0 at NaN): one pass over the pairs, one over the pixels."""
    h, w = d.shape
    n = h * w
    parent = np.arange(n)
    flat = d.ravel()
    for i in range(h):
        for j in range(w):
            k = i * w + j
            v = flat[k]
            if v != v:
                continue
            if j + 1 < w:
                u = flat[k + 1]
                if u == u and abs(v - u) <= max_diff:
                    a, b = _find(parent, k), _find(parent, k + 1)
                    if a != b:
                        parent[max(a, b)] = min(a, b)
            if i + 1 < h:
                u = flat[k + w]
                if u == u and abs(v - u) <= max_diff:
                    a, b = _find(parent, k), _find(parent, k + w)
                    if a != b:
                        parent[max(a, b)] = min(a, b)
    count = np.zeros(n, np.int64)
    for k in range(n):
        if flat[k] == flat[k]:
            count[_find(parent, k)] += 1
    area = np.zeros(n, np.int64)
    for k in range(n):
        if flat[k] == flat[k]:
            area[k] = count[_find(parent, k)]
    return area.reshape(h, w)


def filter_speckles(disparity: np.ndarray, max_size: int, max_diff: float) -> np.ndarray:
    """Pixels of regions smaller than ``max_size`` px (see the module docstring): the ones to reject.

    Parameters
    ----------
    disparity : (H, W) float
        Disparity (px), NaN where no match was accepted.
    max_size : int
        Regions of fewer pixels than this are speckles; 0 turns the filter off.
    max_diff : float
        Largest disparity step (px) between 4-neighbours of one region.

    Returns
    -------
    speckle : (H, W) bool
        Valid pixels in a region under ``max_size`` pixels.

    Examples
    --------
    >>> d = np.full((20, 20), 50.0); d[5:7, 5:7] = 80.0  # a 4 px island of wrong matches
    >>> int(filter_speckles(d, 10, 2.0).sum()), int(filter_speckles(d, 4, 2.0).sum())
    (4, 0)
    """
    if max_size <= 0:
        return np.zeros(np.shape(disparity), bool)
    area = speckle_regions(disparity, max_diff)
    return (area > 0) & (area < max_size)
