"""Casting camera rays into the Mitsuba scene: one ``ray_intersect`` for all pixels."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangesim.core.backend import mitsuba


@dataclass
class PrimaryHits:
    """What each camera ray hit, flattened row-major over the image (N = H * W).

    Attributes
    ----------
    t : (N,) float32
        Distance (mm) along the unit camera ray to the hit; inf on a miss.
    normal_world : (N, 3) float32
        Geometric normal of the hit triangle as wound in the mesh (not flipped); NaN on a miss.
    part, face : (N,) int32
        Object index and triangle index within it; -1 on a miss.
    recast : int
        Number of rays cast a second time by the shared-edge guard.
    """

    t: np.ndarray
    normal_world: np.ndarray
    part: np.ndarray
    face: np.ndarray
    recast: int = 0

    @property
    def hit(self) -> np.ndarray:
        return np.isfinite(self.t)


def pixel_directions(K: np.ndarray, height: int, width: int, offset=(0.0, 0.0), index=None):
    """Dr.Jit (3, N) camera-frame ray directions K^-1 (j + 0.5, i + 0.5, 1), z component 1.

    ``offset`` = (du, dv) shifts every sample point in pixels (used to re-cast rays);
    ``index`` selects flat pixel indices (default: all pixels, row-major).
    """
    import drjit as dr

    mi = mitsuba()
    if index is None:
        idx = dr.arange(mi.UInt32, height * width)
    else:
        idx = mi.UInt32(np.asarray(index, dtype=np.uint32))
    col = mi.Float(idx % width) + (0.5 + offset[0])
    row = mi.Float(idx // width) + (0.5 + offset[1])
    return mi.Vector3f((col - K[0, 2]) / K[0, 0], (row - K[1, 2]) / K[1, 1], 1.0)


def _intersect(mscene, pose: np.ndarray, d_cam, maxt: float):
    """Intersect rays (camera-frame directions ``d_cam``) and return numpy arrays."""
    import drjit as dr

    mi = mitsuba()
    to_world = mi.Transform4f(pose.astype(np.float32).tolist())
    d_world = dr.normalize(to_world @ d_cam)
    ray = mi.Ray3f(mi.Point3f(*(float(c) for c in pose[:3, 3])), d_world)
    ray.maxt = maxt
    si = mscene.scene.ray_intersect(ray)
    hit = si.is_valid()
    t = dr.select(hit, si.t, dr.inf)
    part = mscene.part_index(si)
    face = dr.select(hit, mi.Int32(si.prim_index), -1)
    n = dr.select(hit, si.n, dr.nan)
    dr.eval(t, part, face, n)
    return (
        np.array(t, dtype=np.float32),
        np.ascontiguousarray(np.array(n, dtype=np.float32).T),
        np.array(part, dtype=np.int32),
        np.array(face, dtype=np.int32),
        np.ascontiguousarray(np.array(d_world, dtype=np.float32).T),
    )


def cast_primary(mscene, K, height, width, pose, maxt, watertight) -> PrimaryHits:
    """One vectorised ``ray_intersect`` over all pixels, plus the shared-edge guard.

    Embree can let a ray through an edge shared by two triangles (Mitsuba #1149). On a closed
    mesh that shows up as a miss inside the silhouette (all four neighbours hit) or as a hit
    on the inside of the far wall (a back face of a watertight object). Only those rays are
    cast again with a 1e-3 pixel shift, and the new hit replaces the old one when it is
    plausible (front facing, or any hit for a former miss).

    Parameters
    ----------
    mscene : MitsubaScene
    K : (3, 3) intrinsics; height, width : image size
    pose : (4, 4) camera-to-world
    maxt : float
        Longest ray (mm); surfaces beyond are not seen.
    watertight : (n_objects,) bool
        Which objects are closed (their back faces can never be visible).
    """
    t, n, part, face, d_world = _intersect(mscene, pose, pixel_directions(K, height, width), maxt)
    hits = PrimaryHits(t, n, part, face)
    suspect = _leak_suspects(hits, d_world, np.asarray(watertight, bool), height, width)
    if suspect.any():
        index = np.flatnonzero(suspect)
        d_again = pixel_directions(K, height, width, offset=(1e-3, 1e-3), index=index)
        t2, n2, part2, face2, d2 = _intersect(mscene, pose, d_again, maxt)
        back2 = np.einsum("ij,ij->i", n2, d2) > 0
        ok = np.isfinite(t2) & ~(back2 & np.asarray(watertight, bool)[np.maximum(part2, 0)])
        for old, new in ((hits.t, t2), (hits.normal_world, n2), (hits.part, part2), (hits.face, face2)):
            old[index[ok]] = new[ok]
        hits.recast = len(index)
    return hits


def _leak_suspects(hits: PrimaryHits, d_world, watertight, height, width) -> np.ndarray:
    hit = hits.hit
    back = hit & (np.einsum("ij,ij->i", hits.normal_world, d_world) > 0)
    back &= watertight[np.maximum(hits.part, 0)]
    grid = hit.reshape(height, width)
    enclosed = np.zeros_like(grid)
    enclosed[1:-1, 1:-1] = grid[:-2, 1:-1] & grid[2:, 1:-1] & grid[1:-1, :-2] & grid[1:-1, 2:]
    return back | (~hit & enclosed.ravel())
