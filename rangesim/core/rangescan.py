"""RangeScan: the one currency type. Everything that makes range data returns one."""
from __future__ import annotations

import dataclasses
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

    The camera frame follows OpenCV: x right, y down, z forward; lengths are millimetres
    whatever the scene's ``units`` (a scene in metres is scaled on loading), and so are the
    pose's translation and ``sigma``. H x W is the sensor's image size.

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
        (3,) in the camera frame, and anything a reader or the scanner adds. ``None`` is
        taken as ``{}`` (like leaving it out); anything else that is not a dict, or a
        ``sensor`` entry that is not a dict, is refused.
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

    Raises
    ------
    RangesimError
        At construction, for a field of the wrong shape or holding values its dtype cannot
        hold exactly (a status of 300, a part of 2**40 or 0.5, a NaN in ``valid``); a
        plain cast would wrap or round them silently. Values that convert exactly are
        converted (int64 labels in range, 0 / 1 for ``valid``, float64 depth to float32).
        Also for a pose that is not finite or whose rotation block is singular, a
        ``meta["K"]`` that is no finite 3x3 pinhole matrix with positive focal lengths, and
        a negative ``sigma``.

    Notes
    -----
    Scans compare by value (``==``): every field equal, arrays element by element with NaN
    equal to NaN, ``meta`` as nested values (a list equals the array of its values); two
    runs of one seed give equal scans. Scans are mutable and have no hash.
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
        # the writers re-run these checks on a scan whose fields were reassigned after
        # construction (checked_scan: a copy made through this constructor)
        if self.meta is None:  # "no meta", as when the argument is left out
            self.meta = {}
        if not isinstance(self.meta, dict):
            raise RangesimError(f"RangeScan.meta must be a dict, got {type(self.meta).__name__}")
        sensor = self.meta.get("sensor")
        if sensor is not None and not isinstance(sensor, dict):  # as load_scan refuses in a file
            raise RangesimError(
                f"RangeScan.meta.sensor must be a table (dict), got {type(sensor).__name__} {sensor!r:.60}"
            )
        depth = None if self.depth is None else _as_array("depth", self.depth)
        if depth is None or depth.ndim != 2:
            got = "None" if depth is None else f"shape {depth.shape}"
            raise RangesimError(f"RangeScan.depth must be a 2-D (H, W) array, got {got}")
        h, w = depth.shape
        for name, dtype, trailing in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
            value = getattr(self, name)
            if value is None:
                if name in _REQUIRED:
                    raise RangesimError(f"RangeScan.{name} is required, got None")
                continue
            value = _exact_array(name, value, np.dtype(dtype))
            if value.shape != (h, w) + trailing:
                raise RangesimError(
                    f"RangeScan.{name} has shape {value.shape}, expected {(h, w) + trailing}"
                )
            setattr(self, name, value)
        try:
            pose = np.asarray(self.pose, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise RangesimError(f"RangeScan.pose must be a 4x4 matrix of numbers ({exc})") from exc
        if pose.size != 16:
            raise RangesimError(f"RangeScan.pose must be a 4x4 matrix, got shape {pose.shape}")
        pose = pose.reshape(4, 4)
        # the ground truth and the world-frame points invert it (not check_pose's rigid test:
        # recorded poses carry rounded quaternions)
        if not np.all(np.isfinite(pose)):
            raise RangesimError("RangeScan.pose holds NaN or infinity")
        det = float(np.linalg.det(pose[:3, :3]))
        if not abs(det) > 1e-6:
            raise RangesimError(f"RangeScan.pose has a singular rotation block (determinant {det:.3g}): it maps "
                                "the scan onto a plane or a point")
        self.pose = pose
        negative = None if self.sigma is None else self.sigma[self.sigma < 0]  # (NaN compares False)
        if negative is not None and negative.size:
            raise RangesimError("RangeScan.sigma is a standard deviation: it must be >= 0 (NaN where not "
                                f"predicted), found {float(negative.min())!r}")
        _intrinsics(self.meta.get("K"))

    # -- shape and geometry ------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return self.depth.shape  # type: ignore[return-value]

    @property
    def K(self) -> np.ndarray | None:
        """3x3 pinhole intrinsics (float64), or None for scans without a pinhole model.

        Raises RangesimError where ``meta["K"]`` (reassigned since construction) is not one:
        see :func:`_intrinsics`.
        """
        return _intrinsics(self.meta.get("K"))

    def __eq__(self, other: object) -> bool:
        """Field by field: arrays equal element by element (NaN equal to NaN, as a scan
        writes and reads them back), ``meta`` equal as nested values (lists and arrays alike).
        Two runs of one seed give equal scans."""
        if not isinstance(other, RangeScan):
            return NotImplemented
        for f in dataclasses.fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if f.name == "meta":
                if not _same_value(a, b):
                    return False
            elif a is None or b is None:
                if a is not b:
                    return False
            elif np.shape(a) != np.shape(b) or not np.array_equal(a, b, equal_nan=True):
                return False
        return True

    __hash__ = None  # type: ignore[assignment]  (mutable, like the dataclass it replaces)

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
        Fields reassigned since construction are checked again first (see :func:`checked_scan`).
        """
        return save_scan(self, path)  # which re-checks the fields (checked_scan)

    def __repr__(self) -> str:
        # must not raise: fields and meta may have been reassigned after construction
        h, w = (tuple(np.shape(self.depth)) + (0, 0))[:2]
        try:
            n_valid: int | str = int(np.count_nonzero(self.valid))
        except (TypeError, ValueError):
            n_valid = "?"
        meta = self.meta if isinstance(self.meta, dict) else {}
        sensor = meta.get("sensor")
        name = sensor.get("name", "?") if isinstance(sensor, dict) else "?"
        return f"RangeScan({h}x{w}, valid={n_valid}, sensor={name!r})"


#: fields every scan has (the others in OPTIONAL_PIXEL_FIELDS may be None)
_REQUIRED = frozenset(name for name, _, _ in PIXEL_FIELDS)


def checked_scan(scan: Any, source: str | Path | None = None, doing: str = "write") -> RangeScan:
    """``scan`` as a writer (or a reader, with ``doing="read"``) may use it: a RangeScan that
    passes the constructor's checks.

    Fields can be reassigned after construction (``scan.valid = ...``; a reader that sets the
    pose from a ``.conf``); the writers call this first, so every format refuses (or converts)
    the same values the constructor does, and ``load_scan`` calls it on what a reader
    returns. Returns a shallow copy made through the constructor (arrays already of the right
    dtype are not copied); ``scan`` itself is left unchanged.

    Parameters
    ----------
    scan : RangeScan
    source : str or Path, optional
        The file being written or read; prefixed to a RangesimError's message.
    doing : {"write", "read"}
        What the caller does with it, for the messages ("cannot write the scan: ...").

    Raises
    ------
    TypeError
        If ``scan`` is not a RangeScan.
    RangesimError
        If a field fails the constructor's checks.
    """
    if not isinstance(scan, RangeScan):
        # no path in the message: save_scan hands writers a temporary name
        raise TypeError(f"can only {doing} a RangeScan, got {type(scan).__name__}")
    try:
        return dataclasses.replace(scan)
    except RangesimError as exc:
        # (a read names the file only: the constructor's words say what is wrong in it)
        raise RangesimError(f"cannot write the scan: {exc}" if doing == "write" else str(exc), source) from exc


def _intrinsics(k: Any) -> np.ndarray | None:
    """``meta["K"]`` as a float64 (3, 3) pinhole matrix, None where absent; a one-line
    RangesimError where it is not one (finite, with focal lengths fx = K[0, 0] and
    fy = K[1, 1] > 0): pixel rays, footprints and the ground truth all divide by them."""
    if k is None:
        return None
    try:
        K = np.asarray(k, dtype=np.float64)
    except (TypeError, ValueError):
        K = np.empty(0)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or not (K[0, 0] > 0 and K[1, 1] > 0):
        raise RangesimError(f"RangeScan.meta['K'] must be a finite 3x3 pinhole matrix with positive focal "
                            f"lengths K[0][0], K[1][1], got {k!r:.80}")
    return K


def _same_value(a: Any, b: Any) -> bool:
    """``a == b`` for nested meta values: dicts by keys, lists, tuples and arrays element by
    element (NaN equal to NaN)."""
    if isinstance(a, dict) or isinstance(b, dict):
        return (isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys()
                and all(_same_value(a[k], b[k]) for k in a))
    if isinstance(a, (list, tuple, np.ndarray)) or isinstance(b, (list, tuple, np.ndarray)):
        try:
            x, y = np.asarray(a), np.asarray(b)
        except (TypeError, ValueError):  # ragged: element by element
            return (isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b)
                    and all(_same_value(u, v) for u, v in zip(a, b)))
        if x.dtype == object or y.dtype == object:
            if x.ndim == 0 or y.ndim == 0:
                return x.ndim == y.ndim and _same_value(x.item(), y.item())
            return len(x) == len(y) and all(_same_value(u, v) for u, v in zip(x, y))
        return x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f" and y.dtype.kind == "f")
    if isinstance(a, np.generic):  # numpy scalars as Python's (NaN below)
        a = a.item()
    if isinstance(b, np.generic):
        b = b.item()
    if isinstance(a, (float, complex)) and isinstance(b, (float, complex)) and a != a and b != b:
        return True
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # values that do not compare to one truth value
        return False


def _as_array(name: str, value: Any) -> np.ndarray:
    """``np.asarray(value)``, refusing what is not an array of numbers (ragged lists, strings)."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as exc:  # a ragged nested list
        raise RangesimError(f"RangeScan.{name} is not an array of numbers ({exc})") from exc
    if array.dtype.kind not in "biuf":  # complex, object, strings, dates
        raise RangesimError(f"RangeScan.{name} must hold real numbers, got dtype {array.dtype}")
    return array


def _exact_array(name: str, value: Any, dtype: np.dtype) -> np.ndarray:
    """``value`` as a ``dtype`` array, refusing any element the conversion would change.

    A plain cast wraps 300 to 44 in a uint8 status, 2**40 to 0 in an int32 part and makes
    NaN True in ``valid``. Float fields may lose float64 precision (as stored), not range.
    """
    array = _as_array(name, value)
    if array.dtype == dtype:  # nothing to convert or check: no copy, no pass over the data
        return array
    kind = array.dtype.kind
    if dtype.kind == "f":
        with np.errstate(over="ignore"):
            out = array.astype(dtype)
        if kind == "f" and array.dtype.itemsize > dtype.itemsize:
            overflow = np.isinf(out) & np.isfinite(array)
            if overflow.any():
                first = array[overflow].flat[0].item()
                raise RangesimError(f"RangeScan.{name} holds {first!r}, beyond the {dtype.name} range")
        return out
    if dtype.kind == "b":
        # integers: non-zero is True (an OpenCV-style 0 / 255 mask); floats only 0 or 1 (NaN, which
        # a cast makes True, is neither)
        if kind == "f":
            bad = (array != 0) & (array != 1)
            if bad.any():
                first = array[bad].flat[0].item()
                raise RangesimError(f"RangeScan.{name} must hold booleans (or 0 / 1, or integers: non-zero is "
                                    f"True), found {first!r}")
        return array.astype(dtype)
    # integer fields
    if kind == "f":
        with np.errstate(invalid="ignore"):
            bad = ~(np.isfinite(array) & (np.trunc(array) == array))
        if bad.any():
            first = array[bad].flat[0].item()
            raise RangesimError(f"RangeScan.{name} must hold integers, found {first!r}")
    if kind != "b" and array.size:
        info = np.iinfo(dtype)
        low, high = array.min(), array.max()
        if low < info.min or high > info.max:
            first = (low if low < info.min else high).item()
            raise RangesimError(
                f"RangeScan.{name} holds {first!r}, outside the {dtype.name} range {info.min}..{info.max}"
            )
    return array.astype(dtype)
