"""Laser shadows: one vectorised ``ray_test`` from each surface point towards its laser source."""
from __future__ import annotations

import drjit as dr

from rangesim.core.backend import mitsuba


def occluded(mscene, points_world, normals_world, sources_world, active):
    """True where scene geometry blocks the segment from a surface point to its laser source.

    Parameters
    ----------
    mscene : MitsubaScene
    points_world, normals_world, sources_world : mi.Vector3f / mi.Point3f
        Surface points, their unit normals (either orientation) and the laser sources, world
        frame, mm.
    active : mi.Bool
        Which points to test; the others return False.

    Notes
    -----
    Shadow rays start slightly off the surface, on the laser's side, by 1e-6 of the point's
    distance from the origin plus 1e-4 mm (float32 intersections are accurate to a few ulps),
    so a surface never shadows itself.
    """
    mi = mitsuba()
    to_source = sources_world - points_world
    side = dr.sign(dr.dot(normals_world, to_source))
    eps = 1e-4 + 1e-6 * dr.norm(points_world)
    origin = points_world + normals_world * (side * eps)
    to_source = sources_world - origin
    length = dr.norm(to_source)
    ray = mi.Ray3f(mi.Point3f(origin), to_source / length)
    ray.maxt = length
    return mscene.scene.ray_test(ray, active) & active
