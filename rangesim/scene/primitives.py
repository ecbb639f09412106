"""Simple solids for scene files and tests (box, cylinder, sphere, plane), in scene units."""
from __future__ import annotations

from typing import Any

import numpy as np
import trimesh

from rangesim.core.errors import RangesimError


def _positive(spec: dict[str, Any], key: str, default=None, source="scene") -> float:
    value = spec.get(key, default)
    if value is None:
        raise RangesimError(f"primitive needs '{key}'", source=source)
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise RangesimError(f"primitive '{key}' must be a number or a list of numbers, got {value!r}",
                            source=source) from None
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise RangesimError(f"primitive '{key}' must be positive, got {value!r}", source=source)
    return arr


#: the geometry keys of each primitive (a key of another kind is refused, not ignored)
PRIMITIVE_KEYS = {"box": ("size",), "cylinder": ("radius", "height", "sections"),
                  "sphere": ("radius", "subdivisions"), "plane": ("size",)}
#: every primitive geometry key (none of them applies to a mesh or a model)
GEOMETRY_KEYS = frozenset(k for keys in PRIMITIVE_KEYS.values() for k in keys)
#: tessellation limits: a cylinder of 3 sections is a prism (2 is flat); an icosphere of
#: subdivision s has 20 4^s faces (8: 1.3 million, about 200 MB with its Mitsuba copy)
SECTIONS = (3, 65536)
SUBDIVISIONS = (0, 8)


def _scalar(spec: dict[str, Any], key: str, source: Any) -> float:
    value = _positive(spec, key, source=source)
    if value.shape != ():
        raise RangesimError(f"primitive '{key}' must be one number, got {spec[key]!r}", source=source)
    return float(value)


def _count(spec: dict[str, Any], key: str, default: int, bounds: tuple[int, int], source: Any) -> int:
    value = spec.get(key, default)
    lo, hi = bounds
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer)) or value != int(value) \
            or not lo <= value <= hi:
        raise RangesimError(f"primitive '{key}' must be a whole number in {lo}..{hi}, got {value!r}", source=source)
    return int(value)


def make_primitive(kind: str, spec: dict[str, Any], source="scene") -> trimesh.Trimesh:
    """Mesh of a primitive solid centred on the origin.

    Parameters
    ----------
    kind : {"box", "cylinder", "sphere", "plane"}
        ``box``: ``size`` = [x, y, z]; ``cylinder`` (axis z): ``radius``, ``height``,
        ``sections`` (default 64); ``sphere``: ``radius``, ``subdivisions`` (default 4);
        ``plane`` (an open square sheet facing +z): ``size`` = [x, y].
    spec : dict
        The object's table from the scene file.
    """
    if kind == "box":
        size = _positive(spec, "size", source=source)
        if size.shape != (3,):
            raise RangesimError("box 'size' must be [x, y, z]", source=source)
        return trimesh.creation.box(extents=size)
    if kind == "cylinder":
        return trimesh.creation.cylinder(
            radius=_scalar(spec, "radius", source),
            height=_scalar(spec, "height", source),
            sections=_count(spec, "sections", 64, SECTIONS, source),
        )
    if kind == "sphere":
        return trimesh.creation.icosphere(
            subdivisions=_count(spec, "subdivisions", 4, SUBDIVISIONS, source),
            radius=_scalar(spec, "radius", source),
        )
    if kind == "plane":
        size = _positive(spec, "size", source=source)
        if size.shape != (2,):
            raise RangesimError("plane 'size' must be [x, y]", source=source)
        hx, hy = size / 2
        vertices = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]], float)
        return trimesh.Trimesh(vertices, np.array([[0, 1, 2], [0, 2, 3]]), process=False)
    raise RangesimError(
        f"unknown primitive {kind!r} (box, cylinder, sphere, plane)", source=source
    )
