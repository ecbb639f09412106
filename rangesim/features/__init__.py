"""Features of edge maps (the paper's section 5): straight segments, circles from the edge
direction, arcs, model-guided ellipses, and the relations between them.

Image positions are (x = column, y = row) in pixels, integers at pixel centres.
"""
from rangesim.features._arcs import Arc, arcs
from rangesim.features._circles import Circle, circle_hypotheses, circles
from rangesim.features._ellipses import Ellipse, ellipses, mesh_circles, predict_ellipses
from rangesim.features._lines import Segment, lines, segment_pairs
from rangesim.features._relations import relations, relations_to_csv, relations_to_json

__all__ = [
    "Arc", "Circle", "Ellipse", "Segment", "arcs", "circle_hypotheses", "circles", "ellipses",
    "lines", "mesh_circles", "predict_ellipses", "relations", "relations_to_csv",
    "relations_to_json", "segment_pairs",
]
