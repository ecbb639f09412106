"""Loading and validating triangle meshes: re-exported from :mod:`rangesim.cad.meshes`.

Mesh files are read in the CAD layer (``rangesim.cad.load_model`` opens them too, and
``cad`` sits below ``scene``); scenes use the same functions through this module.
"""
from rangesim.cad.meshes import MESH_SUFFIXES, load_mesh, validate_mesh

__all__ = ["MESH_SUFFIXES", "load_mesh", "validate_mesh"]
