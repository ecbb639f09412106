"""EdgeMap: what every edge detector returns."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rangesim.core.constants import EdgeLabel


@dataclass
class EdgeMap:
    """Edge pixels of a range image.

    Attributes
    ----------
    mask : (H, W) bool
        Edge pixels.
    labels : (H, W) uint8
        :class:`~rangesim.core.constants.EdgeLabel` per pixel (0 off the mask; on the mask
        0 where the detector cannot tell the type).
    strength : (H, W) float32
        The detector's response (units depend on the method; documented there), 0 off edges
        is not required: it is the raw response everywhere, NaN where undefined.
    direction : (H, W) float32 or None
        Edge normal direction in the image, radians, angle of the (x = column, y = row)
        vector across the edge (gradient detector; None for others).
    method : str
        The detector's name.
    params : dict
        The parameters it ran with.
    """

    mask: np.ndarray
    labels: np.ndarray
    strength: np.ndarray
    direction: np.ndarray | None = None
    method: str = ""
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.mask = np.asarray(self.mask, dtype=bool)
        shape = self.mask.shape
        self.labels = np.asarray(self.labels, dtype=np.uint8)
        self.strength = np.asarray(self.strength, dtype=np.float32)
        if self.labels.shape != shape or self.strength.shape != shape:
            raise ValueError(f"EdgeMap arrays must share the mask's shape {shape}")
        if self.direction is not None:
            self.direction = np.asarray(self.direction, dtype=np.float32)
            if self.direction.shape != shape:
                raise ValueError(f"EdgeMap.direction must have shape {shape}")
        self.labels = np.where(self.mask, self.labels, EdgeLabel.NONE).astype(np.uint8)

    def label_mask(self, label: EdgeLabel | int) -> np.ndarray:
        """Edge pixels of one type."""
        return self.mask & (self.labels == int(label))

    def __repr__(self) -> str:
        counts = {EdgeLabel(k).name.lower(): int(np.count_nonzero(self.labels[self.mask] == k)) for k in EdgeLabel}
        return f"EdgeMap({self.method!r}, {self.mask.shape[0]}x{self.mask.shape[1]}, edges={int(self.mask.sum())}, {counts})"
