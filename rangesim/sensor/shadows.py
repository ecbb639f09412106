"""Laser shadows: one vectorised ``ray_test`` from each surface point towards its laser source."""
from __future__ import annotations

import numpy as np

from rangesim.core.backend import mitsuba


def occluded(mscene, points_world, normals_world, sources_world, active) -> np.ndarray:
    """True where scene geometry blocks the segment from a surface point to its laser source.

    Parameters
    ----------
    mscene : MitsubaScene
    points_world, normals_world, sources_world : (N, 3) float arrays
        Surface points, their unit normals (either orientation) and the laser sources, world
        frame, mm.
    active : (N,) bool
        Which points to test; the others return False.

    Notes
    -----
    Shadow rays start slightly off the surface, on the laser's side, by 1e-5 of the scene's
    coordinate magnitude (float32 intersections are accurate to a few ulps), so a surface
    never shadows itself.
    """
    result = np.zeros(len(points_world), dtype=bool)
    index = np.flatnonzero(active)
    if len(index) == 0:
        return result
    mi = mitsuba()
    p = points_world[index].astype(np.float64)
    n = normals_world[index].astype(np.float64)
    s = sources_world[index].astype(np.float64)
    to_source = s - p
    side = np.sign(np.einsum("ij,ij->i", n, to_source))[:, None]
    eps = 1e-5 * (1.0 + np.abs(p).max())
    origin = p + side * n * eps
    to_source = s - origin
    length = np.linalg.norm(to_source, axis=1)
    direction = to_source / length[:, None]

    def vec(a, cls):
        a = np.ascontiguousarray(a.T, dtype=np.float32)
        return cls(a[0], a[1], a[2])

    ray = mi.Ray3f(vec(origin, mi.Point3f), vec(direction, mi.Vector3f))
    ray.maxt = mi.Float(length.astype(np.float32))
    result[index] = np.array(mscene.scene.ray_test(ray), dtype=bool)
    return result
