"""Scan files: :func:`save_scan` / :func:`load_scan` pick the format by extension.

Writers: ``.exr`` (the native format, exact), ``.npz`` (exact), ``.ply`` (valid points
only, export). Readers: ``.exr`` and ``.npz``; other modules add readers for more
formats with :func:`register_reader` (and writers with :func:`register_writer`). Every
save goes through :func:`atomic_path`, so a failed write never leaves a partial file.

The writer registry and :func:`save_scan` live in :mod:`rangesim.core.writers`, so that
:meth:`RangeScan.save` works without core importing io; importing this module registers
the writers above there.
"""
from __future__ import annotations

import os
import struct
import tokenize
import zipfile
import zlib
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from rangesim.core.atomic import atomic_path
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan, checked_scan
from rangesim.core.writers import WRITERS, Writer, register_writer, save_scan
from rangesim.io.exr import read_exr, write_exr
from rangesim.io.npz import read_npz, write_npz
from rangesim.io.ply import write_ply

__all__ = [
    "atomic_path",
    "check_scan_contents",
    "load_scan",
    "read_exr",
    "read_npz",
    "register_reader",
    "register_writer",
    "save_scan",
    "write_exr",
    "write_npz",
    "write_ply",
]

Reader = Callable[..., RangeScan]

#: lower-case suffix -> writer(scan, path): the registry in core that save_scan and
#: RangeScan.save dispatch through (writers write directly, save_scan makes it atomic)
_WRITERS: dict[str, Writer] = WRITERS
#: lower-case suffix -> reader(path, **kwargs) -> RangeScan
_READERS: dict[str, Reader] = {}

register_writer(".exr", write_exr)
register_writer(".npz", write_npz)
register_writer(".ply", write_ply)


def _describe_suffix(path: Path) -> str:
    return f"{path.suffix!r} files" if path.suffix else "files without an extension"


def _reader_for(path: Path) -> Reader | None:
    """The reader registered for the longest matching suffix (".msu.gz" before ".gz")."""
    suffixes = [s.lower() for s in path.suffixes]
    for k in range(len(suffixes)):
        reader = _READERS.get("".join(suffixes[k:]))
        if reader is not None:
            return reader
    return None


def register_reader(suffixes: str | Iterable[str], func: Reader) -> None:
    """Make :func:`load_scan` read files with these extensions through ``func``.

    Parameters
    ----------
    suffixes : str or iterable of str
        Extensions such as ``".pcd"`` or ``"pcd"``, or compound ones such as
        ``".msu.gz"``; matched case-insensitively, the longest matching one first. A
        later registration for the same suffix replaces the earlier one.
    func : callable
        ``func(path: Path, **kwargs) -> RangeScan``; should raise
        :class:`RangesimError` for bad files.
    """
    if isinstance(suffixes, str):
        suffixes = [suffixes]
    for suffix in suffixes:
        suffix = suffix.lower()
        _READERS[suffix if suffix.startswith(".") else "." + suffix] = func


register_reader(".exr", read_exr)
register_reader(".npz", read_npz)


def check_scan_contents(scan: RangeScan, path: str | Path) -> RangeScan:
    """Refuse a scan file whose contents every reader of it would trip over later, in one line.

    ``meta["units"]`` (when present) must be ``"mm"``, and every valid pixel's ``xyz`` finite (a
    NaN point counted as measured). The RangeScan constructor's checks are run again, for
    what a reader set after building the scan (a pose from a ``.conf``; a registered reader
    of another package): a pose that is not finite or has a singular rotation block (a NaN pose
    was printed and used, a zero one made every world point the origin), a ``meta["K"]`` that
    is no pinhole matrix, a ``meta["sensor"]`` that is no table, fields of the wrong shape.

    Returns
    -------
    RangeScan
        The scan as the constructor checked it (the same arrays).
    """
    import numpy as np

    scan = checked_scan(scan, path, doing="read")
    units = scan.meta.get("units", "mm")
    if units != "mm":  # every reader of a scan takes its coordinates as millimetres
        raise RangesimError(f"the scan's meta.units is {units!r:.40}: rangesim scans are in millimetres (\"mm\")", path)
    bad = int(np.count_nonzero(~np.isfinite(scan.xyz[scan.valid]).all(axis=-1)))
    if bad:
        raise RangesimError(f"{bad:,} valid pixels have NaN or infinite coordinates (xyz)", path)
    return scan


def load_scan(path: str | Path, **kwargs: Any) -> RangeScan:
    """Read a scan; the reader is chosen by extension (see :func:`register_reader`).

    Parameters
    ----------
    path : str or Path
    **kwargs
        Passed to the reader (for formats that need e.g. an image size).

    Returns
    -------
    RangeScan

    Raises
    ------
    RangesimError
        If the file is missing, its extension has no reader, or it cannot be read.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise RangesimError(f"load_scan takes a file name, got {type(path).__name__}")
    path = Path(path)
    if not path.exists():
        raise RangesimError("no such file", path)
    if not path.is_file():
        raise RangesimError("not a file", path)
    reader = _reader_for(path)
    if reader is None:
        supported = ", ".join(sorted(_READERS))
        raise RangesimError(
            f"cannot read scans from {_describe_suffix(path)};"
            f" supported: {supported}",
            path,
        )
    try:
        return check_scan_contents(reader(path, **kwargs), path)
    except RangesimError:
        raise
    except (OSError, ValueError, KeyError, EOFError, IndexError, TypeError, SyntaxError, struct.error, zlib.error,
            zipfile.BadZipFile, tokenize.TokenError) as exc:
        # safety net for registered readers that let a parser error through (a mangled .npy header in an
        # .npz raises SyntaxError or TokenError); the message stays one printable line
        detail = " ".join(str(exc).split())[:200].encode("ascii", "backslashreplace").decode()
        raise RangesimError(f"cannot read scan ({type(exc).__name__}: {detail})", path) from exc
