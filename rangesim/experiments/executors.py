"""Where experiment tasks run: in this process, a local process pool, or a Dask cluster.

Every executor runs a top-level function on plain-data payloads and yields
``(index, result, error)`` in completion order; the caller (the driver process) writes all
files, so workers need no access to the output folder (a remote Dask worker needs the
scene files, at the same paths, and rangesim installed).

* ``workers = 0``: in this process, one task after the other (Dr.Jit keeps all its threads).
* local pool (default): ``concurrent.futures.ProcessPoolExecutor`` with the ``spawn`` start
  method (Mitsuba and Dr.Jit do not survive a fork once initialised); each worker sets
  Dr.Jit to one thread (:func:`init_worker`) so N workers use N cores.
* ``local:N``: a ``dask.distributed.LocalCluster`` of N single-threaded worker processes on
  127.0.0.1 (no dashboard).
* ``tcp://HOST:PORT``: an existing Dask scheduler. Start its workers with ``--nthreads 1``
  (one process per core): Dr.Jit's thread pool is per process.
"""
from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from rangesim.core.errors import RangesimError

#: set in worker processes by :func:`init_worker`: tasks use one thread
_SINGLE_THREADED = False
#: the most ``local:N`` Dask workers per available core
MAX_LOCAL_WORKERS_PER_CORE = 8
#: BLAS / OpenMP thread variables set to 1 for spawned workers (read when numpy loads)
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def available_cores() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def init_worker() -> None:
    """Make this process a single-threaded worker: Dr.Jit (and, through the environment,
    BLAS) on one thread. Called once in every pool or Dask worker process."""
    global _SINGLE_THREADED
    if _SINGLE_THREADED:
        return
    _SINGLE_THREADED = True
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    # a worker's warnings on one line, as the command line prints its own (not Python's two
    # lines with the source file and the code)
    import warnings

    warnings.showwarning = _one_line_warning
    _exit_with_parent()
    import drjit as dr

    dr.set_thread_count(1)


def init_pool_worker() -> None:
    """:func:`init_worker` for a local pool's process, which also ignores Ctrl-C: the terminal sends
    SIGINT to the whole process group, and the driver, not each worker, decides what stops (it
    ends the pool's processes itself; see :meth:`Executor.close`)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    init_worker()


def _exit_with_parent() -> None:
    """Linux: this worker gets SIGTERM when the process that started it dies (a driver killed
    with SIGKILL left its pool workers blocked on a pipe for good, holding their memory)."""
    import ctypes
    import signal
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - no prctl: the old behaviour
        return
    if os.getppid() == 1:  # the parent died before the call: nobody would send the signal
        os._exit(1)


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ARG001
    import sys

    text = " ".join(str(message).split())
    print(f"rangesim: warning: {text}", file=sys.stderr if file is None else file)


def single_threaded() -> bool:
    """True inside a worker set up by :func:`init_worker`."""
    return _SINGLE_THREADED


def _call_in_worker(fn: Callable[[Any], Any], payload: Any) -> Any:
    """A Dask task: set the worker up (once), then run ``fn(payload)``."""
    init_worker()
    return fn(payload)


def parse_scheduler(text: str | None) -> tuple[str, Any]:
    """``None`` -> ("pool", None); ``local:N`` -> ("local", N); ``tcp://H:P`` -> ("tcp", text).

    Raises
    ------
    RangesimError
        Anything else.
    """
    if text is None or text == "":
        return "pool", None
    if text.startswith("local:"):
        n = text[6:]
        if not n.isdigit() or int(n) < 1:
            raise RangesimError(f"--scheduler local:N needs a worker count N >= 1, got {text!r}")
        return "local", int(n)
    if text.startswith(("tcp://", "tls://")) and len(text) > 6:
        return "tcp", text
    if text.startswith("inproc://"):
        # its workers are threads of this process, which each task would make single-threaded
        raise RangesimError(f"--scheduler {text!r} is an in-process Dask cluster, which rangesim does not run on: "
                            "start it with processes=True (or protocol='tcp') and pass its tcp:// address")
    raise RangesimError(f"--scheduler must be local:N or tcp://HOST:PORT, got {text!r}")


class Executor:
    """Runs ``fn(payload)`` for many payloads; a context manager.

    Parameters
    ----------
    workers : int, optional
        Local pool size (default: the cores available, at most ``max_tasks``); 0 runs in
        this process. With a Dask scheduler, ignored.
    scheduler : str, optional
        ``local:N`` or ``tcp://HOST:PORT`` (see the module docstring).
    max_tasks : int, optional
        Upper bound on the pool size (no more processes than tasks).
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None, max_tasks: int | None = None):
        self.kind, self.address = parse_scheduler(scheduler)
        if workers is not None and (isinstance(workers, bool) or workers < 0):
            raise RangesimError(f"--workers must be >= 0, got {workers}")
        if self.kind == "pool":
            n = available_cores() if workers is None else int(workers)
            if max_tasks is not None and n > 0:
                n = max(1, min(n, max_tasks))
            if n == 0:
                self.kind = "serial"
            self.workers = n
        elif self.kind == "local":
            n, cores = int(self.address), available_cores()
            if n > MAX_LOCAL_WORKERS_PER_CORE * cores:
                # each is a process with its own Dr.Jit and scene: local:100000 hung starting them
                raise RangesimError(f"--scheduler local:{n} asks for more than {MAX_LOCAL_WORKERS_PER_CORE} worker "
                                    f"processes per core ({cores} cores here); a worker per core is the fastest")
            if max_tasks is not None:  # as the local pool: no more processes than tasks
                n = max(1, min(n, max_tasks))
            self.address = self.workers = n
        else:
            self.workers = None
        self._pool: ProcessPoolExecutor | None = None
        self._client = None
        self._cluster = None
        self._saved_env: dict[str, str | None] = {}

    # -- lifecycle --------------------------------------------------------------------
    def __enter__(self) -> "Executor":
        if self.kind == "pool":
            # spawned workers read these when they import numpy; the driver's BLAS is loaded already
            self._saved_env = {k: os.environ.get(k) for k in THREAD_VARIABLES}
            for k in THREAD_VARIABLES:
                os.environ[k] = "1"
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=init_pool_worker)
        elif self.kind in ("local", "tcp"):
            self._start_dask()
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        self.close(abort=exc_type is not None and issubclass(exc_type, (KeyboardInterrupt, SystemExit)))

    def close(self, abort: bool = False) -> None:
        """Stop the pool or cluster (pending tasks are cancelled).

        Parameters
        ----------
        abort : bool
            End a local pool's processes at once instead of waiting for the tasks they run
            (Ctrl-C, SIGTERM: a scan task may run for minutes, and a shutdown that waits for a
            pool whose workers were interrupted could wait for good).
        """
        if self._pool is not None:
            if abort:
                processes = list((getattr(self._pool, "_processes", None) or {}).values())
                self._pool.shutdown(wait=False, cancel_futures=True)
                for process in processes:
                    process.terminate()
                for process in processes:
                    process.join(timeout=10)
            else:
                self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            for k, v in self._saved_env.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def _start_dask(self) -> None:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover - a dependency of rangesim
            raise RangesimError(f"--scheduler needs dask[distributed] ({exc})") from exc
        import logging

        if self.kind == "local":
            self._cluster = LocalCluster(n_workers=int(self.address), threads_per_worker=1, processes=True,
                                         host="127.0.0.1", dashboard_address=None,
                                         silence_logs=logging.CRITICAL)  # a failed task is reported once, by us
            self._client = Client(self._cluster)
        else:
            try:
                self._client = Client(self.address, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise RangesimError(f"cannot reach the Dask scheduler ({exc})", source=self.address) from exc

    def describe(self) -> str:
        """A few words for messages: ``2 local processes``, ``Dask local:2``, ..."""
        if self.kind == "serial":
            return "this process"
        if self.kind == "pool":
            return f"{self.workers} local process{'es' if self.workers != 1 else ''}"
        if self.kind == "local":
            return f"Dask LocalCluster of {self.address} workers"
        return f"Dask scheduler {self.address}"

    # -- running --------------------------------------------------------------------------
    def run(self, fn: Callable[[Any], Any], payloads: Sequence[Any]) -> Iterator[tuple[int, Any, BaseException | None]]:
        """Run ``fn`` on every payload; yield ``(index, result, None)`` or ``(index, None,
        error)`` as tasks finish (any order). Stopping the iteration early cancels the rest."""
        if self.kind == "serial":
            yield from self._run_serial(fn, payloads)
        elif self.kind == "pool":
            yield from self._run_pool(fn, payloads)
        else:
            yield from self._run_dask(fn, payloads)

    @staticmethod
    def _run_serial(fn, payloads):
        for i, payload in enumerate(payloads):
            try:
                result = fn(payload)
            except (KeyboardInterrupt, SystemExit):
                raise
            except BaseException as exc:  # noqa: BLE001 -- reported per task
                yield i, None, exc
            else:
                yield i, result, None

    def _submit(self, fn, payload):
        """``pool.submit`` with SIGINT ignored while it runs: a submit may spawn a worker, which
        then starts with SIGINT ignored from its first line (the initializer's own ignore comes
        only after the worker's imports, and Ctrl-C during those printed a worker traceback)."""
        import signal

        from rangesim.core.signals import signal_handler

        with signal_handler(signal.SIGINT, signal.SIG_IGN):
            return self._pool.submit(fn, payload)

    def _run_pool(self, fn, payloads):
        assert self._pool is not None, "use the Executor as a context manager"
        # a window of pending tasks (not thousands of futures at once): 4 per worker
        window = 4 * self.workers
        todo = iter(enumerate(payloads))
        pending: dict[Any, int] = {}
        try:
            while True:
                while len(pending) < window:
                    item = next(todo, None)
                    if item is None:
                        break
                    pending[self._submit(fn, item[1])] = item[0]
                if not pending:
                    return
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    i = pending.pop(future)
                    exc = future.exception()
                    if isinstance(exc, BrokenProcessPool):
                        # a spawned worker imports the calling script: one that starts the pool at its
                        # top level starts it again in every worker, which then dies
                        exc = RangesimError(
                            "the worker processes died (BrokenProcessPool); called from a script, put the call "
                            "under `if __name__ == \"__main__\":` (the workers are spawned and import the "
                            "script), or run with workers=0")
                    yield (i, None, exc) if exc is not None else (i, future.result(), None)
        finally:
            for future in pending:
                future.cancel()

    def _run_dask(self, fn, payloads):
        from dask.distributed import as_completed

        client = self._client
        futures = [client.submit(_call_in_worker, fn, p, pure=False, key=f"rangesim-task-{i}-{os.getpid()}-{id(p)}")
                   for i, p in enumerate(payloads)]
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for future in as_completed(futures):
                i = index[future.key]
                if future.status == "error":
                    yield i, None, future.exception()
                else:
                    yield i, future.result(), None
                future.release()
        finally:
            for f in futures:
                if not f.done():
                    f.cancel()
