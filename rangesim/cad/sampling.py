"""Surface points at a resolution: the polygon-filling sampler of section 3 of the paper.

Algorithm
---------
Every triangle is projected onto the coordinate plane (yz, zx or xy) where its normal has
its largest component and cut by the lines of one **global** square grid of spacing
``h``: lines at integer multiples of ``h``, shared by all triangles, so samples of
adjacent triangles meet up across their edges. On each cutting line the two crossings
with the triangle's edges are the start and the end of its inside segment (a triangle
is convex: start/end pairing gives one segment per line). The samples are

* the grid nodes on the segments (the nodes of the projection grid inside the
  triangle), at multiples of ``h`` along each line;
* segment end points, for the cutting lines of *both* grid directions, so a thin
  triangle lying between two parallel lines is still cut by the lines of the other
  direction;

lifted back onto the triangle as affine combinations of its vertices (exactly on its
plane). Samples closer than ``1e-6 h`` are merged.

Which end points are samples (``ends``): triangles fall into six groups, one per
projection plane and side (sign of the normal's largest component); within a group the
projected triangles of a consistently wound mesh tile a region without folds, so a
cutting line runs on from one triangle into the next. ``"triangle"`` (the default) keeps
every triangle's ends (the paper's per-polygon filling). ``"surface"`` keeps only ends on
the mesh boundary and on seams between groups: an end on an edge between two triangles
of one group is the paper's "middle" point, where the segment goes on. ``"thin"`` also drops ends within ``h / 2`` of a grid node and keeps at most one per
``h / 2`` voxel, so surfaces folded finer than ``h`` (threads) do not collect a point at
every fold. Point counts ("triangle" / "surface" / "thin"): a 300k-triangle sphere at
1/100 of its size ~290k / ~29k / ~26k (area / h^2: 30k); the threaded Green Piece at
0.2 in ~53k / ~43k / ~1.5k (area / h^2: 1k).

Guarantees
----------
With ``h`` the resolution and a point's *nearest point* its nearest other sample:

* (b) every sample lies on the mesh (an affine combination of one triangle's vertices);
* (a) consecutive samples on a cutting line are at most ``h`` apart in the projection
  plane and -- the plane being the one closest to the surface, so |slope| <= 1 along
  each grid direction -- at most ``h * sqrt(2)`` apart in 3-D, also across an edge into
  the next triangle of a group. So on a connected surface larger than ``h`` each
  sample's nearest point is within ``h * sqrt(3)``, the paper's bound (exceptions: a
  line that only touches a seam vertex; ``"thin"`` moves a neighbour by at most
  ``h / 2 * sqrt(3)``). Measured: at most ``1.4 h``;
* (c) every projected region wider than ``h`` in either grid direction is crossed by
  lines and gets samples (with ``"triangle"``: every triangle wider than ``h`` in its
  projection has samples on it); a sample-less triangle (smaller than ``h``) whose
  centroid is farther than ``h`` from every sample (a small isolated part) gets its
  centroid added, one per ``h``-sized voxel. Every surface point is then within
  ``h * sqrt(3)`` of a sample -- measured at most ``0.9 h`` on the test meshes (box,
  icosphere, slivers, tiny triangles), the fine sphere and the built-in models.

Normals
-------
The barycentric interpolation of the mesh's vertex normals, normalised (the paper's
"bi-linear interpolation of normals at vertices"). Vertex normals average the faces
around a vertex, so on a CAD mesh with sharp edges the normals are blended across the
edges -- on a box of two triangles per side every normal is tilted except at the face
centres. ``smooth=False`` gives the exact face normals.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from rangesim.core.errors import RangesimError
from rangesim.core.units import parse_length

#: file types :meth:`SurfacePoints.save` writes
POINT_SUFFIXES = (".ply", ".npz")

#: samples closer than this fraction of the resolution are one sample
MERGE_FRACTION = 1e-6

#: ``ends="thin"``: voxel side (and node distance) for thinning segment ends, in resolutions
THIN_FRACTION = 0.5

#: the choices of ``surface_points(ends=...)``
ENDS = ("thin", "surface", "triangle")

#: most samples one call may produce (about 80 bytes each, plus working memory)
MAX_POINTS = 20_000_000

#: (triangle, cutting line) rows handled at once, bounding the working memory
_CHUNK_ROWS = 1_000_000

#: the three edges of a triangle, as local vertex indices (edge e starts at corner e)
_EDGES = ((0, 1), (1, 2), (2, 0))


@dataclass(frozen=True)
class SurfacePoints:
    """Points sampled on a mesh's surface, with unit normals.

    Attributes
    ----------
    points : (N, 3) float64
        Positions, mm, in the mesh's frame.
    normals : (N, 3) float64
        Unit normals (outwards for a consistently wound, outward-facing mesh).
    face_index : (N,) int64
        The triangle of the mesh each point lies on.
    resolution : float
        The grid spacing ``h`` the points were sampled at, mm.
    """

    points: np.ndarray
    normals: np.ndarray
    face_index: np.ndarray
    resolution: float

    def __len__(self) -> int:
        return len(self.points)

    def subset(self, mask: np.ndarray) -> "SurfacePoints":
        """The points selected by a boolean mask or an index array."""
        return SurfacePoints(self.points[mask], self.normals[mask], self.face_index[mask], self.resolution)

    def save(self, path: str | Path) -> Path:
        """Write the points atomically: ``.ply`` (binary, with normals) or ``.npz`` (exact).

        The PLY has the project's point-cloud layout (:mod:`rangesim.io.ply`: float32
        ``x y z nx ny nz intensity``, intensity 1) and an identity pose, so the
        "camera frame" its header names is the mesh's frame; trimesh, Open3D and
        MeshLab read it. The NPZ keeps float64 ``points`` and ``normals``, int64
        ``face_index`` and ``resolution`` (mm).

        Parameters
        ----------
        path : str or Path
            Target file; parent directories are created.

        Returns
        -------
        Path
            The file written.

        Raises
        ------
        RangesimError
            An unsupported extension.
        """
        from rangesim.core.precision import warn_float32_steps
        from rangesim.io.atomic import atomic_path
        from rangesim.io.ply import VERTEX_DTYPE, ply_header

        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in POINT_SUFFIXES:
            found = f"{path.suffix!r} files" if path.suffix else "files without an extension"
            raise RangesimError(f"cannot write points as {found}; supported: {', '.join(POINT_SUFFIXES)}",
                                source=path)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            if suffix == ".npz":  # to a file object: np.savez would append ".npz" to the temp name
                np.savez(fh, points=self.points, normals=self.normals,
                         face_index=self.face_index, resolution=np.float64(self.resolution))
            else:
                warn_float32_steps(self.points, path.name, "a .ply stores float32: write .npz (float64)",
                                   stacklevel=4)
                vertices = np.empty(len(self), dtype=VERTEX_DTYPE)
                for i, axis in enumerate("xyz"):
                    vertices[axis] = self.points[:, i]
                    vertices["n" + axis] = self.normals[:, i]
                vertices["intensity"] = 1.0
                fh.write(ply_header(len(vertices), None, frame="model frame (mm)"))
                fh.write(vertices.tobytes())
        return path


def surface_points(
    mesh: trimesh.Trimesh,
    resolution: float | str,
    *,
    smooth: bool = True,
    ends: str = "triangle",
    view: Any = None,
) -> SurfacePoints:
    """Sample a mesh's surface at a resolution (the paper's polygon filling, section 3).

    See the module docstring for the algorithm and its guarantees. Vectorised over the
    triangles: about 1 s for a 300k-triangle mesh at 1/100 of its size.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The surface, mm. Zero-area triangles are skipped (they cover nothing; their
        edges belong to their neighbours). Vertices with equal coordinates count as one
        (STL triangle soups work).
    resolution : float or str
        Grid spacing ``h``: a number in mm or a length string such as ``"0.2in"``
        (:func:`rangesim.core.units.parse_length`); must be positive.
    smooth : bool
        True: normals interpolated from ``mesh.vertex_normals`` (blended across sharp
        edges; a triangle soup without shared vertices gets its face normals). False:
        the face normal of each point's triangle.
    ends : {"triangle", "surface", "thin"}
        Which segment end points are samples (see the module docstring): ``"triangle"``
        (default) every triangle's (the paper's per-polygon filling: every triangle wider
        than ``h`` in its projection has samples of its own); ``"surface"`` those on the
        mesh boundary and on seams between projection planes; ``"thin"``
        those, less the ones within ``h / 2`` of a grid node and at most one per
        ``h / 2`` voxel, so the count follows the resolution also on surfaces folded
        finer than ``h`` (threads, knurls).
    view : None
        No longer handled here: sampling is pure geometry, and what a viewpoint sees
        takes ray casting in the scene layer. Passing a viewpoint raises
        :class:`RangesimError` naming the replacement,
        :func:`rangesim.scene.visibility.visible_surface_points` (one range view, the
        paper's Fig. 10) or :func:`rangesim.scene.visibility.visible_points` (other
        occluders).

    Returns
    -------
    SurfacePoints
        Points, unit normals and face indices (grouped by projection plane, not sorted).

    Raises
    ------
    RangesimError
        A bad resolution, an empty mesh, a resolution so fine the sample count would
        exceed :data:`MAX_POINTS`, or a ``view``.

    Examples
    --------
    >>> import numpy as np
    >>> import trimesh
    >>> from rangesim.cad import surface_points
    >>> cube = trimesh.creation.box((20, 20, 20))
    >>> samples = surface_points(cube, 5.0)                    # every 5 mm
    >>> samples.points.shape[1], bool(np.all(np.abs(samples.points).max(1) > 9.999))   # all on the faces
    (3, True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 3.
    """
    if view is not None:
        raise RangesimError(
            "surface_points(view=...) moved to the scene layer: use "
            "rangesim.scene.visibility.visible_surface_points(mesh, resolution, view) "
            "or visible_points(surface_points(mesh, resolution), mesh, view)"
        )
    h = parse_length(resolution, positive=True, what="resolution")
    if ends not in ENDS:
        raise RangesimError(f"ends must be one of {', '.join(ENDS)}, got {ends!r}")
    if not (hasattr(mesh, "vertices") and hasattr(mesh, "faces")):
        raise RangesimError(f"surface_points needs a triangle mesh (a trimesh.Trimesh, or vertices and faces), "
                            f"got a {type(mesh).__name__}")
    try:
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except (TypeError, ValueError):
        raise RangesimError("surface_points needs a mesh's vertices and faces as arrays of numbers") from None
    if faces.ndim != 2 or faces.shape[1:] != (3,) or len(faces) == 0:
        raise RangesimError("cannot sample an empty mesh (no triangles)")
    if vertices.ndim != 2 or vertices.shape[1:] != (3,) or faces.min() < 0 or faces.max() >= len(vertices):
        raise RangesimError(f"surface_points needs (n, 3) vertices and faces indexing them, got {vertices.shape} "
                            f"vertices and face indices {faces.min()}..{faces.max()}")
    if not np.all(np.isfinite(vertices)):
        raise RangesimError("cannot sample a mesh with NaN or infinite vertex coordinates")
    tri = vertices[faces]                                        # (F, 3 corners, 3 xyz)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    scale = float(np.abs(vertices).max()) + h
    solid = double_area > (1e-12 * scale) ** 2                   # skip zero-area triangles
    axis = np.argmax(np.abs(cross), axis=1)
    group = 2 * axis + (np.take_along_axis(cross, axis[:, None], axis=1)[:, 0] > 0)
    # equal coordinates = one vertex: edges are shared by id, crossings computed alike
    _, vid = np.unique(vertices, axis=0, return_inverse=True)
    corner_ids = vid.reshape(-1)[faces]
    inner = np.zeros(faces.shape, dtype=bool) if ends == "triangle" else _inner_edges(corner_ids, group, solid)

    # projected coordinates in grid units (lines at exact integers): (F, 3 corners, 2)
    u, v = (axis + 1) % 3, (axis + 2) % 3
    uv = np.take_along_axis(tri, np.stack([u, v], axis=1)[:, None, :], axis=2) / h
    lines = (np.floor(uv.max(axis=1)) - np.ceil(uv.min(axis=1)) + 1).clip(min=0)[solid]  # (F', 2)
    # a bound on the work: two ends per (triangle, line) row, a node per h^2 of area
    expected = 2.0 * float(lines.sum()) + 0.5 * float(double_area[solid].sum()) / h**2
    if expected > MAX_POINTS:
        raise RangesimError(f"resolution {h:g} mm is too fine for this mesh (about {expected:.2g} points); "
                            f"use a coarser one")

    found_face, found_weight, found_node = [], [], []
    for ids in (np.flatnonzero(solid & (group == g)) for g in range(6)):
        for along_v in (True, False):                            # lines u = i, then lines v = j
            coords = uv[ids] if along_v else uv[ids][:, :, ::-1]
            for chunk in _chunks(coords, _CHUNK_ROWS):
                tri_of, weights, is_node = _cut(coords[chunk], corner_ids[ids[chunk]], inner[ids[chunk]],
                                                nodes=along_v)
                found_face.append(ids[chunk][tri_of])
                found_weight.append(weights)
                found_node.append(is_node)
    face_index = np.concatenate([np.zeros(0, np.int64), *found_face])
    weights = np.concatenate([np.zeros((0, 3)), *found_weight])
    is_node = np.concatenate([np.zeros(0, bool), *found_node])
    points = np.einsum("nk,nkd->nd", weights, tri[face_index])
    keep, is_node = _merge(points, is_node, MERGE_FRACTION * h)
    if ends == "thin":
        keep[keep] = _thin(points[keep], is_node[keep], THIN_FRACTION * h)
    points, face_index, weights = points[keep], face_index[keep], weights[keep]
    points, face_index, weights = _add_small_parts(points, face_index, weights, tri, solid, h)

    if smooth:
        normals = np.einsum("nk,nkd->nd", weights, np.asarray(mesh.vertex_normals)[faces[face_index]])
    else:
        normals = cross[face_index].copy()
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    # vertex normals of opposite sign can cancel (a sheet folded onto itself): face normal
    flat = length[:, 0] < 1e-9
    normals[flat], length[flat] = cross[face_index[flat]], double_area[face_index[flat], None]
    return SurfacePoints(points, normals / length, face_index.astype(np.int64), h)


# -- the sampler ----------------------------------------------------------------------------
def _inner_edges(corner_ids: np.ndarray, group: np.ndarray, solid: np.ndarray) -> np.ndarray:
    """(F, 3) bool: edge e of face f is shared with one other face of the same group.

    Both faces must be non-degenerate and wound consistently (they run the edge in
    opposite directions), so their projections lie on opposite sides of it and a cutting
    line runs straight on from one into the other. Boundary, seam and non-manifold
    edges are not inner.
    """
    start = corner_ids
    end = corner_ids[:, [1, 2, 0]]
    n_v = int(corner_ids.max()) + 1
    key = (np.minimum(start, end) * n_v + np.maximum(start, end)).ravel()
    order = np.argsort(key, kind="stable")
    k = key[order]
    # runs of exactly two equal keys
    same = k[1:] == k[:-1]
    pair = same.copy()
    pair[1:] &= ~same[:-1]
    pair[:-1] &= ~same[1:]
    first, second = order[:-1][pair], order[1:][pair]
    f1, f2 = first // 3, second // 3
    ok = (
        (f1 != f2) & solid[f1] & solid[f2] & (group[f1] == group[f2])
        & (start.ravel()[first] == end.ravel()[second])        # opposite directions
    )
    inner = np.zeros(corner_ids.size, dtype=bool)
    inner[first[ok]] = inner[second[ok]] = True
    return inner.reshape(corner_ids.shape)


def _chunks(coords: np.ndarray, max_rows: int) -> list[slice]:
    """Slices of triangles with at most about ``max_rows`` (triangle, cutting line) rows each."""
    rows = (np.floor(coords[:, :, 0].max(axis=1)) - np.ceil(coords[:, :, 0].min(axis=1)) + 1).clip(min=0)
    total = np.cumsum(rows)
    cuts = np.searchsorted(total, np.arange(max_rows, total[-1] if len(total) else 0, max_rows), side="right")
    bounds = [0, *cuts.tolist(), len(coords)]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


def _cut(
    coords: np.ndarray, corner_ids: np.ndarray, inner: np.ndarray, nodes: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut projected triangles with the grid lines ``a = i`` (integers): start/end pairing.

    Parameters
    ----------
    coords : (n, 3, 2) float64
        Triangle corners in grid units, (a, b): lines are ``a = const``, samples walk
        along ``b``.
    corner_ids : (n, 3) int64
        Vertex ids of the corners; each edge is evaluated from its lower id, so faces
        sharing it get bitwise-equal crossings.
    inner : (n, 3) bool
        Edges whose crossings are not samples (the line runs on into the next face).
    nodes : bool
        Also return the grid nodes ``b = j`` on each segment, not only its ends.

    Returns
    -------
    tri_of : (m,) int64
        Row of ``coords`` each sample belongs to.
    weights : (m, 3) float64
        Barycentric coordinates of each sample in its triangle.
    is_node : (m,) bool
        True for grid nodes, False for segment ends.
    """
    a, b = coords[..., 0], coords[..., 1]
    first = np.ceil(a.min(axis=1))
    count = (np.floor(a.max(axis=1)) - first + 1).clip(min=0).astype(np.int64)
    # one row per (triangle, cutting line), expanded without a Python loop
    tri_of = np.repeat(np.arange(len(coords)), count)
    line = first[tri_of] + _ranks(count)                         # exact integers, as floats
    a_t, b_t, id_t, inner_t = a[tri_of], b[tri_of], corner_ids[tri_of], inner[tri_of]
    n = len(tri_of)
    rows = np.arange(n)

    # each edge's crossing with the row's line: b value, barycentric weights, hit flag
    crossings = []
    for edge, (p, q) in enumerate(_EDGES):
        swap = id_t[:, p] > id_t[:, q]
        s, e = np.where(swap, q, p), np.where(swap, p, q)        # from the lower vertex id
        a_s, a_e, b_s, b_e = a_t[rows, s], a_t[rows, e], b_t[rows, s], b_t[rows, e]
        # exact comparisons in grid units; an edge lying on the line is skipped (its ends
        # are crossings of the two other edges)
        hit = (np.minimum(a_s, a_e) <= line) & (line <= np.maximum(a_s, a_e)) & (a_s != a_e)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip((line - a_s) / (a_e - a_s), 0.0, 1.0)
        t = np.where(line == a_e, 1.0, t)                        # a vertex on the line: exact
        cross_b = np.where(line == a_e, b_e, b_s + t * (b_e - b_s))
        w = np.zeros((n, 3))
        w[rows, s] = 1.0 - t
        w[rows, e] += t
        crossings.append((hit, cross_b, w, inner_t[:, edge]))
    # start = lowest crossing, end = highest (convex: all others lie between)
    hits = np.stack([hit for hit, _, _, _ in crossings], axis=1)          # (n, 3 edges)
    cross_bs = np.stack([cb for _, cb, _, _ in crossings], axis=1)
    ok = hits.any(axis=1)                                      # always, up to rounding
    lo_e = np.argmin(np.where(hits, cross_bs, np.inf), axis=1)
    hi_e = np.argmax(np.where(hits, cross_bs, -np.inf), axis=1)
    lo_b, hi_b = cross_bs[rows, lo_e], cross_bs[rows, hi_e]
    all_w = np.stack([w for _, _, w, _ in crossings], axis=1)   # (n, 3 edges, 3)
    lo_w, hi_w = all_w[rows, lo_e], all_w[rows, hi_e]
    # an end is a sample if it lies on a non-inner edge (a vertex lies on two edges)
    lo_keep = np.zeros(n, dtype=bool)
    hi_keep = np.zeros(n, dtype=bool)
    for hit, cb, _, inn in crossings:
        lo_keep |= hit & ~inn & (cb == lo_b)
        hi_keep |= hit & ~inn & (cb == hi_b)
    lo_keep &= ok
    hi_keep &= ok & (hi_b != lo_b)                               # a touch point once
    ends_tri = np.concatenate([tri_of[lo_keep], tri_of[hi_keep]])
    ends_w = np.concatenate([lo_w[lo_keep], hi_w[hi_keep]])
    if not nodes:
        return ends_tri, ends_w, np.zeros(len(ends_tri), dtype=bool)

    # grid nodes on each segment, ends included (a node on an inner edge is a sample)
    tri_of, lo_b, hi_b, lo_w, hi_w = tri_of[ok], lo_b[ok], hi_b[ok], lo_w[ok], hi_w[ok]
    j0 = np.ceil(lo_b)
    n_nodes = (np.floor(hi_b) - j0 + 1).clip(min=0).astype(np.int64)
    seg = np.repeat(np.arange(len(tri_of)), n_nodes)
    j = j0[seg] + _ranks(n_nodes)
    span = hi_b[seg] - lo_b[seg]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(span > 0, (j - lo_b[seg]) / span, 0.0)[:, None]
    node_w = (1.0 - s) * lo_w[seg] + s * hi_w[seg]
    is_node = np.r_[np.zeros(len(ends_tri), dtype=bool), np.ones(len(seg), dtype=bool)]
    return np.concatenate([ends_tri, tri_of[seg]]), np.concatenate([ends_w, node_w]), is_node


def _ranks(count: np.ndarray) -> np.ndarray:
    """0, 1, ..., count[i]-1 for each i, concatenated: the position within each group."""
    starts = np.repeat(np.cumsum(count) - count, count)
    return np.arange(int(count.sum())) - starts


def _merge(points: np.ndarray, is_node: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Keep the first of samples closer than ``tol`` (shared edges, nodes on edges).

    Returns the (N,) keep mask and the node flags, a kept sample counting as a node when
    a node was merged into it.
    """
    keep = np.ones(len(points), dtype=bool)
    is_node = is_node.copy()
    if len(points) < 2:
        return keep, is_node
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    keep[pairs[:, 1]] = False                                   # pairs come as (i < j)
    is_node[pairs[is_node[pairs[:, 1]], 0]] = True
    return keep, is_node


def _thin(points: np.ndarray, is_node: np.ndarray, spacing: float) -> np.ndarray:
    """(N,) keep mask: every node; ends farther than ``spacing`` from the nodes, one per voxel.

    Voxels are cubes of side ``spacing`` on a global grid, centred on multiples of
    ``spacing`` (ends lie on the cutting lines, so a voxel face there would split them by
    rounding); the first end in each is kept. A dropped end has a kept sample within
    ``spacing * sqrt(3)``.
    """
    keep = is_node.copy()
    ends = np.flatnonzero(~is_node)
    if ends.size and is_node.any():
        dist, _ = cKDTree(points[is_node]).query(points[ends], distance_upper_bound=spacing)
        ends = ends[~np.isfinite(dist)]
    voxel = np.floor(points[ends] / spacing + 0.5).astype(np.int64)
    _, first = np.unique(voxel, axis=0, return_index=True)
    keep[ends[first]] = True
    return keep


def _add_small_parts(points, face_index, weights, tri, solid, h):
    """Add centroids of sample-less triangles farther than ``h`` from all samples, one per voxel.

    A triangle smaller than ``h`` is normally covered by its neighbours' samples; this
    catches small parts on their own (a tiny loose triangle, a small feature between the
    lines).
    """
    has_point = np.zeros(len(tri), dtype=bool)
    has_point[face_index] = True
    empty = np.flatnonzero(solid & ~has_point)
    if empty.size == 0:
        return points, face_index, weights
    centroid = tri[empty].mean(axis=1)
    if len(points):
        dist, _ = cKDTree(points).query(centroid, distance_upper_bound=h)
        far = ~np.isfinite(dist)
        empty, centroid = empty[far], centroid[far]
    # one per h-voxel, so a cluster of tiny triangles adds one point, not one each
    _, first = np.unique(np.floor(centroid / h).astype(np.int64), axis=0, return_index=True)
    first.sort()
    return (
        np.concatenate([points, centroid[first]]),
        np.concatenate([face_index, empty[first]]),
        np.concatenate([weights, np.full((len(first), 3), 1.0 / 3.0)]),
    )
