"""Decomposition of a surface model into sub-parts at its concave creases (section 6 of the
paper: an object is segmented at regions of deep concavity), and closing a sub-part's open
surface so it can be cut and weighed like a solid.
"""
from __future__ import annotations

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def concave_creases(mesh: trimesh.Trimesh, crease_deg: float = 30.0) -> np.ndarray:
    """Mask (E,) over ``mesh.face_adjacency``: concave edges with dihedral angle above ``crease_deg``."""
    angles = np.degrees(mesh.face_adjacency_angles)
    return (~mesh.face_adjacency_convex) & (angles > crease_deg)


def decompose(mesh: trimesh.Trimesh, crease_deg: float = 30.0, min_area_frac: float = 0.01) -> np.ndarray:
    """Segment a mesh's faces into regions separated by concave creases.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A closed surface model.
    crease_deg : float
        Edges whose faces meet concavely at more than this angle (deg, 0 = flat) separate regions.
    min_area_frac : float
        Regions smaller than this fraction of the total area are merged into the neighbour they
        share the longest boundary with.

    Returns
    -------
    (n_faces,) int
        Region per face, 0 the largest by area.
    """
    n = len(mesh.faces)
    adj = mesh.face_adjacency
    keep = ~concave_creases(mesh, crease_deg)
    graph = coo_matrix((np.ones(int(keep.sum())), (adj[keep, 0], adj[keep, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return merge_small_regions(mesh, labels, min_area_frac)


def merge_small_regions(mesh: trimesh.Trimesh, labels: np.ndarray, min_area_frac: float = 0.01,
                        force: np.ndarray | None = None) -> np.ndarray:
    """Merge small regions (or those in ``force``) into their longest-bordering neighbour.

    Parameters
    ----------
    labels : (n_faces,) int
    min_area_frac : float
        Area fraction under which a region is merged.
    force : (k,) int, optional
        Labels merged whatever their size (e.g. the cutters of a part tree).

    Returns
    -------
    (n_faces,) int
        Relabelled 0..R-1 by decreasing area.
    """
    labels = np.asarray(labels).copy()
    adj = mesh.face_adjacency
    edge_len = np.linalg.norm(np.diff(mesh.vertices[mesh.face_adjacency_edges], axis=1)[:, 0], axis=1)
    total = mesh.area
    forced = set() if force is None else {int(f) for f in force}
    while True:
        ids, inv = np.unique(labels, return_inverse=True)
        area = np.bincount(inv.ravel(), weights=mesh.area_faces, minlength=len(ids))
        small = [(area[k], ids[k]) for k in range(len(ids)) if area[k] < min_area_frac * total or ids[k] in forced]
        if not small or len(ids) == 1:
            break
        _, victim = min(small)
        la, lb = labels[adj[:, 0]], labels[adj[:, 1]]
        border = (la == victim) ^ (lb == victim)
        if not border.any():
            forced.discard(victim)
            if area[np.searchsorted(ids, victim)] >= min_area_frac * total:
                continue
            break  # an isolated small shell: leave it
        other = np.where(la[border] == victim, lb[border], la[border])
        nb, ninv = np.unique(other, return_inverse=True)
        target = nb[np.argmax(np.bincount(ninv.ravel(), weights=edge_len[border]))]
        labels[labels == victim] = target
        forced.discard(victim)
    ids, inv = np.unique(labels, return_inverse=True)
    area = np.bincount(inv.ravel(), weights=mesh.area_faces, minlength=len(ids))
    rank = np.empty(len(ids), int)
    rank[np.argsort(-area)] = np.arange(len(ids))
    return rank[inv.ravel()]


def region_adjacency(mesh: trimesh.Trimesh, labels: np.ndarray) -> dict[tuple[int, int], np.ndarray]:
    """Shared boundaries between regions.

    Returns
    -------
    dict
        ``(a, b)`` with ``a < b`` -> (k, 2) vertex indices of the mesh edges the regions share.
    """
    adj = mesh.face_adjacency
    la, lb = labels[adj[:, 0]], labels[adj[:, 1]]
    cross = la != lb
    pairs = np.sort(np.stack([la[cross], lb[cross]], axis=1), axis=1)
    edges = mesh.face_adjacency_edges[cross]
    out: dict[tuple[int, int], np.ndarray] = {}
    if len(pairs) == 0:
        return out
    keys, inv = np.unique(pairs, axis=0, return_inverse=True)
    inv = inv.ravel()
    for k, (a, b) in enumerate(keys):
        out[(int(a), int(b))] = edges[inv == k]
    return out


def capped_submesh(mesh: trimesh.Trimesh, faces: np.ndarray) -> trimesh.Trimesh:
    """The sub-surface on ``faces``, closed by fanning every boundary loop to its centroid.

    A region cut out of a closed surface along creases is open where it met its neighbours;
    the fan caps close it (exactly when the loop is planar and star-shaped from its centroid,
    approximately otherwise), so plane sections give closed curves and the volume properties
    (inertia) are defined.
    """
    sub = mesh.submesh([np.asarray(faces)], append=True, repair=False)
    sub.merge_vertices()
    directed = sub.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = directed[counts[inv.ravel()] == 1]
    if len(boundary) == 0:
        return sub
    nv = len(sub.vertices)
    g = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(nv, nv))
    _, comp = connected_components(g, directed=False)
    loop_of_edge = comp[boundary[:, 0]]
    loops, loop_idx = np.unique(loop_of_edge, return_inverse=True)
    centres = np.stack([sub.vertices[np.unique(boundary[loop_of_edge == c])].mean(axis=0) for c in loops])
    vertices = np.vstack([sub.vertices, centres])
    caps = np.column_stack([boundary[:, 1], boundary[:, 0], nv + loop_idx.ravel()])
    return trimesh.Trimesh(vertices, np.vstack([sub.faces, caps]), process=False)
