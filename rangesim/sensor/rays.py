"""Casting camera rays into the Mitsuba scene: one ``ray_intersect`` for all pixels."""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import drjit as dr
import numpy as np

from rangesim.core.backend import aligned, coherent_rays, mitsuba, opaque_point, opaque_scalar, opaque_transform

#: shift (pixels) of the second ray cast by the shared-edge guard
RECAST_OFFSET_PX = 1e-3

#: rays are cast in square tiles of this many pixels a side, then put back in row-major
#: order: Embree's coherent traversal takes neighbouring rays in packets, and a 4 x 4 tile
#: is a tighter bundle than 16 pixels of a row (1024^2 on 2 CPU cores: 60 -> 39 ms at 1.3M
#: triangles, 96 -> 68 ms at 5.2M; 8 x 8 tiles 44 ms, 16 x 16 no gain). The results are the
#: same ray for ray, only their order changes.
RAY_TILE_PX = 4


@functools.lru_cache(maxsize=8)
def _tile_permutation(height: int, width: int, tile: int) -> tuple[np.ndarray, np.ndarray]:
    """(order, position), (H * W,) uint32 each: ``order[k]`` is the row-major index of the
    k-th pixel in tile order (tiles of ``tile`` x ``tile`` pixels, row-major over the tiles and
    within each; partial tiles at the right and bottom edges), ``position`` its inverse."""
    n = height * width
    i, j = np.divmod(np.arange(n, dtype=np.int64), width)
    tiles_x = -(-width // tile)
    key = ((i // tile) * tiles_x + j // tile) * (tile * tile) + (i % tile) * tile + j % tile
    # ranks of the keys (unique; gaps where partial tiles lack pixels): a cumulative count
    present = np.zeros(int(key.max()) + 1, np.int64)
    present[key] = 1
    position = (np.cumsum(present) - 1)[key]
    order = np.empty(n, np.int64)
    order[position] = np.arange(n)
    return aligned(order.astype(np.uint32)), aligned(position.astype(np.uint32))


def tile_order(height: int, width: int):
    """(order, position) as ``mi.UInt32``: :func:`_tile_permutation` of the image size
    (data, not kernel constants: a new image size compiles nothing)."""
    mi = mitsuba()
    order, position = _tile_permutation(int(height), int(width), RAY_TILE_PX)
    return mi.UInt32(order), mi.UInt32(position)


@dataclass
class PrimaryHits:
    """What each camera ray hit, as evaluated Dr.Jit arrays over N = H * W pixels (row-major).

    Attributes
    ----------
    rays : mi.Vector3f
        Camera-frame ray through each pixel centre, z component 1.
    t : mi.Float
        Distance (mm) along the unit ray to the hit; inf on a miss.
    point_world : mi.Point3f
        Hit position in the world frame from the triangle's barycentric coordinates (more
        accurate on the surface than origin + t * direction; shadow rays start from it).
    normal_world : mi.Vector3f
        Geometric normal of the hit triangle as wound in the mesh (not flipped).
    part, face : mi.Int32
        Object index and triangle index within it; -1 on a miss.
    recast : int
        Number of rays cast a second time by the shared-edge guard.
    tiles : (mi.UInt32, mi.UInt32) or None
        The :func:`tile_order` the rays were cast in (secondary rays from the hits, such as
        the laser-shadow rays, are cast in it too).
    """

    rays: Any
    t: Any
    point_world: Any
    normal_world: Any
    part: Any
    face: Any
    recast: int = 0
    tiles: Any = None

    @property
    def hit(self):
        return dr.isfinite(self.t)


def pixel_rays(K: np.ndarray, width: int, index, offset: float = 0.0):
    """Camera-frame rays K^-1 (j + 0.5, i + 0.5, 1) (z = 1) for flat pixel indices ``index``."""
    mi = mitsuba()
    # opaque: a new image size (and so a new focal length in pixels) compiles nothing
    w = width if not isinstance(width, (int, np.integer)) else opaque_scalar(width, "UInt32")
    fx, fy, cx, cy = (opaque_scalar(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    col = mi.Float(index % w) + (0.5 + offset)
    row = mi.Float(index // w) + (0.5 + offset)
    return mi.Vector3f((col - cx) / fx, (row - cy) / fy, 1.0)


def _intersect(mscene, pose: np.ndarray, rays, maxt: float):
    """Intersect camera-frame rays; returns (t, point, normal, part, face, directions), world frame."""
    mi = mitsuba()
    to_world = opaque_transform(pose)
    d_world = dr.normalize(to_world @ rays)
    ray = mi.Ray3f(opaque_point(pose[:3, 3]), d_world)
    ray.maxt = opaque_scalar(maxt)  # depends on the image size (the corner ray)
    # coherent where it pays: neighbouring pixels' rays share an origin and nearly a
    # direction, and on AVX-512 CPUs Embree's coherent traversal of them is ~1.7x faster
    # (55 -> 33 ms at 1024^2, 327k triangles; 95 -> 87 ms at 5.2M); see coherent_rays
    si = mscene.scene.ray_intersect(ray, mi.RayFlags.All, coherent_rays())
    hit = si.is_valid()
    t = dr.select(hit, si.t, dr.inf)
    part = mscene.part_index(si)
    face = dr.select(hit, mi.Int32(si.prim_index), -1)
    return t, si.p, si.n, part, face, d_world


def cast_primary(mscene, K, height, width, pose, maxt, watertight) -> PrimaryHits:
    """One vectorised ``ray_intersect`` over all pixels, plus the shared-edge guard.

    Embree can let a ray through an edge shared by two triangles (Mitsuba #1149). On a closed
    mesh that shows up as a hit on the inside of its far wall (a back face of a watertight
    object), or, where the far wall leaks too or lies on another surface, as a pixel whose
    four neighbours all see one object that it does not (a miss, or a hit on the floor
    behind). Only those rays are cast again, shifted by 1e-3 pixel, and the new hit
    replaces the old one when it is plausible (not a back face of a closed object). A
    genuine one-pixel feature casts the same way again and stays.

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
    mi = mitsuba()
    n_pix = height * width
    index = dr.arange(mi.UInt32, n_pix)
    w, h = opaque_scalar(width, "UInt32"), opaque_scalar(height, "UInt32")  # sizes as kernel inputs
    # cast in tiles (RAY_TILE_PX), then back to row-major order
    order, position = tiles = tile_order(height, width)
    hits = _intersect(mscene, pose, pixel_rays(K, w, order), maxt)
    dr.eval(*hits)
    t, p, n, part, face, d_world = (dr.gather(type(v), v, position) for v in hits)
    rays = pixel_rays(K, w, index)
    closed = mi.Bool(aligned(np.asarray(watertight, dtype=bool)))
    dr.eval(t, p, n, part, face, d_world)

    hit = dr.isfinite(t)
    back = hit & (dr.dot(n, d_world) > 0) & dr.gather(mi.Bool, closed, part, hit)
    col, row = index % w, index // w
    inner = (col > 0) & (col < w - 1) & (row > 0) & (row < h - 1)
    # a pixel whose four neighbours all see one object it does not see: a ray that slipped
    # through that object (a miss inside a silhouette, or a hit on whatever lies behind)
    around = dr.gather(mi.Int32, part, index + 1, inner)
    isolated = inner & (around != part)
    for neighbour in (index - 1, index + w, index - w):
        isolated &= dr.gather(mi.Int32, part, neighbour, inner) == around
    suspect = back | isolated
    recast = int(dr.count(suspect)[0]) if dr.width(suspect) else 0
    if recast:
        sel = dr.compress(suspect)
        t2, p2, n2, part2, face2, d2 = _intersect(mscene, pose, pixel_rays(K, w, sel, RECAST_OFFSET_PX), maxt)
        ok = dr.isfinite(t2) & ~((dr.dot(n2, d2) > 0) & dr.gather(mi.Bool, closed, part2, dr.isfinite(t2)))
        dr.scatter(t, t2, sel, ok)
        dr.scatter(p, p2, sel, ok)
        dr.scatter(n, n2, sel, ok)
        dr.scatter(part, part2, sel, ok)
        dr.scatter(face, face2, sel, ok)
        dr.eval(t, p, n, part, face)
    return PrimaryHits(rays, t, p, n, part, face, recast, tiles)


#: camera rays end at this multiple of the far limit: surfaces beyond are "no surface" (Mitsuba #61)
MAX_RAY_FACTOR = 2.0


@dataclass
class CameraHits:
    """The primary hits of a view in the camera frame (evaluated Dr.Jit arrays, N = H * W).

    Attributes
    ----------
    hits : PrimaryHits
    points : mi.Vector3f
        Hit points, camera frame, mm (inf on a miss).
    normals : mi.Vector3f
        Unit geometric normals, camera frame, turned to face the camera.
    """

    hits: PrimaryHits
    points: Any
    normals: Any


def camera_hits(scene, sensor, pose: np.ndarray, rows: tuple[int, int] | None = None) -> CameraHits:
    """Cast the pixel-centre rays of ``sensor`` from ``pose`` (see :func:`cast_primary`).

    Rays are as long as ``MAX_RAY_FACTOR`` times the far limit along the image corner's ray.
    ``rows`` (first, stop): only that band of image rows (the same rays as in the whole
    image, N = (stop - first) * W).
    """
    K, h, w = sensor.K, sensor.height, sensor.width
    corner = float(np.hypot(np.hypot(w / 2 / K[0, 0], h / 2 / K[1, 1]), 1.0))  # longest ray of unit depth
    if rows is not None:
        K = K.copy()
        K[1, 2] -= rows[0]  # the band's first row is row 0 of its rays
        h = rows[1] - rows[0]
    watertight = np.array([o.watertight for o in scene.objects])
    hits = cast_primary(scene.mitsuba_scene(), K, h, w, pose,
                        MAX_RAY_FACTOR * sensor.params["range"]["far"] * corner, watertight)
    points = dr.normalize(hits.rays) * hits.t
    to_camera = opaque_transform(np.linalg.inv(pose))
    normals = dr.normalize(to_camera @ hits.normal_world)
    normals = dr.select(dr.dot(normals, points) > 0, -normals, normals)  # the visible side faces the camera
    return CameraHits(hits, points, normals)
