"""``run_sweep``: every task of a sweep file, resumably, then the table and the plots."""
from __future__ import annotations

import json
import os
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rangesim.core.errors import RangesimError
from rangesim.core.progress import Progress
from rangesim.core.version import __version__
from rangesim.experiments.executors import Executor
from rangesim.experiments.grid import SweepTask, plan_sweep
from rangesim.experiments.results import (
    TABLE_NAMES,
    build_table,
    scan_path,
    task_path,
    write_json,
    write_table,
    write_task_file,
)
from rangesim.experiments.sweep_file import SweepSpec, check_spec, load_sweep
from rangesim.experiments.tasks import run_sweep_task


@dataclass
class SweepRun:
    """What :func:`run_sweep` did.

    Attributes
    ----------
    out : Path
        The output folder.
    table : pandas.DataFrame
        The results (also in ``out/results.parquet`` and ``.csv``).
    n_tasks, n_run, n_reused : int
        Tasks in the sweep, run now, and found finished from an earlier run.
    seconds : float
        Wall time of this call.
    executor : str
        Where the tasks ran.
    files : list of Path
        Table and plot files written.
    replaced : str or None
        The other sweep (name and file) whose results the folder held before this run, if
        any: its task files stay (a cache: a task of the same parameters is reused), the
        table and the plots follow this sweep.
    """

    out: Path
    table: Any
    n_tasks: int
    n_run: int
    n_reused: int
    seconds: float
    executor: str
    files: list[Path] = field(default_factory=list)
    replaced: str | None = None


def _todo(tasks: list[SweepTask], out: Path, keep_scans: bool) -> list[SweepTask]:
    return [t for t in tasks
            if not task_path(out, t.key).is_file() or (keep_scans and not scan_path(out, t.key).is_file())]


def _describe_error(exc: BaseException) -> str:
    if isinstance(exc, RangesimError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


def run_sweep(sweep: str | Path | SweepSpec, out: str | Path, *, keep_scans: bool = False,
              workers: int | None = None, scheduler: str | None = None, progress: bool | None = None,
              plots: bool = True) -> SweepRun:
    """Run a sweep: every task not finished yet, then the results table and plots.

    Parameters
    ----------
    sweep : str, Path or SweepSpec
        A sweep file (:mod:`rangesim.experiments.sweep_file`) or one already loaded.
    out : str or Path
        Output folder (created); see :mod:`rangesim.experiments.results` for its layout.
    keep_scans : bool
        Also write every scan to ``out/scans/<key>.exr``.
    workers : int, optional
        Local worker processes (default: the cores available); 0 runs in this process.
    scheduler : str, optional
        ``local:N`` (a Dask LocalCluster of N workers) or ``tcp://HOST:PORT`` (a running
        Dask scheduler); default: the local process pool.
    progress : bool, optional
        Progress on stderr (:class:`rangesim.core.progress.Progress`): True shows it (a bar on a
        terminal, log lines elsewhere), False hides it; default: as ``set_progress`` says.
    plots : bool
        Draw the plots (F1 against SNR, F1 against each swept parameter).

    Returns
    -------
    SweepRun

    Raises
    ------
    RangesimError
        A bad sweep file or output folder; tasks that failed (the others are kept: a rerun
        only retries the failed ones).
    """
    start = time.perf_counter()
    if isinstance(sweep, SweepSpec):
        spec = check_spec(sweep)  # built or changed in Python: what load_sweep checks in a file
    elif isinstance(sweep, (str, os.PathLike)):
        spec = load_sweep(sweep)
    else:
        raise RangesimError(f"run_sweep takes a sweep .toml file or a SweepSpec, got {type(sweep).__name__}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RangesimError("output must be a directory", source=out)
    tasks = plan_sweep(spec, keep_scans=keep_scans)
    _check_parts_in_range(tasks, spec.path)
    todo = _todo(tasks, out, keep_scans)
    executor = Executor(workers, scheduler, max_tasks=len(todo))  # checks the options before any file
    failures: list[tuple[SweepTask, BaseException]] = []
    where = executor.describe() if todo else "nowhere (every task was finished)"
    with ExitStack() as stack:
        if todo:
            stack.enter_context(executor)  # a scheduler that cannot be reached: no file written
        replaced = _other_sweep(out / "sweep.json", spec)
        write_json(out / "sweep.json", _provenance(spec, len(tasks)))
        # the table (and the plots, when drawn or of another sweep) are rebuilt from the task files
        # at the end: until then old ones (another plan, tasks that fail now) would not describe
        # this sweep.json
        stale = [out / name for name in TABLE_NAMES]
        if plots or replaced:
            stale += (out / "plots").glob("f1_vs_*.png")  # the sweep's own plots, no other picture
        for path in stale:
            path.unlink(missing_ok=True)
        if todo:
            bar = stack.enter_context(Progress(len(tasks), f"sweep {spec.name}", initial=len(tasks) - len(todo),
                                               enabled=progress))
            for i, result, error in executor.run(run_sweep_task, [t.payload for t in todo]):
                task = todo[i]
                if error is not None:
                    failures.append((task, error))
                else:
                    if result["scan"] is not None:
                        from rangesim.io import save_scan

                        save_scan(result["scan"], scan_path(out, task.key))
                    write_task_file(out, task, result["rows"])  # last: the task counts as done
                bar.update(1)
    if failures:
        task, error = min(failures, key=lambda f: f[0].index)
        shown = ", ".join(f"{k}={v}" for k, v in task.columns.items() if k != "seed")
        raise RangesimError(
            f"{len(failures)} of {len(todo)} tasks failed; first ({shown}): {_describe_error(error)}; "
            f"finished tasks are kept, a rerun (once the cause is fixed) does only the others", source=spec.path)
    table = build_table(tasks, out)
    files = write_table(table, out)
    if plots and len(table):
        from rangesim.viz.sweep_plots import save_sweep_plots

        plot_files = save_sweep_plots(table, spec.swept_keys, out / "plots", title=spec.name,
                                      tolerance_px=spec.tolerance_px)
        files += plot_files
    return SweepRun(out, table, len(tasks), len(todo) - len(failures), len(tasks) - len(todo),
                    time.perf_counter() - start, where, files, replaced)


def _check_parts_in_range(tasks: list[SweepTask], source: Any) -> None:
    """Refuse, before any scan, a pose table whose distances put the part outside the sensor's
    working range in every view (as ``make_dataset`` does): each such task would score an empty
    scan. Checked once per scene, object overrides, pose table and the sensor's camera and
    working range (what the check reads: a grid over noise parameters is one check, not one per
    combination, which took ~10 ms each and kept a 10^4-task sweep silent for minutes); each
    scene loaded once. Object overrides that no task's scene can take (a misspelt parameter:
    every task would fail the same way) are refused here too, with the first one's message;
    a value only some grid points make bad fails just those tasks, named, when they run."""
    from rangesim.experiments.poses import check_distance_in_range, resolve_pose_table
    from rangesim.experiments.scenes import load_task_scene
    from rangesim.sensor import load_sensor

    seen = set()
    scenes: dict[str, Any] = {}  # scene key -> the scene, None where it cannot be built
    errors: list[RangesimError] = []

    def scene_of(p: dict) -> Any:
        key = json.dumps([p["scene_path"], p["objects"]], sort_keys=True, default=str)
        if key not in scenes:
            try:
                scenes[key] = load_task_scene(p["scene_path"], p["objects"])
            except RangesimError as exc:
                scenes[key] = None
                errors.append(exc)
        return scenes[key]

    # one scene that builds is enough to know the overrides' keys are right
    if tasks and not any(scene_of(task.payload) is not None for task in tasks):
        raise RangesimError(f"no task's scene can be built: {errors[0]}", source=source)
    for task in tasks:
        p = task.payload
        if p["pose"] is None:
            continue
        s = p["sensor"]
        optics = {k: s.get(k) for k in ("name", "camera", "range")} if isinstance(s, dict) else s
        key = json.dumps([p["scene_path"], p["objects"], optics, p["pose"]], sort_keys=True, default=str)
        if key in seen:
            continue
        seen.add(key)
        scene = scene_of(p)
        if scene is None:
            continue  # a bad override value fails its own tasks, named, when they run
        try:
            sensor = load_sensor(p["sensor"])
        except RangesimError:
            continue
        check_distance_in_range(resolve_pose_table(p["pose"], scene, sensor), scene, sensor, source=source)


def _other_sweep(provenance: Path, spec: SweepSpec) -> str | None:
    """``name (file)`` of the sweep an output folder's ``sweep.json`` describes when it is
    not ``spec`` (another name or sweep file); None for a new folder or the same sweep."""
    try:
        old = json.loads(provenance.read_text())
    except (OSError, ValueError):
        return None
    # the file as typed then, or resolved (written so since): ../s1.toml and /abs/s1.toml are one sweep
    if not isinstance(old, dict) or (old.get("name") == spec.name
                                     and old.get("sweep") in (str(spec.path), str(Path(spec.path).resolve()))):
        return None
    return f"{old.get('name')!r} ({old.get('sweep')})"


def _provenance(spec: SweepSpec, n_tasks: int) -> dict[str, Any]:
    return {
        "sweep": str(Path(spec.path).resolve()), "name": spec.name, "description": spec.description,
        "rangesim_version": __version__, "tasks": n_tasks,
        "scenes": [{"label": s.label, "path": s.path, "sha1": s.sha1} for s in spec.scenes],
        "sensors": [{"label": s.label, "sensor": s.data} for s in spec.sensors],
        "grid": spec.grid, "set": spec.fixed, "pose": spec.pose, "views": spec.views,
        "repeats": spec.repeats, "seed": spec.seed, "detectors": spec.detectors,
        "tolerance_px": spec.tolerance_px, "crease_deg": spec.crease_deg, "snr_window": spec.snr_window,
    }
