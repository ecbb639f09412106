"""Reading TOML files with one-line errors."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from rangesim.core.errors import RangesimError


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing file or a syntax error raises :class:`RangesimError`."""
    path = Path(path)
    if path.is_dir():
        raise RangesimError("is a directory, not a TOML file", source=path)
    if not path.is_file():
        raise RangesimError("no such file", source=path)
    try:
        data = path.read_bytes()
        # a byte-order mark (Windows editors write one) is no TOML syntax error
        return tomllib.loads(data.removeprefix(b"\xef\xbb\xbf").decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise RangesimError(f"invalid TOML: {exc}", source=path) from exc


def check_keys(table: dict[str, Any], allowed: set[str], where: str, source) -> None:
    """Reject keys a table does not know (catches typos such as ``basline``)."""
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise RangesimError(
            f"unknown key(s) {', '.join(unknown)} in {where}; known: {', '.join(sorted(allowed))}",
            source=source,
        )
