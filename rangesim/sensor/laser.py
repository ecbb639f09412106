"""Laser-sheet geometry of the two sweep types, in the camera frame (mm).

The laser origin L sits on the camera's +x axis at ``baseline``. The stripe is seen by the
camera as a near-vertical line, so the peak is localised along the image rows (u).

rotating
    A mirror swings the sheet about an axis through L parallel to the camera's y axis. The
    sheet that lights a point P is the plane through L containing P and the y direction;
    the light comes from L.
translating
    The sheet keeps a fixed tilt (``tilt_deg`` from the optical axis, leaning towards the
    camera) and moves along the camera's x axis. The sheet lighting P is the plane of that
    tilt through P; the light comes from the point where that plane crosses the stage line
    (the x axis through L).
"""
from __future__ import annotations

import numpy as np


def sheet_through(points: np.ndarray, sweep: str, baseline: float, tilt_rad: float):
    """Laser source position and unit sheet normal for the sheet that lights each point.

    Parameters
    ----------
    points : (N, 3) float array
        Surface points, camera frame, mm.
    sweep : {"rotating", "translating"}
    baseline : float
        Laser origin offset along the camera's +x axis, mm.
    tilt_rad : float
        Translating sweep only: sheet tilt from the optical axis, radians.

    Returns
    -------
    source : (N, 3) float array
        Where the light lighting each point comes from, mm.
    normal : (N, 3) float array
        Unit normal of the sheet through each point (sign arbitrary).
    """
    px, pz = points[:, 0], points[:, 2]
    source = np.zeros_like(points)
    normal = np.zeros_like(points)
    if sweep == "rotating":
        source[:, 0] = baseline
        # plane through L containing P - L and the y axis: normal = (P - L) x y
        nx, nz = -pz, px - baseline
        length = np.hypot(nx, nz)
        normal[:, 0], normal[:, 2] = nx / length, nz / length
    elif sweep == "translating":
        # sheet direction (-sin t, 0, cos t); normal (cos t, 0, sin t)
        source[:, 0] = px + np.tan(tilt_rad) * pz
        normal[:, 0], normal[:, 2] = np.cos(tilt_rad), np.sin(tilt_rad)
    else:
        raise ValueError(f"unknown sweep {sweep!r}")
    return source, normal
