"""Laser-sheet geometry of the two sweep types, in the camera frame (mm), on Dr.Jit arrays.

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

import math

import drjit as dr

from rangesim.core.backend import mitsuba


def sheet_through(points, sweep: str, baseline: float, tilt_rad: float):
    """Laser source position and unit sheet normal for the sheet that lights each point.

    Parameters
    ----------
    points : mi.Vector3f, N points
        Surface points, camera frame, mm.
    sweep : {"rotating", "translating"}
    baseline : float
        Laser origin offset along the camera's +x axis, mm.
    tilt_rad : float
        Translating sweep only: sheet tilt from the optical axis, radians.

    Returns
    -------
    source : mi.Vector3f
        Where the light that reaches each point comes from, mm.
    normal : mi.Vector3f
        Unit normal of the sheet through each point (sign arbitrary).
    """
    mi = mitsuba()
    zero = dr.zeros(mi.Float, dr.width(points))
    if sweep == "rotating":
        source = mi.Vector3f(baseline + zero, zero, zero)
        # plane through L containing P - L and the y axis: normal = (P - L) x y
        normal = dr.normalize(mi.Vector3f(-points.z, zero, points.x - baseline))
    elif sweep == "translating":
        # sheet direction (-sin t, 0, cos t); normal (cos t, 0, sin t)
        source = mi.Vector3f(points.x + math.tan(tilt_rad) * points.z, zero, zero)
        normal = mi.Vector3f(math.cos(tilt_rad) + zero, zero, math.sin(tilt_rad) + zero)
    else:
        raise ValueError(f"unknown sweep {sweep!r}")
    return source, normal
