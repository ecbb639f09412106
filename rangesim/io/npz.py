"""NumPy ``.npz`` scan files: every field with its exact dtype, plus meta and pose.

Arrays: one per RangeScan field, named after it (``xyz_true`` only when present);
``pose`` (4, 4) float64; ``meta`` a 0-d unicode array holding JSON; and
``rangesim_format_version`` a 0-d int. Nothing is pickled, so files load with
``allow_pickle=False``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import OPTIONAL_PIXEL_FIELDS, PIXEL_FIELDS, RangeScan, checked_scan
from rangesim.io.exr import decode_meta, encode_meta

FORMAT_VERSION = 1
VERSION_KEY = "rangesim_format_version"
#: local-file-header signature that starts every non-empty zip archive, and the empty one's
ZIP_MAGIC, EMPTY_ZIP_MAGIC = b"PK\x03\x04", b"PK\x05\x06"


def write_npz(scan: RangeScan, path: str | Path) -> None:
    """Write ``scan`` to a compressed ``.npz`` at ``path`` (directly; not atomic).

    Use :func:`rangesim.io.save_scan` for an atomic write.

    Parameters
    ----------
    scan : RangeScan
    path : str or Path
        Target file, written as given (numpy's habit of appending ``.npz`` is avoided).

    Raises
    ------
    TypeError
        If ``scan`` is not a RangeScan.
    RangesimError
        If a field reassigned since construction fails the constructor's checks, or meta
        is not JSON-serialisable.
    """
    # fields may have been reassigned since construction: checked (and converted) as the
    # constructor does, so every array below already has its field's dtype and shape
    scan = checked_scan(scan, path)
    arrays: dict[str, np.ndarray] = {}
    for field, _, _ in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
        value = getattr(scan, field)
        if value is not None:
            arrays[field] = value
    arrays["pose"] = scan.pose
    arrays["meta"] = np.array(encode_meta(scan.meta, path))
    arrays[VERSION_KEY] = np.array(FORMAT_VERSION)
    # a file object, because np.savez appends ".npz" to any path not ending in exactly that
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def read_npz(path: str | Path) -> RangeScan:
    """Read a scan written by :func:`write_npz`; every array comes back bit-exact.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    RangeScan

    Raises
    ------
    RangesimError
        If the file is missing, not a readable npz, or lacks a rangesim array.
    """
    path = Path(path)
    if not path.is_file():
        raise RangesimError("no such file", path)
    # our own handle: np.load leaks the one it opens when the zip is corrupt
    with open(path, "rb") as fh:
        # np.load would try other formats and report e.g. "pickled data" for plain garbage
        if fh.read(len(ZIP_MAGIC)) not in (ZIP_MAGIC, EMPTY_ZIP_MAGIC):
            raise RangesimError("not an .npz file (no zip signature)", path)
        fh.seek(0)
        try:
            with np.load(fh, allow_pickle=False) as data:
                # read everything now: a truncated archive may only fail on member access
                arrays: dict[str, np.ndarray] = {key: data[key] for key in data.files}
        except Exception as exc:  # zipfile, zlib, numpy format and OS errors alike
            raise RangesimError(
                f"not a readable .npz file ({type(exc).__name__}: {exc})", path
            ) from exc
    return _scan_from_arrays(arrays, path)


def _check_kind(field: str, values: np.ndarray | None, dtype: np.dtype, path: Path) -> None:
    """A field's array must hold the kind of numbers the field is: a cast would silently drop a
    complex depth's imaginary part or take a 0.5 in ``valid`` as True."""
    if values is None:
        return
    kind = values.dtype.kind
    if dtype.kind == "b":
        ok = kind == "b" or (kind in "iu" and bool(np.isin(values, (0, 1)).all()))
        need = "booleans (or integers 0 / 1)"
    elif dtype.kind == "f":
        ok, need = kind in "fiu", "real numbers"
    else:
        ok, need = kind in "iub", "integers"
    if not ok:
        raise RangesimError(f"array {field} must hold {need}, got {values.dtype}", path)


def _scan_from_arrays(arrays: dict[str, np.ndarray], path: Path) -> RangeScan:
    try:
        version = int(arrays[VERSION_KEY]) if VERSION_KEY in arrays else FORMAT_VERSION
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"corrupt {VERSION_KEY} ({exc})", path) from exc
    if version > FORMAT_VERSION:
        raise RangesimError(
            f"rangesim npz format version {version} is newer than this reader"
            f" ({FORMAT_VERSION}); update rangesim",
            path,
        )
    if version < 1:
        raise RangesimError(f"corrupt {VERSION_KEY}: {version} (versions start at 1)", path)
    fields: dict[str, Any] = {}
    for field, _, _ in PIXEL_FIELDS:
        if field not in arrays:
            raise RangesimError(f"not a rangesim scan: missing array {field}", path)
        fields[field] = arrays[field]
    for field, _, _ in OPTIONAL_PIXEL_FIELDS:
        fields[field] = arrays.get(field)
    for field, dtype, _ in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
        _check_kind(field, fields[field], np.dtype(dtype), path)
    status = np.asarray(fields["status"])
    unknown = status > max(Status) if status.dtype.kind == "u" else (status < 0) | (status > max(Status))
    if np.any(unknown):
        code, count = int(status[unknown].flat[0]), int(np.count_nonzero(unknown))
        raise RangesimError(f"array status holds code {code} at {count:,} pixels; the codes are "
                            f"0-{int(max(Status))} (rangesim.core.constants.Status)", path)
    try:
        meta = decode_meta(str(arrays["meta"])) if "meta" in arrays else {}
        pose = arrays["pose"] if "pose" in arrays else np.eye(4)
        return RangeScan(**fields, pose=pose, meta=meta)
    except ValueError as exc:  # bad JSON, wrong shapes
        raise RangesimError(f"inconsistent scan: {exc}", path) from exc
