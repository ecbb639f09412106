"""EdgeMap: what every edge detector returns, and the label the detectors add to
:class:`~rangesim.core.constants.EdgeLabel`."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError

__all__ = ["EdgeMap", "RIM", "LABEL_NAMES", "MAX_OFFSET_PX", "check_labels", "check_offsets"]

#: ``EdgeMap.labels`` value of a *rim*: a measured pixel where the measured surface ends
#: against pixels that saw no surface (a through-hole's rim over an absent floor, a part's
#: silhouette against empty space; PCL's NaN boundary, see
#: :func:`~rangesim.edges._discontinuities.find_discontinuities`). It is the near side of
#: a step to nothing, so an occluding contour, but the far side was never measured; the
#: detectors keep it apart from JUMP (whose far side was). The value follows
#: :class:`~rangesim.core.constants.EdgeLabel`'s 0-3, which keep theirs.
RIM = 4

#: name of every label an EdgeMap can carry
LABEL_NAMES = {**{int(k): k.name.lower() for k in EdgeLabel}, RIM: "rim"}

#: the largest ``EdgeMap.offset`` component, px: an offset places the edge within its pixel's
#: reach (the detectors give at most 0.5: half a pixel spacing at a contour, the crease
#: response's peak within +-0.5 px); the feature finders' compiled kernels index their
#: accumulators and grids by the moved points, so larger or non-finite offsets are refused
MAX_OFFSET_PX = 1.0


def check_offsets(values: np.ndarray, what: str = "EdgeMap.offset") -> None:
    """Refuse offsets (any shape, px) that are not finite or exceed :data:`MAX_OFFSET_PX`."""
    values = np.asarray(values)
    if values.size == 0:
        return
    bad = ~np.isfinite(values)
    if bad.any():
        raise RangesimError(f"{what} holds {int(bad.sum())} non-finite values at edge pixels")
    worst = float(np.abs(values).max())
    if worst > MAX_OFFSET_PX:
        raise RangesimError(f"{what} reaches {worst:g} px at an edge pixel: at most {MAX_OFFSET_PX:g} px "
                            "(an offset places the edge within its pixel's reach)")


def check_labels(labels: np.ndarray, name: str) -> None:
    """Refuse labels that are no edge type: whole numbers 0 (none) .. :data:`RIM` (4) only; a
    one-line RangesimError naming ``name``, the first bad value and how many there are."""
    labels = np.asarray(labels)
    if labels.dtype.kind not in "biuf":
        raise RangesimError(f"{name} must be a numeric (H, W) array, got {labels.dtype}")
    if labels.size == 0:
        return
    bad = (labels < 0) | (labels > RIM)
    if labels.dtype.kind == "f":
        bad |= ~np.isfinite(labels) | (labels != np.round(labels))
    if np.any(bad):
        raise RangesimError(f"{name} must hold whole numbers 0-{RIM} ({', '.join(LABEL_NAMES.values())}), "
                            f"got {labels[bad].flat[0].item()!r} at {int(np.count_nonzero(bad)):,} pixels")


@dataclass
class EdgeMap:
    """Edge pixels of a range image.

    Attributes
    ----------
    mask : (H, W) bool
        Edge pixels.
    labels : (H, W) uint8
        :class:`~rangesim.core.constants.EdgeLabel` per pixel (0 off the mask; on the mask
        0 where the detector cannot tell the type), or :data:`RIM` (4) where the measured
        surface ends against pixels that saw nothing.
    strength : (H, W) float32
        The detector's response (units depend on the method; documented there), 0 off edges
        is not required: it is the raw response everywhere, NaN where undefined.
    direction : (H, W) float32 or None
        Edge normal direction in the image, radians, angle of the (x = column, y = row)
        vector across the edge (gradient detector, and normal on block-matched scans; None
        for others).
    method : str
        The detector's name.
    params : dict
        The parameters it ran with.
    offset : (H, W, 2) float32 or None
        (dx, dy), pixels, from each edge pixel's centre to where the edge most likely lies,
        read at edge pixels only. The detectors set it at jump and rim pixels: an occluding
        contour lies between the last pixel of the near surface and the first beyond it, on
        average half a pixel spacing from the near pixel's centre
        (:func:`~rangesim.edges._discontinuities.contour_offsets`). ``gradient`` and ``normal``
        also set it at their crease pixels, to the peak of the crease response across the
        line (:func:`~rangesim.edges._thinning.ridge_offsets`, within +-0.5 px); the other
        detectors leave creases at 0, but for the far end of a wall the scanner did not
        measure (:mod:`~rangesim.edges._gap_folds`), which every detector but pcl_organized
        places as a jump's contour, towards the gap. The feature finders fit their circles, ellipses and
        lines to the edge pixels moved by it. None: the pixel centres.
    """

    mask: np.ndarray
    labels: np.ndarray
    strength: np.ndarray
    direction: np.ndarray | None = None
    method: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    offset: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.mask = np.asarray(self.mask, dtype=bool)
        shape = self.mask.shape
        raw = np.asarray(self.labels)
        if raw.shape == shape:  # (before the uint8 cast: -1 would read 255)
            check_labels(raw[self.mask], "EdgeMap.labels at edge pixels")
        self.labels = np.asarray(self.labels, dtype=np.uint8)
        self.strength = np.asarray(self.strength, dtype=np.float32)
        if self.labels.shape != shape or self.strength.shape != shape:
            raise RangesimError(f"EdgeMap arrays must share the mask's shape {shape}")
        if self.direction is not None:
            self.direction = np.asarray(self.direction, dtype=np.float32)
            if self.direction.shape != shape:
                raise RangesimError(f"EdgeMap.direction must have shape {shape}")
        if self.offset is not None:
            self.offset = np.asarray(self.offset, dtype=np.float32)
            if self.offset.shape != shape + (2,):
                raise RangesimError(f"EdgeMap.offset must have shape {shape + (2,)}")
            check_offsets(self.offset[self.mask])  # read at edge pixels only
        # labels only on edge pixels (NONE = 0); a product is ~20x cheaper than np.where
        self.labels = self.labels * self.mask

    def label_mask(self, label: EdgeLabel | int) -> np.ndarray:
        """Edge pixels of one type."""
        return self.mask & (self.labels == int(label))

    def __repr__(self) -> str:
        on = self.labels[self.mask]
        counts = {name: int(np.count_nonzero(on == k)) for k, name in LABEL_NAMES.items()}
        return f"EdgeMap({self.method!r}, {self.mask.shape[0]}x{self.mask.shape[1]}, edges={int(self.mask.sum())}, {counts})"
