"""Loading and validating triangle meshes (STL, OBJ, PLY, OFF, GLB via trimesh).

The home of mesh loading: :func:`rangesim.cad.load_model` reads mesh files with it, and
the scene layer (:mod:`rangesim.scene.meshes`) re-exports it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from rangesim.core.errors import RangesimError

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")


def load_mesh(path: str | Path) -> trimesh.Trimesh:
    """Read a mesh file into one :class:`trimesh.Trimesh`, keeping the file's face order.

    A file holding several geometries (an OBJ with groups, a GLB scene) is concatenated in
    file order. The mesh is validated with :func:`validate_mesh`.

    Raises
    ------
    RangesimError
        Missing or unreadable file, a file with no triangles, non-finite vertices.
    """
    path = Path(path)
    if not path.is_file():
        raise RangesimError("no such mesh file", source=path)
    try:
        # process=False keeps the face order of the file, so face indices in scans match it
        loaded = trimesh.load(path, process=False)
    except Exception as exc:
        raise RangesimError(f"cannot read mesh ({type(exc).__name__}: {exc})", source=path) from exc
    if isinstance(loaded, trimesh.Scene):
        geometries = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        if not geometries:
            raise RangesimError("file holds no triangle mesh", source=path)
        loaded = trimesh.util.concatenate(geometries)
    if not isinstance(loaded, trimesh.Trimesh):
        raise RangesimError(
            f"file holds a {type(loaded).__name__}, not a triangle mesh", source=path
        )
    return validate_mesh(loaded, source=path)


def validate_mesh(mesh: trimesh.Trimesh, source: str | Path = "mesh") -> trimesh.Trimesh:
    """Check a mesh is usable for ray casting and return a cleaned copy.

    Duplicate vertices are merged (face order is kept) and a closed mesh wound inside-out is
    flipped, so its normals point outwards.

    Raises
    ------
    RangesimError
        No triangles, non-finite vertex coordinates, or face indices out of range.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if faces.ndim != 2 or len(faces) == 0:
        raise RangesimError("mesh is empty (no triangles)", source=source)
    if faces.shape[1] != 3:
        raise RangesimError(f"faces must be triangles, got {faces.shape[1]} indices", source=source)
    if not np.all(np.isfinite(vertices)):
        bad = int(np.count_nonzero(~np.isfinite(vertices).all(axis=1)))
        raise RangesimError(f"{bad} vertices have NaN or infinite coordinates", source=source)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise RangesimError("face indices out of range of the vertex list", source=source)
    clean = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    clean.merge_vertices()
    if clean.is_watertight and clean.is_winding_consistent and clean.volume < 0:
        clean.invert()
    return clean
