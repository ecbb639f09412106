"""Besl-Jain HK sign map: eight surface types from the signs of K and H."""
from __future__ import annotations

from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike

from rangesim.core import params as P
from rangesim.core.errors import RangesimError

__all__ = ["SurfaceType", "hk_sign_map", "surface_type_name", "SURFACE_TYPE_NAMES"]


class SurfaceType(IntEnum):
    """Labels of :func:`hk_sign_map`; the values are Besl and Jain's type numbers
    T = 1 + 3 (1 + sgn H) + (1 - sgn K), with 0 for pixels without curvature.

    Sign convention (that of :mod:`rangesim.curvature.quadric`): H is measured against the
    normal facing the viewer (scans) or pointing out of the solid (meshes), negative where
    the surface bends away from it, so a convex cap (a sphere seen from outside) is a PEAK.
    """

    UNDEFINED = 0       #: K or H is NaN (invalid pixel, failed fit)
    PEAK = 1            #: K > 0, H < 0 (convex cap)
    RIDGE = 2           #: K = 0, H < 0 (convex cylinder)
    SADDLE_RIDGE = 3    #: K < 0, H < 0
    IMPOSSIBLE = 4      #: K > 0, H = 0: cannot occur (H^2 >= K); reachable only if eps_K < eps_H^2
    FLAT = 5            #: K = 0, H = 0 (plane)
    MINIMAL = 6         #: K < 0, H = 0 (minimal surface)
    PIT = 7             #: K > 0, H > 0 (concave cap, a bowl seen from inside)
    VALLEY = 8          #: K = 0, H > 0 (concave cylinder)
    SADDLE_VALLEY = 9   #: K < 0, H > 0


#: label value -> lower-case name ("saddle ridge", ...)
SURFACE_TYPE_NAMES: dict[int, str] = {
    int(t): t.name.lower().replace("_", " ") for t in SurfaceType
} | {int(SurfaceType.MINIMAL): "minimal surface"}


def surface_type_name(label: int) -> str:
    """Name of a :class:`SurfaceType` label, e.g. ``surface_type_name(1) == "peak"``."""
    if label not in SURFACE_TYPE_NAMES:
        raise RangesimError(f"no surface type {label!r}; the labels are {min(SURFACE_TYPE_NAMES)}-{max(SURFACE_TYPE_NAMES)}")
    return SURFACE_TYPE_NAMES[int(label)]


def hk_sign_map(
    K: ArrayLike, H: ArrayLike, eps_K: float = 1e-5, eps_H: float = 1e-3
) -> np.ndarray:
    """Besl-Jain surface-type labels from Gaussian and mean curvature.

    ``sgn_eps(v) = 0`` where ``|v| <= eps``, else the sign of v; the label is
    ``1 + 3 (1 + sgn_eps(H)) + (1 - sgn_eps(K))`` (see :class:`SurfaceType`).

    Parameters
    ----------
    K : array, any shape
        Gaussian curvature, 1/mm^2 (per pixel (H, W) or per vertex (V,)).
    H : array, same shape
        Mean curvature, 1/mm, with the sign convention of :mod:`rangesim.curvature.quadric`
        (negative on convex surfaces seen from outside / from the camera).
    eps_K : float
        Zero band for K, 1/mm^2. The default 1e-5 treats radii above ~316 mm as flat in K.
    eps_H : float
        Zero band for H, 1/mm. The default 1e-3 treats a cylinder of radius > 500 mm as flat.
        With ``eps_K >= eps_H**2`` (the defaults) IMPOSSIBLE never occurs, since H^2 >= K.

    Returns
    -------
    uint8 array, the shape of K
        :class:`SurfaceType` values; UNDEFINED where K or H is NaN.

    Examples
    --------
    >>> from rangesim.curvature import hk_sign_map, surface_type_name
    >>> labels = hk_sign_map([0.0004, 0.0, -0.0004, 0.0], [-0.02, -0.01, 0.0, 0.0])
    >>> [surface_type_name(t) for t in labels]
    ['peak', 'ridge', 'minimal surface', 'flat']

    References
    ----------
    .. [1] P. J. Besl, R. C. Jain, "Invariant surface characteristics for 3D object recognition
       in range images", Computer Vision, Graphics, and Image Processing 33(1), 33-80 (1986),
       doi:10.1016/0734-189X(86)90220-3.
    .. [2] P. J. Besl, R. C. Jain, "Segmentation through variable-order surface fitting", IEEE
       TPAMI 10(2), 167-192 (1988), doi:10.1109/34.3881.
    """
    # (a negative eps would make every value non-zero: no flat, ridge or saddle ridge at all)
    eps_K = P.number(eps_K, "eps_K", 0, unit="1/mm^2")
    eps_H = P.number(eps_H, "eps_H", 0, unit="1/mm")
    K = np.asarray(K, dtype=np.float64)
    H = np.asarray(H, dtype=np.float64)
    if K.shape != H.shape:
        raise RangesimError(f"K and H shapes differ: {K.shape} vs {H.shape}")
    sk = np.where(K > eps_K, 1, np.where(K < -eps_K, -1, 0))
    sh = np.where(H > eps_H, 1, np.where(H < -eps_H, -1, 0))
    labels = (1 + 3 * (1 + sh) + (1 - sk)).astype(np.uint8)
    labels[~(np.isfinite(K) & np.isfinite(H))] = SurfaceType.UNDEFINED
    return labels
