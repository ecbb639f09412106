"""Readers (and writers) for recorded range data; importing this registers them.

After ``import rangesim.recorded``, :func:`rangesim.load_scan` reads:

========================  ====================================================  ==================
suffix                    what                                                  reader
========================  ====================================================  ==================
``.ply``                  Cyberware / Stanford range grid (organized), or a     :func:`read_ply`
                          plain point cloud (no faces; unorganized 1 x N)
``.pcd``                  PCD v0.7 ascii / binary / binary_compressed           :func:`load_pcd`
``.msu``, ``.msu.gz``     MSU / White Scanner range image                       :func:`read_msu`
``.xyz``                  XYZ text point list                                   :func:`read_xyz`
``.npz``                  rangesim scan, or a ``points`` array (point list)     :func:`read_scan_npz`
========================  ====================================================  ==================

Every reader takes ``conf=`` (a Stanford ``.conf``: the ``bmesh`` line for the file's
name sets the pose, ``p_world = R(q)^T p + t``); point lists and MSU files take
``units=`` (their coordinates' unit; scans are always in mm). Recorded scans have
``xyz_true`` None, NaN normals and ``part``/``face`` -1 unless the file says more, status
0 (valid) or 1 (no surface), and ``meta`` with ``units``, ``frame`` (``"scanner"`` or
``"file"``: not the OpenCV camera frame of synthetic scans; no ``K``) and ``source``.
Bad files raise a one-line :class:`~rangesim.core.errors.RangesimError` naming the file.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io import read_npz, register_reader, register_writer
from rangesim.io.npz import EMPTY_ZIP_MAGIC, ZIP_MAGIC
from rangesim.io.ply_header import read_ply_header
from rangesim.recorded.common import check_file, grid_scan, read_bytes
from rangesim.recorded.conf import apply_conf, conf_pose, read_conf
from rangesim.recorded.cyberware import cyberware_from, read_cyberware_ply
from rangesim.recorded.lzf import LZFError, lzf_decompress, lzf_store
from rangesim.recorded.msu import read_msu, write_msu
from rangesim.recorded.pcd import load_pcd, read_pcd, write_pcd
from rangesim.recorded.pointlist import (
    _point_ply_from,
    _points_npz_from,
    read_point_ply,
    read_points_npz,
    read_xyz,
)

__all__ = [
    "LZFError",
    "conf_pose",
    "grid_scan",
    "load_pcd",
    "lzf_decompress",
    "lzf_store",
    "read_conf",
    "read_cyberware_ply",
    "read_msu",
    "read_pcd",
    "read_ply",
    "read_point_ply",
    "read_points_npz",
    "read_scan_npz",
    "read_xyz",
    "write_msu",
    "write_pcd",
]


def read_ply(path: str | Path, *, conf: str | Path | None = None, units: str | None = None) -> RangeScan:
    """Read a PLY scan: a Cyberware range grid if it has one, else a point cloud.

    Parameters
    ----------
    path : str or Path
    conf : str or Path, optional
        A Stanford ``.conf`` giving the pose.
    units : str, optional
        Unit of a point cloud's coordinates (default mm). Range grids are always metres.

    Returns
    -------
    RangeScan
        Organized (:func:`read_cyberware_ply`) or 1 x N (:func:`read_point_ply`).

    Raises
    ------
    RangesimError
        A malformed file, or a mesh (faces), which is not a scan.
    """
    path = check_file(path)
    raw = read_bytes(path)
    header = read_ply_header(raw, path)
    if header.element("range_grid") is not None:
        if units is not None:
            raise RangesimError("units= does not apply to Cyberware range grids (always metres)", path)
        return cyberware_from(raw, header, path, conf=conf)
    return _point_ply_from(raw, header, path, units=units or "mm", conf=conf)


def read_scan_npz(path: str | Path, *, conf: str | Path | None = None, units: str | None = None) -> RangeScan:
    """Read an ``.npz``: a rangesim scan (:func:`rangesim.io.read_npz`), or a point list.

    An archive with a ``points`` array and no ``depth`` is a point list
    (:func:`read_points_npz`, ``units`` default mm); anything else goes to
    :func:`rangesim.io.read_npz` (``units`` not allowed: rangesim scans are in mm).
    """
    path = check_file(path)
    arrays: dict[str, np.ndarray] | None = None
    try:
        with open(path, "rb") as fh:
            if fh.read(4) in (ZIP_MAGIC, EMPTY_ZIP_MAGIC):
                fh.seek(0)
                with np.load(fh, allow_pickle=False) as data:
                    if "points" in data.files and "depth" not in data.files:
                        arrays = {k: data[k] for k in ("points", "normals", "intensity", "pose") if k in data.files}
    except Exception:  # let read_npz report a broken archive in its words
        arrays = None
    if arrays is not None:
        return _points_npz_from(arrays, path, units=units or "mm", conf=conf)
    if units is not None:
        raise RangesimError("units= applies to point-list .npz files only (rangesim scans are in mm)", path)
    return apply_conf(read_npz(path), conf, path)


def _checked_options(func: Callable[..., RangeScan], what: str) -> Callable[..., RangeScan]:
    """``func`` for the registry: unknown keyword options become a one-line RangesimError."""
    accepted = [name for name in inspect.signature(func).parameters if name != "path"]

    def reader(path: Path, **options: Any) -> RangeScan:
        unknown = sorted(set(options) - set(accepted))
        if unknown:
            raise RangesimError(
                f"{what} files take no option {', '.join(unknown)} (options: {', '.join(accepted)})", path
            )
        return func(path, **options)

    reader.__name__ = reader.__qualname__ = func.__name__
    reader.__doc__ = func.__doc__
    return reader


def _save_pcd(scan: RangeScan, path: Path) -> None:
    """``scan.save("x.pcd")``: an organized binary PCD that PCL and Open3D read.

    Fields x y z (metres, NaN where invalid), the normals and intensity when the scan has
    them, and ``label`` (uint32: the scan's ``part`` + 1, 0 where no surface was hit).
    """
    label = np.clip(np.asarray(scan.part, np.int64) + 1, 0, None).astype(np.uint32)
    write_pcd(scan, path, extras={"label": label})


register_writer(".pcd", _save_pcd)
register_reader(".ply", _checked_options(read_ply, "PLY"))
register_reader(".pcd", _checked_options(load_pcd, "PCD"))
register_reader([".msu", ".msu.gz"], _checked_options(read_msu, "MSU"))
register_reader(".xyz", _checked_options(read_xyz, "XYZ"))
register_reader(".npz", _checked_options(read_scan_npz, "NPZ"))
