"""Triangulation: a camera ray through the detected stripe peak meets the laser sheet.

A detected peak at column u + e (e: localisation error in pixels) gives the camera ray
r = ((u + e - cx) / f, (v - cy) / f, 1); the point reported is r's intersection with the
sheet that lit the pixel, X = (n . P) / (n . r) r, which lies in the sheet. Its depth is
z = (n . P) / (n . r), so dz/du = -z n_x / (f (n . r)): for a rotating sweep and a surface
on the optical axis this is z^2 / (f b), the classic law sigma_z = z^2 sigma_u / (f b).
"""
from __future__ import annotations

import numpy as np


def depth_per_pixel(points, sheet_normal, rays, focal_px):
    """|dz/du| (mm per pixel of peak shift along the row) at each point.

    Parameters
    ----------
    points, sheet_normal, rays : (N, 3) float arrays
        Surface points (mm), unit sheet normals, and camera rays with z component 1.
    focal_px : float
    """
    n_dot_r = np.einsum("ij,ij->i", sheet_normal, rays)
    return np.abs(points[:, 2] * sheet_normal[:, 0] / (focal_px * n_dot_r))


def triangulate(points, sheet_normal, rays, shift_px, focal_px):
    """Points reported for peaks shifted by ``shift_px`` columns from the true position.

    Parameters
    ----------
    points : (N, 3) float array
        True surface points, mm (they define the sheet offset n . P).
    sheet_normal : (N, 3) float array
    rays : (N, 3) float array
        Camera rays through the pixel centres, z component 1.
    shift_px : (N,) float array
        Peak position error along the row, pixels (0 gives back ``points``).
    focal_px : float

    Returns
    -------
    (N, 3) float array of reported points, mm, on the sheets.
    """
    shifted = rays.copy()
    shifted[:, 0] += shift_px / focal_px
    offset = np.einsum("ij,ij->i", sheet_normal, points)
    return shifted * (offset / np.einsum("ij,ij->i", sheet_normal, shifted))[:, None]
