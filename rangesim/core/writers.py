"""The registry of scan writers, by file extension, that :meth:`RangeScan.save` goes through.

The file formats live in :mod:`rangesim.io`, a layer above core, so core cannot import
them: instead ``rangesim.io`` registers its writers (``.exr``, ``.npz``, ``.ply``) here
with :func:`register_writer` when it is imported, and ``import rangesim`` (which every
``import rangesim.<anything>`` runs first) imports ``rangesim.io``. :func:`save_scan`
picks the writer by extension and makes every write atomic (see
:func:`~rangesim.core.atomic.atomic_path`), so a failed write never leaves a partial
file; it is the one :func:`rangesim.io.save_scan` re-exports.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.atomic import atomic_path
from rangesim.core.errors import RangesimError

__all__ = ["WRITERS", "Writer", "register_writer", "save_scan"]

#: ``writer(scan, path)``: writes the RangeScan ``scan`` to ``path`` directly (not
#: atomically: :func:`save_scan` hands it a temporary name and renames it afterwards)
Writer = Callable[[Any, Path], None]

#: lower-case suffix -> writer; fill it with :func:`register_writer`
WRITERS: dict[str, Writer] = {}


def register_writer(suffixes: str | Iterable[str], func: Writer) -> None:
    """Make :func:`save_scan` (and :meth:`RangeScan.save`) write files with these extensions through ``func``.

    Parameters
    ----------
    suffixes : str or iterable of str
        Extensions such as ``".exr"`` or ``"exr"``, matched case-insensitively. A later
        registration for the same suffix replaces the earlier one.
    func : callable
        ``func(scan: RangeScan, path: Path) -> None``; writes ``path`` directly and
        should raise :class:`RangesimError` (with ``source`` the path it was given) for
        data the format cannot store.
    """
    if isinstance(suffixes, str):
        suffixes = [suffixes]
    for suffix in suffixes:
        suffix = suffix.lower()
        WRITERS[suffix if suffix.startswith(".") else "." + suffix] = func


def save_scan(scan: Any, path: str | Path) -> Path:
    """Write ``scan`` atomically; the format follows the extension.

    Parameters
    ----------
    scan : RangeScan
    path : str or Path
        ``.exr``, ``.npz`` or ``.ply`` (any case), or another registered extension.
        Missing parent directories are created.

    Returns
    -------
    Path
        The path written.

    Raises
    ------
    RangesimError
        For an unsupported extension or data the format cannot store exactly.
    """
    path = Path(path)
    writer = WRITERS.get(path.suffix.lower())
    if writer is None:
        supported = ", ".join(sorted(WRITERS)) or "none (import rangesim.io to register the scan formats)"
        what = f"{path.suffix!r} files" if path.suffix else "files without an extension"
        raise RangesimError(f"cannot write scans as {what}; supported: {supported}", path)
    from rangesim.core.rangescan import checked_scan  # rangescan imports this module

    scan = checked_scan(scan, path)  # fields reassigned since construction pass its checks again
    pose = getattr(scan, "pose", None)
    if pose is not None and not np.all(np.isfinite(pose)):  # no reader takes such a pose back
        raise RangesimError("cannot write the scan: its pose holds NaN or infinity", path)
    with atomic_path(path) as tmp:
        try:
            writer(scan, tmp)
        except RangesimError as exc:
            if exc.source != str(tmp):
                raise
            # the writer only saw the temporary name; the user knows the final one
            relabelled = RangesimError(str(exc).replace(str(tmp), str(path), 1))
            relabelled.source = str(path)
            raise relabelled from exc
    return path
