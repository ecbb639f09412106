"""Path tracing the laser stripe once for every sweep position.

The camera image of sweep position ``f`` is a sum over light paths camera -> x_1 -> ... ->
x_k -> laser. A path's geometry and BSDF throughput do not depend on where the sheet is;
only the laser's irradiance at its last vertex does, through the sheet's Gaussian thickness
profile. So each path is traced once (Mitsuba ``ray_intersect``, ``ray_test`` and the
objects' BSDFs, next-event estimation towards the laser at every vertex) and every vertex is
returned with its weight and its sweep coordinate: :mod:`rangesim.sensor.frames` then
spreads it into every frame whose sheet lights it. That is the estimator a per-frame path
tracer would use, with the same random paths for all frames (common random numbers): 128
or 1000 frames cost one path-tracing pass.

Radiometry (relative units): the laser source at S gives an irradiance, perpendicular to its
rays, of ``pi * (z_ref / |x - S|)^2 * g(d)`` at distance d from the sheet centre (g: the
sheet's Gaussian thickness profile, peak 1), the inverse-square law of the geometric
scanner. A pixel records radiance, so a white Lambertian target facing the laser at
``z_ref`` reads 1 at the stripe's peak, and ``noise.min_signal`` keeps its meaning.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import numpy as np

from rangesim.core.backend import mitsuba, opaque_point, opaque_transform
from rangesim.sensor.laser import sheet_coordinate, sheet_through


@dataclass
class StripeVertices:
    """Path vertices that receive laser light, over a tile of pixels.

    Attributes
    ----------
    pixel : (M,) int64
        Tile-local pixel index (row-major).
    weight : (M,) float64
        Radiance the vertex sends to the pixel when the sheet centre passes through it,
        relative units, already divided by the paths per pixel.
    s : (M,) float64
        Sweep coordinate of the sheet through the vertex (rad for rotating, mm for
        translating; see :func:`rangesim.sensor.laser.sheet_coordinate`).
    lam : (M,) float64
        Length per unit of ``s`` at the vertex, mm.
    bounce : (M,) int8
        0 for the surface the pixel sees, 1 after one interreflection, ...
    """

    pixel: np.ndarray
    weight: np.ndarray
    s: np.ndarray
    lam: np.ndarray
    bounce: np.ndarray


def trace_stripe_paths(mscene, pose: np.ndarray, K: np.ndarray, width: int, row0: int, rows: int,
                       spp: int, max_depth: int, laser: dict, reference_distance: float,
                       seed_state: int) -> StripeVertices:
    """Trace ``spp`` paths per pixel of image rows ``row0 .. row0 + rows - 1``.

    Parameters
    ----------
    mscene : MitsubaScene
        Scene with a BSDF on every shape.
    pose : (4, 4) camera-to-world; K : (3, 3) intrinsics; width : image width, pixels.
    row0, rows : int
        The tile.
    spp : int
        Paths per pixel (a box filter: ``spp`` evenly spaced sub-pixel columns, a uniform
        random position along each).
    max_depth : int
        Mitsuba's convention: 2 = direct laser light only, 3 = plus one interreflection.
    laser : dict
        ``sweep``, ``baseline`` (mm), ``tilt_rad``.
    reference_distance : float
        z_ref, mm.
    seed_state : int
        PCG32 state; a path's random numbers depend only on it and the path's global index
        (not on the tiling).

    Notes
    -----
    Scalars that change between tiles (first row, seed) enter the kernels as opaque
    variables, so every tile after the first reuses the compiled kernels.
    """
    mi = mitsuba()
    n = rows * width * spp
    index = dr.arange(mi.UInt32, n)
    first = dr.opaque(mi.UInt32, row0 * width * spp)
    pcg = mi.PCG32(size=n, initstate=dr.opaque(mi.UInt64, seed_state),
                   initseq=mi.UInt64(index + first))
    pixel = index // spp
    # sub-pixel positions: evenly spaced across the row (the direction the stripe sweeps), a
    # midpoint rule for the pixel's width whose samples centre on the pixel centre, and
    # uniform along the column; random jitter across the row would add peak noise of
    # 1 / (spp sqrt(12 spp)) pixels that no real pixel has
    stratum = mi.Float(index % spp)
    col = mi.Float(pixel % width) + (stratum + 0.5) / spp
    row = mi.Float(pixel // width + dr.opaque(mi.UInt32, row0)) + pcg.next_float32()
    direction = mi.Vector3f((col - K[0, 2]) / K[0, 0], (row - K[1, 2]) / K[1, 1], 1.0)
    to_world = opaque_transform(pose)
    to_camera = opaque_transform(np.linalg.inv(pose))
    ray = mi.Ray3f(opaque_point(pose[:3, 3]), dr.normalize(to_world @ direction))
    ctx = mi.BSDFContext()
    throughput = mi.Float(1.0)
    active = mi.Bool(True)
    z2 = reference_distance**2
    pixel_np = np.asarray(pixel).astype(np.int64)
    out = []
    for bounce in range(max_depth - 1):
        si = mscene.scene.ray_intersect(ray, active)
        active &= si.is_valid()
        bsdf = si.bsdf(ray)
        p_camera = to_camera @ si.p
        source, _ = sheet_through(mi.Vector3f(p_camera), laser["sweep"], laser["baseline"], laser["tilt_rad"])
        s, lam = sheet_coordinate(mi.Vector3f(p_camera), laser["sweep"], laser["baseline"], laser["tilt_rad"])
        source_world = to_world @ mi.Point3f(source)
        to_source = source_world - si.p
        d2 = dr.squared_norm(to_source)
        f = bsdf.eval(ctx, si, si.to_local(to_source * dr.rsqrt(d2)), active)
        lit = active & ~mscene.scene.ray_test(si.spawn_ray_to(source_world), active)
        weight = dr.select(lit, throughput * f[0] * (math.pi * z2) / d2, 0.0)
        dr.eval(weight, s, lam)
        w = np.asarray(weight, dtype=np.float64)
        keep = w > 0
        out.append((pixel_np[keep], w[keep] / spp, np.asarray(s, dtype=np.float64)[keep],
                    np.asarray(lam, dtype=np.float64)[keep], np.full(int(keep.sum()), bounce, np.int8)))
        if bounce == max_depth - 2:
            break
        sample, bsdf_weight = bsdf.sample(ctx, si, pcg.next_float32(),
                                          mi.Point2f(pcg.next_float32(), pcg.next_float32()), active)
        throughput *= bsdf_weight[0]
        active &= throughput > 0
        ray = si.spawn_ray(si.to_world(sample.wo))
        dr.eval(ray, throughput, active)
    parts = [np.concatenate(column) for column in zip(*out)]
    return StripeVertices(*parts)
