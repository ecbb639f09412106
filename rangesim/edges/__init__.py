"""Edge detection on range data (pure NumPy/SciPy over arrays; no Mitsuba, no files).

Every detector takes a RangeScan (synthetic or recorded, NaN holes allowed) and returns an
:class:`EdgeMap`; :data:`DETECTORS` names them for the CLI, sweeps and benchmarks.
:func:`estimate_depth_noise` measures a scan's depth noise in pixel footprints, the level
the detectors' noise-adaptive defaults key on. Labels are
:class:`~rangesim.core.constants.EdgeLabel` values plus :data:`RIM` (4): where the measured
surface ends against pixels that saw nothing.

The detectors live in private modules (``_gradient``, ``_normal``, ``_curvature``,
``_line_fit``, ``_pcl_organized``; chains in ``_link``), the pieces they share in
``_scan_access``, ``_noise``, ``_discontinuities``, ``_differences``, ``_thinning`` and
``_grid``; the public API is this package's namespace. A malformed scan (a per-pixel field
of another shape, valid pixels at infinite depth or behind a pinhole camera) or parameter
(wrong type, sign or range) is refused up front with a
:class:`~rangesim.core.errors.RangesimError` naming it (``_scan_access.check_scan``, ``_params``).
"""
from rangesim.edges._curvature import curvature
from rangesim.edges._gradient import gradient
from rangesim.edges._line_fit import line_fit, line_fit_points
from rangesim.edges._link import EdgeChain, link
from rangesim.edges._noise import estimate_depth_noise
from rangesim.edges._normal import normal
from rangesim.edges._pcl_organized import OrganizedEdgeMap, pcl_organized
from rangesim.edges.edgemap import RIM, EdgeMap

#: name -> detector(scan, **params) -> EdgeMap
DETECTORS = {
    "gradient": gradient,
    "line_fit": line_fit,
    "normal": normal,
    "curvature": curvature,
    "pcl_organized": pcl_organized,
}

__all__ = [
    "DETECTORS", "RIM", "EdgeChain", "EdgeMap", "OrganizedEdgeMap", "curvature", "estimate_depth_noise",
    "gradient", "line_fit", "line_fit_points", "link", "normal", "pcl_organized",
]
