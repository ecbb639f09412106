"""What is wrong with a mesh file that trimesh could not read, in words a user can act on.

trimesh reports a truncated binary STL as "no triangle mesh" and a PLY body cut short as a
reshape error; :func:`diagnose_mesh_file` looks at the bytes and names the real problem
(empty file, truncated binary STL with the triangle count its header promises, a PLY
without ``end_header`` or with a body shorter than its header says, a GLB without its
magic, an OFF file without its first line).
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.io.ply_header import PLY_TYPES, read_ply_header

#: bytes looked at for text formats (a header, the first lines)
_PEEK = 1 << 20


def _stl(raw: bytes, size: int) -> str | None:
    head = raw[:512].lstrip().lower()
    if head.startswith(b"solid") and (b"facet" in raw[:_PEEK].lower() or size < 84):
        return None  # ASCII: trimesh's reader says what is wrong
    if size < 84:
        return f"truncated binary STL: {size:,} bytes, shorter than the 84-byte header"
    (count,) = struct.unpack("<I", raw[80:84])
    expected = 84 + 50 * count
    if count == 0:
        return "binary STL with 0 triangles"
    if size < expected:
        return (f"truncated binary STL: its header says {count:,} triangles ({expected:,} bytes), "
                f"the file has {size:,} bytes")
    return None


def _ply(raw: bytes, size: int, path: Path) -> str | None:
    try:
        header = read_ply_header(raw, path)
    except RangesimError as exc:
        return str(exc).removeprefix(f"{path}: ")
    if header.format == "ascii":
        return None
    need = 0
    for element in header.elements:
        if element.has_lists:
            # faces of triangles (the usual mesh): a count byte/short/int and three indices
            props = element.properties
            if len(props) != 1 or props[0].list_count is None:
                return None
            count = np.dtype(PLY_TYPES.get(props[0].list_count, props[0].list_count)).itemsize
            need += element.count * (count + 3 * np.dtype(props[0].dtype).itemsize)
            continue
        need += element.count * sum(np.dtype(p.dtype).itemsize for p in element.properties)
    body = size - header.data_offset
    if body < need:
        return f"truncated PLY: its header promises at least {need:,} bytes of data, the file has {body:,}"
    return None


def diagnose_mesh_file(path: str | Path) -> str | None:
    """The problem with a mesh file in one line (without the file name), or None if none is found."""
    path = Path(path)
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            raw = f.read(_PEEK)
            if size > _PEEK:
                f.seek(max(size - 4096, 0))
                raw_tail = f.read()
            else:
                raw_tail = b""
    except OSError as exc:
        return exc.strerror or str(exc)
    if size == 0:
        return "file is empty"
    suffix = path.suffix.lower()
    if suffix == ".stl":
        return _stl(raw + raw_tail if raw_tail else raw, size)
    if suffix == ".ply":
        return _ply(raw, size, path)
    if suffix == ".glb":
        if not raw.startswith(b"glTF"):
            return "not a binary glTF file (no 'glTF' magic)"
        if size >= 12:
            (length,) = struct.unpack("<I", raw[8:12])
            if size < length:
                return f"truncated GLB: its header says {length:,} bytes, the file has {size:,}"
        return None
    text = raw.decode("latin-1")
    if suffix == ".off" and not text.lstrip().upper().startswith(("OFF", "COFF", "NOFF", "STOFF")):
        return "not an OFF file (no 'OFF' first line)"
    return None
