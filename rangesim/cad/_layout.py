"""Checks of a parametric part's layout: sizes that are sizes, and features that lie on the part.

A built-in part lists its features (hole rims, edges) from its parameters, so a hole placed off
the plate would be listed as a rim the mesh does not have: the analytic ground truth would be
wrong. These checks refuse such parameters with a one-line message naming the parameter.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError


def tuples(model: str, key: str, value: Any, fields: tuple[str, ...], *, many: bool = True) -> list[tuple[float, ...]]:
    """``value`` as a list of tuples of ``len(fields)`` finite numbers (one tuple unless ``many``).

    Examples
    --------
    >>> tuples("part", "holes", [(1, 2, 3)], ("x", "y", "radius"))
    [(1.0, 2.0, 3.0)]
    """
    shape = f"({', '.join(fields)})"
    what = f"a list of {shape}" if many else shape
    rows = value if many else [value]
    if not isinstance(rows, (list, tuple)):
        raise RangesimError(f"{model}: {key} must be {what}, got {value!r}")
    out = []
    for row in rows:
        if (not isinstance(row, (list, tuple)) or len(row) != len(fields)
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in row)):
            raise RangesimError(f"{model}: {key} must be {what} (finite numbers), got {value!r}")
        out.append(tuple(float(v) for v in row))
    return out


def positive(model: str, **sizes: float) -> None:
    """Every named size a finite number > 0."""
    for key, value in sizes.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise RangesimError(f"{model}: {key} must be a number > 0, got {value!r}")


def within(model: str, what: str, x: float, y: float, reach: float, half_length: float, half_width: float) -> None:
    """The disc of radius ``reach`` about (x, y) inside the rectangle |x| < half_length, |y| < half_width (mm)."""
    if abs(x) + reach >= half_length or abs(y) + reach >= half_width:
        raise RangesimError(f"{model}: {what} at ({x:g}, {y:g}) reaching {reach:g} mm does not lie on the "
                            f"{2 * half_length:g} x {2 * half_width:g} mm plate")


# ---------------------------------------------------------------------------------------------
# footprints on the plate top: features that overlap cut or cover each other's rims
# ---------------------------------------------------------------------------------------------
#: the least gap a user's layout keeps between two features and between a feature and the edge of
#: the face it stands on, mm (features that touch or overlap cover or cut each other's rims, which
#: would be listed where the mesh has none)
MIN_GAP_MM = 0.5


def circle(x: float, y: float, r: float) -> tuple:
    """The footprint of a disc of radius ``r`` about (x, y)."""
    return ("circle", np.array([x, y], dtype=float), float(r))


def box(x0: float, y0: float, x1: float, y1: float) -> tuple:
    """The footprint of an axis-aligned rectangle."""
    return polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])


def polygon(vertices) -> tuple:
    """The footprint of a convex polygon (vertices in order, either way round)."""
    return ("polygon", np.asarray(vertices, dtype=float), 0.0)


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = 0.0 if not ab.any() else min(1.0, max(0.0, float(np.dot(p - a, ab) / np.dot(ab, ab))))
    return float(np.linalg.norm(p - (a + t * ab)))


def _edges(poly: np.ndarray):
    return zip(poly, np.roll(poly, -1, axis=0), strict=True)


def _inside_polygon(p: np.ndarray, poly: np.ndarray) -> bool:
    sides = [float((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) for a, b in _edges(poly)]
    return all(s >= 0 for s in sides) or all(s <= 0 for s in sides)


def _separated(a: np.ndarray, b: np.ndarray) -> bool:
    """Two convex polygons have a separating axis (one of their edges' normals)."""
    for poly in (a, b):
        for p, q in _edges(poly):
            axis = np.array([p[1] - q[1], q[0] - p[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return True
    return False


def gap(a: tuple, b: tuple) -> float:
    """The clearance between two footprints (:func:`circle`, :func:`box`, :func:`polygon`), mm:
    negative when they overlap.

    Examples
    --------
    >>> gap(circle(0, 0, 1), circle(3, 0, 1)), gap(box(0, 0, 1, 1), circle(3, 0.5, 1)), gap(box(0, 0, 2, 2), box(1, 1, 3, 3)) < 0
    (1.0, 1.0, True)
    """
    (ka, pa, ra), (kb, pb, rb) = a, b
    if ka == "circle" and kb == "circle":
        return float(np.linalg.norm(pa - pb)) - ra - rb
    if ka == "circle":
        (ka, pa, ra), (kb, pb, rb) = b, a
    if kb == "circle":  # a polygon and a circle
        if _inside_polygon(pb, pa):
            return -rb - min(_point_segment(pb, p, q) for p, q in _edges(pa))
        return min(_point_segment(pb, p, q) for p, q in _edges(pa)) - rb
    if not _separated(pa, pb):
        return -1.0
    return min(min(_point_segment(v, p, q) for v in one for p, q in _edges(other))
               for one, other in ((pa, pb), (pb, pa)))


def clear(model: str, name_a: str, a: tuple, name_b: str, b: tuple, min_gap: float = MIN_GAP_MM) -> None:
    """Refuse two named footprints closer than ``min_gap`` mm, naming both."""
    g = gap(a, b)
    if g < min_gap:
        state = "overlap" if g < 0 else f"lie {g:.3g} mm apart"
        raise RangesimError(f"{model}: {name_a} and {name_b} {state}; features must keep {min_gap:g} mm "
                            "apart (one would cut or cover the other's rims)")


def apart(model: str, footprints: list[tuple[str, tuple]], min_gap: float = MIN_GAP_MM) -> None:
    """Refuse any two of the named footprints closer than ``min_gap`` mm, naming both."""
    for i, (name_a, a) in enumerate(footprints):
        for name_b, b in footprints[i + 1:]:
            clear(model, name_a, a, name_b, b, min_gap)


def reach_x(footprint: tuple) -> tuple[float, float]:
    """The x range a footprint covers."""
    kind, p, r = footprint
    return (p[0] - r, p[0] + r) if kind == "circle" else (float(p[:, 0].min()), float(p[:, 0].max()))


def clearance_in_rounded_rect(footprint: tuple, half_length: float, half_width: float, round_r: float) -> float:
    """How far the footprint stays inside a rectangle of the given half sizes whose corners are
    rounded with radius ``round_r`` (mm; negative when it reaches out)."""
    kind, p, r = footprint
    core = np.array([half_length - round_r, half_width - round_r])
    points = p[None, :] if kind == "circle" else p
    q = np.abs(points) - core
    # signed distance to the core rectangle (negative inside)
    sd = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    return float(round_r - (sd + r).max())
