"""Test solids with known centre lines: a bent and tapered ellipsoid (the paper's figure 17),
a tube swept along a circular arc, a straight cylinder. Millimetres."""
from __future__ import annotations

import numpy as np
import trimesh


def deformed_ellipsoid(semi_axes: tuple[float, float, float] = (60.0, 20.0, 15.0), bend: float = 0.006,
                       taper: float = 0.4, subdivisions: int = 4) -> tuple[trimesh.Trimesh, callable]:
    """An icosphere scaled to an ellipsoid (long axis x), tapered along x and bent in z.

    The centre line is z = bend * x^2 (taper scales y, z about it by 1 + taper * x / (2 a): 1 -+ taper / 2 at
    the ends).

    Returns
    -------
    mesh : trimesh.Trimesh
    centre_line : callable
        ``centre_line(x)`` -> (len(x), 3) points of the true centre line.
    """
    a, b, c = semi_axes
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = sphere.vertices * [a, b, c]
    scale = 1.0 + taper * v[:, 0] / a * 0.5
    v[:, 1] *= scale
    v[:, 2] *= scale
    v[:, 2] += bend * v[:, 0] ** 2
    mesh = trimesh.Trimesh(v, sphere.faces, process=False)

    def centre_line(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        return np.column_stack([x, np.zeros_like(x), bend * x ** 2])

    return mesh, centre_line


def bent_tube(radius: float = 8.0, bend_radius: float = 60.0, angle_deg: float = 100.0,
              n_around: int = 32, n_along: int = 64) -> tuple[trimesh.Trimesh, np.ndarray, float]:
    """A closed tube of circular section swept along a circular arc in the xy plane about the origin.

    Returns
    -------
    mesh : trimesh.Trimesh
    centre : (3,) float
        Centre of the arc (the origin).
    bend_radius : float
        Radius of the centre line, mm.
    """
    phi = np.radians(np.linspace(0.0, angle_deg, n_along))
    th = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    # ring j at arc angle phi_j: centre R (cos, sin, 0), tangent (-sin, cos, 0), radial (cos, sin, 0)
    rad = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], 1)
    z = np.array([0.0, 0.0, 1.0])
    pts = (bend_radius * rad[:, None, :] + radius * (np.cos(th)[None, :, None] * rad[:, None, :]
                                                    + np.sin(th)[None, :, None] * z))
    verts = pts.reshape(-1, 3)
    faces = []
    for j in range(n_along - 1):
        for i in range(n_around):
            a, b = j * n_around + i, j * n_around + (i + 1) % n_around
            c, d = a + n_around, b + n_around
            faces += [[a, c, b], [b, c, d]]
    ends = np.array([bend_radius * rad[0], bend_radius * rad[-1]])
    e0, e1 = len(verts), len(verts) + 1
    verts = np.vstack([verts, ends])
    last = (n_along - 1) * n_around
    for i in range(n_around):
        faces.append([e0, i, (i + 1) % n_around])
        faces.append([e1, last + (i + 1) % n_around, last + i])
    mesh = trimesh.Trimesh(verts, np.array(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh, np.zeros(3), bend_radius


def swept_tube(centre_line, radius, t_range: tuple[float, float] = (0.0, 1.0), n_around: int = 48,
               n_along: int = 96) -> trimesh.Trimesh:
    """A closed tube of circular section swept along a space curve, flat caps at both ends.

    Parameters
    ----------
    centre_line : callable
        ``centre_line(t)`` -> (len(t), 3) points of the centre line, mm.
    radius : float or callable
        Section radius, mm, or ``radius(t)`` -> (len(t),) for a tapered tube.
    t_range : (float, float)
        Parameter interval swept.
    n_around, n_along : int
        Vertices around each ring and rings along the curve.

    Returns
    -------
    trimesh.Trimesh
        Outward-facing; ring ``j`` lies in the plane perpendicular to the curve's tangent at
        its ``t_j`` (parallel-transported frames, so the tube does not twist).
    """
    t = np.linspace(*t_range, n_along)
    c = np.asarray(centre_line(t), float)
    r = np.broadcast_to(np.asarray(radius(t) if callable(radius) else radius, float), t.shape)
    tangent = np.gradient(c, t, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    u = np.cross(tangent[0], np.eye(3)[np.argmin(np.abs(tangent[0]))])
    frames = []
    for tj in tangent:  # parallel transport: remove the tangential part, renormalise
        u = u - (u @ tj) * tj
        u /= np.linalg.norm(u)
        frames.append((u, np.cross(tj, u)))
    th = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    rings = np.array([cj + rj * (np.cos(th)[:, None] * fu + np.sin(th)[:, None] * fv)
                      for cj, rj, (fu, fv) in zip(c, r, frames)])
    verts = np.vstack([rings.reshape(-1, 3), c[[0, -1]]])
    j, i = np.meshgrid(np.arange(n_along - 1), np.arange(n_around), indexing="ij")
    a = (j * n_around + i).ravel()
    b = (j * n_around + (i + 1) % n_around).ravel()
    faces = [np.stack([a, a + n_around, b], 1), np.stack([b, a + n_around, b + n_around], 1)]
    e0, e1, last = n_along * n_around, n_along * n_around + 1, (n_along - 1) * n_around
    ring = np.arange(n_around)
    faces += [np.stack([np.full(n_around, e0), ring, (ring + 1) % n_around], 1),
              np.stack([np.full(n_around, e1), last + (ring + 1) % n_around, last + ring], 1)]
    mesh = trimesh.Trimesh(verts, np.vstack(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh
