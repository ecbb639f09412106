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
    Shadow rays start off the surface on the laser's side by Mitsuba's own spawn offset,
    (1 + max |p_i|) * ``mi.math.RayEpsilon`` (0.05 mm at 600 mm from the origin): float32
    positions carry errors of a few ulps of the coordinates, and a smaller offset lets a
    plane shadow itself (seen on CUDA, whose rsqrt is approximate).
    """
    mi = mitsuba()
    to_source = sources_world - points_world
    side = dr.sign(dr.dot(normals_world, to_source))
    magnitude = dr.select(dr.abs(points_world.x) > dr.abs(points_world.y), dr.abs(points_world.x), dr.abs(points_world.y))
    magnitude = dr.select(magnitude > dr.abs(points_world.z), magnitude, dr.abs(points_world.z))
    eps = (1.0 + magnitude) * mi.math.RayEpsilon
    origin = points_world + normals_world * (side * eps)
    to_source = sources_world - origin
    length = dr.norm(to_source)
    ray = mi.Ray3f(mi.Point3f(origin), to_source / length)
    ray.maxt = length
    return mscene.scene.ray_test(ray, active) & active
