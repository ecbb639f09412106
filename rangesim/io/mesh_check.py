"""What is wrong with a mesh file that trimesh could not read, in words a user can act on.

trimesh reports a truncated binary STL as "no triangle mesh" and a PLY body cut short as a
reshape error; :func:`diagnose_mesh_file` looks at the bytes and names the real problem
(empty file, a directory, truncated binary STL with the triangle count its header promises,
a file named .stl that is no STL, a PLY without ``end_header`` or with a body shorter than
its header says, a GLB without its magic, an OFF file without its first line). With
``full=True`` it also reads the whole body of the text formats: an ASCII PLY or OFF with
fewer vertices or faces than its header says, an OBJ face index outside its vertex list.
"""
from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.io.ply_header import PLY_TYPES, PlyElement, PlyHeader, read_ply_header

#: bytes looked at for text formats (a header, the first lines)
_PEEK = 1 << 20
#: bytes a text file is made of (ASCII printable and whitespace)
_TEXT_BYTES = frozenset(range(0x20, 0x7F)) | frozenset(b"\t\n\r")
#: how other mesh formats start, for a file named .stl that is none
_OTHER_MAGIC = (b"ply", b"glTF", b"OFF", b"COFF")
_PLURAL = {"vertex": "vertices"}


def _stl(raw: bytes, size: int) -> str | None:
    head = raw[:512].lstrip().lower()
    if head.startswith(b"solid") and (b"facet" in raw[:_PEEK].lower() or size < 84):
        # (padding after the last line: NULs, a DOS end-of-file byte)
        last = raw.rstrip(b" \t\r\n\0\x1a").lower().rsplit(b"\n", 1)[-1].strip()
        if b"facet" in raw[:_PEEK].lower() and not last.startswith(b"endsolid"):
            return "truncated ASCII STL: no closing 'endsolid' line" + (
                "" if last.startswith(b"endfacet") else " (it ends inside a facet)")
        return None  # ASCII: trimesh's reader says what is wrong
    if size < 84:
        return f"truncated binary STL: {size:,} bytes, shorter than the 84-byte header"
    (count,) = struct.unpack("<I", raw[80:84])
    expected = 84 + 50 * count
    if count == 0:
        return "binary STL with 0 triangles"
    if size < expected:
        # a text file's "triangle count" is four letters (>= 538 million triangles): no binary
        # STL cut short, but another file under an .stl name
        if raw.startswith(_OTHER_MAGIC) or set(raw[80:84]) <= _TEXT_BYTES:
            if head.startswith(b"solid"):
                return None  # ASCII STL without facets: trimesh's "no triangle mesh" says it
            first = (raw.lstrip()[:40].splitlines() or [b""])[0].decode("latin-1")
            return (f"not an STL file (starts with {first!r}): neither a binary STL (its size does not "
                    "match its triangle count) nor an ASCII one ('solid ...')")
        return (f"truncated binary STL: its header says {count:,} triangles ({expected:,} bytes), "
                f"the file has {size:,} bytes")
    return None


def _counts(expected: dict[str, int], found: dict[str, int]) -> str:
    """'expected 8 vertices and 12 faces, found 8 vertices and 3 faces'."""
    def words(counts: dict[str, int]) -> str:
        return " and ".join(f"{n:,} {_PLURAL.get(name, name + 's')}" for name, n in counts.items())

    return f"expected {words(expected)}, found {words(found)}"


def _ply_ascii(path: Path, header: PlyHeader) -> str | None:
    """A truncated ASCII PLY body: fewer complete rows than the header's element counts."""
    expected = {e.name: e.count for e in header.elements}
    found = dict.fromkeys(expected, 0)
    with open(path, "rb") as f:
        f.seek(header.data_offset)
        lines = (line.split() for line in f)
        for element in header.elements:
            if element.count == 0:
                continue
            for words in lines:
                if not words:
                    continue
                if not _ply_row_complete(words, element):
                    break  # a row cut short (the file's last): not counted
                found[element.name] += 1
                if found[element.name] == element.count:
                    break
            if found[element.name] < element.count:
                return f"truncated ASCII PLY: {_counts(expected, found)}"
    return None


def _ply_row_complete(words: list[bytes], element: PlyElement) -> bool:
    """True when a row of an ASCII PLY holds a value for each property (a list: its count and items)."""
    at = 0
    for prop in element.properties:
        if prop.list_count is None:
            at += 1
            continue
        try:
            at += 1 + int(words[at])
        except (IndexError, ValueError):
            return False
    return len(words) >= at


def _off(path: Path) -> str | None:
    """A truncated OFF body: fewer complete vertex or face lines than its count line says."""
    with open(path, "rb") as f:
        lines, counts = _off_header(f)
        if counts is None:
            return "OFF file has no vertex/face count line"
        n_vertices, n_faces = counts
        expected = {"vertex": n_vertices, "face": n_faces}
        found = dict.fromkeys(expected, 0)
        for words in lines:
            kind = "vertex" if found["vertex"] < n_vertices else "face"
            if kind == "face" and found["face"] == n_faces:
                break
            try:
                complete = len(words) >= (3 if kind == "vertex" else 1 + int(words[0]))
            except ValueError:
                complete = False
            if not complete:
                break
            found[kind] += 1
    if found != expected:
        return f"truncated OFF: {_counts(expected, found)}"
    return None


def _obj(path: Path) -> str | None:
    """An OBJ face index outside the vertex list (OBJ counts from 1; negative: from the last vertex so far)."""
    n_vertices, worst = 0, None  # worst: (index, line number) of the largest positive index
    with open(path, "rb") as f:
        for number, line in enumerate(f, start=1):
            words = line.split(b"#")[0].split()
            if not words:
                continue
            if words[0] == b"v":
                n_vertices += 1
            elif words[0] == b"f":
                for word in words[1:]:
                    try:
                        index = int(word.split(b"/")[0])
                    except ValueError:
                        continue
                    if index == 0:
                        return (f"face index out of range of the vertex list: line {number} has index 0 "
                                "(OBJ indices start at 1)")
                    if index < 0 and -index > n_vertices:
                        return (f"face index out of range of the vertex list: line {number} has index {index}, "
                                f"{n_vertices:,} vertices before it")
                    if worst is None or index > worst[0]:
                        worst = (index, number)
    if worst is not None and worst[0] > n_vertices:
        return (f"face index out of range of the vertex list: line {worst[1]} refers to vertex {worst[0]:,}, "
                f"the file has {n_vertices:,} vertices")
    return None


#: an index 0 between separators, as it appears in an OBJ face line (``f 0 1 2``, ``f 1/1 0/2 2/3``)
_ZERO_TOKENS = tuple(a + b"0" + b for a in (b" ", b"\t") for b in (b" ", b"/", b"\n", b"\r", b"\t"))


def _zero_index_line(data: bytes) -> int | None:
    """Offset of the first OBJ face line holding a vertex index 0, or None. ``bytes.find`` over
    the few spellings (memchr speed); a match in another record (``v 0 0 1``) skips its line."""
    found = []
    for token in _ZERO_TOKENS:
        i = data.find(token)
        while i >= 0:
            start = data.rfind(b"\n", 0, i) + 1
            comment = data.find(b"#", start, i)  # an index 0 in a comment ('f 1 2 3 # was 0') is none
            if data[start:start + 2] in (b"f ", b"f\t") and comment < 0:
                found.append(start)
                break
            end = data.find(b"\n", i + 1)
            i = data.find(token, end) if end >= 0 else -1
    if data.endswith((b" 0", b"\t0")):  # the file's last token
        start = data.rfind(b"\n") + 1
        if data[start:start + 2] in (b"f ", b"f\t") and data.find(b"#", start) < 0:
            found.append(start)
    return min(found) if found else None


def _obj_quick(path: Path) -> str | None:
    """What :func:`check_text_mesh` finds in an OBJ that trimesh read: an index 0 (read as the
    last vertex: a wrong face and no error) or a last line cut short (a truncated file, read
    as a part of the part)."""
    data = path.read_bytes()
    zero = _zero_index_line(data)
    if zero is not None:
        line = data.count(b"\n", 0, zero) + 1
        return f"face index out of range of the vertex list: line {line:,} has index 0 (OBJ indices start at 1)"
    if data and not data.endswith((b"\n", b"\r")):
        last = data.rsplit(b"\n", 1)[-1].split()
        needed = {b"v": 4, b"vn": 4, b"f": 4, b"vt": 2}
        if last and len(last) < needed.get(last[0], 0):
            line = data.count(b"\n") + 1
            return f"truncated OBJ: its last line ({line:,}) ends in the middle of a '{last[0].decode()}' record"
    return None


def _off_header(f) -> tuple[Iterator[list[bytes]], tuple[int, int] | None]:
    """An open OFF file's remaining lines (as words) and the vertex and face counts its count
    line declares (None if it has none). trimesh reads OFF line by line: comments stripped,
    blank lines skipped, the counts after the OFF keyword on its own line or on the next."""
    lines = (w for w in (line.split(b"#")[0].split() for line in f) if w)
    first = next(lines, [b""])
    counts = first[1:] or next(lines, [])
    try:
        return lines, (int(counts[0]), int(counts[1]))
    except (IndexError, ValueError):
        return lines, None


def _off_counts(path: Path) -> tuple[int, int] | None:
    """The vertex and face counts an OFF file's count line declares (None if it has none)."""
    with open(path, "rb") as f:
        return _off_header(f)[1]


def check_text_mesh(path: str | Path, n_vertices: int, n_faces: int) -> str | None:
    """The problem with an OBJ or OFF file that trimesh read without an error, or None.

    trimesh reads a truncated OFF or OBJ as the part of the part it holds, and an OBJ index 0
    as the last vertex: no error, a wrong mesh. Cheap checks of the loaded mesh against the
    file: an OFF's declared counts (the whole body is read only when they are not met) and one
    pass over an OBJ's bytes.

    Parameters
    ----------
    path : str or Path
        The file trimesh read.
    n_vertices, n_faces : int
        What it read: vertices, and triangles (an OFF polygon of n sides gives n - 2).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".obj":
        return _obj_quick(path)
    if suffix == ".off":
        counts = _off_counts(path)
        if counts is not None and (n_vertices < counts[0] or n_faces < counts[1]):
            # fewer than declared: the body decides (OFF may also list 1- and 2-vertex elements,
            # which trimesh drops, so fewer triangles alone are no truncation)
            return _off(path)
    return None


def _ply(raw: bytes, size: int, path: Path, full: bool) -> str | None:
    try:
        header = read_ply_header(raw, path)
    except RangesimError as exc:
        return str(exc).removeprefix(f"{path}: ")
    if header.format == "ascii":
        return _ply_ascii(path, header) if full else None
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


def diagnose_mesh_file(path: str | Path, full: bool = False) -> str | None:
    """The problem with a mesh file in one line (without the file name), or None if none is found.

    Parameters
    ----------
    path : str or Path
        The mesh file.
    full : bool
        Also read the whole body of an OBJ, OFF or ASCII PLY (truncation, face indices out of
        range): for after a reader failed, not before every load (it reads the file once more).
    """
    path = Path(path)
    if path.is_dir():
        return "is a directory, not a mesh file"
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
        try:
            return _ply(raw, size, path, full)
        except OSError as exc:
            return exc.strerror or str(exc)
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
    try:
        if full and suffix == ".off":
            return _off(path)
        if full and suffix == ".obj":
            return _obj(path)
    except OSError as exc:
        return exc.strerror or str(exc)
    return None
