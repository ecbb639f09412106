"""Laser shadows: one vectorised ``ray_test`` from each surface point towards its laser source."""
from __future__ import annotations

import drjit as dr

from rangesim.core.backend import coherent_rays, mitsuba, opaque_transform


def occluded(mscene, points_world, normals_world, sources_world, active, tiles=None):
    """True where scene geometry blocks the segment from a surface point to its laser source.

    Parameters
    ----------
    mscene : MitsubaScene
    points_world, normals_world, sources_world : mi.Vector3f / mi.Point3f
        Surface points, their unit normals (either orientation) and the laser sources, world
        frame, mm.
    active : mi.Bool
        Which points to test; the others return False.
    tiles : (order, position) mi.UInt32, optional
        Cast the rays in this order (:func:`rangesim.sensor.rays.tile_order`: neighbouring
        points' shadow rays in one packet), the answer in the points' own order.

    Notes
    -----
    Shadow rays start off the surface on the laser's side by Mitsuba's own spawn offset,
    (1 + max |p_i|) * ``mi.math.RayEpsilon`` (0.05 mm at 600 mm from the origin): float32
    positions carry errors of a few ulps of the coordinates, and a smaller offset lets a
    plane shadow itself (seen on CUDA, whose rsqrt is approximate).
    """
    mi = mitsuba()
    if tiles is not None:
        order, position = tiles
        inputs = (points_world, normals_world, sources_world, active)
        dr.eval(*inputs)
        tiled = occluded(mscene, *(v if dr.width(v) == 1 else dr.gather(type(v), v, order) for v in inputs))
        dr.eval(tiled)
        return dr.gather(mi.Bool, tiled, position)
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
    # coherent where it pays (AVX-512 CPUs: neighbouring points' shadow rays head for nearly
    # the same source, 35 -> 27 ms at 1024^2, 327k triangles; see coherent_rays)
    return mscene.scene.ray_test(ray, coherent_rays(), active) & active


def laser_reach(mscene, view, sources, pose, near: float, far: float):
    """Which camera hits lie in the working range, and which of those the laser lights directly.

    Parameters
    ----------
    mscene : MitsubaScene
    view : CameraHits
        Primary hits, camera frame (:func:`rangesim.sensor.rays.camera_hits`).
    sources : mi.Vector3f
        Laser source lighting each point, camera frame, mm.
    pose : (4, 4) camera-to-world
    near, far : float
        Working range on the camera's z axis, mm.

    Returns
    -------
    in_range : mi.Bool
        A surface was hit with ``near <= z <= far``.
    lit : mi.Bool
        A surface was hit, faces its laser source, and nothing blocks the way (tested only
        in range; out of range it counts as lit when it faces the laser).
    """
    mi = mitsuba()
    hits, points = view.hits, view.points
    in_range = hits.hit & (points.z >= near) & (points.z <= far)
    facing = dr.dot(view.normals, sources - points) > 0
    blocked = occluded(mscene, hits.point_world, hits.normal_world,
                       opaque_transform(pose) @ mi.Point3f(sources), active=in_range & facing, tiles=hits.tiles)
    return in_range, hits.hit & facing & ~blocked
