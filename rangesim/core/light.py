"""Where a sensor's light comes from: the laser or projector point lighting each surface point.

Camera frame (OpenCV axes), mm. The laser origin L sits on the camera's +x axis at
``laser.baseline``. A rotating mirror (``laser.sweep = "rotating"``) and a structured-light
projector light every point from L; a translating sheet of tilt t lights P from the point
where its sheet crosses the x axis, ``(P_x + tan(t) P_z, 0, 0)``. The formulas are written
once, on any array type (NumPy or Dr.Jit), so the scanner that casts the shadows
(:mod:`rangesim.sensor.laser`) and the edge detectors that reason about them
(:mod:`rangesim.edges._self_shadow`) share them.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np


def sheet_tilt_rad(tilt_deg: float | None, baseline: float, reference_distance: float) -> float:
    """Translating sweep: the sheet's angle from the optical axis, towards the camera, radians.

    ``tilt_deg`` None aims the sheet from L at the optical axis at ``reference_distance`` (mm).
    """
    if tilt_deg is None:
        return math.atan2(baseline, reference_distance)
    return math.radians(tilt_deg)


def source_x(x: Any, z: Any, sweep: str, baseline: float, tilt_rad: float) -> Any:
    """x of the light source of the points ``(x, ., z)`` (its y and z are 0), mm.

    Parameters
    ----------
    x, z : arrays (NumPy or Dr.Jit) of one shape, mm
    sweep : {"rotating", "translating"}
    baseline : float
        Laser origin on the camera's +x axis, mm.
    tilt_rad : float
        Translating sweep's sheet tilt (:func:`sheet_tilt_rad`).
    """
    if sweep == "rotating":
        return 0.0 * x + baseline
    if sweep == "translating":
        return x + math.tan(tilt_rad) * z
    raise ValueError(f"unknown sweep {sweep!r}")


def mid_range(range_table: Mapping[str, Any]) -> float:
    """The middle of a ``[range]`` table's working range (mm)."""
    return 0.5 * (float(range_table["near"]) + float(range_table["far"]))


def reference_distance(range_table: Mapping[str, Any]) -> float:
    """A ``[range]`` table's reference distance (mm): ``reference`` where given, else mid-range.

    The photometry and the noise terms are stated there (a white target facing the sensor at
    this distance returns signal 1; ``noise.signal_px``, ``noise.correlation_mm``, the
    structured-light exposure and reference plane). Given explicitly it is a property of the
    device, so changing ``near`` or ``far`` leaves a surface at a fixed distance as bright and
    as noisy as before; left out, it moves with the working range.
    """
    given = range_table.get("reference")
    return float(given) if given is not None else mid_range(range_table)


def light_sources(points: np.ndarray, sensor: Mapping[str, Any]) -> np.ndarray | None:
    """(N, 3) light source of each point, camera frame, mm; None for a sensor without one.

    Parameters
    ----------
    points : (N, 3) float
        Surface points, camera frame, mm.
    sensor : mapping
        The sensor's tables as a scan's ``meta["sensor"]`` holds them (``mode``, ``laser``,
        ``range``): ``"geometric"`` and ``"rendered"`` scans are lit by their sheets,
        ``"structured_light"`` ones by the projector at L; other modes (a stage's
        orthographic sweep) return None.
    """
    points = np.asarray(points, np.float64).reshape(-1, 3)
    laser, mode = sensor.get("laser") or {}, sensor.get("mode")
    baseline = laser.get("baseline")
    if baseline is None or mode not in ("geometric", "rendered", "structured_light"):
        return None
    out = np.zeros_like(points)
    # a structured-light projector sits at L: as a rotating mirror (its presets' sweep key)
    sweep = "rotating" if mode == "structured_light" else laser.get("sweep", "rotating")
    rng = sensor.get("range") or {}
    # the sensor's reference distance, as Sensor.tilt_rad takes it
    reference = reference_distance({"near": 0.0, "far": 0.0, **rng})
    tilt = sheet_tilt_rad(laser.get("tilt_deg"), float(baseline), reference)
    out[:, 0] = source_x(points[:, 0], points[:, 2], sweep, float(baseline), tilt)
    return out
