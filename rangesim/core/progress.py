"""Progress of long work: a tqdm bar on a terminal, plain log lines elsewhere (CI logs, nohup).

One mechanism for every long loop (sweeps, datasets, rendered-mode tiles, ``detect --method
all``, ``compare``). Nothing shows for work that ends within :data:`DELAY_S` seconds. Where
stderr is not a terminal, a line such as::

    rangesim: sweep snr: 12/40 tasks (30 %), 35 s, about 82 s left

is written every :data:`LOG_EVERY_S` seconds and at every tenth of the work, and one more
when it ends. The default (:func:`set_progress`) is a bar on a terminal and, for library
calls, nothing elsewhere; the command line turns the log lines on (``--quiet`` turns all off).
"""
from __future__ import annotations

import sys
import time
from typing import Literal

from rangesim.core.errors import RangesimError

#: seconds of work before anything is shown
DELAY_S = 3.0
#: a log line at least this often (seconds) while work goes on
LOG_EVERY_S = 10.0

_Mode = Literal["auto", "log", "off"]
_default: _Mode = "auto"


def set_progress(mode: _Mode) -> None:
    """How :class:`Progress` shows with ``enabled=None``.

    ``"auto"``: a bar on a terminal, nothing elsewhere (the library's default); ``"log"``: a
    bar on a terminal, log lines elsewhere (the command line's); ``"off"``: nothing.
    """
    global _default
    if mode not in ("auto", "log", "off"):
        raise RangesimError(f"progress mode must be 'auto', 'log' or 'off', got {mode!r}")
    _default = mode


class Progress:
    """Count work done; show it as a bar or as log lines (see the module docstring).

    Parameters
    ----------
    total : int
        Units of work.
    desc : str
        What the work is (``"sweep snr"``).
    unit : str
        Name of a unit (``"task"``, ``"tile"``).
    initial : int
        Units already done (reused results).
    enabled : bool, optional
        True: show (a bar on a terminal, else log lines); False: never; None: as
        :func:`set_progress` says.
    stream : file, optional
        Where to write (default ``sys.stderr``).
    delay_s : float, optional
        Seconds before anything shows (default :data:`DELAY_S`).

    Examples
    --------
    >>> import io
    >>> out = io.StringIO()
    >>> with Progress(4, "demo", enabled=True, stream=out, delay_s=0.0) as bar:
    ...     for _ in range(4):
    ...         bar.update()
    >>> out.getvalue().splitlines()[-1].startswith("rangesim: demo: 4/4 tasks (100 %)")
    True
    """

    def __init__(self, total: int, desc: str, unit: str = "task", initial: int = 0, enabled: bool | None = None,
                 stream=None, delay_s: float | None = None):
        self.total, self.desc, self.unit, self.done = int(total), desc, unit, int(initial)
        self.stream = stream if stream is not None else sys.stderr
        self.delay_s = DELAY_S if delay_s is None else delay_s
        terminal = bool(getattr(self.stream, "isatty", lambda: False)())
        mode = _default if enabled is None else ("log" if enabled else "off")
        self._bar = None
        self._log = mode == "log" and not terminal
        if mode != "off" and terminal:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, initial=self.done, desc=desc, unit=unit, file=self.stream,
                             delay=self.delay_s, dynamic_ncols=True, smoothing=0.1)
        self._start = self._last = time.monotonic()
        self._first = self.done
        self._written: int | None = None  # the count of the last line written
        self._tenth = self._tenths(self.done)

    def _tenths(self, done: int) -> int:
        return 10 * done // self.total if self.total > 0 else 10

    def update(self, n: int = 1) -> None:
        """``n`` more units done."""
        self.done += n
        if self._bar is not None:
            self._bar.update(n)
        if not self._log:
            return
        now = time.monotonic()
        tenth = self._tenths(self.done)
        if now - self._start >= self.delay_s and (now - self._last >= LOG_EVERY_S or tenth > self._tenth):
            self._write(now)
        self._tenth = tenth

    def _write(self, now: float) -> None:
        elapsed = now - self._start
        line = f"rangesim: {self.desc}: {self.done:,}/{self.total:,} {self.unit}s"
        if self.total > 0:
            line += f" ({100 * self.done // self.total} %)"
        line += f", {elapsed:.0f} s"
        rate = (self.done - self._first) / elapsed if elapsed > 0 else 0.0
        if 0 < self.done < self.total and rate > 0:
            line += f", about {(self.total - self.done) / rate:.0f} s left"
        print(line, file=self.stream, flush=True)
        self._last, self._written = now, self.done

    def close(self) -> None:
        """End the bar; a last log line if any was written and the work is not already at its end."""
        if self._bar is not None:
            self._bar.close()
        if self._log and self._written is not None and self._written != self.done:
            self._write(time.monotonic())

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
