"""The one exception type for user errors: the CLI prints its message on one line, no traceback."""
from __future__ import annotations

from pathlib import Path


class RangesimError(ValueError):
    """A problem with the user's input (a file, a parameter), described in one line.

    Parameters
    ----------
    message : str
        What is wrong.
    source : str or Path, optional
        The file (or preset, or parameter) the problem is in; prefixed to the message.
    """

    def __init__(self, message: str, source: str | Path | None = None):
        self.source = None if source is None else str(source)
        text = message if source is None else f"{source}: {message}"
        super().__init__(" ".join(text.split()))
