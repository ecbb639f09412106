"""RangeScan: the one currency type. Everything that makes range data returns one."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.writers import save_scan

#: (name, dtype, trailing shape) of the per-pixel arrays, in a fixed order used by the writers
PIXEL_FIELDS: tuple[tuple[str, type, tuple[int, ...]], ...] = (
    ("depth", np.float32, ()),
    ("xyz", np.float32, (3,)),
    ("valid", np.bool_, ()),
    ("normal", np.float32, (3,)),
    ("intensity", np.float32, ()),
    ("part", np.int32, ()),
    ("face", np.int32, ()),
    ("status", np.uint8, ()),
)
#: optional per-pixel ground truth (synthetic scans only)
OPTIONAL_PIXEL_FIELDS: tuple[tuple[str, type, tuple[int, ...]], ...] = (
    ("xyz_true", np.float32, (3,)),
    ("sigma", np.float32, ()),
)


@dataclass
class RangeScan:
    """A single-view range image with per-pixel labels, in the camera frame.

    The camera frame follows OpenCV: x right, y down, z forward; units are those of the
    scene (millimetres by default). H x W is the sensor's image size.

    Attributes
    ----------
    depth : (H, W) float32
        z of the measured point in the camera frame; NaN where invalid.
    xyz : (H, W, 3) float32
        Measured points in the camera frame; NaN where invalid.
    valid : (H, W) bool
        True where a point was measured (``status == 0``).
    normal : (H, W, 3) float32
        True unit surface normal at the hit, camera frame, facing the camera; NaN where no
        surface was hit.
    intensity : (H, W) float32
        The stripe's return signal, relative to a white Lambertian target at the reference
        distance (see the sensor docs); 0 where no surface was hit.
    part : (H, W) int32
        Index of the scene object hit, -1 for none.
    face : (H, W) int32
        Triangle index within that object, -1 for none.
    status : (H, W) uint8
        :class:`~rangesim.core.constants.Status` code per pixel.
    pose : (4, 4) float64
        Camera-to-world transform.
    meta : dict
        Sensor parameters, seed, rangesim version, ``K`` (3x3 intrinsics as nested lists:
        pixel (row i, column j) looks along K^-1 (j + 0.5, i + 0.5, 1)), ``laser_origin``
        (3,) in the camera frame, and anything a reader or the scanner adds.
    xyz_true : (H, W, 3) float32 or None
        Noise-free surface point behind every pixel that hit a surface (whatever its
        status), camera frame; NaN on a miss. Ground truth for synthetic scans; None for
        recorded data.
    sigma : (H, W) float32 or None
        The noise model's predicted std of ``depth`` at every valid pixel (mm; NaN where
        invalid): what a detector threshold can use. Simulated scans carry it (laser stripes:
        :mod:`rangesim.sensor.stripe_noise`; block matching: :mod:`rangesim.sensor.matching_noise`,
        where a depth fattened over an edge errs by more than any noise law says);
        None where no model predicts it (recorded data).
    """

    depth: np.ndarray
    xyz: np.ndarray
    valid: np.ndarray
    normal: np.ndarray
    intensity: np.ndarray
    part: np.ndarray
    face: np.ndarray
    status: np.ndarray
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    meta: dict[str, Any] = field(default_factory=dict)
    xyz_true: np.ndarray | None = None
    sigma: np.ndarray | None = None

    def __post_init__(self) -> None:
        h, w = np.shape(self.depth)[:2]
        for name, dtype, trailing in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
            value = getattr(self, name)
            if value is None:
                continue
            value = np.asarray(value, dtype=dtype)
            if value.shape != (h, w) + trailing:
                raise RangesimError(
                    f"RangeScan.{name} has shape {value.shape}, expected {(h, w) + trailing}"
                )
            setattr(self, name, value)
        self.pose = np.asarray(self.pose, dtype=np.float64).reshape(4, 4)

    # -- shape and geometry ------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return self.depth.shape  # type: ignore[return-value]

    @property
    def K(self) -> np.ndarray | None:
        """3x3 pinhole intrinsics (float64), or None for scans without a pinhole model."""
        k = self.meta.get("K")
        return None if k is None else np.asarray(k, dtype=np.float64)

    def points(self, frame: str = "camera") -> np.ndarray:
        """Valid measured points as an (N, 3) float64 array, row-major pixel order.

        Parameters
        ----------
        frame : {"camera", "world"}
            Camera frame (as stored) or world frame (through ``pose``).
        """
        p = self.xyz[self.valid].astype(np.float64)
        if frame == "world":
            return p @ self.pose[:3, :3].T + self.pose[:3, 3]
        if frame != "camera":
            raise RangesimError(f"frame must be 'camera' or 'world', not {frame!r}")
        return p

    def count(self, status: Status | int) -> int:
        """Number of pixels with the given status code."""
        return int(np.count_nonzero(self.status == int(status)))

    # -- files -------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the scan; the format follows the extension (.exr, .npz, .ply).

        The file is written under a temporary name and renamed, so a failed write leaves
        no partial file. Returns the path written. The writers are those registered with
        :func:`rangesim.core.writers.register_writer` (``rangesim.io`` registers its own).
        """
        return save_scan(self, path)

    def __repr__(self) -> str:
        h, w = self.shape
        return (
            f"RangeScan({h}x{w}, valid={int(self.valid.sum())}, "
            f"sensor={self.meta.get('sensor', {}).get('name', '?')!r})"
        )
