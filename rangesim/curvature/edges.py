"""Curvature edge points: both principal curvatures large (the paper's Fig. 12 rule)."""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from rangesim.core import params as P
from rangesim.core.errors import RangesimError

__all__ = ["curvature_edges"]


def curvature_edges(k1: ArrayLike, k2: ArrayLike, threshold: float) -> np.ndarray:
    """Edge points where the absolute values of both principal curvatures exceed a threshold.

    The rule of the founding paper (section 4, Fig. 12). It marks points curved strongly
    in every direction (corners, tips, tight blends); a straight crease or a cylinder has
    one principal curvature near 0 and is not marked. Independent of the sign convention.
    With quadric fits (:func:`~rangesim.curvature.curvature_scan`), a crease that crosses
    the window obliquely leaks some curvature into the along-crease direction (about a
    third of the corner response on a box: ~0.07 vs ~0.25 /mm for a 5 x 5 window at
    ~2 mm pixels), so set the threshold above that level.

    Parameters
    ----------
    k1, k2 : array, any (same) shape
        Principal curvatures, 1/mm: per-pixel maps (H, W) or per-vertex arrays (V,).
    threshold : float
        Curvature threshold, 1/mm (e.g. 1/5 marks points curved tighter than a 5 mm radius
        in both directions).

    Returns
    -------
    bool array, the shape of k1
        True at edge points; False where either curvature is NaN.

    Examples
    --------
    >>> from rangesim.curvature import curvature_edges
    >>> curvature_edges([0.5, 0.5, 0.01], [0.4, 0.0, 0.01], threshold=0.2).tolist()   # corner, crease, flat
    [True, False, False]

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 4.
    """
    threshold = P.number(threshold, "threshold", 0, unit="1/mm")
    try:
        k1 = np.asarray(k1, dtype=np.float64)
        k2 = np.asarray(k2, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"k1 and k2 must be arrays of curvatures (1/mm): {exc}") from None
    if k1.shape != k2.shape:
        raise RangesimError(f"k1 and k2 shapes differ: {k1.shape} vs {k2.shape}")
    with np.errstate(invalid="ignore"):
        return (np.abs(k1) > threshold) & (np.abs(k2) > threshold)
