"""CAD: parametric parts, part trees, B-spline surfaces, analytic features, surface sampling.

Knows parts, not sensors or scenes: pure geometry over NumPy, SciPy and trimesh (mesh
files are read here, :mod:`rangesim.cad.meshes`). What a viewpoint sees of sampled points
is ray casting, in the scene layer: :func:`rangesim.scene.visibility.visible_points`.
"""
from rangesim.cad._green_piece import green_piece
from rangesim.cad._renault_piece import renault_piece
from rangesim.cad.bspline import BSplineSurface, ParametricSurface, surface_curvatures, tessellate_surface
from rangesim.cad.coons import CoonsPatch, coons_patch
from rangesim.cad.features import AnalyticFeatures, Circle3D, Curve3D, Segment3D
from rangesim.cad.machined import machined_design, machined_part  # seeded benchmark parts (issue 14)
from rangesim.cad.models import MODELS, load_model, model_names
from rangesim.cad.part import BuiltPart, PartNode
from rangesim.cad.sampling import SurfacePoints, surface_points

__all__ = [
    "AnalyticFeatures", "BSplineSurface", "BuiltPart", "Circle3D", "CoonsPatch", "Curve3D", "MODELS",
    "ParametricSurface", "PartNode", "Segment3D", "coons_patch", "green_piece", "load_model", "model_names",
    "renault_piece", "machined_design", "machined_part", "SurfacePoints", "surface_curvatures", "surface_points", "tessellate_surface",
]
