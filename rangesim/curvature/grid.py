"""Per-pixel curvature of an organized range scan by local quadric fits (:mod:`.quadric`)."""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from rangesim.core import params as P
from rangesim.core.errors import RangesimError
from rangesim.curvature.quadric import fit_quadric_grid_batch

__all__ = ["curvature_scan"]

#: points (pixels x window^2) per batch: bounds the (3, window^2, n) temporaries to a few MB each
_CHUNK_VALUES = 25 << 15


def _xyz_valid(scan: Any) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) float64 points and (H, W) validity from a RangeScan or a bare array."""
    if hasattr(scan, "xyz"):
        xyz = np.asarray(scan.xyz, dtype=np.float64)
        valid = np.asarray(getattr(scan, "valid", np.ones(xyz.shape[:2], bool)), bool)
    else:
        xyz = np.asarray(scan, dtype=np.float64)
        valid = np.ones(xyz.shape[:2], bool)
    if xyz.ndim != 3 or xyz.shape[2] != 3:
        raise RangesimError(f"expected an (H, W, 3) point grid, got shape {xyz.shape}")
    return xyz, valid & np.isfinite(xyz).all(axis=2)


def curvature_scan(
    scan: Any,
    window: int = 5,
    min_points: int | None = None,
    max_dist: float | None = None,
) -> dict[str, np.ndarray]:
    """Per-pixel curvature of an organized point grid (a range scan).

    Each valid pixel's neighbourhood is the ``window`` x ``window`` block of the grid
    around it; invalid or NaN pixels in the block get weight 0 (so holes and the image
    border are handled), and a quadric is fitted in a frame whose normal is the block's
    PCA normal turned towards the camera (origin of the scan frame).

    Sign convention (see :mod:`rangesim.curvature.quadric`): normals face the camera and a
    curvature is negative where the surface bends away from the camera, so a sphere of
    radius r seen from outside gives k1 = k2 = H = -1/r, K = 1/r^2 (Besl-Jain "peak"), a
    convex cylinder k1 = 0, k2 = -1/r, and a hollow seen from inside positive values.

    Parameters
    ----------
    scan : RangeScan or (H, W, 3) array
        A RangeScan (``scan.xyz`` and ``scan.valid`` are used; camera frame, mm) or a bare
        point grid in a frame whose origin is the viewpoint, NaN for missing points.
    window : int
        Odd block size in pixels (3 to 255).
    min_points : int, optional
        Least number of valid pixels in the block; fewer gives NaN. Default: just over
        half the block (13 of 25 for ``window=5``), at least 6.
    max_dist : float, optional
        Also drop block pixels farther than this (mm, 3D) from the centre pixel, so fits
        do not straddle depth discontinuities. Default: keep all.

    Returns
    -------
    dict
        ``K`` (H, W) 1/mm^2; ``H``, ``k1``, ``k2`` (H, W) 1/mm with k1 >= k2; ``normal``,
        ``dir1``, ``dir2`` (H, W, 3) fitted unit normal (towards the camera) and principal
        directions; ``n_points`` (H, W) int valid pixels used. Float arrays are float64,
        NaN at invalid pixels and where the fit is not possible.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> curv = rs.curvature.curvature_scan(scan)
    >>> sorted(curv)[:4], curv["K"].shape
    (['H', 'K', 'dir1', 'dir2'], (120, 128))

    References
    ----------
    .. [1] P. J. Besl, R. C. Jain, "Invariant surface characteristics for 3D object recognition
       in range images", Computer Vision, Graphics, and Image Processing 33(1), 33-80 (1986),
       doi:10.1016/0734-189X(86)90220-3.
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 4.
    """
    window = P.odd_window(window, "window", none=False)
    min_points = P.whole(min_points, "min_points", 6, none=True)  # a quadric has 6 coefficients
    max_dist = P.number(max_dist, "max_dist", 0, lo_open=True, what="distance", unit="mm", none=True)
    if min_points is None:
        min_points = max(6, window * window // 2 + 1)
    xyz, valid = _xyz_valid(scan)
    h, w = valid.shape
    r = window // 2
    grid = np.where(valid[..., None], xyz, np.nan)
    padded = np.pad(grid, ((r, r), (r, r), (0, 0)), constant_values=np.nan)
    blocks = sliding_window_view(padded, (window, window), axis=(0, 1))  # (H, W, 3, win, win)

    out = {key: np.full((h, w), np.nan) for key in ("K", "H", "k1", "k2")}
    out.update({key: np.full((h, w, 3), np.nan) for key in ("normal", "dir1", "dir2")})
    out["n_points"] = np.zeros((h, w), np.int64)
    rows, cols = np.nonzero(valid)
    per_batch = max(1, _CHUNK_VALUES // (window * window))  # the batch's (3, k, n) copies stay a few MB
    for b0 in range(0, rows.size, per_batch):
        i, j = rows[b0:b0 + per_batch], cols[b0:b0 + per_batch]
        centres = grid[i, j]                                         # (n, 3)
        pts = blocks[i, j].reshape(-1, 3, window * window)           # (n, 3, k)
        pts = np.ascontiguousarray(pts.transpose(1, 2, 0))           # (3, k, n)
        weights = np.isfinite(pts).all(axis=0).astype(np.float64)
        if max_dist is not None:
            dist = np.sqrt(((pts - centres.T[:, None, :]) ** 2).sum(axis=0))
            weights[~(dist <= max_dist)] = 0.0
        fit = fit_quadric_grid_batch(centres, pts, weights, -centres, min_points)
        for key in ("K", "H", "k1", "k2", "normal", "dir1", "dir2", "n_points"):
            out[key][i, j] = fit[key]
    return out
