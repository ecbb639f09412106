"""Generalized cylinders from a surface model (section 6 of the paper).

Three steps: (1) decompose the object into sub-parts at its concave creases, or take the
sub-parts of its part tree; (2) per sub-part, the recursive splitting: the axis of least
moment of inertia gives the first axis between the centroids of two cross-sections near the
extremes; the cross-section through the mid-point of an axis segment, perpendicular to it,
splits the segment and the surface in two, recursively, until a segment is no longer than the
resolution or a new cross-section is not closed or crosses another; then every cross-section
is moved to its centroid and turned perpendicular to the local axis (step 5 of the paper),
the end sections included: they are re-cut perpendicular to the axis extrapolated from the
interior, never steering it; (3) junctions between the generalized cylinders of neighbouring
sub-parts.

Each split only cuts the triangles of its own piece, and the pieces of one level share out
the surface, so a level costs O(m) and the n cross-sections come in O(log n) levels:
O(m log n) in all. The adjustment re-cuts the whole solid (a turned plane leaves the split's
pieces), O(m n) per pass, a few passes.

Sub-parts as closed solids: from a part tree (a :class:`~rangesim.cad.part.BuiltPart`), each
material leaf's own design solid (closed, exact); from face labels or the crease
decomposition, the labelled faces of the surface closed by fanning each open boundary loop to
its centroid (:func:`~rangesim.volumes._decompose.capped_submesh`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from rangesim.core.errors import RangesimError
from rangesim.volumes._decompose import capped_submesh, decompose, merge_small_regions, region_adjacency
from rangesim.volumes.sections import Section, cut_section, sections_intersect


@dataclass
class Junction:
    """Where the generalized cylinders of two neighbouring sub-parts meet.

    Attributes
    ----------
    a, b : str
        Names of the two generalized cylinders.
    point : (3,) float
        Mean of the shared boundary's vertices, mm.
    boundary : (k, 2, 3) float
        The mesh edges the two sub-parts share, mm.
    length : float
        Length of the shared boundary, mm.
    angle_deg : float
        Angle between the two axes' local directions at their points nearest ``point``
        (0..90 deg, axes as lines).
    where_a, where_b : {"start", "end", "middle"}
        Which part of each axis is nearest the junction.
    """

    a: str
    b: str
    point: np.ndarray
    boundary: np.ndarray
    length: float
    angle_deg: float
    where_a: str
    where_b: str

    def to_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "point": self.point.tolist(), "length": self.length,
                "angle_deg": self.angle_deg, "where_a": self.where_a, "where_b": self.where_b,
                "n_boundary_edges": len(self.boundary)}


@dataclass
class GeneralizedCylinder:
    """One sub-part as an axis, cross-sections and a sweeping rule.

    Attributes
    ----------
    name : str
    axis : (N, 3) float
        Polyline through the cross-sections' centroids, mm.
    sections : list of Section
        N closed planar cross-sections, in axis order; ``section.origin`` is its centroid and
        ``section.normal`` the local axis direction.
    faces : (F,) int
        Faces of the input mesh that belong to the sub-part.
    mesh : trimesh.Trimesh
        The closed solid the axis and sections were taken from.
    recursions : int
        Deepest level of the recursive split reached.
    junctions : list of Junction
    """

    name: str
    axis: np.ndarray
    sections: list[Section]
    faces: np.ndarray
    mesh: trimesh.Trimesh = field(repr=False)
    recursions: int = 0
    junctions: list[Junction] = field(default_factory=list)

    @property
    def length(self) -> float:
        """Length of the axis polyline, mm."""
        return float(np.linalg.norm(np.diff(self.axis, axis=0), axis=1).sum())

    @property
    def sweep(self) -> dict[str, np.ndarray]:
        """The sweeping rule sampled at the cross-sections.

        Returns
        -------
        dict
            ``s`` (N,) arc length along the axis (mm), ``area`` (N,) mm^2, ``perimeter`` (N,) mm,
            ``radii`` (N, 2) principal radii (mm), ``eccentricity`` (N,) 1 - r2/r1, ``tangent``
            (N, 3) unit axis directions.
        """
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.axis, axis=0), axis=1))])
        radii = np.array([sec.radii for sec in self.sections]).reshape(-1, 2)
        return {
            "s": s,
            "area": np.array([sec.area for sec in self.sections]),
            "perimeter": np.array([sec.perimeter for sec in self.sections]),
            "radii": radii,
            "eccentricity": 1.0 - radii[:, 1] / np.maximum(radii[:, 0], 1e-12),
            "tangent": np.array([sec.normal for sec in self.sections]).reshape(-1, 3),
        }

    def to_dict(self, with_points: bool = True) -> dict[str, Any]:
        """JSON-ready dict (sections with their loops unless ``with_points`` is False)."""
        sections = [sec.to_dict() for sec in self.sections]
        if not with_points:
            for d in sections:
                d.pop("points"), d.pop("holes")
        return {
            "name": self.name, "axis": self.axis.tolist(), "length": self.length,
            "recursions": self.recursions, "n_faces": int(len(self.faces)),
            "sweep": {k: v.tolist() for k, v in self.sweep.items()},
            "sections": sections, "junctions": [j.to_dict() for j in self.junctions],
        }


# -- step 2: axis and cross-sections of one closed sub-part --------------------------------
def least_inertia_axis(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (3,) and unit direction (3,) of the axis of least moment of inertia.

    Uses the solid's inertia (unit density) when the mesh encloses a volume, else the area-weighted
    covariance of the triangles.
    """
    if mesh.volume > 1e-9 * max(mesh.scale, 1e-9) ** 3:
        centre = np.asarray(mesh.center_mass, float)
        moments, axes = np.linalg.eigh(np.asarray(mesh.moment_inertia, float))
        return centre, axes[:, 0]
    w = mesh.area_faces / mesh.area_faces.sum()
    c = mesh.triangles_center
    centre = w @ c
    cov = (c - centre).T @ ((c - centre) * w[:, None])
    return centre, np.linalg.eigh(cov)[1][:, -1]


@dataclass
class _Piece:
    tris: np.ndarray  # (F, 3, 3) triangles between two consecutive sections


def axis_and_sections(mesh: trimesh.Trimesh, resolution: float, max_recursions: int = 10,
                      end_offset: float = 0.03, adjust_passes: int = 3
                      ) -> tuple[np.ndarray, list[Section], int]:
    """The paper's recursive splitting on one closed solid.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed surface of the sub-part (mm).
    resolution : float
        A segment of the axis no longer than this is not split (mm).
    max_recursions : int
        Deepest level of splitting (the paper's figure 18 shows 1, 3 and 5).
    end_offset : float
        The first two cross-sections lie this fraction of the extent inside the extremes.
    adjust_passes : int
        Passes of the final adjustment (0: keep the sections as split): the first from the
        middle outwards, the others re-centring every section (see :func:`_adjust_pass`);
        it stops early once nothing moves.

    Returns
    -------
    axis : (N, 3) float
    sections : list of N Section
    recursions : int
        Deepest level reached.
    """
    tris = np.asarray(mesh.triangles, float)
    tol = 1e-7 * max(float(mesh.scale), 1e-9)
    centre, a = least_inertia_axis(mesh)
    t = (mesh.vertices - centre) @ a
    lo, hi = float(t.min()), float(t.max())
    delta = end_offset * (hi - lo)
    ends = []
    for tt in (lo + delta, hi - delta):
        sec, closed = cut_section(tris, centre + tt * a, a, tol=tol)
        if sec is None:
            raise ValueError("the sub-part has no cross-section near its extremes")
        ends.append(sec)
    for s in ends:
        s.normal = a.copy()

    # -- recursive split: a list of sections and the pieces between them --
    deepest = 0

    def split(piece: _Piece, s0: Section, s1: Section, depth: int) -> tuple[list[Section], list[_Piece]]:
        nonlocal deepest
        p0, p1 = s0.centroid, s1.centroid
        seg = p1 - p0
        length = float(np.linalg.norm(seg))
        if depth >= max_recursions or length <= resolution or length == 0:
            return [s0, s1], [piece]
        d = seg / length
        mid = (p0 + p1) / 2
        new, closed = cut_section(piece.tris, mid, d, near=mid, tol=tol)
        if new is None or not closed or sections_intersect(new, s0) or sections_intersect(new, s1):
            return [s0, s1], [piece]
        deepest = max(deepest, depth + 1)
        # split the surface at the plane: triangles touching either side go to that side
        dist = (piece.tris - new.centroid) @ d
        left = _Piece(piece.tris[dist.min(axis=1) <= tol])
        right = _Piece(piece.tris[dist.max(axis=1) >= -tol])
        sa, pa = split(left, s0, new, depth + 1)
        sb, pb = split(right, new, s1, depth + 1)
        return sa + sb[1:], pa + pb

    sections, _ = split(_Piece(tris), ends[0], ends[1], 0)

    # -- adjust (step 5): each section through its centroid, perpendicular to the local axis --
    for k in range(adjust_passes):
        if not _adjust_pass(tris, sections, tol, outwards=k == 0) and k > 0:
            break
    for s in sections:
        s.origin = s.centroid.copy()
    axis = np.array([s.centroid for s in sections])
    return axis, sections, deepest


#: an end section may not cut a face whose normal is within this angle of the axis (deg): such
#: a face is an end cap (a smooth tip 3 % of the length from its extreme is about 45 deg off)
END_CAP_DEG = 30.0
#: an end section may slide inwards to this fraction of its distance from its neighbour
END_MIN_FRACTION = 0.5


def _tangent(pts: np.ndarray, i: int, lo: int, hi: int) -> np.ndarray:
    """Unit axis direction at ``pts[i]``: the derivative of the quadratic through three
    consecutive points of ``pts[lo:hi + 1]`` (centred on ``i`` where it can be), in arc length.

    Second-order accurate on an unevenly spaced axis, where the chord of the two neighbours is
    only first-order accurate; with two points, the chord.
    """
    if hi - lo < 2:
        t = pts[min(i + 1, hi)] - pts[max(i - 1, lo)]
        return t / max(np.linalg.norm(t), 1e-300)
    j = min(max(i - 1, lo), hi - 2)
    p = pts[j:j + 3]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    if s[1] <= 0 or s[2] <= s[1]:
        t = p[2] - p[0]
    else:
        x = s[i - j]
        w = [(2 * x - s[1] - s[2]) / ((s[0] - s[1]) * (s[0] - s[2])),
             (2 * x - s[0] - s[2]) / ((s[1] - s[0]) * (s[1] - s[2])),
             (2 * x - s[0] - s[1]) / ((s[2] - s[0]) * (s[2] - s[1]))]
        t = w[0] * p[0] + w[1] * p[1] + w[2] * p[2]
    return t / max(np.linalg.norm(t), 1e-300)


def _rotate(v: np.ndarray, k: np.ndarray, angle: float) -> np.ndarray:
    """``v`` turned by ``angle`` (rad) about the unit axis ``k`` (Rodrigues)."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(k, v) * s + k * (k @ v) * (1 - c)


def _extrapolated_section(tris: np.ndarray, old: Section, nb: Section, nb2: Section | None, tol: float,
                          end: bool) -> Section | None:
    """A section re-cut perpendicular to the axis extrapolated outwards from its two inner
    neighbours ``nb`` (next to it) and ``nb2``.

    The axis beyond ``nb`` is continued as a circular arc with the turning rate (rad/mm) of
    the normals from ``nb2`` to ``nb`` (a straight line without ``nb2``), and the section
    keeps the distance of its old centroid from ``nb`` along ``nb``'s normal. Any closed cut
    beyond ``nb`` is taken, except for an ``end`` section: that one slides inwards (down to
    ``END_MIN_FRACTION`` of the distance) until it cuts no face turned towards the axis
    (within ``END_CAP_DEG``): such a face is an end cap, and a section through it is not a
    section of the sweep. None when no cut qualifies.
    """
    c1 = nb.centroid
    n1 = nb.normal * np.sign((old.centroid - c1) @ nb.normal or 1.0)  # pointing outwards
    dist = float((old.centroid - c1) @ n1)
    if dist <= tol:
        return None
    k, rate = np.zeros(3), 0.0
    if nb2 is not None:
        n2 = nb2.normal * np.sign(nb2.normal @ n1 or 1.0)
        cross = np.cross(n2, n1)
        sin = float(np.linalg.norm(cross))
        d12 = float(np.linalg.norm(c1 - nb2.centroid))
        if sin > 1e-12 and d12 > tol:
            k, rate = cross / sin, float(np.arctan2(sin, n2 @ n1)) / d12
    for frac in (np.linspace(1.0, END_MIN_FRACTION, 6) if end else (1.0,)):
        length = frac * dist
        tangent = _rotate(n1, k, rate * length)
        chord = _rotate(n1, k, rate * length / 2)  # the chord of an arc bisects its end tangents
        origin = c1 + length * chord
        sec, closed = cut_section(tris, origin, tangent, near=origin, tol=tol)
        if sec is None or not closed or (sec.centroid - c1) @ n1 <= tol:
            continue
        if not end or not _cuts_cap(tris, sec, tol):
            return sec
    return None


def _cuts_cap(tris: np.ndarray, sec: Section, tol: float) -> bool:
    """Whether the plane of ``sec`` cuts, within its loop's reach, a face whose normal is
    within ``END_CAP_DEG`` of the section's normal."""
    d = (tris - sec.origin) @ sec.normal
    crossing = (d.min(axis=1) < -tol) & (d.max(axis=1) > tol)
    if not crossing.any():
        return False
    t = tris[crossing]
    reach = np.linalg.norm(sec.points - sec.centroid, axis=1).max() + tol
    near = np.linalg.norm(t.mean(axis=1) - sec.centroid, axis=1) <= reach
    n = np.cross(t[near, 1] - t[near, 0], t[near, 2] - t[near, 0])
    length = np.linalg.norm(n, axis=1)
    cos = np.abs(n @ sec.normal)[length > 0] / length[length > 0]
    return bool(np.any(cos > np.cos(np.radians(END_CAP_DEG))))


def _adjust_pass(tris: np.ndarray, sections: list[Section], tol: float, outwards: bool) -> bool:
    """One pass of step 5 on the whole solid ``tris``: the sections re-cut perpendicular to
    the local axis at their centroids, in place. Returns whether anything moved.

    ``outwards``: the three middle sections take the axis direction of the quadratic through
    their neighbours' centroids, and the others, from the middle out, are re-cut
    perpendicular to the axis extrapolated from their two (already adjusted) inner
    neighbours (:func:`_extrapolated_section`): the first cuts near the extremes, and the
    split's cuts next to them, may be far off the axis, and must not steer it. Otherwise
    every interior section takes the quadratic's direction (Jacobi) and the two end sections
    are extrapolated. The cuts are of the whole solid, not of the pieces of the split, whose
    borders are the split's own (possibly oblique) planes. A new section that would cross
    another (the next or the one after) is not taken.
    """
    n = len(sections)
    if n < 2:
        return False
    new = list(sections)
    pts = np.array([s.centroid for s in sections])

    def central(i: int) -> None:
        t = _tangent(pts, i, 0, n - 1)
        sec, closed = cut_section(tris, pts[i], t, near=pts[i], tol=tol)
        if sec is not None and closed:
            new[i] = sec

    def extrapolate(i: int, step: int) -> None:
        nb2 = new[i - 2 * step] if 0 <= i - 2 * step < n else None
        sec = _extrapolated_section(tris, sections[i], new[i - step], nb2, tol, end=i in (0, n - 1))
        if sec is not None:
            new[i] = sec

    if n == 2:
        for i in (0, 1):
            central(i)
    elif outwards:
        mid = n // 2
        core = [i for i in (mid - 1, mid, mid + 1) if 0 < i < n - 1]
        for i in core:
            central(i)
        for i in range(max(core) + 1, n):
            extrapolate(i, 1)
        for i in range(min(core) - 1, -1, -1):
            extrapolate(i, -1)
    else:
        for i in range(1, n - 1):
            central(i)
        extrapolate(n - 1, 1)
        extrapolate(0, -1)
    # the paper's sections never cross: a new one that crosses a neighbour keeps its old cut
    for _ in range(n):
        crossing = {k for i in range(n - 1) for j in (i + 1, i + 2) if j < n and sections_intersect(new[i], new[j])
                    for k in (i, j) if new[k] is not sections[k]}
        if not crossing:
            break
        for k in crossing:
            new[k] = sections[k]
    moved = max(float(np.linalg.norm(a.centroid - b.centroid) + np.linalg.norm(np.cross(a.normal, b.normal)))
                for a, b in zip(new, sections))
    sections[:] = new
    return moved > tol


# -- steps 1 and 3 --------------------------------------------------------------------------
def _subparts(mesh: trimesh.Trimesh, parts: Any, crease_deg: float, min_area_frac: float
              ) -> tuple[np.ndarray, list[str], list[trimesh.Trimesh]]:
    """Face labels, names and closed solids of the sub-parts."""
    if parts is None:
        labels = decompose(mesh, crease_deg, min_area_frac)
        names = [f"region_{k}" for k in range(labels.max() + 1)]
        return labels, names, [capped_submesh(mesh, np.flatnonzero(labels == k)) for k in range(len(names))]
    if hasattr(parts, "tree") and hasattr(parts, "face_labels"):  # a BuiltPart: its material leaves
        from rangesim.cad.part import manifold_to_trimesh

        leaves = parts.tree.leaves()
        cutters = _cutter_leaves(parts.tree)
        force = [k for k, leaf in enumerate(leaves) if leaf.name in cutters]
        raw = np.asarray(parts.face_labels)
        merged = merge_small_regions(mesh, raw, 0.0, force=np.array(force, int))
        labels = np.empty_like(merged)
        names, solids = [], []
        for new_id in range(merged.max() + 1):
            mine = raw[merged == new_id]
            leaf = leaves[int(np.bincount(mine[~np.isin(mine, force)] if np.any(~np.isin(mine, force)) else mine).argmax())]
            labels[merged == new_id] = len(names)
            names.append(leaf.name)
            solids.append(manifold_to_trimesh(leaf.solid))
        return labels, names, solids
    labels = np.asarray(parts, dtype=np.int64)
    if labels.shape != (len(mesh.faces),):
        raise RangesimError(f"parts must be a BuiltPart or ({len(mesh.faces)},) face labels, got shape {labels.shape}")
    ids = np.unique(labels)
    remap = np.searchsorted(ids, labels)
    return remap, [f"part_{int(i)}" for i in ids], [capped_submesh(mesh, np.flatnonzero(remap == k)) for k in range(len(ids))]


def _cutter_leaves(node) -> set[str]:
    """Names of leaves that only ever remove material (below a difference's second+ child)."""
    out: set[str] = set()
    if node.operation == "difference":
        for child in node.children[1:]:
            out |= {leaf.name for leaf in child.leaves()}
    for child in node.children:
        out |= _cutter_leaves(child)
    return out


def _nearest_on_axis(axis: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, str]:
    """Unit local direction (3,) of the axis nearest ``point`` and where it is (start/end/middle)."""
    if len(axis) < 2:
        return np.zeros(3), "middle"
    a, b = axis[:-1], axis[1:]
    ab = b - a
    t = np.clip(((point - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
    dist = np.linalg.norm(a + t[:, None] * ab - point, axis=1)
    k = int(np.argmin(dist))
    where = "start" if (k == 0 and t[k] < 0.5) else "end" if (k == len(ab) - 1 and t[k] > 0.5) else "middle"
    return ab[k] / max(np.linalg.norm(ab[k]), 1e-300), where


def junctions(mesh: trimesh.Trimesh, labels: np.ndarray, gcs: list[GeneralizedCylinder]) -> list[Junction]:
    """Junctions between sub-parts that share mesh edges (attached to both cylinders too)."""
    out = []
    for (ia, ib), edges in region_adjacency(mesh, labels).items():
        ga, gb = gcs[ia], gcs[ib]
        seg = mesh.vertices[edges]
        point = mesh.vertices[np.unique(edges)].mean(axis=0)
        da, wa = _nearest_on_axis(ga.axis, point)
        db, wb = _nearest_on_axis(gb.axis, point)
        angle = float(np.degrees(np.arccos(np.clip(abs(da @ db), 0, 1))))
        j = Junction(ga.name, gb.name, point, seg, float(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1).sum()),
                     angle, wa, wb)
        out.append(j)
        ga.junctions.append(j)
        gb.junctions.append(j)
    return out


def generalized_cylinders(mesh: trimesh.Trimesh, resolution: float, parts: Any = None, *,
                          max_recursions: int = 10, crease_deg: float = 30.0, min_area_frac: float = 0.01,
                          end_offset: float = 0.03, adjust_passes: int = 3) -> list[GeneralizedCylinder]:
    """A generalized-cylinder model of a surface: one cylinder per sub-part, with junctions.

    Limitation: a section plane that cuts a sub-part into several pieces keeps the piece
    nearest the axis (right for the far arm of a bent part, wrong for a plate pierced by a
    hole, whose section there is two pieces: half the area, the axis pulled off the centre
    line); give such parts by their part tree (``parts``: the holes as cutters).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed surface model (mm).
    resolution : float
        Axis segments no longer than this are not split further (mm).
    parts : None, BuiltPart or (n_faces,) int
        The sub-parts: None decomposes ``mesh`` at concave creases (:func:`decompose`); a
        BuiltPart uses its part tree (each material leaf's design solid; cutter faces such as
        hole walls join the sub-part they border); face labels use the labelled regions.
    max_recursions : int
        Deepest split level (figure 18 of the paper: 1, 3, 5).
    crease_deg, min_area_frac : float
        Decomposition: concave dihedral angle (deg) that separates regions, and the area
        fraction under which a region is merged into a neighbour.
    end_offset : float
        First cross-sections this fraction of the extent inside the extremes.
    adjust_passes : int
        Passes of the final adjustment of the sections.

    Returns
    -------
    list of GeneralizedCylinder
        In sub-part order, each with its ``junctions``.

    Examples
    --------
    >>> from rangesim.volumes import generalized_cylinders
    >>> from rangesim.volumes.shapes import deformed_ellipsoid
    >>> mesh, centre_line = deformed_ellipsoid(subdivisions=3)
    >>> [len(generalized_cylinders(mesh, 4.0, max_recursions=r)[0].sections) for r in (1, 3, 5)]   # Fig. 18
    [3, 9, 33]

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 6.
    .. [2] T. O. Binford, "Visual perception by computer", IEEE Conference on Systems and
       Control, Miami (1971) (generalized cylinders).
    """
    labels, names, solids = _subparts(mesh, parts, crease_deg, min_area_frac)
    gcs = []
    for k, (name, solid_mesh) in enumerate(zip(names, solids)):
        axis, sections, depth = axis_and_sections(solid_mesh, resolution, max_recursions, end_offset, adjust_passes)
        gcs.append(GeneralizedCylinder(name, axis, sections, np.flatnonzero(labels == k), solid_mesh, depth))
    junctions(mesh, labels, gcs)
    return gcs
