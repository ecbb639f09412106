"""Closed solids with sculptured tops: a B-spline height patch over a footprint, vertical
walls down to a floor, and the floor. The building block of freeform parts.
"""
from __future__ import annotations

import manifold3d
import numpy as np

from rangesim.cad.bspline import BSplineSurface


def clamped_knots(n_control: int, degree: int = 3) -> np.ndarray:
    """Uniform clamped knot vector on [0, 1] for ``n_control`` control points."""
    inner = np.linspace(0.0, 1.0, n_control - degree + 1)[1:-1]
    return np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])


def height_patch(x_range, y_range, heights: np.ndarray, degree: int = 3) -> BSplineSurface:
    """A cubic tensor-product B-spline z(x, y) over a rectangle.

    Parameters
    ----------
    x_range, y_range : (2,) float, mm
        The footprint; u runs along x, v along y.
    heights : (n_u, n_v) float, mm
        z of the control points, laid on a regular grid over the footprint. Two outer rings
        at the same height make the surface tangent to that level at its border (a blend).
    """
    heights = np.asarray(heights, dtype=np.float64)
    n_u, n_v = heights.shape
    x = np.linspace(*x_range, n_u)
    y = np.linspace(*y_range, n_v)
    control = np.stack(np.broadcast_arrays(x[:, None], y[None, :], heights), axis=-1)
    return BSplineSurface(control, clamped_knots(n_u, degree), clamped_knots(n_v, degree), degree, degree)


def surface_solid(surface: BSplineSurface, n_u: int, n_v: int, floor_z: float) -> manifold3d.Manifold:
    """The closed solid between ``floor_z`` and a height patch, with vertical walls.

    The patch is sampled on an ``n_u`` x ``n_v`` parameter grid (u along x, v along y, so
    S_u x S_v points up); the walls join its border to the floor, whose triangles are the
    same grid pressed flat. Every border point must lie above ``floor_z``.
    """
    (u0, u1), (v0, v1) = surface.domain
    uu, vv = np.meshgrid(np.linspace(u0, u1, n_u), np.linspace(v0, v1, n_v), indexing="ij")
    top = surface.evaluate(uu, vv).reshape(-1, 3)
    floor = top.copy()
    floor[:, 2] = floor_z
    i, j = np.meshgrid(np.arange(n_u - 1), np.arange(n_v - 1), indexing="ij")
    a = (i * n_v + j).ravel()
    b, c, d = a + n_v, a + n_v + 1, a + 1
    grid = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    n = n_u * n_v
    # the border, counter-clockwise seen from above (+x along u, +y along v)
    border = np.concatenate([
        np.arange(n_u - 1) * n_v,                          # v = v0, u increasing
        (n_u - 1) * n_v + np.arange(n_v - 1),              # u = u1, v increasing
        (n_u - 1) * n_v + (n_v - 1) - np.arange(n_u - 1) * n_v,  # v = v1, u decreasing
        (n_v - 1) - np.arange(n_v - 1),                    # u = u0, v decreasing
    ])
    nxt = np.roll(border, -1)
    walls = np.concatenate([np.stack([border, nxt + n, nxt], 1), np.stack([border, border + n, nxt + n], 1)])
    faces = np.concatenate([grid, grid[:, ::-1] + n, walls])
    vertices = np.concatenate([top, floor])
    mesh = manifold3d.Mesh(vert_properties=vertices.astype(np.float32), tri_verts=faces.astype(np.uint32))
    solid = manifold3d.Manifold(mesh)
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"freeform solid is not a closed manifold: {solid.status()}")
    return solid
