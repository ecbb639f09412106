"""Building the Mitsuba 3 scene from NumPy meshes (no temporary files)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from rangesim.core.backend import mitsuba

if TYPE_CHECKING:
    from rangesim.scene.scene import Scene


@dataclass
class MitsubaScene:
    """A Mitsuba scene and its shapes, in the order of ``Scene.objects``."""

    scene: Any
    shapes: list[Any]
    variant: str

    def part_index(self, si):
        """Dr.Jit Int32 array: index of the shape each interaction hit, -1 for a miss.

        One lazy ``dr.select`` per object, evaluated as a single kernel by the caller
        (reading ``si.shape`` element by element is slow, Mitsuba #1145).
        """
        import drjit as dr

        mi = mitsuba()
        part = dr.full(mi.Int32, -1, dr.width(si.t))
        for k, shape in enumerate(self.shapes):
            part = dr.select(si.shape == mi.ShapePtr(shape), k, part)
        return part


def numpy_to_mitsuba_mesh(name: str, vertices: np.ndarray, faces: np.ndarray, bsdf=None):
    """A ``mi.Mesh`` filled from (N, 3) vertices and (M, 3) faces.

    Vertices are converted to float32 and faces to uint32, transposed to the (3, N)
    C-contiguous layout Dr.Jit expects.
    """
    import drjit as dr

    mi = mitsuba()
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = bsdf
    mesh = mi.Mesh(name, len(vertices), len(faces), props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(
        mi.Point3f(np.ascontiguousarray(np.asarray(vertices, dtype=np.float32).T))
    )
    params["faces"] = dr.ravel(mi.Vector3u(np.ascontiguousarray(np.asarray(faces, dtype=np.uint32).T)))
    params.update()
    return mesh


def build_mitsuba_scene(scene: "Scene") -> MitsubaScene:
    """Build the Mitsuba scene of ``scene``'s objects: one ``mi.Mesh`` per object."""
    mi = mitsuba()
    shapes = [
        numpy_to_mitsuba_mesh(f"object{k}", obj.mesh.vertices, obj.mesh.faces)
        for k, obj in enumerate(scene.objects)
    ]
    mi_scene = mi.load_dict({"type": "scene", **{f"object{k}": s for k, s in enumerate(shapes)}})
    return MitsubaScene(mi_scene, shapes, mi.variant())
