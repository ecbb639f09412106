"""Checks of a parametric part's layout: sizes that are sizes, and features that lie on the part.

A built-in part lists its features (hole rims, edges) from its parameters, so a hole placed off
the plate would be listed as a rim the mesh does not have: the analytic ground truth would be
wrong. These checks refuse such parameters with a one-line message naming the parameter.
"""
from __future__ import annotations

import math
from typing import Any

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
