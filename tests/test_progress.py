"""Progress of long work (issue 16 item 6): bars on terminals, log lines in logs, nothing for short work."""
from __future__ import annotations

import io
import re

import pytest

from rangesim.core import progress
from rangesim.core.progress import Progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_lines_every_tenth_and_at_the_end():
    out = io.StringIO()
    with Progress(20, "sweep demo", enabled=True, stream=out, delay_s=0.0) as bar:
        for _ in range(20):
            bar.update()
    lines = out.getvalue().splitlines()
    assert len(lines) == 10  # one per tenth: 2, 4, ..., 20 tasks
    assert all(re.fullmatch(r"rangesim: sweep demo: \d+/20 tasks \(\d+ %\), \d+ s(, about \d+ s left)?", x)
               for x in lines), lines
    assert lines[-1].startswith("rangesim: sweep demo: 20/20 tasks (100 %)")


def test_short_work_shows_nothing_and_disabled_never():
    out = io.StringIO()
    with Progress(5, "quick", enabled=True, stream=out) as bar:  # ends within DELAY_S
        for _ in range(5):
            bar.update()
    with Progress(5, "off", enabled=False, stream=out, delay_s=0.0) as bar:
        bar.update(5)
    assert out.getvalue() == ""


def test_a_terminal_gets_a_bar_not_log_lines():
    out = Terminal()
    with Progress(4, "bar demo", unit="tile", enabled=True, stream=out, delay_s=0.0) as bar:
        bar.update(4)
    text = out.getvalue()
    assert "bar demo" in text and "4/4" in text and "tile" in text and "rangesim: bar demo" not in text


def test_library_default_is_silent_off_a_terminal(monkeypatch):
    monkeypatch.setattr(progress, "_default", "auto")
    out = io.StringIO()
    with Progress(3, "library", stream=out, delay_s=0.0) as bar:
        bar.update(3)
    assert out.getvalue() == ""
    with pytest.raises(ValueError):
        progress.set_progress("loud")
