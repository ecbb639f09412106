"""Small ready-made scenes and scans for examples and doctests (as ``skimage.data`` serves scikit-image).

>>> import rangesim as rs
>>> scan = rs.datasets.plate_scan()
>>> scan.shape
(120, 128)
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any, Mapping

import numpy as np

from rangesim.core.errors import RangesimError

__all__ = ["plate_scene", "plate_scan", "PLATE_VIEW"]

#: the camera of :func:`plate_scan`: above and in front of the plate (camera position, target)
PLATE_VIEW = ((20.0, -60.0, 300.0), (0.0, 0.0, 0.0))


@lru_cache(maxsize=1)
def plate_scene():
    """A 60 x 40 x 10 mm plate with an 8 mm-radius through hole, on a 300 mm table (mm).

    Built once per process (CAD boolean by manifold3d) and shared by every caller.
    """
    import trimesh

    from rangesim.scene import load_scene

    plate = trimesh.creation.box((60, 40, 10)).difference(trimesh.creation.cylinder(8, 20))
    table = trimesh.creation.box((300, 300, 2)).apply_translation((0, 0, -6))
    return load_scene([plate, table])


def plate_scan(changes: Mapping[str, Any] | None = None, *, sensor: str = "white_scanner", width: int = 128,
               height: int = 120, seed: int = 0):
    """:func:`plate_scene` scanned from :data:`PLATE_VIEW` by a small ``sensor`` (default 128 x 120).

    Parameters
    ----------
    changes : mapping, optional
        Dotted sensor keys to change (``{"noise.sigma_px": 0}``), as ``Sensor.with_params``.
    sensor : str
        Preset name.
    width, height : int
        Image size, pixels.
    seed : int
        Noise seed.
    """
    from rangesim.core.geometry import look_at
    from rangesim.sensor import load_sensor, scan

    if changes is not None and not isinstance(changes, Mapping):
        raise RangesimError(f"changes must be a mapping of dotted sensor keys to values, got {type(changes).__name__}")
    s = load_sensor(sensor).with_params({"camera.width": width, "camera.height": height, **dict(changes or {})})
    eye, target = PLATE_VIEW
    return scan(plate_scene(), s, pose=look_at(np.array(eye), np.array(target)), seed=seed)
