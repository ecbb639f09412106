"""Timing helpers shared by the benchmark scripts."""
from __future__ import annotations

import os
import statistics
import time
from pathlib import Path
from typing import Any, Callable


def timed(fn: Callable[[], Any], repeat: int) -> tuple[float, float, list[float], Any]:
    """Run ``fn`` once (warm-up), then ``repeat`` times.

    Returns
    -------
    cold : float
        Seconds of the warm-up run.
    median : float
        Median seconds of the timed runs.
    times : list of float
        Every timed run, seconds.
    result : Any
        What the last run returned.
    """
    t0 = time.perf_counter()
    result = fn()
    cold = time.perf_counter() - t0
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return cold, statistics.median(times), times, result


def interleaved(functions: dict[str, Callable[[], Any]], repeat: int) -> dict[str, tuple[float, float, list[float], Any]]:
    """Like :func:`timed` for several functions, run in turns so a busy moment hits them all alike.

    Each function runs once cold (in order), then ``repeat`` rounds run every function once.
    Returns, per name, (cold, median, times, last result).
    """
    out: dict[str, list] = {}
    for name, fn in functions.items():
        t0 = time.perf_counter()
        result = fn()
        out[name] = [time.perf_counter() - t0, [], result]
    for _ in range(repeat):
        for name, fn in functions.items():
            t0 = time.perf_counter()
            out[name][2] = fn()
            out[name][1].append(time.perf_counter() - t0)
    return {name: (cold, statistics.median(times), times, result) for name, (cold, times, result) in out.items()}


def cpu_info() -> dict[str, Any]:
    """CPU model and core counts of this machine."""
    info: dict[str, Any] = {"os.cpu_count": os.cpu_count()}
    try:
        info["affinity"] = len(os.sched_getaffinity(0))
    except AttributeError:
        pass
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["model"] = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return info
