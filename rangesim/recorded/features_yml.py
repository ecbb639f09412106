"""Labelled CAD features of the machined targets (``*_features.yml`` beside a ``*_trimesh.obj``,
as in the ABC dataset's feature files): a small block-YAML reader and the conversion of the
labelled curves into :class:`~rangesim.cad.features.AnalyticFeatures`.

PyYAML is not a dependency, so :func:`parse_block_yaml` reads the subset these files use:
block mappings and sequences by indentation (``key: value``, ``key:`` then a nested block,
``- item``, ``- key: value`` and compact ``- - item``), plain scalars (integers, floats,
``true``/``false``, ``null``/``~``, bare or quoted strings) and ``#`` comment lines. No flow
collections, anchors, tags or multi-line strings.

A curve ``{type: Circle, location, radius, z_axis, sharp, vert_indices}`` becomes a
:class:`~rangesim.cad.features.Circle3D` (centre = location, normal = z_axis); a curve
``{type: Line, location, direction, vert_indices}`` becomes a
:class:`~rangesim.cad.features.Segment3D` whose end points are the extreme projections on
the line of the OBJ vertices it lists. Other curve types (BSpline, ...) are left out.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError

__all__ = ["parse_block_yaml", "obj_vertices", "curves_to_features", "read_features_yml"]


def _scalar(text: str) -> Any:
    t = text.strip()
    if t == "" or t in ("null", "Null", "NULL", "~"):
        return None
    if t in ("true", "True", "TRUE"):
        return True
    if t in ("false", "False", "FALSE"):
        return False
    if len(t) >= 2 and t[0] == t[-1] and t[0] in "'\"":
        return t[1:-1]
    try:
        return int(t)
    except ValueError:
        pass
    try:
        return float(t)
    except ValueError:
        return t


def _split_key(text: str) -> tuple[str, str] | None:
    """(key, rest) of ``key: rest`` / ``key:``, or None when the text is not a mapping entry."""
    if text[:1] in "'\"":
        q = text[0]
        end = text.find(q, 1)
        if end > 0 and text[end + 1:end + 2] == ":" and (len(text) == end + 2 or text[end + 2] == " "):
            return text[1:end], text[end + 2:].strip()
        return None
    k = text.find(": ")
    if k < 0:
        return (text[:-1].strip(), "") if text.endswith(":") else None
    return text[:k].strip(), text[k + 2:].strip()


def parse_block_yaml(text: str) -> Any:
    """The value of a block-style YAML document (the subset described in the module notes).

    Raises
    ------
    RangesimError
        On a structure outside the subset (bad indentation, flow collections).
    """
    lines: list[list] = []  # [indent, content, line number]
    for n, raw in enumerate(text.splitlines(), 1):
        stripped = raw.strip()
        if not stripped or stripped.startswith("#") or stripped in ("---", "..."):
            continue
        if "\t" in raw[: len(raw) - len(raw.lstrip())]:
            raise RangesimError(f"line {n}: tabs in indentation")
        lines.append([len(raw) - len(raw.lstrip(" ")), stripped, n])
    if not lines:
        return None
    value, i = _block(lines, 0, lines[0][0])
    if i != len(lines):
        raise RangesimError(f"line {lines[i][2]}: unexpected indentation")
    return value


def _block(lines: list[list], i: int, indent: int) -> tuple[Any, int]:
    """Parse the node starting at line i, whose lines have exactly ``indent``."""
    text = lines[i][1]
    if text[0] in "[{":
        raise RangesimError(f"line {lines[i][2]}: flow collections are not supported")
    if text == "-" or text.startswith("- "):
        items = []
        while i < len(lines) and lines[i][0] == indent and (lines[i][1] == "-" or lines[i][1].startswith("- ")):
            rest = lines[i][1][1:]
            if rest.strip() == "":
                i += 1
                if i < len(lines) and lines[i][0] > indent:
                    v, i = _block(lines, i, lines[i][0])
                else:
                    v = None
            else:
                # the item's content acts as a node indented past the dash
                pad = len(rest) - len(rest.lstrip(" "))
                lines[i] = [indent + 1 + pad, rest.strip(), lines[i][2]]
                v, i = _block(lines, i, lines[i][0])
            items.append(v)
        return items, i
    if _split_key(text) is not None:
        out: dict[str, Any] = {}
        while i < len(lines) and lines[i][0] == indent:
            kv = _split_key(lines[i][1])
            if kv is None:
                raise RangesimError(f"line {lines[i][2]}: expected 'key: value'")
            key, rest = kv
            i += 1
            if rest:
                out[key] = _scalar(rest)
            elif i < len(lines) and (lines[i][0] > indent or (
                    lines[i][0] == indent and (lines[i][1] == "-" or lines[i][1].startswith("- ")))):
                out[key], i = _block(lines, i, lines[i][0])
            else:
                out[key] = None
        return out, i
    return _scalar(text), i + 1


def obj_vertices(path: str | Path) -> np.ndarray:
    """(N, 3) float vertices of a Wavefront OBJ, in file order (``v`` lines only)."""
    text = Path(path).read_bytes().decode("utf-8", errors="replace")
    rows = [ln.split()[1:4] for ln in text.splitlines() if ln.startswith("v ")]
    try:
        return np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise RangesimError(f"OBJ vertices are not 3 numbers each ({exc})", source=path) from None


def curves_to_features(curves: list[dict], vertices: np.ndarray | None = None, *,
                       sharp_only: bool = True, part: str = ""):
    """AnalyticFeatures of labelled curves (in the CAD file's frame).

    Parameters
    ----------
    curves : list of dict
        The ``curves`` list of a features file.
    vertices : (N, 3) float, optional
        The OBJ's vertices (for the end points of lines); lines are left out without them.
    sharp_only : bool
        Keep only curves labelled ``sharp: true`` (creases; smooth tangent curves make no
        edge).

    Returns
    -------
    AnalyticFeatures
        Circles named ``circle_<k>`` and segments ``line_<k>``, k the curve's index in the file.
    """
    from rangesim.cad.features import AnalyticFeatures, Circle3D, Segment3D

    circles, segments = [], []
    for k, c in enumerate(curves):
        if not isinstance(c, dict) or (sharp_only and not c.get("sharp", False)):
            continue
        kind = c.get("type")
        if kind == "Circle":
            normal = np.asarray(c.get("z_axis", (0.0, 0.0, 1.0)), float)
            center, r = np.asarray(c["location"], float), float(c["radius"])
            if any(np.allclose(center, o.center, atol=1e-6) and abs(r - o.radius) < 1e-6 for o in circles):
                continue  # one circle labelled as several arcs: keep it once
            circles.append(Circle3D(f"circle_{k}", np.asarray(c["location"], float),
                                    normal / np.linalg.norm(normal), float(c["radius"]), part=part))
        elif kind == "Line" and vertices is not None and c.get("vert_indices"):
            loc = np.asarray(c["location"], float)
            d = np.asarray(c["direction"], float)
            d /= np.linalg.norm(d)
            idx = np.asarray(c["vert_indices"], int)
            t = (vertices[idx] - loc) @ d
            if t.max() - t.min() <= 0:
                continue
            segments.append(Segment3D(f"line_{k}", loc + t.min() * d, loc + t.max() * d, part=part))
    return AnalyticFeatures(circles, segments)


def read_features_yml(path: str | Path, obj: str | Path | None = None, matrix: np.ndarray | None = None,
                      *, sharp_only: bool = True):
    """Labelled lines and circles of a ``*_features.yml`` file as AnalyticFeatures.

    Parameters
    ----------
    path : path of the features file
    obj : path of the matching OBJ, optional
        Default: the file's name with ``_features.yml`` replaced by ``_trimesh.obj`` when it
        exists (needed for the lines' end points).
    matrix : (4, 4) float, optional
        Object-to-world transform applied to the features (e.g. the scene's
        :func:`rangesim.core.geometry.object_transform` of the object).
    sharp_only : bool
        See :func:`curves_to_features`.
    """
    path = Path(path)
    if obj is None:
        guess = path.with_name(path.name.replace("_features.yml", "_trimesh.obj"))
        obj = guess if guess.is_file() and guess != path else None
    # only the ``curves`` section is needed: stop at the next top-level key
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RangesimError(f"not a UTF-8 text file (byte {exc.start:,})", source=path) from None
    lines = text.splitlines(keepends=True)
    start = next((n for n, ln in enumerate(lines) if ln.startswith("curves:")), None)
    if start is None:
        raise RangesimError(f"{path}: no 'curves' section")
    end = next((n for n in range(start + 1, len(lines))
                if lines[n][:1] not in (" ", "-", "#", "\n", "\r", "")), len(lines))
    try:
        doc = parse_block_yaml("".join(lines[start:end]))
        vertices = obj_vertices(obj) if obj is not None else None
        feats = curves_to_features(doc.get("curves") or [], vertices, sharp_only=sharp_only)
    except RangesimError:
        raise
    except (ValueError, TypeError, KeyError, IndexError, AttributeError) as exc:
        raise RangesimError(f"cannot read the curves ({type(exc).__name__}: {exc})", source=path) from exc
    return feats.transformed(np.asarray(matrix, float)) if matrix is not None else feats
