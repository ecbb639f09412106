"""Memory estimates checked before a big job starts: refuse in one line rather than crash.

A job (a scan of many pixels, a rendered frame stack, a finely tessellated CAD model) is
estimated before anything is allocated, and compared with the memory budget: the memory
the machine has available now (``MemAvailable`` on Linux), or ``RANGESIM_MEMORY_LIMIT``
when that is set and smaller (bytes, or a number with a K, M, G or T suffix, e.g. ``2G``).
"""
from __future__ import annotations

import os
import re

from rangesim.core.errors import RangesimError

_UNITS = {"": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}


def parse_size(text: str) -> int:
    """Bytes from ``"2G"``, ``"512M"``, ``"1.5e9"`` (case-insensitive, optional ``B``/``iB``)."""
    match = re.fullmatch(r"\s*([0-9.eE+]+)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", str(text))
    if not match:
        raise RangesimError(f"RANGESIM_MEMORY_LIMIT must be a size such as 2G or 512M, got {text!r}")
    try:
        value = float(match.group(1))
    except ValueError:
        raise RangesimError(f"RANGESIM_MEMORY_LIMIT must be a size such as 2G or 512M, got {text!r}") from None
    if not value > 0:
        raise RangesimError(f"RANGESIM_MEMORY_LIMIT must be positive, got {text!r}")
    return int(value * _UNITS[match.group(2).upper()])


def available_memory() -> int | None:
    """Bytes of memory available to a new job on this machine, or None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def memory_budget() -> tuple[int | None, str]:
    """(bytes, where the figure comes from): the smaller of RANGESIM_MEMORY_LIMIT and the free memory."""
    limit_text = os.environ.get("RANGESIM_MEMORY_LIMIT", "").strip()
    available = available_memory()
    if limit_text:
        limit = parse_size(limit_text)
        if available is None or limit <= available:
            return limit, "RANGESIM_MEMORY_LIMIT"
    return available, "available on this machine"


def format_bytes(n: float) -> str:
    """``1.5 GB``-style text (powers of 1024)."""
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PB"  # pragma: no cover


def check_memory(estimate: float, what: str, source: str | None = None) -> None:
    """Raise a one-line RangesimError if ``estimate`` bytes exceed the memory budget.

    Parameters
    ----------
    estimate : float
        Bytes the job would need.
    what : str
        The parameter(s) that set the size and how, e.g. ``"camera.width x camera.height =
        20000 x 20000 px"``; the message names them and the estimate.
    """
    budget, origin = memory_budget()
    if budget is None or estimate <= budget:
        return
    raise RangesimError(
        f"{what} needs about {format_bytes(estimate)} of memory, more than the {format_bytes(budget)} "
        f"{origin}; reduce it" + (" or raise RANGESIM_MEMORY_LIMIT" if origin == "RANGESIM_MEMORY_LIMIT" else ""),
        source=source,
    )
