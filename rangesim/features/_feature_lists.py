"""Lists of found features as the functions that take them check them."""
from __future__ import annotations

from typing import Any

from rangesim.core.errors import RangesimError


def feature_list(items: Any, name: str, attrs: tuple[str, ...], caller: str) -> list:
    """``items`` as a list, each with ``attrs`` (a segment: start and end; a circle or arc:
    center; an ellipse: center and orientation), else a one-line RangesimError naming
    ``caller`` and the argument ``name``. None is an empty list."""
    if items is None:
        return []
    if hasattr(items, attrs[0]) or isinstance(items, (str, bytes)) or not hasattr(items, "__iter__"):
        raise RangesimError(f"{caller}: {name} must be a list of features, got one {type(items).__name__}")
    items = list(items)
    for k, item in enumerate(items):
        missing = [a for a in attrs if not hasattr(item, a)]
        if missing:
            raise RangesimError(f"{caller}: {name}[{k}] is a {type(item).__name__}, not a feature with "
                                f"{' and '.join(attrs)} (as rs.features returns)")
    return items
