"""What every recorded-data reader shares: file checks, units, meta, and the scan itself.

:func:`grid_scan` makes the RangeScan of measured points on an image grid (an organized
scan, or 1 x N for a point list); :func:`recorded_meta` the meta it carries.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.precision import warn_float32_steps
from rangesim.core.rangescan import RangeScan
from rangesim.core.units import UNITS_MM

__all__ = ["check_file", "grid_scan", "read_bytes", "recorded_meta", "unit_scale"]


def check_file(path: str | Path) -> Path:
    """``path`` as a Path; RangesimError if it is missing or not a regular file."""
    path = Path(path)
    if not path.exists():
        raise RangesimError("no such file", path)
    if not path.is_file():
        raise RangesimError("not a file", path)
    return path


def read_bytes(path: Path) -> bytes:
    """The whole file; OS errors become a one-line RangesimError."""
    try:
        return path.read_bytes()
    except OSError as exc:
        raise RangesimError(f"cannot read file ({exc.strerror or exc})", path) from exc


def unit_scale(units: str, path: str | Path | None = None) -> float:
    """Millimetres per file unit (``"mm"``, ``"cm"``, ``"m"``, ``"in"``)."""
    scale = UNITS_MM.get(str(units).strip().lower())
    if scale is None:
        raise RangesimError(
            f"unknown length unit {units!r}; use one of {', '.join(sorted(UNITS_MM))}", path
        )
    return scale


def recorded_meta(fmt: str, path: Path, frame: str, **extra: Any) -> dict[str, Any]:
    """The meta every recorded scan carries: units, frame and source file (JSON-friendly)."""
    return {"units": "mm", "frame": frame, "source": {"format": fmt, "file": path.name}, **extra}


#: the largest |coordinate| (mm) a recorded scan may hold: what float32, the scan's storage, can
#: (far points lose precision first, which :func:`warn_float32_steps` says)
MAX_RECORDED_MM = float(np.finfo(np.float32).max)


def grid_scan(
    xyz: np.ndarray,
    meta: dict[str, Any],
    *,
    valid: np.ndarray | None = None,
    normal: np.ndarray | None = None,
    intensity: np.ndarray | None = None,
    pose: np.ndarray | None = None,
) -> RangeScan:
    """A RangeScan from measured points on an image grid (recorded data: no ground truth).

    Parameters
    ----------
    xyz : (H, W, 3) array
        Points in millimetres; a cell is valid where all three are finite (and ``valid``).
    meta : dict
        The scan's meta (JSON-friendly).
    valid : (H, W) bool, optional
        An extra validity mask (e.g. a flag image).
    normal : (H, W, 3) array, optional
        Recorded normals; NaN where absent or invalid.
    intensity : (H, W) array, optional
        Recorded intensity; 0 where absent or invalid.
    pose : (4, 4) array, optional
        Sensor-to-world transform in millimetres (identity by default).

    Returns
    -------
    RangeScan
        ``depth`` = z, ``status`` 0 (valid) or 1 (no surface), ``part``/``face`` -1,
        ``xyz_true`` None.
    """
    source = meta.get("source")
    name = source.get("file", "recording") if isinstance(source, dict) else "recording"
    with np.errstate(invalid="ignore"):
        largest = np.abs(np.asarray(xyz, dtype=np.float64))
        largest = float(largest[np.isfinite(largest)].max(initial=0.0))
    if largest > MAX_RECORDED_MM:  # float32 turned them into infinity: "no surface", with a warning
        raise RangesimError(f"coordinates reach {largest:.3g} mm, beyond what a scan's float32 holds "
                            f"({MAX_RECORDED_MM:.3g}): wrong units?", source=name)
    warn_float32_steps(xyz, name, "a scan stores float32: subtract an offset first (e.g. the points' centroid)")
    xyz = np.asarray(xyz, dtype=np.float32)
    ok = np.isfinite(xyz).all(axis=-1)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    xyz = np.where(ok[..., None], xyz, np.float32(np.nan))
    h, w = ok.shape
    if normal is None:
        normal = np.full((h, w, 3), np.nan, dtype=np.float32)
    else:
        normal = np.where(ok[..., None], np.asarray(normal, dtype=np.float32), np.float32(np.nan))
    if intensity is None:
        intensity = np.zeros((h, w), dtype=np.float32)
    else:
        intensity = np.where(ok, np.nan_to_num(np.asarray(intensity, dtype=np.float32)), np.float32(0))
    labels = np.full((h, w), -1, dtype=np.int32)
    return RangeScan(
        depth=xyz[..., 2].copy(),
        xyz=xyz,
        valid=ok,
        normal=normal,
        intensity=intensity,
        part=labels,
        face=labels.copy(),
        status=np.where(ok, np.uint8(Status.VALID), np.uint8(Status.MISS)),
        pose=np.eye(4) if pose is None else pose,
        meta=meta,
    )
