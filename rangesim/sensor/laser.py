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
from rangesim.core.light import source_x


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
    source = mi.Vector3f(source_x(points.x, points.z, sweep, baseline, tilt_rad), zero, zero)
    if sweep == "rotating":
        # plane through L containing P - L and the y axis: normal = (P - L) x y
        normal = dr.normalize(mi.Vector3f(-points.z, zero, points.x - baseline))
    else:
        # sheet direction (-sin t, 0, cos t); normal (cos t, 0, sin t)
        normal = mi.Vector3f(math.cos(tilt_rad) + zero, zero, math.sin(tilt_rad) + zero)
    return source, normal


def sheet_coordinate(points, sweep: str, baseline: float, tilt_rad: float):
    """Sweep coordinate ``s`` of the sheet through each point, and the length per unit of ``s``.

    The sweep is a family of sheets indexed by ``s``: the mirror angle for a rotating sweep
    (radians, ``atan2(x - baseline, z)``: 0 along the optical axis), the signed offset
    ``n . P`` of the translating sheet (mm). A point at distance ``d`` (mm) from the sheet
    ``s'`` has ``d ~= lam * (s - s')`` with ``lam`` the distance from the mirror axis
    (rotating, mm per radian) or 1 (translating).

    Parameters
    ----------
    points : mi.Vector3f or (N, 3) ndarray
        Points in the camera frame, mm. Dr.Jit and NumPy inputs both work.
    sweep, baseline, tilt_rad
        As in :func:`sheet_through`.

    Returns
    -------
    s, lam : arrays of the input's kind, shape (N,)
    """
    import numpy as np

    dx_is_numpy = isinstance(points, np.ndarray)
    x, z = (points[:, 0], points[:, 2]) if dx_is_numpy else (points.x, points.z)
    if sweep == "rotating":
        dx = x - baseline
        if dx_is_numpy:
            return np.arctan2(dx, z), np.hypot(dx, z)
        return dr.atan2(dx, z), dr.sqrt(dx * dx + z * z)
    if sweep == "translating":
        s = math.cos(tilt_rad) * x + math.sin(tilt_rad) * z
        return s, (np.ones_like(s) if dx_is_numpy else dr.full(type(s), 1.0, dr.width(s)))
    raise ValueError(f"unknown sweep {sweep!r}")


def intersect_sheet(rays, s, sweep: str, baseline: float, tilt_rad: float):
    """Points where camera rays meet the sheets ``s`` (NumPy).

    Parameters
    ----------
    rays : (N, 3) ndarray
        Camera-frame ray directions through the camera centre (any length).
    s : (N,) ndarray
        Sweep coordinate of the sheet per ray (see :func:`sheet_coordinate`).

    Returns
    -------
    (N, 3) ndarray of points, mm; NaN where the ray runs parallel to its sheet.
    """
    import numpy as np

    if sweep == "rotating":
        # plane through L = (b, 0, 0) containing (sin s, 0, cos s) and y: normal (cos s, 0, -sin s)
        normal = np.stack([np.cos(s), np.zeros_like(s), -np.sin(s)], axis=-1)
        offset = normal[:, 0] * baseline
    elif sweep == "translating":
        normal = np.broadcast_to(np.array([math.cos(tilt_rad), 0.0, math.sin(tilt_rad)]), rays.shape)
        offset = s
    else:
        raise ValueError(f"unknown sweep {sweep!r}")
    denom = np.einsum("ij,ij->i", normal, rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.abs(denom) > 1e-9, offset / denom, np.nan)
    return rays * t[:, None]
