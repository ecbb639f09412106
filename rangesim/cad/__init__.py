"""CAD: parametric parts, part trees, B-spline surfaces, analytic features, surface sampling.

Knows parts, not sensors.
"""
from rangesim.cad.features import AnalyticFeatures, Circle3D, Segment3D
from rangesim.cad.green_piece import green_piece
from rangesim.cad.models import MODELS, load_model, model_names
from rangesim.cad.part import BuiltPart, PartNode

__all__ = [
    "AnalyticFeatures", "BuiltPart", "Circle3D", "MODELS", "PartNode", "Segment3D",
    "green_piece", "load_model", "model_names",
]
