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
            radius=float(_positive(spec, "radius", source=source)),
            height=float(_positive(spec, "height", source=source)),
            sections=int(spec.get("sections", 64)),
        )
    if kind == "sphere":
        return trimesh.creation.icosphere(
            subdivisions=int(spec.get("subdivisions", 4)),
            radius=float(_positive(spec, "radius", source=source)),
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
