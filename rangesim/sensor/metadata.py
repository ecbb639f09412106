"""The metadata every simulated scan carries, whatever the scanner mode."""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.core.version import __version__


def scan_meta(scene, sensor, seed: int, mode: str, **extra: Any) -> dict[str, Any]:
    """``RangeScan.meta`` of a simulated scan.

    Parameters
    ----------
    scene : Scene
    sensor : Sensor
    seed : int
    mode : str
        The scanner mode that made the scan.
    **extra
        Mode-specific entries (recast rays, frames, timings, ...).

    Returns
    -------
    dict with ``sensor`` (its TOML keys), ``sensor_source``, ``mode``, ``seed``,
    ``rangesim_version``, ``K`` (3x3 as nested lists), ``laser_origin``, ``scene``,
    ``objects``, ``variant`` (Mitsuba), ``units`` and ``extra``.
    """
    from rangesim.core.backend import mitsuba

    meta = {
        "sensor": sensor.to_dict(),
        "sensor_source": sensor.source,
        "mode": mode,
        "seed": int(seed),
        "rangesim_version": __version__,
        "K": np.asarray(sensor.K).tolist(),
        "laser_origin": sensor.laser_origin.tolist(),
        "scene": scene.source,
        "objects": [o.name for o in scene.objects],
        "variant": mitsuba().variant(),
        "units": "mm",
    }
    if getattr(scene, "source_units", None):  # a bare mesh file read in other units than mm
        meta["scene_units"] = scene.source_units
    meta.update(extra)
    return meta
