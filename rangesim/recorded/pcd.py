"""Point Cloud Library PCD v0.7 files: ``ascii``, ``binary`` and ``binary_compressed``.

Read: :func:`read_pcd` returns the scan and the file's other fields (``label``, ``rgba``,
...) as arrays on the same grid; :func:`load_pcd` (what ``rs.load_scan`` uses) returns
the scan only, with the field names in ``meta["pcd_fields"]``. Write: :func:`write_pcd`.

Layout: ``HEIGHT > 1`` is an organized cloud and becomes an H x W image (row-major);
``HEIGHT == 1`` an unorganized 1 x N scan. Coordinates are metres in the file and
millimetres in the scan; a point is valid where x, y and z are finite (Kinect-type
files store NaN where there is no return). ``normal_x/y/z`` and ``intensity`` fill the
scan's ``normal`` and ``intensity``. The frame is the file's own
(``meta["frame"] == "file"``; for Kinect-type organized clouds the camera's optical frame,
x right, y down, z forward); ``depth`` is z. ``VIEWPOINT`` is kept in
``meta["pcd"]["viewpoint"]`` and not applied: ``pose`` is the identity unless a
``conf`` is given.

``binary_compressed``: after the header, two little-endian uint32 (compressed and
uncompressed size) and an LZF stream (:mod:`rangesim.recorded.lzf`); decompressed, the
data is stored field after field, each over all points; padding fields (``_``) take no
space there, as in PCL.
"""
from __future__ import annotations

import io
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io.atomic import atomic_path
from rangesim.recorded.common import check_file, grid_scan, read_bytes, recorded_meta
from rangesim.recorded.conf import apply_conf
from rangesim.recorded.lzf import LZFError, lzf_decompress, lzf_store
from rangesim.recorded.text import parse_numbers

__all__ = ["PCD_DATA_KINDS", "load_pcd", "read_pcd", "write_pcd"]

PCD_DATA_KINDS = ("ascii", "binary", "binary_compressed")
#: (TYPE, SIZE) -> NumPy type code, little-endian as PCL writes
_TYPES = {
    ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8",
    ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8",
    ("F", 4): "<f4", ("F", 8): "<f8",
}
#: the most elements one PCD field may hold per point
MAX_FIELD_COUNT = 65536
_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
#: fields that fill RangeScan arrays rather than the extras
_SCAN_FIELDS = {"x", "y", "z", "normal_x", "normal_y", "normal_z", "intensity"}
_IDENTITY_VIEWPOINT = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
#: metres (file) -> millimetres (scan)
_MM = 1000.0
_MAX_HEADER_LINES = 1000


@dataclass
class PcdField:
    """One PCD field: its name, NumPy type code, bytes per element and element count."""

    name: str
    code: str
    size: int
    count: int

    @property
    def padding(self) -> bool:
        return self.name == "_"


@dataclass
class PcdHeader:
    """The parsed header; ``offset`` is where the data starts in the file."""

    version: str
    fields: list[PcdField]
    width: int
    height: int
    viewpoint: list[float]
    points: int
    data: str
    offset: int


# -- reading ---------------------------------------------------------------------------------
def _unit_normals(normal: np.ndarray) -> np.ndarray:
    """Normals as unit vectors: a zero or non-finite one is unknown (NaN, as PCL writes where it
    has none), a finite one of another length is scaled to 1 (unit ones are kept to the bit)."""
    normal = np.asarray(normal, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        length = np.linalg.norm(normal, axis=-1, keepdims=True)
        unit = np.abs(length - 1.0) <= 1e-3
        scaled = np.where(np.isfinite(length) & (length > 0), normal / length, np.nan)
    return np.where(unit, normal, scaled)


#: a PCD whose points lie farther than this (mm, median) from the sensor was most likely written in
#: millimetres (PCD's unit is the metre): a Kinect frame at 0.5-1.2 m then reads as 500-1200 m
PCD_FAR_MM = 100_000.0


def read_pcd(path: str | Path, *, conf: str | Path | None = None,
             sensor: Any = None) -> tuple[RangeScan, dict[str, np.ndarray]]:
    """Read a PCD v0.7 file: the scan and its other fields.

    Parameters
    ----------
    path : str or Path
        ``DATA ascii``, ``binary`` or ``binary_compressed``; fields must include x, y, z.
    conf : str or Path, optional
        A Stanford ``.conf`` whose ``bmesh`` line for this file sets ``pose``.
    sensor : str, Path, dict or Sensor, optional
        What recorded the file: a preset name (``"kinect_v1"``), a sensor TOML, a dict or a
        :class:`~rangesim.sensor.config.Sensor`; its parameters go to ``meta["sensor"]``, so
        that the edge detectors measure a structured-light recording at its block matcher's
        scale (``mode = "structured_light"``, ``structured_light.window``). ``"auto"``: only
        if the depths sit on a disparity lattice
        (:func:`~rangesim.core.quantisation.disparity_lattice`: gaps between depth
        levels growing as z^2), the ``kinect_v1`` preset's, with the evidence in
        ``meta["sensor_evidence"]``; nothing otherwise. Default: no ``meta["sensor"]``.

    Returns
    -------
    scan : RangeScan
        HEIGHT x WIDTH (1 x N when unorganized), millimetres.
    extras : dict of str to ndarray
        Every field other than x/y/z, normal_x/y/z and intensity (e.g. ``label``,
        ``rgba``) in its file dtype, shaped (H, W), or (H, W, COUNT) for COUNT > 1.

    Raises
    ------
    RangesimError
        A missing file, a malformed header (NaN, inconsistent counts), truncated or
        corrupt data, no x/y/z fields, or an unknown ``sensor``.
    """
    path = check_file(path)
    described = _sensor_meta(sensor, path)
    raw = read_bytes(path)
    header = _read_header(raw, path)
    columns = _read_body(raw, header, path)
    h, w = header.height, header.width

    def grid(name: str) -> np.ndarray:
        return columns[name].reshape((h, w) + columns[name].shape[1:])

    names = [f.name for f in header.fields if not f.padding]
    missing = [a for a in "xyz" if a not in columns]
    if missing:
        raise RangesimError(f"no {'/'.join(missing)} field (FIELDS {' '.join(names)})", path)
    if any(columns[a].ndim != 1 for a in "xyz"):
        raise RangesimError("x, y and z must have COUNT 1", path)
    xyz = np.stack([grid(a).astype(np.float64) for a in "xyz"], axis=-1) * _MM
    normal = None
    if all(f"normal_{a}" in columns and columns[f"normal_{a}"].ndim == 1 for a in "xyz"):
        normal = _unit_normals(np.stack([grid(f"normal_{a}") for a in "xyz"], axis=-1))
    intensity = grid("intensity") if "intensity" in columns and columns["intensity"].ndim == 1 else None
    meta = recorded_meta(
        "pcd", path, "file", organized=h > 1, pcd_fields=names,
        pcd={"version": header.version, "data": header.data, "viewpoint": header.viewpoint},
    )
    with np.errstate(invalid="ignore"):
        reach = np.linalg.norm(xyz, axis=-1)
    reach = reach[np.isfinite(reach)]
    if reach.size and float(np.median(reach)) > PCD_FAR_MM:  # PCD's unit is the metre, by its spec
        warnings.warn(f"{path}: its points lie {np.median(reach) / 1e3:,.0f} m from the sensor (median); PCD "
                      "coordinates are metres: was the file written in millimetres?", stacklevel=2)
    scan = grid_scan(xyz, meta, normal=normal, intensity=intensity)
    if described == "auto":
        from rangesim.core.quantisation import DEFAULT_MATCHER_PRESET, disparity_lattice
        from rangesim.sensor.config import load_sensor

        evidence = disparity_lattice(scan.depth) if h > 1 else None
        if evidence is not None:
            # a block-matched recording of unknown make: the Kinect v1 preset's matcher
            scan.meta["sensor"] = load_sensor(DEFAULT_MATCHER_PRESET).to_dict()
            scan.meta["sensor_evidence"] = {"rule": "disparity lattice", **evidence}
    elif described is not None:
        scan.meta["sensor"] = described
    if isinstance(scan.meta.get("sensor"), dict) and h > 1:
        cam = scan.meta["sensor"].get("camera", {})
        if (cam.get("width"), cam.get("height")) != (w, h):
            # the window, noise law and intrinsics are the sensor's own, in its pixels
            warnings.warn(f"{path}: the file is {w} x {h} px, sensor {scan.meta['sensor'].get('name', '?')} "
                          f"{cam.get('width')} x {cam.get('height')}: its intrinsics, window and noise law, in its own "
                          "pixels, are used as they are (a binned or cropped frame?)", stacklevel=2)
    extras = {name: grid(name) for name in names if name not in _SCAN_FIELDS or columns[name].ndim != 1}
    return apply_conf(scan, conf, path), extras


def load_pcd(path: str | Path, *, conf: str | Path | None = None, sensor: Any = None) -> RangeScan:
    """:func:`read_pcd` without the extra fields (their names stay in ``meta["pcd_fields"]``)."""
    return read_pcd(path, conf=conf, sensor=sensor)[0]


def _sensor_meta(sensor: Any, path: Path) -> dict[str, Any] | str | None:
    """``sensor=`` as ``meta["sensor"]`` (a preset's, a file's, a dict's parameters), "auto" or
    None; an unknown or invalid sensor is a one-line RangesimError naming it and the file."""
    if sensor is None or (isinstance(sensor, str) and sensor == "auto"):
        return sensor
    from rangesim.sensor.config import Sensor, load_sensor

    if not isinstance(sensor, (str, Path, dict, Sensor)):
        raise RangesimError(f"sensor= must be a preset name, a TOML path, a dict or a Sensor, "
                            f"not {type(sensor).__name__}", path)
    try:
        return load_sensor(sensor).to_dict()
    except RangesimError as exc:
        raise RangesimError(f"sensor={sensor!r}: {exc}", path) from None


def _read_header(raw: bytes, path: Path) -> PcdHeader:
    entries: dict[str, list[str]] = {}
    offset = 0
    for _ in range(_MAX_HEADER_LINES):
        end = raw.find(b"\n", offset)
        if end < 0:
            raise RangesimError("PCD header has no DATA line (truncated or not a PCD file)", path)
        line = raw[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *words = line.split()
        if key not in _KEYS:
            raise RangesimError(f"not a PCD file (unknown header keyword {key[:40]!r})", path)
        if key in entries:
            raise RangesimError(f"PCD header has {key} twice", path)
        entries[key] = words
        if key == "DATA":
            break
    else:
        raise RangesimError("PCD header has no DATA line", path)

    def one(key: str, default: int | None = None) -> int:
        words = entries.get(key)
        if words is None:
            if default is None:
                raise RangesimError(f"PCD header has no {key} line", path)
            return default
        value = _int(words[0]) if len(words) == 1 else None
        if value is None or value <= 0:
            raise RangesimError(f"PCD header: {key} {' '.join(words)!r} is not a positive integer", path)
        return value

    names = entries.get("FIELDS") or []
    if not names:
        raise RangesimError("PCD header has no FIELDS", path)
    per_field = {}
    for key, default in (("SIZE", None), ("TYPE", None), ("COUNT", ["1"] * len(names))):
        words = entries.get(key, default)
        if words is None:
            raise RangesimError(f"PCD header has no {key} line", path)
        if len(words) != len(names):
            raise RangesimError(f"PCD header: {key} has {len(words)} entries for {len(names)} FIELDS", path)
        per_field[key] = words
    fields = []
    for name, size_word, kind, count_word in zip(names, per_field["SIZE"], per_field["TYPE"], per_field["COUNT"]):
        size, count = _int(size_word), _int(count_word)
        code = _TYPES.get((kind.upper(), size)) if size is not None else None
        if code is None:
            raise RangesimError(f"PCD header: field {name} has unsupported TYPE {kind!r} SIZE {size_word!r}", path)
        if count is None or count <= 0:
            raise RangesimError(f"PCD header: field {name} COUNT {count_word!r} is not a positive integer", path)
        if count > MAX_FIELD_COUNT:  # PCL's widest descriptors (VFH) hold 308
            raise RangesimError(f"PCD header: field {name} COUNT {count:,} is more than {MAX_FIELD_COUNT:,} "
                                "elements per point", path)
        fields.append(PcdField(name, code, size, count))
    real = [f.name for f in fields if not f.padding]
    if len(set(real)) != len(real):
        raise RangesimError(f"PCD header: repeated field names in FIELDS {' '.join(names)}", path)

    width, height = one("WIDTH"), one("HEIGHT", 1)
    points = one("POINTS", width * height)
    if points != width * height:
        raise RangesimError(f"PCD header: POINTS {points} but WIDTH x HEIGHT = {width} x {height} = {width * height}", path)
    viewpoint = list(_IDENTITY_VIEWPOINT)
    if "VIEWPOINT" in entries:
        try:
            viewpoint = [float(w) for w in entries["VIEWPOINT"]]
        except ValueError:
            viewpoint = []
        if len(viewpoint) != 7 or not all(math.isfinite(v) for v in viewpoint):
            raise RangesimError(f"PCD header: VIEWPOINT {' '.join(entries['VIEWPOINT'])!r} is not 7 finite numbers", path)
    data = " ".join(entries.get("DATA", [])).lower()
    if data not in PCD_DATA_KINDS:
        raise RangesimError(f"PCD header: unknown DATA {data!r} (expected ascii, binary or binary_compressed)", path)
    version = " ".join(entries.get("VERSION", ["0.7"]))
    return PcdHeader(version, fields, width, height, viewpoint, points, data, offset)


def _int(word: str) -> int | None:
    return int(word) if re.fullmatch(r"[+-]?\d+", word) else None


def _read_body(raw: bytes, header: PcdHeader, path: Path) -> dict[str, np.ndarray]:
    """Field name -> (POINTS,) or (POINTS, COUNT) array, padding fields dropped."""
    body = memoryview(raw)[header.offset:]
    n, fields = header.points, header.fields
    if header.data == "ascii":
        values = parse_numbers(bytes(body), path, "PCD ascii data")
        width = sum(f.count for f in fields)
        if values.size != n * width:
            raise RangesimError(
                f"PCD ascii data: expected {n} points x {width} values = {n * width} numbers, found {values.size}"
                + (" (truncated)" if values.size < n * width else ""),
                path,
            )
        table = values.reshape(n, width)
        columns, start = {}, 0
        for f in fields:
            block = table[:, start:start + f.count]
            start += f.count
            if f.padding:
                continue
            if f.code[-2] != "f":
                if not np.isfinite(block).all() or (block != np.round(block)).any():
                    raise RangesimError(f"PCD ascii data: integer field {f.name} holds non-integer values", path)
                info = np.iinfo(f.code)
                if info.bits == 64 and block.size and np.abs(block).max() >= 2.0**53:
                    # parsed as float64, whose integers end at 2**53 (2**64 - 1 read back as 0)
                    raise RangesimError(f"PCD ascii data: 64-bit integer field {f.name} holds values of 2**53 or "
                                        "more, which ascii cannot carry exactly here; write the file as binary", path)
                if block.size and (block.min() < info.min or block.max() > info.max):
                    # the cast would wrap them (300 as a U 1 label reads 44)
                    raise RangesimError(f"PCD ascii data: integer field {f.name} holds values outside its type "
                                        f"{np.dtype(f.code).name} ({info.min}..{info.max}): "
                                        f"{block.min():g}..{block.max():g}", path)
            columns[f.name] = _squeeze(block.astype(f.code), f)
        return columns
    if header.data == "binary":
        dtype = np.dtype([(f"f{i}", f.code, (f.count,)) for i, f in enumerate(fields)])
        needed = n * dtype.itemsize
        if len(body) < needed:
            raise RangesimError(
                f"truncated: {n} points need {needed} bytes of binary data, the file has {len(body)}", path
            )
        table = np.frombuffer(body, dtype=dtype, count=n)
        return {f.name: _squeeze(table[f"f{i}"], f) for i, f in enumerate(fields) if not f.padding}
    # binary_compressed
    if len(body) < 8:
        raise RangesimError("truncated: binary_compressed data has no size words", path)
    compressed, uncompressed = (int(v) for v in np.frombuffer(body[:8], dtype="<u4"))
    kept = [f for f in fields if not f.padding]
    expected = n * sum(f.size * f.count for f in kept)
    if uncompressed != expected:
        raise RangesimError(
            f"binary_compressed: uncompressed size {uncompressed} disagrees with the header "
            f"({n} points x {expected // n} bytes = {expected})",
            path,
        )
    if len(body) - 8 < compressed:
        raise RangesimError(
            f"truncated: compressed data is {compressed} bytes, the file has {len(body) - 8} after the header", path
        )
    try:
        data = lzf_decompress(body[8:8 + compressed], uncompressed)
    except LZFError as exc:
        raise RangesimError(f"corrupt binary_compressed data: {exc}", path) from None
    columns, start = {}, 0
    for f in kept:  # field after field, each over all points
        block = np.frombuffer(data, dtype=f.code, count=n * f.count, offset=start).reshape(n, f.count)
        start += n * f.size * f.count
        columns[f.name] = _squeeze(block, f)
    return columns


def _squeeze(block: np.ndarray, field: PcdField) -> np.ndarray:
    """(N, 1) -> (N,) for COUNT 1 fields, as a native-order array."""
    block = block.reshape(len(block), field.count)
    out = block[:, 0] if field.count == 1 else block
    return out.astype(out.dtype.newbyteorder("="), copy=True)


# -- writing ---------------------------------------------------------------------------------
def write_pcd(
    scan: RangeScan,
    path: str | Path,
    *,
    data: str = "binary",
    extras: dict[str, np.ndarray] | None = None,
    precision: str = "float32",
) -> Path:
    """Write ``scan`` (and extra fields) as a PCD v0.7 file, atomically.

    Fields: ``x y z`` (metres, NaN where invalid); ``normal_x/y/z`` when the scan has
    any finite normal; ``intensity`` when any is non-zero; then ``extras``. WIDTH x
    HEIGHT is the scan's image (HEIGHT 1 for a 1 x N scan); VIEWPOINT is
    ``meta["pcd"]["viewpoint"]`` when present, else the identity. ``binary_compressed``
    is written as a valid LZF stream of literal runs (no compression; any reader takes it).

    Parameters
    ----------
    scan : RangeScan
    path : str or Path
    data : {"binary", "ascii", "binary_compressed"}
    extras : dict of str to ndarray, optional
        Arrays of shape (H, W) or (H, W, COUNT), integer, unsigned, float or bool (bool is
        written as U 1, float16 as F 4 and long double as F 8: PCD floats are 4 or 8 bytes).
    precision : {"float32", "float64"}
        Type of x/y/z and the normals. Metres in float32 round-trip millimetres to within
        one float32 ulp; ``"float64"`` round-trips them exactly.

    Returns
    -------
    Path
        The path written.
    """
    path = Path(path)
    if data not in PCD_DATA_KINDS:
        raise RangesimError(f"unknown PCD DATA {data!r}; use one of {', '.join(PCD_DATA_KINDS)}", path)
    if precision not in ("float32", "float64"):
        raise RangesimError(f"precision must be 'float32' or 'float64', not {precision!r}", path)
    h, w = scan.shape
    if h == 0 or w == 0:  # PCD's WIDTH and HEIGHT are positive: no reader takes the file back
        raise RangesimError(f"cannot write an empty {h}x{w} scan as PCD", path)
    n = h * w
    real = np.dtype(precision)
    valid = scan.valid[..., None]
    xyz = np.where(valid, scan.xyz.astype(np.float64) / _MM, np.nan).reshape(n, 3).astype(real)
    columns: list[tuple[str, np.ndarray]] = [(a, xyz[:, i]) for i, a in enumerate("xyz")]
    if np.isfinite(scan.normal).any():
        normal = scan.normal.reshape(n, 3).astype(real)
        columns += [(f"normal_{a}", normal[:, i]) for i, a in enumerate("xyz")]
    if np.any(scan.intensity != 0):
        columns.append(("intensity", scan.intensity.reshape(n)))
    for name, value in (extras or {}).items():
        value = np.asarray(value)
        if not re.fullmatch(r"\w+", name) or name in _SCAN_FIELDS | {"_"} or any(name == c for c, _ in columns):
            raise RangesimError(f"extra field name {name!r} is not usable in a PCD file", path)
        if value.shape[:2] != (h, w) or value.ndim > 3 or value.dtype.kind not in "iufb":
            raise RangesimError(
                f"extra field {name}: need a numeric (H, W) or (H, W, COUNT) array with (H, W) = {(h, w)}, "
                f"got {value.dtype} {value.shape}",
                path,
            )
        if value.dtype.kind == "b":
            value = value.astype(np.uint8)
        elif value.dtype.kind == "f" and value.dtype.itemsize not in (4, 8):  # PCD floats are F 4 or F 8
            value = value.astype(np.float32 if value.dtype.itemsize < 4 else np.float64)
        columns.append((name, value.reshape(n, -1) if value.ndim == 3 else value.reshape(n)))
    header = _header_text(columns, w, h, scan.meta, data)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        if data == "ascii":
            fh.write(_ascii_body(columns))
        elif data == "binary":
            dtype = np.dtype([(f"f{i}", c.dtype.newbyteorder("<"), c.shape[1:]) for i, (_, c) in enumerate(columns)])
            table = np.empty(n, dtype=dtype)
            for i, (_, c) in enumerate(columns):
                table[f"f{i}"] = c
            fh.write(table.tobytes())
        else:
            raw = b"".join(np.ascontiguousarray(c, dtype=c.dtype.newbyteorder("<")).tobytes() for _, c in columns)
            packed = lzf_store(raw)
            fh.write(np.array([len(packed), len(raw)], dtype="<u4").tobytes())
            fh.write(packed)
    return path


def _header_text(columns: list[tuple[str, np.ndarray]], w: int, h: int, meta: dict[str, Any], data: str) -> str:
    kinds = {"i": "I", "u": "U", "f": "F"}
    viewpoint = (meta.get("pcd") or {}).get("viewpoint") if isinstance(meta.get("pcd"), dict) else None
    try:
        viewpoint = [float(v) for v in viewpoint]  # type: ignore[union-attr]
        assert len(viewpoint) == 7 and all(math.isfinite(v) for v in viewpoint)
    except (TypeError, ValueError, AssertionError):
        viewpoint = _IDENTITY_VIEWPOINT
    lines = [
        "# .PCD v0.7 - Point Cloud Data file format (written by rangesim)",
        "VERSION 0.7",
        "FIELDS " + " ".join(name for name, _ in columns),
        "SIZE " + " ".join(str(c.dtype.itemsize) for _, c in columns),
        "TYPE " + " ".join(kinds[c.dtype.kind] for _, c in columns),
        "COUNT " + " ".join(str(c.shape[1] if c.ndim == 2 else 1) for _, c in columns),
        f"WIDTH {w}",
        f"HEIGHT {h}",
        "VIEWPOINT " + " ".join(f"{v:.17g}" for v in viewpoint),
        f"POINTS {w * h}",
        f"DATA {data}",
    ]
    return "\n".join(lines) + "\n"


def _ascii_body(columns: list[tuple[str, np.ndarray]]) -> bytes:
    """One line per point; floats with enough digits to read back exactly."""
    parts, formats = [], []
    for _, c in columns:
        block = c.reshape(len(c), -1)
        parts.append(block)
        fmt = "%d" if c.dtype.kind in "iu" else ("%.9g" if c.dtype.itemsize == 4 else "%.17g")
        formats += [fmt] * block.shape[1]
    if any(p.dtype.kind in "iu" and p.dtype.itemsize == 8 for p in parts):
        table = np.concatenate([p.astype(object) for p in parts], axis=1)
    else:  # float64 holds every value of the other types exactly
        table = np.concatenate([p.astype(np.float64) for p in parts], axis=1)
    out = io.StringIO()
    np.savetxt(out, table, fmt=formats, delimiter=" ")
    return out.getvalue().encode("ascii")
