"""Edge detection on range data (pure NumPy/SciPy over arrays; no Mitsuba, no files).

Every detector takes a RangeScan (synthetic or recorded, NaN holes allowed) and returns an
:class:`EdgeMap`; :data:`DETECTORS` names them for the CLI, sweeps and benchmarks.
"""
from rangesim.edges.curvature import curvature
from rangesim.edges.edgemap import EdgeMap
from rangesim.edges.gradient import gradient
from rangesim.edges.line_fit import line_fit, line_fit_points
from rangesim.edges.link import EdgeChain, link
from rangesim.edges.normal import normal
from rangesim.edges.pcl_organized import OrganizedEdgeMap, pcl_organized

#: name -> detector(scan, **params) -> EdgeMap
DETECTORS = {
    "gradient": gradient,
    "line_fit": line_fit,
    "normal": normal,
    "curvature": curvature,
    "pcl_organized": pcl_organized,
}

__all__ = [
    "DETECTORS", "EdgeChain", "EdgeMap", "OrganizedEdgeMap", "curvature", "gradient", "line_fit",
    "line_fit_points", "link", "normal", "pcl_organized",
]
