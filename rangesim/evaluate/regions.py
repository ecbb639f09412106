"""Region-boundary ground truth from segment labels (e.g. the mOSD Kinect scenes)."""
from __future__ import annotations

import numpy as np

from rangesim.core.errors import RangesimError


def region_boundaries(labels: np.ndarray, valid: np.ndarray | None = None, background: int = 0) -> np.ndarray:
    """(H, W) bool: pixels next to a pixel of another segment.

    Parameters
    ----------
    labels : (H, W) int array
        Segment id per pixel; ``background`` marks pixels with no segment (no data).
    valid : (H, W) bool, optional
        Pixels with a measurement; others never count as a boundary.
    background : int or None
        The id of "no segment" (None: every id is a segment).

    Notes
    -----
    Both pixels of a 4-neighbour pair with different, non-background ids are marked, so a
    boundary is two pixels wide; score it with a tolerance of at least 1 pixel.
    """
    labels = np.asarray(labels)
    if background is not None and (isinstance(background, (bool, np.bool_))
                                   or not isinstance(background, (int, float, np.integer, np.floating))):
        raise RangesimError(f"background must be a segment id (a number) or None, got {background!r:.40}")
    if labels.ndim != 2:
        raise RangesimError(f"labels must be an (H, W) array, got shape {labels.shape}")
    if labels.dtype.kind not in "biuf":
        raise RangesimError(f"labels must be numeric segment ids, got {labels.dtype}")
    ok = labels != background
    if labels.dtype.kind == "f":
        ok &= np.isfinite(labels)  # NaN is no segment (NaN != NaN made every pixel a boundary)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != labels.shape:
            raise RangesimError(f"valid has shape {valid.shape} but labels {labels.shape}")
        ok &= valid
    out = np.zeros(labels.shape, dtype=bool)
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        differ = ok[tuple(a)] & ok[tuple(b)] & (labels[tuple(a)] != labels[tuple(b)])
        out[tuple(a)] |= differ
        out[tuple(b)] |= differ
    return out
