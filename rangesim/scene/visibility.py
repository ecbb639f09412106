"""Which surface points a viewpoint sees: one vectorised Mitsuba ray per point.

:func:`visible_from` is the ray test on bare points; :func:`visible_points` applies it to
samples of :func:`rangesim.cad.surface_points` (pure geometry, in the CAD layer below),
and :func:`visible_surface_points` samples a mesh and keeps what one range view sees
(the paper's Fig. 10).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from rangesim.cad.sampling import SurfacePoints, surface_points
from rangesim.core.backend import mitsuba
from rangesim.core.errors import RangesimError

if TYPE_CHECKING:
    from rangesim.scene.scene import Scene

__all__ = ["visible_from", "visible_points", "visible_surface_points"]


def visible_points(
    samples: SurfacePoints,
    scene: "Scene | trimesh.Trimesh | list[trimesh.Trimesh]",
    viewpoint: Any,
    *,
    tolerance: float | None = None,
) -> SurfacePoints:
    """The samples seen from a viewpoint: facing it and not hidden by the scene.

    Parameters
    ----------
    samples : SurfacePoints
    scene : Scene, trimesh.Trimesh or list of trimesh.Trimesh
        The occluders, mm, including the sampled mesh itself.
    viewpoint : (3,) array_like
        The eye, mm.
    tolerance : float, optional
        See :func:`visible_from`.

    Returns
    -------
    SurfacePoints
        The visible subset, in the original order.
    """
    mask = visible_from(scene, samples.points, viewpoint, normals=samples.normals, tolerance=tolerance)
    return samples.subset(mask)


def visible_surface_points(
    mesh: trimesh.Trimesh,
    resolution: float | str,
    viewpoint: Any,
    *,
    smooth: bool = True,
    ends: str = "triangle",
    tolerance: float | None = None,
) -> SurfacePoints:
    """Sample a mesh at a resolution and keep the points one viewpoint sees, like one range view.

    :func:`rangesim.cad.surface_points` followed by :func:`visible_points` with the mesh
    itself as the only occluder (normal facing the eye, not hidden by the mesh).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The surface, mm.
    resolution : float or str
        Grid spacing, mm or a length string (``"0.2in"``).
    viewpoint : (3,) array_like
        The eye, mm.
    smooth, ends
        As for :func:`rangesim.cad.surface_points`.
    tolerance : float, optional
        See :func:`visible_from`.

    Returns
    -------
    SurfacePoints
        The visible samples, in sampling order.
    """
    eye = np.asarray(viewpoint, dtype=np.float64).reshape(-1)
    if eye.shape == (3,) and np.all(np.isfinite(eye)) and mesh.is_watertight and bool(mesh.contains(eye[None])[0]):
        # (every point would face away or be hidden: an empty view that looks like a result)
        raise RangesimError(f"the viewpoint ({', '.join(f'{c:g}' for c in eye)}) mm lies inside the part: "
                            "nothing is seen from there")
    samples = surface_points(mesh, resolution, smooth=smooth, ends=ends)
    return visible_points(samples, mesh, viewpoint, tolerance=tolerance)


def visible_from(
    scene: Any,
    points: np.ndarray,
    viewpoint: Any,
    *,
    normals: np.ndarray | None = None,
    tolerance: float | None = None,
) -> np.ndarray:
    """True for the points seen from ``viewpoint``: nothing in the scene in front of them.

    One ray per point from the viewpoint towards it, all in one Dr.Jit launch (a Mitsuba
    shadow-ray test up to ``tolerance`` before the point). With ``normals`` a point must
    also face the viewpoint (``normal . (viewpoint - point) > 0``), which drops the back
    of a closed surface even where float32 ray casting would graze past it.

    Parameters
    ----------
    scene : Scene, trimesh.Trimesh or list of trimesh.Trimesh
        The occluders, mm (anything :func:`rangesim.scene.load_scene` accepts); the
        surface the points lie on must be part of it.
    points : (N, 3) float
        Points on the scene's surfaces, mm.
    viewpoint : (3,) array_like
        The eye, mm.
    normals : (N, 3) float, optional
        Outward unit normals of the points.
    tolerance : float, optional
        Hits closer than this to the point (mm) do not hide it. Default
        ``(1 + max |coordinate|) * 4 * mi.math.RayEpsilon`` (about 0.07 mm at 200 mm
        from the origin): Mitsuba intersects in float32, and a point on a shared edge
        may be hit on the neighbouring triangle a few ulps early.

    Returns
    -------
    (N,) bool
    """
    from rangesim.scene.scene import load_scene

    mi = mitsuba()
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    eye = np.asarray(viewpoint, dtype=np.float64).reshape(-1)
    if eye.shape != (3,) or not np.all(np.isfinite(eye)):
        raise RangesimError(f"viewpoint must be three finite numbers (x, y, z), got {viewpoint!r}")
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    if tolerance is None:
        magnitude = max(float(np.abs(points).max()), float(np.abs(eye).max()))
        tolerance = (1.0 + magnitude) * 4.0 * float(mi.math.RayEpsilon)

    mscene = load_scene(scene).mitsuba_scene()
    # a ray through an edge or a vertex can slip between two triangles (float32); a second
    # ray from an eye moved by a hair in an odd direction crosses elsewhere, and a point
    # counts as hidden if either ray is blocked
    nudge = _NUDGE * (1.0 + float(np.abs(eye).max())) * 1e-4
    blocked = np.zeros(len(points), dtype=bool)
    for origin in (eye, eye + nudge):
        blocked |= _blocked(mi, mscene.scene, origin, points, tolerance)
    seen = ~blocked
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        seen &= np.einsum("ij,ij->i", normals, eye - points) > 0.0
    return seen


#: direction of the second ray's eye offset: no symmetry axis of common meshes
_NUDGE = np.array([0.6, -0.48, 0.64])


def _blocked(mi, mi_scene, eye: np.ndarray, points: np.ndarray, tolerance: float) -> np.ndarray:
    """(N,) bool: something lies on the segment from ``eye`` to each point, short of ``tolerance``."""
    to_point = points - eye
    dist = np.linalg.norm(to_point, axis=1)
    direction = to_point / np.where(dist > 0, dist, 1.0)[:, None]
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    ray = mi.Ray3f(mi.Point3f(f32(np.broadcast_to(eye, points.shape).T)), mi.Vector3f(f32(direction.T)))
    # clamped on the NumPy side: dr.maximum does not lower on some LLVM builds
    ray.maxt = mi.Float(f32(np.maximum(dist - tolerance, 0.0)))
    return np.asarray(mi_scene.ray_test(ray), dtype=bool)
