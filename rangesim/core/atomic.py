"""Atomic file writes: write under a temporary name, then rename onto the target.

Used by every layer that writes files (scans, figures, tables); also importable as
:mod:`rangesim.io.atomic`.
"""
from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

#: the longest file name (bytes) most file systems take (ext4, XFS, APFS, NTFS)
MAX_NAME_BYTES = 255


def temp_path_for(path: str | Path) -> Path:
    """A fresh hidden temporary path beside ``path`` that keeps its extension.

    ``scan.exr`` -> ``.scan.tmp-1a2b3c4d.exr``: same directory (so the final rename is
    atomic, never a cross-device copy) and same suffix (libraries that pick the format by
    extension still work). The file is not created.
    """
    path = Path(path)
    # the 14 characters added must not push a long name past the file system's 255 bytes
    stem = path.stem
    while len(f".{stem}.tmp-00000000{path.suffix}".encode()) > MAX_NAME_BYTES and stem:
        stem = stem[:-1]
    while True:
        tmp = path.with_name(f".{stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
        if not tmp.exists():
            return tmp


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write to; move it onto ``path`` only if the block succeeds.

    Creates the parent directory if missing. On an exception (KeyboardInterrupt included)
    the temporary file is removed and ``path`` is left as it was, so readers never see a
    half-written file.

    Parameters
    ----------
    path : str or Path
        The final file.

    Yields
    ------
    Path
        Where the caller writes the file. It does not exist yet; the caller creates it.

    Examples
    --------
    >>> with atomic_path("out/scan.png") as tmp:       # doctest: +SKIP
    ...     imageio.imwrite(tmp, image)
    """
    path = Path(path)
    if path.is_symlink():  # as open() does: the file the link names is replaced, the link stays
        path = path.resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    # not created here (e.g. with mkstemp) so the file gets the usual umask permissions
    tmp = temp_path_for(path)
    try:
        yield tmp
        if path.exists():  # a replaced file keeps its permissions (a 0600 file stays private)
            os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))
        with open(tmp, "rb") as handle:  # on disk before the rename, so a crash leaves old or new
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename is not None and Path(exc.filename) == tmp:
            # the user named the final file: "out/sweep.json: Read-only file system", not the temporary
            raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
