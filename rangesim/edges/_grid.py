"""Pixel-grid conventions of the edge detectors, and shifted / padded views of images.

Analysis layer: pure NumPy over arrays. Conventions used by every detector:

* images are (H, W), row ``i`` grows downwards (image y), column ``j`` rightwards (image x);
  directions are angles of (x = column, y = row) vectors, radians;
* the four neighbour axes are indexed 0..3 with (drow, dcol) steps ``AXES`` = (0, 1), (1, 1),
  (1, 0), (1, -1), i.e. angles 0, 45, 90 and 135 degrees (``AXIS_ANGLES``);
* a neighbour outside the image is ``fill`` (:func:`shift`) or the padding of
  :func:`pad_last2` seen through :func:`padded_view`.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["AXES", "AXIS_ANGLES", "NEIGHBOURS", "shift", "pad_last2", "padded_view", "nonzero2"]

#: (drow, dcol) steps of the four neighbour axes: 0, 45, 90, 135 degrees in (x, y) = (col, row)
AXES: tuple[tuple[int, int], ...] = ((0, 1), (1, 1), (1, 0), (1, -1))
#: angles of the AXES, radians
AXIS_ANGLES = np.array([0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4])
#: the 8 neighbours as (drow, dcol)
NEIGHBOURS: tuple[tuple[int, int], ...] = tuple(
    (dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)
)


# -- shifting ------------------------------------------------------------------------------
def shift(a: np.ndarray, dr: int, dc: int, fill: Any) -> np.ndarray:
    """``out[i, j] = a[i + dr, j + dc]``, ``fill`` outside the image (leading two axes)."""
    h, w = a.shape[:2]
    out = np.empty_like(a)
    if abs(dr) >= h or abs(dc) >= w:
        out[...] = fill
        return out
    r0, r1 = max(0, -dr), min(h, h - dr)
    c0, c1 = max(0, -dc), min(w, w - dc)
    out[r0:r1, c0:c1] = a[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
    out[:r0] = fill
    out[r1:] = fill
    out[:, :c0] = fill
    out[:, c1:] = fill
    return out


def padded_view(p: np.ndarray, r: int, dr: int, dc: int, shape: tuple[int, int]) -> np.ndarray:
    """View of an array padded by ``r`` on its last two axes, shifted by (dr, dc)."""
    h, w = shape
    return p[..., r + dr:r + dr + h, r + dc:r + dc + w]


def pad_last2(a: np.ndarray, r: int, fill: Any) -> np.ndarray:
    """``a`` padded by ``r`` with ``fill`` on its last two axes."""
    widths = [(0, 0)] * (a.ndim - 2) + [(r, r), (r, r)]
    return np.pad(a, widths, constant_values=fill)


def nonzero2(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.nonzero`` of a 2-D mask (rows, columns; row-major order), several times faster.

    ``np.nonzero`` on a 2-D array is ~10x slower than ``np.flatnonzero`` (3.1 against
    0.35 ms on a 1024 x 1024 mask with 1 % set); splitting the flat indices costs little
    on sparse masks.
    """
    return np.divmod(np.flatnonzero(mask), mask.shape[1])

