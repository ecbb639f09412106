"""Planar cross-sections of triangle meshes: slicing, loop chaining, polygon properties,
and the test whether two planar sections cross each other.

All lengths are in the mesh's units (millimetres for the built-in parts).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def plane_basis(normal: np.ndarray) -> np.ndarray:
    """Two unit vectors (2, 3) spanning the plane with unit ``normal`` (3,), right-handed with it."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    helper = np.eye(3)[np.argmin(np.abs(n))]
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(n, u)])


@dataclass
class Section:
    """A closed planar cross-section.

    Attributes
    ----------
    origin : (3,) float
        A point of the cutting plane (the axis point it was cut at), mm.
    normal : (3,) float
        Unit normal of the plane (the local axis direction).
    points : (K, 3) float
        The outer loop, in order, not repeated at the end, mm.
    holes : list of (K_i, 3) float
        Loops inside the outer one (e.g. a hole through the sub-part).
    area : float
        Enclosed area (outer minus holes), mm^2.
    perimeter : float
        Length of the outer loop, mm.
    centroid : (3,) float
        Area centroid, mm.
    radii : (2,) float
        Principal radii, descending: the semi-axes of the ellipse with the same second moments
        of area (a circle of radius r gives (r, r)), mm.
    directions : (2, 3) float
        The in-plane directions of ``radii``.
    """

    origin: np.ndarray
    normal: np.ndarray
    points: np.ndarray
    holes: list[np.ndarray] = field(default_factory=list)
    area: float = 0.0
    perimeter: float = 0.0
    centroid: np.ndarray = field(default_factory=lambda: np.zeros(3))
    radii: np.ndarray = field(default_factory=lambda: np.zeros(2))
    directions: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))

    def to_dict(self) -> dict[str, Any]:
        return {
            "origin": self.origin.tolist(), "normal": self.normal.tolist(),
            "points": np.round(self.points, 6).tolist(),
            "holes": [np.round(h, 6).tolist() for h in self.holes],
            "area": self.area, "perimeter": self.perimeter, "centroid": self.centroid.tolist(),
            "radii": self.radii.tolist(), "directions": self.directions.tolist(),
        }


def chain_loops(segments: np.ndarray, tol: float) -> tuple[list[np.ndarray], list[bool]]:
    """Join line segments into polylines.

    Parameters
    ----------
    segments : (S, 2, 3) float
        Unordered segments, e.g. from :func:`trimesh.intersections.mesh_plane`.
    tol : float
        Endpoints closer than this (per coordinate, after rounding) are the same point.

    Returns
    -------
    loops : list of (K, 3) float
        One ordered vertex list per connected piece.
    closed : list of bool
        Per piece: True when it is a closed loop (every vertex joins exactly two segments).
    """
    if len(segments) == 0:
        return [], []
    pts = segments.reshape(-1, 3)
    keys = np.round(pts / tol).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    verts = pts[first]
    edges = inverse.reshape(-1, 2)
    edges = edges[edges[:, 0] != edges[:, 1]]
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    n = len(verts)
    if len(edges) == 0:
        return [], []
    degree = np.bincount(edges.ravel(), minlength=n)
    closed = []
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    graph = graph + graph.T
    n_comp, comp = connected_components(graph, directed=False)
    loops = []
    indptr, indices = graph.indptr, graph.indices
    for c in range(n_comp):
        members = np.flatnonzero((comp == c) & (degree > 0))
        if len(members) < 2:
            continue
        ends = members[degree[members] == 1]
        start = int(ends[0]) if len(ends) else int(members[0])
        order, prev, cur = [start], -1, start
        while True:  # walk the chain
            nbrs = indices[indptr[cur]:indptr[cur + 1]]
            nxt = [v for v in nbrs if v != prev]
            if not nxt or (nxt[0] == start):
                break
            prev, cur = cur, int(nxt[0])
            order.append(cur)
            if len(order) > len(members):
                break
        loops.append(verts[order])
        closed.append(bool(np.all(degree[members] == 2)) and len(order) == len(members))
    return loops, closed


def polygon_properties(loop: np.ndarray, normal: np.ndarray, holes: list[np.ndarray] = ()) -> dict[str, Any]:
    """Area, perimeter, centroid and principal radii of a planar loop (with holes).

    Parameters
    ----------
    loop : (K, 3) float
        Outer loop, mm.
    normal : (3,) float
        Plane normal.
    holes : list of (K_i, 3) float

    Returns
    -------
    dict
        ``area`` (mm^2), ``perimeter`` (mm), ``centroid`` (3,), ``radii`` (2,) descending (mm),
        ``directions`` (2, 3).
    """
    basis = plane_basis(normal)
    ref = loop.mean(axis=0)

    def moments(poly: np.ndarray) -> np.ndarray:
        p = (poly - ref) @ basis.T
        x, y = p[:, 0], p[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        c = x * yn - xn * y
        a = c.sum() / 2
        sign = 1.0 if a >= 0 else -1.0  # orientation-independent
        cx = ((x + xn) * c).sum() / 6
        cy = ((y + yn) * c).sum() / 6
        ixx = ((x * x + x * xn + xn * xn) * c).sum() / 12
        iyy = ((y * y + y * yn + yn * yn) * c).sum() / 12
        ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * c).sum() / 24
        return sign * np.array([a, cx, cy, ixx, iyy, ixy])

    m = moments(loop) - sum((moments(h) for h in holes), np.zeros(6))
    area = float(m[0])
    if area <= 0:
        return {"area": 0.0, "perimeter": 0.0, "centroid": ref, "radii": np.zeros(2), "directions": basis}
    c2 = m[1:3] / area
    cov = np.array([[m[3] / area - c2[0] ** 2, m[5] / area - c2[0] * c2[1]],
                    [m[5] / area - c2[0] * c2[1], m[4] / area - c2[1] ** 2]])
    ev, evec = np.linalg.eigh(cov)
    ev, evec = ev[::-1], evec[:, ::-1]
    perimeter = float(np.linalg.norm(np.roll(loop, -1, axis=0) - loop, axis=1).sum())
    return {
        "area": area, "perimeter": perimeter, "centroid": ref + c2 @ basis,
        "radii": 2.0 * np.sqrt(np.clip(ev, 0, None)), "directions": evec.T @ basis,
    }


def _point_in_loop(point: np.ndarray, loop: np.ndarray, basis: np.ndarray) -> bool:
    p = (loop - point) @ basis.T
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    crosses = (y > 0) != (yn > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x - y * (xn - x) / (yn - y)
    return bool(np.count_nonzero(crosses & (xi > 0)) % 2)


def slice_triangles(tris: np.ndarray, origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Segments where a plane cuts a triangle soup (vectorised; vertices on the plane count as above).

    Parameters
    ----------
    tris : (F, 3, 3) float
    origin, normal : (3,) float

    Returns
    -------
    (S, 2, 3) float
    """
    d = (tris - origin) @ normal  # (F, 3)
    above = d >= 0
    n_above = above.sum(axis=1)
    hit = (n_above == 1) | (n_above == 2)
    if not hit.any():
        return np.empty((0, 2, 3))
    t, d, above = tris[hit], d[hit], above[hit]
    # the lone vertex is on its own side of the plane
    lone_is_above = above.sum(axis=1) == 1
    lone = np.where(lone_is_above, np.argmax(above, axis=1), np.argmin(above, axis=1))
    rows = np.arange(len(t))
    i0, i1, i2 = lone, (lone + 1) % 3, (lone + 2) % 3
    p0, p1, p2 = t[rows, i0], t[rows, i1], t[rows, i2]
    d0, d1, d2 = d[rows, i0], d[rows, i1], d[rows, i2]
    a = p0 + (p1 - p0) * (d0 / (d0 - d1))[:, None]
    b = p0 + (p2 - p0) * (d0 / (d0 - d2))[:, None]
    return np.stack([a, b], axis=1)


def cut_section(tris: np.ndarray, origin: np.ndarray, normal: np.ndarray,
                near: np.ndarray | None = None, tol: float = 1e-6) -> tuple[Section | None, bool]:
    """The closed cross-section of a triangle soup by a plane.

    Parameters
    ----------
    tris : (F, 3, 3) float
        Triangles of a closed surface, or of the piece of it the recursive split is working on.
    origin, normal : (3,) float
        The plane.
    near : (3,) float, optional
        Of several outer loops, the one whose centroid is nearest this point is kept
        (default ``origin``).
    tol : float
        Points closer than this are merged when the segments are chained (mm).

    Returns
    -------
    section : Section or None
        None when the plane misses the triangles.
    closed : bool
        False when the kept loop (or a hole in it) is open: the plane leaves the piece.
    """
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    origin = np.asarray(origin, float)
    segs = slice_triangles(tris, origin, normal)

    if len(segs) == 0:
        return None, False
    loops, is_closed = chain_loops(np.asarray(segs), tol)
    if not loops:
        return None, False
    basis = plane_basis(normal)
    props = [polygon_properties(lp, normal) for lp in loops]
    areas = np.array([p["area"] for p in props])
    # outer loops: not inside a larger loop
    outer = []
    for i, lp in enumerate(loops):
        inside = any(areas[j] > areas[i] and _point_in_loop(lp[0], loops[j], basis) for j in range(len(loops)) if j != i)
        outer.append(not inside)
    candidates = [i for i in range(len(loops)) if outer[i] and areas[i] > 0]
    if not candidates:
        return None, False
    target = origin if near is None else np.asarray(near, float)
    best = min(candidates, key=lambda i: np.linalg.norm(props[i]["centroid"] - target))
    holes = [loops[j] for j in range(len(loops))
             if j != best and not outer[j] and _point_in_loop(loops[j][0], loops[best], basis)]
    # closedness: every vertex of the kept loop (and its holes) joins exactly two segments
    closed = is_closed[best] and all(is_closed[j] for j in range(len(loops))
                                     if j != best and not outer[j] and _point_in_loop(loops[j][0], loops[best], basis))
    pp = polygon_properties(loops[best], normal, holes)
    sec = Section(origin=origin, normal=normal, points=loops[best], holes=holes, area=pp["area"],
                  perimeter=pp["perimeter"], centroid=pp["centroid"], radii=pp["radii"], directions=pp["directions"])
    return sec, closed


def sections_intersect(a: Section, b: Section, eps: float = 1e-9) -> bool:
    """Whether two planar sections (their outer loops, as filled regions) cross each other.

    Both regions meet the line where the planes meet in sets of intervals; the sections cross
    when an interval of one overlaps an interval of the other. Parallel planes never cross.
    """
    d = np.cross(a.normal, b.normal)
    if np.linalg.norm(d) < 1e-9:
        return False
    d /= np.linalg.norm(d)

    def intervals(sec: Section, other: Section) -> np.ndarray:
        p = sec.points
        s = (p - other.origin) @ other.normal
        sn = np.roll(s, -1)
        cross = (s > eps) != (sn > eps)
        if not cross.any():
            return np.empty((0, 2))
        pn = np.roll(p, -1, axis=0)
        t = s[cross] / (s[cross] - sn[cross])
        hits = p[cross] + t[:, None] * (pn[cross] - p[cross])
        q = np.sort(hits @ d)
        return q[: len(q) // 2 * 2].reshape(-1, 2)

    ia, ib = intervals(a, b), intervals(b, a)
    if len(ia) == 0 or len(ib) == 0:
        return False
    lo = np.maximum(ia[:, None, 0], ib[None, :, 0])
    hi = np.minimum(ia[:, None, 1], ib[None, :, 1])
    return bool(np.any(hi > lo + eps))
