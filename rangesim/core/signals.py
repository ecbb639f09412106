"""Signal handlers swapped for the length of a block: one mechanism for the command line's
SIGTERM-as-interrupt and the worker pool's SIGINT-ignoring submits."""
from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any


@contextmanager
def signal_handler(signum: int, handler: Callable[[int, Any], Any] | int) -> Iterator[None]:
    """Within the block ``signum`` goes to ``handler`` (a function, ``signal.SIG_IGN`` or
    ``SIG_DFL``); the previous handler comes back afterwards.

    Only the main thread may set handlers (Python's rule): elsewhere the block runs unchanged.
    A previous handler that was not set from Python (``None``: an embedding host's) is not
    restored, as ``signal.signal`` cannot take it back.

    Examples
    --------
    >>> import signal
    >>> with signal_handler(signal.SIGINT, signal.SIG_IGN):
    ...     signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    True
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signum, handler)
    try:
        yield
    finally:
        if before is not None:
            signal.signal(signum, before)
