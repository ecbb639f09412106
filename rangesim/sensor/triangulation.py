"""Triangulation: a camera ray through the detected stripe peak meets the laser sheet.

A detected peak at column u + e (e: localisation error in pixels) gives the camera ray
r = ((u + e - cx) / f, (v - cy) / f, 1); the point reported is r's intersection with the
sheet that lit the pixel, X = (n . P) / (n . r) r, which lies in the sheet. Its depth is
z = (n . P) / (n . r), so dz/du = -z n_x / (f (n . r)): for a rotating sweep and a surface
on the optical axis this is z^2 / (f b), the classic law sigma_z = z^2 sigma_u / (f b).
"""
from __future__ import annotations

import drjit as dr

from rangesim.core.backend import mitsuba


def depth_per_pixel(points, sheet_normal, rays, focal_px: float):
    """|dz/du| (mm per pixel of peak shift along the row) at each point.

    Parameters
    ----------
    points, sheet_normal, rays : mi.Vector3f
        Surface points (mm), unit sheet normals, and camera rays with z component 1.
    focal_px : float
    """
    return dr.abs(points.z * sheet_normal.x / (focal_px * dr.dot(sheet_normal, rays)))


def triangulate(points, sheet_normal, rays, shift_px, focal_px: float):
    """Points reported for peaks shifted by ``shift_px`` columns from the true position.

    Parameters
    ----------
    points : mi.Vector3f
        True surface points, mm (they define the sheet offset n . P).
    sheet_normal : mi.Vector3f
    rays : mi.Vector3f
        Camera rays through the pixel centres, z component 1.
    shift_px : mi.Float
        Peak position error along the row, pixels (0 gives back ``points``).
    focal_px : float

    Returns
    -------
    mi.Vector3f of reported points, mm, on the sheets.
    """
    mi = mitsuba()
    shifted = mi.Vector3f(rays.x + shift_px / focal_px, rays.y, rays.z)
    return shifted * (dr.dot(sheet_normal, points) / dr.dot(sheet_normal, shifted))
