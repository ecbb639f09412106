"""OpenEXR scan files: one multi-channel float32 image, meta and pose in the header.

Layout (format version 1)
-------------------------
* One scanline part, ZIP compression (lossless), every channel FLOAT (32-bit).
* Scalar fields are one channel named after the field (``depth``, ``valid``, ...);
  (H, W, 3) fields are three channels ``<field>.X``, ``<field>.Y``, ``<field>.Z``
  (see :func:`channel_names`). ``xyz_true`` is present only for synthetic scans.
* bool and integer fields are stored as float32 values and converted back exactly;
  integers are exact up to 2**24, larger values are refused at write time.
* Header string attributes ``rangesim_meta`` and ``rangesim_pose`` hold JSON (see
  :func:`encode_meta`, :func:`encode_pose`); ``rangesim_format_version`` is an int.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import OPTIONAL_PIXEL_FIELDS, PIXEL_FIELDS, RangeScan, checked_scan

FORMAT_VERSION = 1
META_ATTR = "rangesim_meta"
POSE_ATTR = "rangesim_pose"
VERSION_ATTR = "rangesim_format_version"

#: first four bytes of every OpenEXR file
EXR_MAGIC = b"\x76\x2f\x31\x01"

_TRAILING = {name: trailing for name, _, trailing in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS}
_VECTOR_AXES = ("X", "Y", "Z")


def channel_names(field: str) -> tuple[str, ...]:
    """EXR channel names of a RangeScan field, in component order.

    ``"depth"`` -> ``("depth",)``; ``"xyz"`` -> ``("xyz.X", "xyz.Y", "xyz.Z")``.
    """
    trailing = _TRAILING[field]
    if trailing == ():
        return (field,)
    if trailing == (len(_VECTOR_AXES),):
        return tuple(f"{field}.{axis}" for axis in _VECTOR_AXES)
    raise ValueError(f"no EXR channel layout for field {field!r} with shape {trailing}")


# -- header JSON (shared with the other formats) -------------------------------------------
def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")


#: meta keys not written to files: wall-clock timings and Dr.Jit kernel-cache counts of a run,
#: and the number of row bands a big geometric scan was made in (it depends on the free memory)
VOLATILE_META = ("seconds", "kernels", "bands")


def encode_meta(meta: dict[str, Any], source: str | Path | None = None) -> str:
    """``meta`` as JSON text; numpy arrays become nested lists, numpy scalars Python ones.

    Tuples come back as lists and non-string keys as strings (JSON has nothing else).
    ``source`` (the file being written) only labels the error. Run statistics that vary
    from run to run (:data:`VOLATILE_META`: the rendered mode's stage timings and kernel
    cache counts) stay in memory only, so a scan file is byte-identical for the same seed.
    """
    meta = {k: v for k, v in meta.items() if k not in VOLATILE_META}
    try:
        return json.dumps(meta, default=_json_default)
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"scan meta cannot be stored as JSON: {exc}", source) from exc


def decode_meta(text: str) -> dict[str, Any]:
    """Inverse of :func:`encode_meta`."""
    meta = json.loads(text)
    if not isinstance(meta, dict):
        raise ValueError(f"meta is a JSON {type(meta).__name__}, not an object")
    return meta


def encode_pose(pose: np.ndarray) -> str:
    """(4, 4) float64 pose as JSON; Python's float repr round-trips float64 exactly."""
    return json.dumps(np.asarray(pose, dtype=np.float64).reshape(4, 4).tolist())


def decode_pose(text: str) -> np.ndarray:
    """Inverse of :func:`encode_pose`: a (4, 4) float64 array."""
    return np.asarray(json.loads(text), dtype=np.float64).reshape(4, 4)


# -- exact float32 <-> bool/int conversion ---------------------------------------------------
def _exact_cast(values: np.ndarray, dtype: Any, what: str, source: str | Path) -> np.ndarray:
    """``values.astype(dtype)``, refusing any element the conversion would change."""
    if values.dtype == np.dtype(dtype):
        return values  # nothing to convert: no copy (a 10000^2 scan's fields are GBs)
    with np.errstate(invalid="ignore", over="ignore"):  # bad casts are caught just below
        out = values.astype(dtype)
        back = out.astype(values.dtype)
    same = back == values
    if values.dtype.kind == "f":
        same |= np.isnan(back) & np.isnan(values)
    bad = ~same
    if bad.any():
        first = values[bad].flat[0].item()
        raise RangesimError(
            f"{what} value {first!r} cannot be stored exactly as {np.dtype(dtype).name}"
            " (float32 holds integers exactly only up to 2**24 = 16777216)",
            source,
        )
    return out


# -- write / read ----------------------------------------------------------------------------
def write_exr(scan: RangeScan, path: str | Path) -> None:
    """Write ``scan`` to an OpenEXR file at ``path`` (directly; not atomic).

    Use :func:`rangesim.io.save_scan` for an atomic write.

    Parameters
    ----------
    scan : RangeScan
        H x W scan, H, W >= 1. Integer fields must lie within +-2**24.
    path : str or Path
        Target file. Its extension is not checked.

    Raises
    ------
    TypeError
        If ``scan`` is not a RangeScan.
    RangesimError
        If a field reassigned since construction fails the constructor's checks, a value
        cannot be stored exactly, or meta is not JSON-serialisable.
    """
    scan = checked_scan(scan, path)  # fields may have been reassigned since construction
    h, w = scan.shape
    if h == 0 or w == 0:
        raise RangesimError(f"cannot write an empty {h}x{w} scan as EXR", path)
    channels: dict[str, np.ndarray] = {}
    for field, _, _ in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
        value = getattr(scan, field)
        if value is None:
            continue
        value = _exact_cast(value, np.float32, f"RangeScan.{field}", path)
        planes = value[..., None] if value.ndim == 2 else value
        for i, name in enumerate(channel_names(field)):
            channels[name] = np.ascontiguousarray(planes[..., i])
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        VERSION_ATTR: FORMAT_VERSION,
        META_ATTR: encode_meta(scan.meta, path),
        POSE_ATTR: encode_pose(scan.pose),
    }
    with OpenEXR.File(header, channels) as exr:
        try:
            exr.write(str(path))
        except RuntimeError as exc:  # the bindings' words for an OS failure: '... "file". No space left on device.'
            reason = str(exc).rsplit('". ', 1)[-1].strip().rstrip(".") or type(exc).__name__
            raise RangesimError(f"cannot write file ({reason})", path) from exc


@contextlib.contextmanager
def _quiet_c_output():
    """File descriptors 1 and 2 sent to /dev/null for the block: OpenEXR's C++ library prints its own
    lines about a broken file (on stdout and stderr) before the bindings raise."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
    except (OSError, ValueError, AttributeError):  # no real descriptors (an embedding host): nothing to silence
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            yield
    finally:
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


def read_exr(path: str | Path) -> RangeScan:
    """Read a scan written by :func:`write_exr`; every array comes back bit-exact.

    Parameters
    ----------
    path : str or Path
        An OpenEXR file with the rangesim channels.

    Returns
    -------
    RangeScan
        ``pose`` defaults to identity and ``meta`` to ``{}`` if the header lacks them.

    Raises
    ------
    RangesimError
        If the file is missing, not OpenEXR, lacks a rangesim channel, or holds values
        that do not fit the field's dtype.
    """
    path = Path(path)
    if not path.is_file():
        raise RangesimError("no such file", path)
    with open(path, "rb") as fh:
        # checked here so plainly wrong files fail cleanly, without the library's stderr noise
        if fh.read(len(EXR_MAGIC)) != EXR_MAGIC:
            raise RangesimError("not an OpenEXR file", path)
    try:
        with _quiet_c_output():
            with OpenEXR.File(str(path), separate_channels=True) as exr:
                header = dict(exr.header())
                pixels = {name: ch.pixels for name, ch in exr.channels().items()}
    except Exception as exc:  # the bindings raise bare RuntimeError/ValueError for bad files
        raise RangesimError(f"truncated or corrupt OpenEXR file (the library says: {exc})", path) from exc

    version = header.get(VERSION_ATTR, FORMAT_VERSION)
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise RangesimError(
            f"rangesim EXR format version {version!r} is newer than this reader"
            f" ({FORMAT_VERSION}); update rangesim",
            path,
        )

    fields: dict[str, Any] = {}
    optional = {name for name, _, _ in OPTIONAL_PIXEL_FIELDS}
    for field, dtype, _ in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
        names = channel_names(field)
        missing = [n for n in names if n not in pixels]
        if field in optional and len(missing) == len(names):
            continue
        if missing:
            raise RangesimError(f"not a rangesim scan: missing channel {missing[0]}", path)
        # HALF channels written by other tools widen to float32 exactly
        planes = [np.asarray(pixels[n]).astype(np.float32) for n in names]
        value = planes[0] if len(planes) == 1 else np.stack(planes, axis=-1)
        fields[field] = _exact_cast(value, dtype, f"channel {field}", path)

    try:
        meta = decode_meta(header[META_ATTR]) if META_ATTR in header else {}
        pose = decode_pose(header[POSE_ATTR]) if POSE_ATTR in header else np.eye(4)
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"corrupt rangesim header attribute ({exc})", path) from exc
    try:
        return RangeScan(**fields, pose=pose, meta=meta)
    except ValueError as exc:
        raise RangesimError(f"inconsistent scan: {exc}", path) from exc
