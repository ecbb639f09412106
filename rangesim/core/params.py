"""Parameter checks of the analysis functions (edge detectors, feature finders, scores): one
place that refuses a parameter of the wrong type, sign or range up front with a :class:`~rangesim.core.errors.RangesimError` naming it, the range it
must lie in and the value given (instead of garbage edge maps, or an error from deep inside).

Each check returns the value to use: unchanged for numbers (the detectors' arithmetic stays
the same to the bit), an ``int`` for whole numbers (``3.0`` from a sweep file is 3), a
``bool`` for flags.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError

__all__ = ["number", "whole", "odd_window", "flag", "choice", "jump_rule"]


def _real(value: Any) -> float | None:
    """``value`` as a float when it is a real number (not a bool, string or array), else None."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        return None
    if isinstance(value, np.ndarray):
        if value.ndim != 0 or value.dtype.kind not in "iuf":
            return None
        value = value.item()
    if not isinstance(value, (int, float, np.integer, np.floating)):
        return None
    return float(value)


def _span(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    if hi == math.inf:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if lo == -math.inf:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def number(value: Any, name: str, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False,
           hi_open: bool = False, what: str = "number", unit: str = "", none: bool = False) -> Any:
    """``value`` checked as a finite real number in the given range (None passes with ``none``).

    >>> number(15.0, "threshold", 0, 180, lo_open=True, hi_open=True, what="angle", unit="degrees")
    15.0
    """
    if value is None and none:
        return None
    v = _real(value)
    if v is None or not math.isfinite(v) or not (v > lo if lo_open else v >= lo) or not (v < hi if hi_open else v <= hi):
        span = _span(lo, hi, lo_open, hi_open)
        unit = "" if not unit else f" {unit}" if span.startswith("in") else f" ({unit})"
        raise RangesimError(f"{name} must be a finite {what} {span}{unit}{' or None' if none else ''}, got {value!r:.60}")
    return value


def whole(value: Any, name: str, lo: int = 0, hi: float = math.inf, *, unit: str = "", none: bool = False,
          also: tuple[int, ...] = ()) -> int | None:
    """``value`` checked as a whole number in ``[lo, hi]`` (or one of ``also``), as an int.

    >>> whole(50, "max_search", 0, unit="pixels"), whole(3.0, "k", 2)
    (50, 3)
    """
    if value is None and none:
        return None
    v = _real(value)
    if v is None or not math.isfinite(v) or v != int(v) or not (lo <= v <= hi or int(v) in also):
        span = f"of at least {lo}" if hi == math.inf else f"in [{lo}, {int(hi)}]"
        extra = "".join(f" or {a}" for a in also) + (" or None" if none else "")
        raise RangesimError(f"{name} must be an integer {span}{extra}{f' ({unit})' if unit else ''}, got {value!r:.60}")
    return int(v)


#: largest stencil or block a detector takes, pixels: per-pixel work and memory grow with its
#: square (a 999 px curvature window on a 30 x 32 scan asked for 21 GiB)
MAX_WINDOW_PX = 255


def odd_window(value: Any, name: str, *, none: bool = True) -> int | None:
    """An odd stencil or block size of 3 to :data:`MAX_WINDOW_PX` pixels (None passes: the default)."""
    if value is None and none:
        return None
    v = _real(value)
    if v is None or not math.isfinite(v) or v != int(v) or not 3 <= v <= MAX_WINDOW_PX or int(v) % 2 == 0:
        raise RangesimError(f"{name} must be an odd whole number from 3 to {MAX_WINDOW_PX} (pixels)"
                            f"{' or None' if none else ''}, got {value!r:.60}")
    return int(v)


def flag(value: Any, name: str, *, none: bool = False) -> bool | None:
    """``value`` checked as a bool (True / False, NumPy's, or 0 / 1)."""
    if value is None and none:
        return None
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)) and value in (0, 1):
        return bool(value)
    raise RangesimError(f"{name} must be True or False{' or None' if none else ''}, got {value!r:.60}")


def choice(value: Any, name: str, options: tuple[Any, ...]) -> Any:
    """``value`` checked to be one of ``options``."""
    try:
        ok = value in options
    except (TypeError, ValueError):   # an array compared with strings
        ok = False
    if not ok or isinstance(value, np.ndarray):
        raise RangesimError(f"{name} must be one of {', '.join(map(repr, options))}, got {value!r:.60}")
    return value


def jump_rule(jump_threshold: Any, max_search: Any) -> tuple[Any, int]:
    """The jump rule's parameters, shared by every detector: ``jump_threshold`` a positive
    number of pixel footprints (0 would make every pair of neighbours a jump), ``max_search``
    a whole number of pixels >= 0 (0: only direct neighbours)."""
    jump_threshold = number(jump_threshold, "jump_threshold", 0, lo_open=True, what="number",
                            unit="pixel footprints")
    return jump_threshold, whole(max_search, "max_search", 0, unit="pixels")
