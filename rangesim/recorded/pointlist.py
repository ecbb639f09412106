"""Plain point lists (PLY without faces, ``.xyz`` text, ``.npz`` with ``points``) and the
helpers every recorded-data reader shares.

A point list has no image grid: it becomes an *unorganized* scan, a 1 x N image in file
order (for fitting, e.g. ``line_fit``). Points with a NaN or infinite coordinate stay in
place with status 1 (no surface), so pixel j is always the file's point j.

Shared here: :func:`grid_scan` (a RangeScan from an (H, W, 3) grid of measured points),
:func:`read_ply_header` and :func:`parse_numbers` (fast vectorised text parsing).
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.core.units import UNITS_MM

__all__ = [
    "PlyElement",
    "PlyHeader",
    "grid_scan",
    "parse_numbers",
    "read_ply_header",
    "read_point_ply",
    "read_points_npz",
    "read_xyz",
    "unit_scale",
]

#: PLY scalar type names -> NumPy type codes (without byte order)
PLY_TYPES: dict[str, str] = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
#: a PLY header longer than this is surely not one
MAX_HEADER_BYTES = 1 << 20


# -- shared helpers -------------------------------------------------------------------------
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


def parse_numbers(text: bytes, path: Path, what: str, dtype: type = np.float64) -> np.ndarray:
    """All whitespace-separated numbers in ``text`` as a flat array (vectorised).

    ``nan`` and ``inf`` parse as floats; anything else that is not a number is an error.
    """
    try:
        with warnings.catch_warnings():
            # older NumPy warns (instead of raising) when it stops at unparsable text
            warnings.simplefilter("error", DeprecationWarning)
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        kind = "integers" if np.issubdtype(dtype, np.integer) else "numbers"
        raise RangesimError(f"{what}: expected whitespace-separated {kind}, found other text", path) from None


def line_ends(body: bytes) -> np.ndarray:
    """Offsets of the ends of the lines of ``body`` (a last line without newline counts)."""
    ends = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    last = int(ends[-1]) + 1 if ends.size else 0
    if body[last:].strip():
        ends = np.append(ends, len(body))
    return ends


def line_block(
    body: bytes, ends: np.ndarray, start: int, count: int, path: Path, what: str
) -> bytes:
    """Lines ``start .. start+count-1`` of ``body`` as one block (``ends`` from :func:`line_ends`)."""
    if ends.size < start + count:
        found = max(ends.size - start, 0)
        raise RangesimError(f"{what}: expected {count} lines, the file has {found} (truncated)", path)
    begin = 0 if start == 0 else int(ends[start - 1]) + 1
    return body[begin:int(ends[start + count - 1])] if count else b""


def recorded_meta(fmt: str, path: Path, frame: str, **extra: Any) -> dict[str, Any]:
    """The meta every recorded scan carries: units, frame and source file (JSON-friendly)."""
    return {"units": "mm", "frame": frame, "source": {"format": fmt, "file": path.name}, **extra}


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


def apply_conf(scan: RangeScan, conf: str | Path | None, path: Path) -> RangeScan:
    """Set ``scan.pose`` from a Stanford ``.conf`` entry for ``path``'s file name (if given)."""
    if conf is not None:
        from rangesim.recorded.cyberware import conf_pose  # cyberware imports this module

        scan.pose = conf_pose(conf, path.name)
        scan.meta["pose_source"] = {"conf": Path(conf).name}
    return scan


# -- PLY headers ----------------------------------------------------------------------------
@dataclass
class PlyProperty:
    """One property: a scalar (``list_count`` None) or a list with a count type."""

    name: str
    dtype: str
    list_count: str | None = None


@dataclass
class PlyElement:
    """An element (``vertex``, ``face``, ``range_grid``, ...) with its count and properties."""

    name: str
    count: int
    properties: list[PlyProperty] = field(default_factory=list)

    @property
    def has_lists(self) -> bool:
        return any(p.list_count is not None for p in self.properties)


@dataclass
class PlyHeader:
    """A parsed PLY header; ``data_offset`` is where the body starts in the file."""

    format: str
    elements: list[PlyElement]
    comments: list[str]
    obj_info: list[tuple[str, str]]
    data_offset: int

    def element(self, name: str) -> PlyElement | None:
        """The first element called ``name``, or None."""
        return next((e for e in self.elements if e.name == name), None)


def read_ply_header(raw: bytes, path: Path) -> PlyHeader:
    """Parse the header of a PLY file held in ``raw``.

    Raises
    ------
    RangesimError
        No ``ply`` magic, no ``end_header``, an unknown format or type, or a count that
        is not a non-negative integer (``nan`` included).
    """
    if not raw.startswith(b"ply"):
        raise RangesimError("not a PLY file (it does not start with 'ply')", path)
    match = re.search(rb"end_header[ \t]*\r?\n", raw[:MAX_HEADER_BYTES])
    if match is None:
        raise RangesimError("PLY header has no end_header line (truncated or not a PLY file)", path)
    text = raw[: match.start()].decode("ascii", errors="replace")
    fmt, elements, comments, obj_info = None, [], [], []
    for number, line in enumerate(text.splitlines()[1:], start=2):
        words = line.split()
        if not words:
            continue
        key = words[0]
        if key == "format":
            if len(words) < 2 or words[1] not in PLY_FORMATS:
                raise RangesimError(f"PLY header line {number}: unknown format {line.strip()!r}", path)
            fmt = words[1]
        elif key == "comment":
            comments.append(line.strip()[len("comment"):].strip())
        elif key == "obj_info":
            obj_info.append((words[1] if len(words) > 1 else "", " ".join(words[2:])))
        elif key == "element":
            if len(words) != 3:
                raise RangesimError(f"PLY header line {number}: expected 'element NAME COUNT'", path)
            elements.append(PlyElement(words[1], _count(words[2], f"element {words[1]}", path)))
        elif key == "property":
            if not elements:
                raise RangesimError(f"PLY header line {number}: property before any element", path)
            elements[-1].properties.append(_property(words, number, path))
        else:
            raise RangesimError(f"PLY header line {number}: unknown keyword {key!r}", path)
    if fmt is None:
        raise RangesimError("PLY header has no format line", path)
    return PlyHeader(fmt, elements, comments, obj_info, match.end())


def _count(word: str, what: str, path: Path) -> int:
    try:
        value = int(word)
    except ValueError:
        value = -1
    if value < 0:
        raise RangesimError(f"PLY header: {what} count {word!r} is not a non-negative integer", path)
    return value


def _property(words: list[str], number: int, path: Path) -> PlyProperty:
    if len(words) == 3 and words[1] in PLY_TYPES:
        return PlyProperty(words[2], PLY_TYPES[words[1]])
    if len(words) == 5 and words[1] == "list" and words[2] in PLY_TYPES and words[3] in PLY_TYPES:
        return PlyProperty(words[4], PLY_TYPES[words[3]], PLY_TYPES[words[2]])
    raise RangesimError(f"PLY header line {number}: cannot read {' '.join(words)!r}", path)


# -- point-list readers ----------------------------------------------------------------------
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


def read_xyz(path: str | Path, *, units: str = "mm", conf: str | Path | None = None) -> RangeScan:
    """Read an XYZ text file (one point per line, ``x y z`` first) as a 1 x N scan.

    Lines starting with ``#`` and blank lines are skipped. Every line must have the same
    number of columns (at least 3); columns after the third are ignored (their count is
    ``meta["xyz_columns"]``).

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
    lines = [line for line in raw.splitlines() if line.strip() and not line.lstrip().startswith(b"#")]
    if not lines:
        raise RangesimError("no points in the file", path)
    columns = len(lines[0].split())
    values = parse_numbers(b"\n".join(lines), path, "XYZ data")
    if columns < 3 or values.size != columns * len(lines):
        raise RangesimError(
            f"XYZ data: every line needs the same number (>= 3) of columns; line 1 has {columns}, "
            f"{len(lines)} lines hold {values.size} numbers",
            path,
        )
    table = values.reshape(len(lines), columns)
    scan = _points_scan(table[:, :3], path, "xyz", unit_scale(units, path), xyz_columns=columns)
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
