"""From a sweep to its tasks: one task per scan (scene x sensor x grid values x view x
repeat), each with a key and seeds derived from its parameters.

* **key**: the first 20 hex digits of the SHA-1 of the task's parameters as canonical JSON
  (sorted keys, no spaces): the scene file's name and content hash, the object overrides,
  the full sensor (every key, after the overrides), the pose table, the view and repeat
  index, the sweep seed, the detectors with their thresholds, the tolerance, the crease
  angle, the SNR window, :data:`TASK_FORMAT` and the code's fingerprint
  (:func:`code_fingerprint`: a resumed run after a code update redoes its tasks). Equal
  parameters and code give equal keys on any machine, in any order; a task's files are ``tasks/<key>.json`` (and ``scans/<key>.exr``).
* **seeds**: a ``numpy.random.SeedSequence`` of the sweep seed and the SHA-1 of the
  parameters that make the thing seeded. The pose seed covers the scene, its object
  overrides, the pose table and the view index, not the sensor: every sensor setting of a
  sweep sees the same views (paired comparisons). The noise seed covers everything the scan
  depends on (scene, overrides, sensor, pose table, view, repeat): of the sensor, the settings
  its mode reads (a grid key only some sensors read repeats the others' scans exactly). Neither depends on the
  detectors, on the order tasks run in or on how many workers run them.
"""
from __future__ import annotations

import functools
import hashlib
import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.experiments.sweep_file import SweepSpec, split_overrides
from rangesim.sensor.config import UNUSED_BY_MODE, UnusedSensorKeyWarning

#: bump when a task's output changes meaning: old task files then no longer match any key
TASK_FORMAT = 1
#: hex digits of a task key (80 bits: collisions are not a concern at any sweep size)
KEY_DIGITS = 20


@functools.lru_cache(maxsize=None)
def code_fingerprint() -> str:
    """SHA-1 (16 hex digits) of the rangesim package's Python sources, file by file in path order.

    Part of every task key (sweeps and datasets): a resumed run after a code update (a detector
    changed, a noise model refitted) must not reuse the rows or views the old code made, which
    ``__version__`` alone does not tell apart. Read once per process (about 200 files, a few ms).
    """
    import rangesim

    root = Path(rangesim.__file__).resolve().parent
    digest = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def canonical_json(obj: Any) -> str:
    """Canonical JSON of plain data: sorted keys, no whitespace, tuples as lists."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True, default=_plain)


def _plain(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON data")


def digest(obj: Any) -> str:
    """SHA-1 hex digest of :func:`canonical_json`."""
    return hashlib.sha1(canonical_json(obj).encode("utf-8")).hexdigest()


def task_key(params: Any) -> str:
    """The key of a task: :data:`KEY_DIGITS` hex digits of :func:`digest`."""
    return digest(params)[:KEY_DIGITS]


def derive_seed(seed: int, params: Any) -> int:
    """A 63-bit seed from a base seed and parameters (``numpy.random.SeedSequence``).

    Parameters
    ----------
    seed : int
        The sweep's (or dataset's) seed, >= 0.
    params : JSON-able
        What the seeded thing depends on.

    Returns
    -------
    int
        In [0, 2**63); the same for the same inputs on every machine.
    """
    h = digest(params)
    words = [int(h[i:i + 8], 16) for i in range(0, 40, 8)]
    state = np.random.SeedSequence([int(seed), *words]).generate_state(2, np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])


@dataclass(frozen=True)
class SweepTask:
    """One scan of a sweep and what to do with it.

    Attributes
    ----------
    index : int
        Position in the plan (the results table's row order).
    key : str
        See the module docstring.
    columns : dict
        The row's parameter columns: ``scene``, ``sensor``, one per grid key, ``view``,
        ``repeat``, ``seed`` (the noise seed).
    payload : dict
        Everything a worker needs (plain data, picklable): see
        :func:`rangesim.experiments.tasks.run_sweep_task`.
    """

    index: int
    key: str
    columns: dict[str, Any]
    payload: dict[str, Any]


def plan_sweep(spec: SweepSpec, keep_scans: bool = False) -> list[SweepTask]:
    """Expand a sweep into its tasks, in a fixed order: scenes, sensors, grid combinations
    (file order, last key fastest), views, repeats."""
    from rangesim.sensor.config import sensor_from_dict

    tasks: list[SweepTask] = []
    fixed_sensor, fixed_pose, fixed_objects = split_overrides(spec.fixed)
    evaluation = {"detectors": spec.detectors, "tolerance_px": spec.tolerance_px,
                  "crease_deg": spec.crease_deg, "snr_window": spec.snr_window}
    combos = spec.combinations()
    sensors = {s.label: sensor_from_dict(s.data, source=s.label) for s in spec.sensors}
    for scene in spec.scenes:
        scene_id = {"file": Path(scene.path).name, "sha1": scene.sha1}
        for sensor_ref in spec.sensors:
            for combo in combos:
                sensor_changes, pose_changes, object_changes = split_overrides(combo)
                changes = {**fixed_sensor, **sensor_changes}
                sensor = _with_changes(sensors[sensor_ref.label], changes)
                sensor_data = sensor.to_dict()
                # the noise seed sees only the settings the sensor reads: a swept key its mode
                # leaves idle repeats its scans exactly, as the planner's warning says
                read = {k: v for k, v in changes.items() if k not in UNUSED_BY_MODE.get(sensor.mode, ())}
                seeded = sensor_data if read == changes else _with_changes(sensors[sensor_ref.label], read).to_dict()
                objects = _merge_objects(fixed_objects, object_changes)
                pose_table = None if spec.views == 0 else {**spec.pose, **fixed_pose, **pose_changes}
                for view in range(max(spec.views, 1)):
                    pose_id = {"scene": scene_id, "objects": objects, "pose": pose_table, "view": view}
                    pose_seed = derive_seed(spec.seed, pose_id)
                    for repeat in range(spec.repeats):
                        scan_id = {**pose_id, "sensor": sensor_data, "repeat": repeat}
                        noise_seed = derive_seed(spec.seed, {**scan_id, "sensor": seeded})
                        key = task_key({"format": TASK_FORMAT, "code": code_fingerprint(), "seed": spec.seed,
                                        "scan": scan_id, "evaluation": evaluation})
                        columns = {"scene": scene.label, "sensor": sensor_ref.label, **combo,
                                   "view": view, "repeat": repeat, "seed": noise_seed}
                        payload = {
                            "key": key, "scene_path": scene.path, "objects": objects, "sensor": sensor_data,
                            "pose": pose_table, "pose_seed": pose_seed, "noise_seed": noise_seed,
                            "keep_scan": bool(keep_scans), "columns": columns, **evaluation,
                        }
                        tasks.append(SweepTask(len(tasks), key, columns, payload))
    _refuse_repeated_tasks(tasks, spec)
    return tasks


def _with_changes(base: Any, changes: dict[str, Any]) -> Any:
    """``base.with_params(changes)`` (``base`` itself without changes), quietly: a swept mode
    leaves the other mode's keys idle, which is no news in a plan."""
    if not changes:
        return base
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedSensorKeyWarning)
        return base.with_params(changes)


def _refuse_repeated_tasks(tasks: list[SweepTask], spec: SweepSpec) -> None:
    """Two grid entries that make the same scan (``0`` and ``0.0``, a preset and its own file, one
    scene by two paths, a value listed twice) would share one task file but not one row: refuse."""
    first: dict[str, SweepTask] = {}
    for task in tasks:
        other = first.setdefault(task.key, task)
        if other is not task:
            def shown(t):
                return ", ".join(f"{k}={v}" for k, v in t.columns.items() if k != "seed")
            raise RangesimError(f"two entries of the sweep make the same scan: ({shown(other)}) and ({shown(task)}); "
                                "list each value, sensor and scene once", source=spec.path)


def _merge_objects(a: dict[str, dict[str, Any]], b: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    out = {name: dict(values) for name, values in a.items()}
    for name, values in b.items():
        out.setdefault(name, {}).update(values)
    return out
