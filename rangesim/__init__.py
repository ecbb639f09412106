"""rangesim: laser-stripe range-sensor simulation on CAD parts, with exact ground truth.

>>> import rangesim as rs
>>> scene = rs.load_scene("scenes/green_piece.toml")
>>> sensor = rs.load_sensor("white_scanner")
>>> scan = rs.scan(scene, sensor, seed=0)
"""
__version__ = "0.1.0"

from rangesim.core import RangeScan, RangesimError, Status
from rangesim.io import load_scan, save_scan
from rangesim.scene import Scene, SceneObject, load_scene
from rangesim.sensor import Sensor, default_pose, intensity_image, load_sensor, scan
from rangesim import cad, curvature, edges, evaluate, features, volumes  # noqa: E402  (subpackages as rs.*)
from rangesim.evaluate import ground_truth_edges  # noqa: E402
from rangesim.twin import calibrate, twin  # noqa: E402
from rangesim import recorded  # noqa: E402,F401  (registers the readers of recorded formats with load_scan)

__all__ = [
    "RangeScan", "RangesimError", "Status", "Scene", "SceneObject", "Sensor",
    "load_scene", "load_sensor", "load_scan", "save_scan", "scan", "default_pose",
    "__version__", "cad", "curvature", "edges", "evaluate", "features", "volumes", "ground_truth_edges",
    "twin", "calibrate", "intensity_image",
]
