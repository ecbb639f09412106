"""Cyberware range scans in Stanford's PLY layout (``range_grid``).

The file is ASCII: ``obj_info num_cols`` / ``num_rows`` and scanner fields in the header,
``element vertex N`` (x y z, metres), then ``element range_grid R*C`` whose lines are
``0`` (no sample in the cell) or ``1 i`` (vertex i), row-major. The grid becomes the image:
R x C, cell (r, c) -> pixel (r, c), empty cells status 1 with NaN points.

Frame: the scanner's own (``meta["frame"] == "scanner"``), *not* the OpenCV camera frame
of synthetic scans: x is the sweep direction (steps of ``echo_lgincr``), y runs down the
columns, z is the range axis; ``depth`` is z in mm. There is no pinhole model, so
``meta["K"]`` is absent.

Poses come from a Stanford ``.conf`` (see :mod:`rangesim.recorded.conf`).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io.ply_header import PlyHeader, read_ply_header
from rangesim.recorded.common import check_file, grid_scan, read_bytes, recorded_meta
from rangesim.recorded.conf import apply_conf
from rangesim.recorded.text import line_block, line_ends, parse_numbers

__all__ = ["cyberware_from", "read_cyberware_ply"]

#: Cyberware files are in metres; scans are in millimetres
METRES_TO_MM = 1000.0
_WHITESPACE = np.frombuffer(b" \t\r\n\v\f", dtype=np.uint8)


def read_cyberware_ply(path: str | Path, *, conf: str | Path | None = None) -> RangeScan:
    """Read a Cyberware / Stanford range-grid PLY as an organized scan.

    Parameters
    ----------
    path : str or Path
        An ASCII PLY with ``obj_info num_cols``/``num_rows``, a ``vertex`` element with
        ``x y z`` (metres; an ``intensity`` property is kept) and a ``range_grid``.
    conf : str or Path, optional
        A Stanford ``.conf`` file; the ``bmesh`` line naming this file sets ``pose``.

    Returns
    -------
    RangeScan
        num_rows x num_cols, millimetres, scanner frame; ``meta["scanner"]`` holds every
        ``obj_info`` field (numbers as numbers, e.g. ``echo_lgincr`` 0.0005 m,
        ``echo_frames``), ``meta["ply_properties"]`` the vertex properties.

    Raises
    ------
    RangesimError
        A missing file, no range grid, a grid size that disagrees with the header, a
        truncated or malformed body, a vertex index out of range, or (with ``conf``) no
        pose for this file.
    """
    path = check_file(path)
    raw = read_bytes(path)
    return cyberware_from(raw, read_ply_header(raw, path), path, conf=conf)


def cyberware_from(raw: bytes, header: PlyHeader, path: Path, *, conf: Any = None) -> RangeScan:
    """:func:`read_cyberware_ply` on a file already read and its parsed header."""
    grid_element = header.element("range_grid")
    if grid_element is None:
        raise RangesimError("PLY file has no range_grid element: not a Cyberware range scan", path)
    scanner = _obj_info(header.obj_info, path)
    rows, cols = (_grid_size(scanner, key, path) for key in ("num_rows", "num_cols"))
    cells = rows * cols
    if grid_element.count != cells:
        raise RangesimError(
            f"range_grid has {grid_element.count} cells but num_rows x num_cols = {rows} x {cols} = {cells}",
            path,
        )
    if header.format != "ascii":
        raise RangesimError("binary range-grid PLY files are not supported (only ASCII Cyberware files)", path)
    vertex = header.element("vertex")
    if vertex is None:
        raise RangesimError("PLY file has no vertex element", path)
    names = [p.name for p in vertex.properties]
    if vertex.has_lists or not {"x", "y", "z"} <= set(names):
        raise RangesimError(f"vertex properties {' '.join(names)!r}: need scalar x, y and z", path)

    # ASCII PLY: every element item is one line, elements in header order
    body = raw[header.data_offset:]
    ends = line_ends(body)
    line, blocks = 0, {}
    for element in header.elements:
        if element is vertex or element is grid_element:
            blocks[element.name] = line_block(body, ends, line, element.count, path, f"{element.name} data")
        line += element.count

    values = parse_numbers(blocks["vertex"], path, "vertex data")
    if values.size != vertex.count * len(names):
        raise RangesimError(
            f"vertex data: expected {vertex.count} lines of {len(names)} numbers, found {values.size} numbers",
            path,
        )
    table = values.reshape(vertex.count, len(names))
    index = _grid_indices(blocks["range_grid"], cells, vertex.count, path)

    hit = index >= 0
    columns = [names.index(a) for a in "xyz"]
    xyz = np.full((cells, 3), np.nan)  # float64 until grid_scan has checked the range
    xyz[hit] = table[index[hit]][:, columns] * METRES_TO_MM
    intensity = None
    if "intensity" in names:
        intensity = np.zeros(cells, dtype=np.float32)
        intensity[hit] = table[index[hit], names.index("intensity")]
        intensity = intensity.reshape(rows, cols)
    meta = recorded_meta(
        "cyberware_ply", path, "scanner", organized=True, scanner=scanner,
        ply_properties=names, vertex_count=vertex.count,
    )
    scan = grid_scan(xyz.reshape(rows, cols, 3), meta, intensity=intensity)
    return apply_conf(scan, conf, path)


def _obj_info(entries: list[tuple[str, str]], path: Path) -> dict[str, Any]:
    """``obj_info`` fields as a dict: integers, floats (finite) or strings."""
    info: dict[str, Any] = {}
    for key, text in entries:
        value: Any = text
        for kind in (int, float):
            try:
                value = kind(text)
                break
            except ValueError:
                continue
        if isinstance(value, float) and not math.isfinite(value):
            raise RangesimError(f"PLY header: obj_info {key} is {text!r}, not a finite number", path)
        info[key] = value
    return info


def _grid_size(scanner: dict[str, Any], key: str, path: Path) -> int:
    value = scanner.get(key)
    if value is None:
        raise RangesimError(f"PLY header has no 'obj_info {key}': not a Cyberware range scan", path)
    if not isinstance(value, int) or value <= 0:
        raise RangesimError(f"PLY header: obj_info {key} is {value!r}, not a positive integer", path)
    return value


def _grid_indices(text: bytes, cells: int, n_vertices: int, path: Path) -> np.ndarray:
    """Vertex index per grid cell (-1 where empty) from the ``range_grid`` lines, vectorised.

    Each line is a list: a count, then that many vertex indices (Cyberware files have
    counts 0 or 1; with more, the first index is used).
    """
    chars = np.frombuffer(text, dtype=np.uint8)
    space = np.isin(chars, _WHITESPACE)
    starts = ~space
    starts[1:] &= space[:-1]
    line_of = np.cumsum(chars == 10)  # the line each byte is on
    per_line = np.bincount(line_of[starts], minlength=cells)[:cells]
    empty = np.flatnonzero(per_line == 0)
    if empty.size:
        raise RangesimError(f"range_grid line {empty[0] + 1} is empty", path)
    tokens = parse_numbers(text, path, "range_grid data", dtype=np.int64)
    first = np.cumsum(per_line) - per_line
    declared = tokens[first]
    wrong = np.flatnonzero(declared != per_line - 1)
    if wrong.size:
        k = wrong[0]
        raise RangesimError(
            f"range_grid line {k + 1}: declares {declared[k]} vertex indices but holds {per_line[k] - 1}", path
        )
    index = np.full(cells, -1, dtype=np.int64)
    has = declared > 0
    index[has] = tokens[first[has] + 1]
    bad = np.flatnonzero(has & ((index < 0) | (index >= n_vertices)))
    if bad.size:
        raise RangesimError(
            f"range_grid line {bad[0] + 1}: vertex index {index[bad[0]]} out of range (0..{n_vertices - 1})", path
        )
    return index
