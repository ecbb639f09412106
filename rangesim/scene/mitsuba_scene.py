"""Building the Mitsuba 3 scene from NumPy meshes (no temporary files).

This module does not import :mod:`rangesim.scene.scene` (which imports it to build and
cache ``Scene.mitsuba_scene()``): :func:`build_mitsuba_scene` takes anything shaped like
a :class:`~rangesim.scene.scene.Scene` (see :class:`SceneLike`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from rangesim.core.backend import aligned, mitsuba
from rangesim.core.errors import RangesimError
from rangesim.scene.materials import bsdf_dict


class SceneLike(Protocol):
    """What :func:`build_mitsuba_scene` reads of a Scene.

    ``objects``: each with ``name``, ``material``, ``albedo`` and ``mesh`` (``vertices``
    (N, 3), ``faces`` (M, 3)); ``source``: the scene file, for error messages.
    """

    @property
    def objects(self) -> Sequence[Any]: ...

    @property
    def source(self) -> str: ...


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
        mi.Point3f(aligned(np.asarray(vertices, dtype=np.float32).T))
    )
    params["faces"] = dr.ravel(mi.Vector3u(aligned(np.asarray(faces, dtype=np.uint32).T)))
    params.update()
    return mesh


def build_mitsuba_scene(scene: SceneLike) -> MitsubaScene:
    """Build the Mitsuba scene of ``scene``'s objects: one ``mi.Mesh`` per object.

    Each mesh carries its object's BSDF (see :mod:`rangesim.scene.materials`): the
    geometric scanner ignores it, the rendered scanner path-traces through it.
    """
    mi = mitsuba()
    shapes = []
    for k, obj in enumerate(scene.objects):
        try:
            bsdf = mi.load_dict(bsdf_dict(obj.material, obj.albedo))
        except Exception as exc:  # e.g. an unknown measured conductor name
            raise RangesimError(f"object {obj.name!r}: bad material ({exc})".splitlines()[0],
                                source=scene.source) from exc
        shapes.append(numpy_to_mitsuba_mesh(f"object{k}", obj.mesh.vertices, obj.mesh.faces, bsdf=bsdf))
    # uniform white room light: only the white-light intensity image uses it (the scanners
    # cast their own rays and light the scene with the laser alone)
    mi_scene = mi.load_dict({"type": "scene", "ambient": {"type": "constant", "radiance": 1.0},
                             **{f"object{k}": s for k, s in enumerate(shapes)}})
    return MitsubaScene(mi_scene, shapes, mi.variant())
