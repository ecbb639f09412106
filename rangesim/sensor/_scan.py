"""``scan()``: join a scene and a sensor into a RangeScan (the sensor's mode picks the method)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.scene.scene import Scene, load_scene
from rangesim.sensor.config import Sensor, load_sensor


def default_pose(scene: Scene, sensor: Sensor) -> np.ndarray:
    """The scene's [view], or a pose that frames the whole scene inside the working range.

    The camera looks at the bounding-box centre from above and in front (elevation about
    54 degrees) at a distance where the bounding sphere fills 90 % of the narrower field of
    view, kept inside [near + radius, far - radius] where the working range allows.
    """
    if scene.view is not None:
        return scene.view
    radius = scene.bounding_radius
    fov = math.radians(sensor.params["camera"]["fov_deg"])
    narrow = 2 * math.atan(math.tan(fov / 2) * min(1.0, sensor.height / sensor.width))
    fit = radius / math.sin(0.45 * narrow)
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    distance = min(max(fit, near + radius), max(near + radius, far - radius))
    return scene.framing_pose(distance)


def scan(scene: Any, sensor: Any, pose: np.ndarray | None = None, seed: int = 0,
         keep_frames: bool = False) -> "RangeScan | tuple[RangeScan, Any]":
    """Scan a scene with a range sensor.

    Parameters
    ----------
    scene : Scene, str, Path, trimesh.Trimesh or list of them
        Anything :func:`rangesim.load_scene` accepts.
    sensor : Sensor, str, Path or dict
        Anything :func:`rangesim.load_sensor` accepts.
    pose : (4, 4) array, optional
        Camera-to-world transform (OpenCV camera axes); default: the scene's [view], or a
        pose framing the scene (:func:`default_pose`).
    seed : int
        Seed of the noise; the same seed gives the same scan, another seed changes only the
        noise.
    keep_frames : bool
        Rendered mode only: also return the raw frame stack
        (:class:`rangesim.sensor.rendered.FrameStack`).

    Returns
    -------
    RangeScan, or (RangeScan, FrameStack) with ``keep_frames``

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.scan("scenes/green_piece.toml", "white_scanner", seed=0)
    >>> scan.depth.shape == (scan.meta["sensor"]["camera"]["height"],
    ...                      scan.meta["sensor"]["camera"]["width"])
    True
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RangesimError(f"seed must be a non-negative integer, got {seed!r}")
    scene = load_scene(scene)
    sensor = load_sensor(sensor)
    if pose is None:
        pose = default_pose(scene, sensor)
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise RangesimError("pose must be a finite 4x4 camera-to-world matrix")
    rot = pose[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise RangesimError("pose rotation must be orthonormal and right-handed")
    if sensor.mode == "geometric":
        from rangesim.sensor.geometric import scan_geometric

        if keep_frames:
            raise RangesimError("only the rendered mode has frames (set mode = \"rendered\")", source=sensor.source)
        return scan_geometric(scene, sensor, pose, int(seed))
    if sensor.mode == "rendered":
        from rangesim.sensor.rendered import scan_rendered

        return scan_rendered(scene, sensor, pose, int(seed), keep_frames=keep_frames)
    if sensor.mode == "structured_light":
        from rangesim.sensor.structured_light import scan_structured_light

        if keep_frames:
            raise RangesimError("only the rendered mode has frames (set mode = \"rendered\")", source=sensor.source)
        return scan_structured_light(scene, sensor, pose, int(seed))
    raise RangesimError(f"sensor mode {sensor.mode!r} is not available", source=sensor.source)
