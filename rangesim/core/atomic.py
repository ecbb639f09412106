"""Atomic file writes: write under a temporary name, then rename onto the target.

Used by every layer that writes files (scans, figures, tables); also importable as
:mod:`rangesim.io.atomic`.
"""
from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def temp_path_for(path: str | Path) -> Path:
    """A fresh hidden temporary path beside ``path`` that keeps its extension.

    ``scan.exr`` -> ``.scan.tmp-1a2b3c4d.exr``: same directory (so the final rename is
    atomic, never a cross-device copy) and same suffix (libraries that pick the format by
    extension still work). The file is not created.
    """
    path = Path(path)
    while True:
        tmp = path.with_name(f".{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
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
    path.parent.mkdir(parents=True, exist_ok=True)
    # not created here (e.g. with mkstemp) so the file gets the usual umask permissions
    tmp = temp_path_for(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
