"""Plain point lists: PLY without faces, ``.xyz`` text, ``.npz`` with ``points``.

A point list has no image grid: it becomes an *unorganized* scan, a 1 x N image in file
order (for fitting, e.g. ``line_fit``). Points with a NaN or infinite coordinate stay in
place with status 1 (no surface), so pixel j is always the file's point j.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io.ply_header import PLY_FORMATS, PlyElement, PlyHeader, read_ply_header
from rangesim.recorded.common import check_file, grid_scan, read_bytes, recorded_meta, unit_scale
from rangesim.recorded.conf import apply_conf
from rangesim.recorded.text import line_block, line_ends, parse_numbers

__all__ = ["read_point_ply", "read_points_npz", "read_xyz"]


def _points_scan(
    points: np.ndarray,
    path: Path,
    fmt: str,
    scale: float,
    *,
    normals: np.ndarray | None = None,
    intensity: np.ndarray | None = None,
    pose: np.ndarray | None = None,
    **meta: Any,
) -> RangeScan:
    """An unorganized 1 x N scan from (N, 3) points in file units."""
    n = len(points)
    xyz = (np.asarray(points, dtype=np.float64) * scale).astype(np.float32).reshape(1, n, 3)
    return grid_scan(
        xyz,
        recorded_meta(fmt, path, "file", organized=False, **meta),
        normal=None if normals is None else np.asarray(normals).reshape(1, n, 3),
        intensity=None if intensity is None else np.asarray(intensity).reshape(1, n),
        pose=pose,
    )


def read_point_ply(path: str | Path, *, units: str = "mm", conf: str | Path | None = None) -> RangeScan:
    """Read a PLY point cloud (no faces, no ``range_grid``) as an unorganized 1 x N scan.

    Parameters
    ----------
    path : str or Path
        ASCII or binary PLY whose ``vertex`` element has ``x y z`` (and optionally
        ``nx ny nz`` and ``intensity``, kept). A ``comment pose`` line of 16 numbers, as
        written by :func:`rangesim.io.write_ply`, becomes the pose.
    units : str
        Units of the file's coordinates (``"mm"``, ``"m"``, ...); the scan is in mm.
    conf : str or Path, optional
        A Stanford ``.conf`` giving the pose (overrides a ``comment pose``).

    Returns
    -------
    RangeScan
        1 x N, ``meta["frame"] == "file"`` (the file's own frame).

    Raises
    ------
    RangesimError
        A missing or malformed file, a PLY with faces (a mesh), or no x/y/z.
    """
    path = check_file(path)
    raw = read_bytes(path)
    header = read_ply_header(raw, path)
    return _point_ply_from(raw, header, path, units=units, conf=conf)


def _point_ply_from(raw: bytes, header: PlyHeader, path: Path, *, units: str, conf: Any) -> RangeScan:
    scale = unit_scale(units, path)
    faces = sum(e.count for e in header.elements if e.name in ("face", "tristrips"))
    if faces:
        raise RangesimError(
            f"a mesh with {faces} faces, not a scan (load it as a scene, or sample it with rangesim points)",
            path,
        )
    vertex = header.element("vertex")
    if vertex is None:
        raise RangesimError("PLY file has no vertex element", path)
    columns = _ply_vertices(raw, header, vertex, path)
    missing = [a for a in "xyz" if a not in columns]
    if missing:
        raise RangesimError(f"PLY vertex element has no {'/'.join(missing)} property", path)
    points = np.stack([columns[a] for a in "xyz"], axis=-1)
    normals = (
        np.stack([columns[a] for a in ("nx", "ny", "nz")], axis=-1)
        if all(a in columns for a in ("nx", "ny", "nz")) else None
    )
    pose = _comment_pose(header.comments, scale, path)
    scan = _points_scan(
        points, path, "ply_points", scale, normals=normals, intensity=columns.get("intensity"),
        pose=pose, ply_properties=[p.name for p in vertex.properties],
    )
    return apply_conf(scan, conf, path)


def _ply_vertices(raw: bytes, header: PlyHeader, vertex: PlyElement, path: Path) -> dict[str, np.ndarray]:
    """The vertex element's scalar properties as 1-D arrays."""
    before = header.elements[: header.elements.index(vertex)]
    if vertex.has_lists:
        raise RangesimError("PLY vertex element has list properties; cannot read it as points", path)
    body = raw[header.data_offset:]
    names = [p.name for p in vertex.properties]
    if header.format == "ascii":
        skip = sum(e.count for e in before)
        text = line_block(body, line_ends(body), skip, vertex.count, path, "PLY vertex data")
        values = parse_numbers(text, path, "PLY vertex data")
        if values.size != vertex.count * len(names):
            raise RangesimError(
                f"PLY vertex data: expected {vertex.count} x {len(names)} numbers, found {values.size}", path
            )
        table = values.reshape(vertex.count, len(names))
        return {name: table[:, i] for i, name in enumerate(names)}
    if any(e.count for e in before):
        raise RangesimError("binary PLY with data before the vertex element is not supported", path)
    order = PLY_FORMATS[header.format]
    dtype = np.dtype([(p.name, order + p.dtype) for p in vertex.properties])
    needed = vertex.count * dtype.itemsize
    if len(body) < needed:
        raise RangesimError(
            f"truncated: {vertex.count} vertices need {needed} bytes of data, the file has {len(body)}", path
        )
    table = np.frombuffer(body, dtype=dtype, count=vertex.count)
    return {name: table[name].astype(np.float64) for name in names}


def _comment_pose(comments: list[str], scale: float, path: Path) -> np.ndarray | None:
    """The 4x4 pose of a ``comment pose v0 .. v15`` line (rangesim's PLY export), if any."""
    for comment in comments:
        words = comment.split()
        if words and words[0] == "pose":
            try:
                pose = np.array([float(w) for w in words[1:]], dtype=np.float64)
            except ValueError:
                pose = np.empty(0)
            if pose.size != 16 or not np.isfinite(pose).all():
                raise RangesimError("PLY header: 'comment pose' is not 16 finite numbers", path)
            pose = pose.reshape(4, 4)
            pose[:3, 3] *= scale
            return pose
    return None


#: a point list whose points all lie within this many mm of each other was most likely written
#: in metres (a 0.15 m bunny read as 0.15 mm): :func:`read_xyz` says so
TINY_EXTENT_MM = 2.0


def _xyz_fields(line: bytes) -> list[bytes]:
    """The fields of one XYZ data line: separated by whitespace, or by semicolons or commas
    (spreadsheets' and CloudCompare's exports; semicolons first, which may hold decimal commas),
    each stripped; a trailing separator ends the line."""
    if b";" in line:  # a comma between semicolons is a decimal comma (1,5;2,5;3,5)
        return [f.strip().replace(b",", b".") for f in line.rstrip().rstrip(b";").split(b";")]
    if b"," in line:
        return [f.strip() for f in line.rstrip().rstrip(b",").split(b",")]
    return line.split()


def _numbers_in(fields: list[bytes]) -> int:
    """How many of ``fields`` read as numbers."""
    count = 0
    for f in fields:
        try:
            float(f)
            count += 1
        except ValueError:
            pass
    return count


def read_xyz(path: str | Path, *, units: str = "mm", conf: str | Path | None = None) -> RangeScan:
    """Read an XYZ text file (one point per line, ``x y z`` first) as a 1 x N scan.

    Lines starting with ``#`` or ``//`` and blank lines are skipped, and so is a first line
    without any number (column names: ``x y z``, ``X,Y,Z,R,G,B``, ``x[mm] y[mm] z[mm]``).
    Columns are separated by whitespace, or by semicolons (with decimal commas or points) or
    commas (one separator per line; a comma inside a space-separated column, a decimal comma
    there, is refused). Every line must have
    the same number of columns (at least 3); columns after the third are ignored (their count
    is ``meta["xyz_columns"]``). A point list under :data:`TINY_EXTENT_MM` across read in mm
    gets a warning: it was most likely written in metres.

    Parameters
    ----------
    path : str or Path
    units : str
        Units of the file (the scan is in mm).
    conf : str or Path, optional
        A Stanford ``.conf`` giving the pose.

    Returns
    -------
    RangeScan
    """
    path = check_file(path)
    raw = read_bytes(path)
    numbered = [(k, line) for k, line in enumerate(raw.splitlines(), start=1)
                if line.strip() and not line.lstrip().startswith((b"#", b"//"))]
    header = None
    if numbered and _numbers_in(_xyz_fields(numbered[0][1])) == 0:
        header, numbered = numbered[0], numbered[1:]  # column names
    if not numbered and header is not None:
        raise RangesimError(f"no points in the file: its only data line, line {header[0]} "
                            f"{header[1].decode(errors='replace').strip()[:60]!r}, holds no number (taken for "
                            "column names)", path)
    if not numbered:
        raise RangesimError("no points in the file", path)
    separated = b"," in raw or b";" in raw  # (a comment's comma only costs the per-line path)
    # whitespace columns (the common case) are parsed in one vectorised pass; per-line fields
    # only for separated columns
    rows = [_xyz_fields(line) for _, line in numbered] if separated else None
    counts = [len(row) for row in rows] if separated else [len(line.split()) for _, line in numbered]
    columns = counts[0]
    # each line's own count: a total alone lets ragged lines regroup into other points
    ragged = next((k for k, c in enumerate(counts) if c != columns), None)
    if columns < 3 or ragged is not None:
        raise RangesimError(
            f"XYZ data: every line needs the same number (>= 3) of columns; line {numbered[0][0]} has {columns}"
            + ("" if ragged is None else f", line {numbered[ragged][0]} has {counts[ragged]}"),
            path,
        )
    if separated:
        mixed = next((k for k, row in enumerate(rows) if any(len(f.split()) != 1 for f in row)), None)
        if mixed is not None:
            raise RangesimError(f"XYZ data line {numbered[mixed][0]}: a column holds spaces between its separators "
                                f"({numbered[mixed][1][:60].decode(errors='replace')!r}; decimal commas?)", path)
        text = b"\n".join(b" ".join(row) for row in rows)
    else:
        text = b"\n".join(line for _, line in numbered)
    try:
        values = parse_numbers(text, path, "XYZ data")
    except RangesimError:
        fields = rows if separated else [line.split() for _, line in numbered]
        bad = next(k for k, row in enumerate(fields) if _numbers_in(row) < len(row))
        raise RangesimError(f"XYZ data line {numbered[bad][0]}: not numbers: "
                            f"{numbered[bad][1][:60].decode(errors='replace')!r}", path) from None
    if values.size != columns * len(numbered):
        raise RangesimError(f"XYZ data: {len(numbered)} lines of {columns} columns hold {values.size} numbers", path)
    table = values.reshape(len(numbered), columns)
    scale = unit_scale(units, path)
    finite = table[:, :3][np.isfinite(table[:, :3]).all(axis=1)] * scale
    if len(finite) > 1 and np.ptp(finite, axis=0).max() < TINY_EXTENT_MM and scale == 1.0:
        warnings.warn(f"{path}: the {len(finite):,} points span {np.ptp(finite, axis=0).max():.3g} mm at most "
                      "(written in metres? pass units='m')", stacklevel=2)
    scan = _points_scan(table[:, :3], path, "xyz", scale, xyz_columns=columns)
    return apply_conf(scan, conf, path)


def read_points_npz(path: str | Path, *, units: str = "mm", conf: str | Path | None = None) -> RangeScan:
    """Read an ``.npz`` holding a ``points`` (N, 3) array as a 1 x N scan.

    Optional arrays: ``normals`` (N, 3), ``intensity`` (N,), ``pose`` (4, 4). This is
    the layout ``SurfacePoints.save`` writes.

    Parameters
    ----------
    path : str or Path
    units : str
        Units of the points (the scan is in mm).
    conf : str or Path, optional
        A Stanford ``.conf`` giving the pose (overrides ``pose``).

    Returns
    -------
    RangeScan
    """
    path = check_file(path)
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
            arrays = {k: data[k] for k in ("points", "normals", "intensity", "pose") if k in data.files}
    except Exception as exc:  # zipfile, zlib, numpy format and OS errors alike
        raise RangesimError(f"not a readable .npz file ({type(exc).__name__}: {exc})", path) from exc
    return _points_npz_from(arrays, path, units=units, conf=conf)


def _points_npz_from(arrays: dict[str, np.ndarray], path: Path, *, units: str, conf: Any) -> RangeScan:
    points = arrays.get("points")
    if points is None or points.ndim != 2 or points.shape[1] != 3 or not np.issubdtype(points.dtype, np.number):
        shape = None if points is None else points.shape
        raise RangesimError(f"expected a numeric 'points' array of shape (N, 3), found {shape}", path)
    n = len(points)
    normals, intensity, pose = arrays.get("normals"), arrays.get("intensity"), arrays.get("pose")
    if normals is not None and normals.shape != (n, 3):
        raise RangesimError(f"'normals' has shape {normals.shape}, expected {(n, 3)}", path)
    if intensity is not None and intensity.shape != (n,):
        raise RangesimError(f"'intensity' has shape {intensity.shape}, expected {(n,)}", path)
    scale = unit_scale(units, path)
    if pose is not None:
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise RangesimError("'pose' is not a finite 4 x 4 array", path)
        pose = pose.copy()
        pose[:3, 3] *= scale
    scan = _points_scan(points, path, "npz_points", scale, normals=normals, intensity=intensity, pose=pose)
    return apply_conf(scan, conf, path)
