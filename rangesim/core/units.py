"""Lengths with units: ``"0.2in"``, ``"5 mm"``, ``"1e-3m"`` -> millimetres, the project's unit."""
from __future__ import annotations

import math
import re
from numbers import Real

from rangesim.core.errors import RangesimError

#: length units, in millimetres (keys are lower case; matching is case-insensitive)
UNITS_MM: dict[str, float] = {
    "mm": 1.0,
    "cm": 10.0,
    "m": 1000.0,
    "in": 25.4,
    "inch": 25.4,
    "inches": 25.4,
    '"': 25.4,
}

#: the units as a message lists them (the inch sign quoted: last in a list it read as a stray quote)
UNIT_NAMES = "mm, cm, m, in (or inch, inches, the inch sign '\"')"

# a float literal (sign, digits, optional fraction and exponent), then an optional unit;
# the exponent needs digits, so "1e-3m" is 1e-3 metres and "2em" is rejected
_LENGTH = re.compile(
    r"""^\s*(?P<number>[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*(?P<unit>[a-zA-Z"]*)\s*$"""
)


def parse_length(
    value: str | float | int,
    default_unit: str = "mm",
    *,
    positive: bool = False,
    what: str = "length",
) -> float:
    """A length in millimetres from a number or a string with a unit.

    Parameters
    ----------
    value : str or float or int
        A number (in ``default_unit``) or a string such as ``"0.2in"``, ``"5mm"``,
        ``"0.5 cm"``, ``"1e-3m"``, ``'0.2"'`` or ``"7"`` (``default_unit``). Units are
        the keys of :data:`UNITS_MM`, case-insensitive.
    default_unit : str
        Unit of a bare number.
    positive : bool
        Also reject zero and negative lengths.
    what : str
        Name of the quantity in error messages (e.g. ``"resolution"``).

    Returns
    -------
    float
        The length in millimetres, finite.

    Raises
    ------
    RangesimError
        An unreadable string, an unknown unit, a non-finite value, or (with
        ``positive=True``) a value <= 0.

    Examples
    --------
    >>> parse_length("0.2in"), parse_length("0.5 cm"), parse_length(3, "cm")
    (5.08, 5.0, 30.0)
    """
    default = default_unit.strip().lower()
    if default not in UNITS_MM:
        raise RangesimError(f"unknown length unit {default_unit!r}; use one of {UNIT_NAMES}")
    if isinstance(value, bool):  # bool is an int; True mm is surely a mistake
        raise RangesimError(f"{what} must be a length such as 5mm or 0.2in, got {value!r}")
    if isinstance(value, Real):
        number, unit = float(value), default
    elif isinstance(value, str):
        match = _LENGTH.match(value)
        if match is None:
            raise RangesimError(
                f"{what} must be a number with an optional unit ({UNIT_NAMES}), "
                f"e.g. 5mm or 0.2in; got {value!r}"
            )
        number = float(match["number"])
        unit = match["unit"].lower() or default
        if unit not in UNITS_MM:
            raise RangesimError(f"{what}: unknown unit {match['unit']!r} in {value!r}; use one of {UNIT_NAMES}")
    else:
        raise RangesimError(f"{what} must be a number or a string, got {type(value).__name__}")
    mm = number * UNITS_MM[unit]
    if not math.isfinite(mm):
        raise RangesimError(f"{what} must be finite, got {value!r}")
    if positive and mm <= 0.0:
        raise RangesimError(f"{what} must be positive, got {value!r}")
    return mm

