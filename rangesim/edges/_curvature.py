"""Curvature edge points on scans: both principal curvatures large (the paper's Fig. 12 rule)."""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.core.constants import EdgeLabel
from rangesim.curvature import curvature_edges, curvature_scan
from rangesim.edges._discontinuities import JUMP_THRESHOLD, discontinuities
from rangesim.edges._grid import pad_last2, padded_view
from rangesim.edges._scan_access import scan_depth
from rangesim.edges.edgemap import RIM, EdgeMap

__all__ = ["curvature"]

#: default threshold as a multiple of 1 / (window // 2 * footprint): a 90 degree corner in
#: the fit window gives about 1.0, a straight crease crossing it obliquely leaks about 0.3
#: into its small principal curvature (see rangesim.curvature.curvature_edges)
DEFAULT_RELATIVE_THRESHOLD = 0.5


def curvature(
    scan: Any,
    threshold: float | None = None,
    window: int = 5,
    jump_threshold: float = JUMP_THRESHOLD,
    max_search: int = 50,
) -> EdgeMap:
    """Edge points where both principal curvatures are large, with convex/concave labels.

    The rule of the founding paper's Fig. 12 on per-pixel quadric fits
    (:func:`rangesim.curvature.curvature_scan`, ``window`` x ``window`` blocks, NaN-aware)
    and :func:`rangesim.curvature.curvature_edges`: ``|k1| > threshold`` and
    ``|k2| > threshold``. It marks corners, tips and tight doubly-curved blends; a straight
    crease (one principal curvature ~0) is, by design, not marked, except where the fit
    leaks curvature into the along-crease direction.

    Type from the mean curvature, in :mod:`rangesim.curvature`'s convention (normal towards
    the camera, positive where the surface bends towards it): H < 0 convex, H > 0 concave.
    Jumps: :func:`~rangesim.edges._discontinuities.find_discontinuities` (steps deeper than
    ``jump_threshold`` pixel footprints, searched across NaN gaps), JUMP on the near side;
    curvature points whose fit window contains a discontinuity are dropped (a fit across a
    step is not a surface).

    Parameters
    ----------
    scan : RangeScan
        Uses ``xyz``, ``depth``, ``valid`` (mm, camera frame) and ``meta["K"]`` for the
        footprint (without it, see :func:`~rangesim.edges._scan_access.pixel_geometry`).
    threshold : float, optional
        Curvature threshold, 1/mm. Default (None): range-adaptive, ``0.5 / (window // 2 *
        footprint)`` per pixel (``footprint = z / f`` mm per pixel): a fit over a block of
        half-width R = ``window // 2 * footprint`` mm cannot resolve radii below ~R, and a
        90 degree corner responds with ~1 / R in both directions, a crease leaks ~0.3 / R.
    window : int
        Odd fit-block size, pixels (>= 3).
    jump_threshold : float
        Depth-discontinuity threshold in pixel footprints: neighbours whose depths differ by
        more than this many footprints (``z / f`` mm) are a jump. Default
        :data:`~rangesim.edges._discontinuities.JUMP_THRESHOLD` = cot(15 deg) = 3.73, the ground
        truth's rule (a continuous surface jumps only beyond 75 degrees slant); for a pinhole
        camera it is ``jump_threshold / f`` times the depth (PCL's 0.02 z is 0.02 f).
    max_search : int
        Pixels searched across NaN gaps for the jump rule (0: only direct neighbours).

    Returns
    -------
    EdgeMap
        ``method="curvature"``; ``strength`` is ``min(|k1|, |k2|)`` in 1/mm (NaN where the
        fit failed); ``labels`` CONVEX/CONCAVE/JUMP; ``direction`` None.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> edges = rs.edges.curvature(scan)
    >>> edges.method, bool(edges.mask.any())
    ('curvature', True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    .. [2] P. J. Besl, R. C. Jain, "Invariant surface characteristics for 3D object recognition
       in range images", Computer Vision, Graphics, and Image Processing 33(1), 33-80 (1986),
       doi:10.1016/0734-189X(86)90220-3.
    """
    window = int(window)
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 3, got {window}")
    r = window // 2
    z, valid = scan_depth(scan)
    disc, geo = discontinuities(scan, z, jump_threshold, max_search)
    curv = curvature_scan(scan, window=window)
    k1, k2, mean = curv["k1"], curv["k2"], curv["H"]
    if threshold is None:
        fp = geo.footprint
        scale = (r * fp).astype(np.float64)           # curvature in units of 1 / R
        points = curvature_edges(k1 * scale, k2 * scale, DEFAULT_RELATIVE_THRESHOLD)
    else:
        points = curvature_edges(k1, k2, float(threshold))
    # drop fits whose block holds a discontinuity (either side of one)
    touching = pad_last2(disc.touching, r, False)
    near_jump = np.zeros(z.shape, bool)
    for dr in range(-r, r + 1):
        for dc in range(-r, r + 1):
            near_jump |= padded_view(touching, r, dr, dc, z.shape)
    points &= ~near_jump
    with np.errstate(invalid="ignore"):
        labels = np.where(mean > 0, EdgeLabel.CONCAVE, EdgeLabel.CONVEX).astype(np.uint8)
    jump = disc.occluding
    labels[disc.rim] = RIM
    labels[jump] = EdgeLabel.JUMP
    strength = np.fmin(np.abs(k1), np.abs(k2))
    params = {
        "threshold": None if threshold is None else float(threshold),
        "relative_threshold": DEFAULT_RELATIVE_THRESHOLD if threshold is None else None,
        "window": window, "jump_threshold": float(jump_threshold), "max_search": int(max_search),
    }
    return EdgeMap(mask=(points | jump | disc.rim) & valid, labels=labels, strength=strength,
                   method="curvature", params=params)
