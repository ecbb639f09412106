"""Fast, vectorised parsing of the text bodies of recorded-data files (PLY, MSU, PCD, XYZ)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError

__all__ = ["line_block", "line_ends", "parse_numbers"]


def parse_numbers(text: bytes, path: Path, what: str, dtype: type = np.float64) -> np.ndarray:
    """All whitespace-separated numbers in ``text`` as a flat array (vectorised).

    ``nan`` and ``inf`` parse as floats; anything else that is not a number is an error.
    """
    try:
        with warnings.catch_warnings():
            # older NumPy warns (instead of raising) when it stops at unparsable text
            warnings.simplefilter("error", DeprecationWarning)
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        kind = "integers" if np.issubdtype(dtype, np.integer) else "numbers"
        raise RangesimError(f"{what}: expected whitespace-separated {kind}, found other text", path) from None


def line_ends(body: bytes) -> np.ndarray:
    """Offsets of the ends of the lines of ``body`` (a last line without newline counts)."""
    ends = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    last = int(ends[-1]) + 1 if ends.size else 0
    if body[last:].strip():
        ends = np.append(ends, len(body))
    return ends


def line_block(
    body: bytes, ends: np.ndarray, start: int, count: int, path: Path, what: str
) -> bytes:
    """Lines ``start .. start+count-1`` of ``body`` as one block (``ends`` from :func:`line_ends`)."""
    if ends.size < start + count:
        found = max(ends.size - start, 0)
        raise RangesimError(f"{what}: expected {count} lines, the file has {found} (truncated)", path)
    begin = 0 if start == 0 else int(ends[start - 1]) + 1
    return body[begin:int(ends[start + count - 1])] if count else b""
