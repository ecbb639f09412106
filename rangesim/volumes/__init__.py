"""Volumes and sweeps (section 6 of the paper): the CSG-like volumetric model of a part tree
(:func:`volumetric_model`, :func:`boolean_expression`) and generalized-cylinder models of surfaces
(:func:`generalized_cylinders`), with the concave-crease decomposition they start from."""
from rangesim.volumes._decompose import capped_submesh, concave_creases, decompose
from rangesim.volumes.gc import (
                                 GeneralizedCylinder,
                                 Junction,
                                 axis_and_sections,
                                 generalized_cylinders,
                                 least_inertia_axis,
)
from rangesim.volumes.sections import Section, cut_section, sections_intersect

__all__ = [
    "GeneralizedCylinder", "Junction", "Section", "axis_and_sections", "capped_submesh", "concave_creases",
    "cut_section", "decompose", "generalized_cylinders", "least_inertia_axis", "sections_intersect",
]
