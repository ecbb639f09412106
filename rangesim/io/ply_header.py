"""PLY headers: the parsed header of a PLY file (any PLY: points, meshes, range grids).

:func:`read_ply_header` reads the ASCII header at the start of a file's bytes into a
:class:`PlyHeader` (format, elements with their properties, comments, ``obj_info``
lines, and where the body starts); the readers in :mod:`rangesim.recorded` then read
the body they understand.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from rangesim.core.errors import RangesimError

__all__ = [
    "MAX_HEADER_BYTES",
    "PLY_FORMATS",
    "PLY_TYPES",
    "PlyElement",
    "PlyHeader",
    "PlyProperty",
    "read_ply_header",
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
    # at a line's start: a comment may mention it
    match = re.search(rb"(?m)^end_header[ \t]*\r?\n", raw[:MAX_HEADER_BYTES])
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
