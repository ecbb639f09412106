"""Task files and the tidy results table of a sweep.

Layout of a sweep's output folder::

    out/sweep.json                 the sweep as run (provenance; rewritten by each run)
    out/tasks/<key>.json           one per finished task: its rows (every detector of one scan)
    out/scans/<key>.exr            with --keep-scans
    out/results.parquet, .csv      the table: one row per scan x detector
    out/plots/*.png

Every file is written under a temporary name and renamed, so a killed run leaves whole
files only; a rerun skips the tasks whose file exists. The table is built from the task
files of the sweep's own tasks, in plan order (then detector order), so it is the same
whether the tasks ran in one go, in pieces, in any order or on any number of workers
(except the run-time columns, :data:`~rangesim.experiments.tasks.TIMING_COLUMNS`).
"""
from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rangesim.core.errors import RangesimError
from rangesim.experiments.grid import TASK_FORMAT, SweepTask, canonical_json
from rangesim.io.atomic import atomic_path

TASKS_DIR = "tasks"
SCANS_DIR = "scans"
TABLE_NAMES = ("results.parquet", "results.csv")


def task_path(out: Path, key: str) -> Path:
    """``out/tasks/<key>.json``."""
    return Path(out) / TASKS_DIR / f"{key}.json"


def scan_path(out: Path, key: str) -> Path:
    """``out/scans/<key>.exr``."""
    return Path(out) / SCANS_DIR / f"{key}.exr"


def write_json(path: Path, data: Any) -> Path:
    """Write JSON atomically (NaN and infinity as JavaScript's NaN / Infinity, as Python reads them)."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(data, indent=1, allow_nan=True), encoding="utf-8")
    return Path(path)


def write_task_file(out: Path, task: SweepTask, rows: list[dict[str, Any]]) -> Path:
    """Write one finished task's rows (atomically)."""
    return write_json(task_path(out, task.key),
                      {"format": TASK_FORMAT, "key": task.key, "columns": task.columns, "rows": rows})


def read_task_rows(out: Path, task: SweepTask) -> list[dict[str, Any]]:
    """The rows of a finished task.

    Raises
    ------
    RangesimError
        The file is missing, unreadable, or belongs to other parameters.
    """
    path = task_path(out, task.key)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RangesimError("task file missing", source=path) from None
    except (OSError, ValueError) as exc:
        raise RangesimError(f"unreadable task file ({exc}); delete it and rerun", source=path) from exc
    if not isinstance(data, dict) or data.get("key") != task.key or data.get("format") != TASK_FORMAT \
            or canonical_json(data.get("columns")) != canonical_json(task.columns):
        raise RangesimError("task file does not match its task; delete it and rerun", source=path)
    return data["rows"]


def _column_values(values: list[Any]) -> list[Any]:
    """A grid column as one type: numbers stay numbers; lists and mixtures become JSON text."""
    plain = [v for v in values if v is not None]
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in plain):
        return values
    if all(isinstance(v, str) for v in plain) or all(isinstance(v, bool) for v in plain):
        return values
    return [v if v is None else json.dumps(v) for v in values]


def build_table(tasks: Sequence[SweepTask], out: Path):
    """The results table (pandas DataFrame) from the task files, rows in plan order.

    Parameters
    ----------
    tasks : sequence of SweepTask
        The sweep's plan (:func:`~rangesim.experiments.grid.plan_sweep`).
    out : Path
        The sweep's output folder.
    """
    import pandas as pd

    rows: list[dict[str, Any]] = []
    for task in sorted(tasks, key=lambda t: t.index):
        rows.extend(read_task_rows(out, task))
    if not rows:
        return pd.DataFrame()
    columns: list[str] = []
    seen: set[str] = set()
    for row in rows:
        for k in row:
            if k not in seen:
                seen.add(k)
                columns.append(k)
    data = {c: _column_values([row.get(c) for row in rows]) for c in columns}
    return pd.DataFrame(data, columns=columns)


def write_table(table, out: Path) -> list[Path]:
    """Write ``results.parquet`` and ``results.csv`` (each atomically); returns the paths."""
    paths = []
    for name in TABLE_NAMES:
        path = Path(out) / name
        with atomic_path(path) as tmp:
            if name.endswith(".parquet"):
                table.to_parquet(tmp, index=False)
            else:
                table.to_csv(tmp, index=False)
        paths.append(path)
    return paths


def read_table(path: str | Path):
    """A results table written by :func:`write_table` (``.parquet`` or ``.csv``)."""
    import pandas as pd

    path = Path(path)
    if path.suffix == ".parquet":
        return pd.read_parquet(path)
    return pd.read_csv(path)
