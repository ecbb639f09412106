"""Ground truth and scores: exact edge labels of synthetic scans, and how well a detector finds them."""
from rangesim.evaluate._edge_scores import edge_scores
from rangesim.evaluate._feature_scores import feature_scores
from rangesim.evaluate._visible import data_boundary, score_edges, visible_truth
from rangesim.evaluate.ground_truth import (
    ImageEllipse,
    ImageSegment,
    ground_truth_edges,
    ground_truth_features,
    jump_edges,
)
from rangesim.evaluate.regions import region_boundaries

__all__ = [
    "ground_truth_edges", "ground_truth_features", "jump_edges", "edge_scores", "feature_scores",
    "ImageEllipse", "ImageSegment", "region_boundaries", "visible_truth", "score_edges", "data_boundary",
]
