"""rangesim: laser-stripe range-sensor simulation on CAD parts, with exact ground truth.

>>> import rangesim as rs
>>> scene = rs.load_scene("scenes/green_piece.toml")
>>> sensor = rs.load_sensor("white_scanner")
>>> scan = rs.scan(scene, sensor, seed=0)
"""
from rangesim import (  # noqa: E402  (subpackages as rs.*)
    cad,
    curvature,
    datasets,  # small scenes and scans for examples and doctests
    edges,
    evaluate,
    features,
    recorded,  # noqa: E402,F401  (registers the readers of recorded formats with load_scan)
    twin,  # noqa: E402  (the package, callable as twin(); rs.twin.compare works)
    volumes,
)
from rangesim.core import RangeScan, RangesimError, Status
from rangesim.core.version import __version__
from rangesim.evaluate import ground_truth_edges  # noqa: E402
from rangesim.io import load_scan, save_scan  # also registers the scan writers RangeScan.save uses
from rangesim.scene import Scene, SceneObject, load_scene
from rangesim.sensor import Sensor, default_pose, intensity_image, load_sensor, scan
from rangesim.twin import calibrate  # noqa: E402

__all__ = [
    "RangeScan", "RangesimError", "Status", "Scene", "SceneObject", "Sensor",
    "load_scene", "load_sensor", "load_scan", "save_scan", "scan", "default_pose",
    "__version__", "cad", "curvature", "edges", "evaluate", "features", "volumes", "ground_truth_edges",
    "twin", "calibrate", "intensity_image", "datasets",
]
