"""Sweep files: which scans to make and how to score them, read from TOML and validated.

A sweep file (paths relative to the file; every key but ``scenes`` optional)::

    name = "snr_sweep"
    scenes = ["green_piece.toml"]          # scene files
    sensors = ["white_scanner"]            # presets or sensor .toml files (default white_scanner)
    views = 3                              # random views per combination (0: the scene's own view)
    repeats = 1                            # noise realisations per view
    seed = 0                               # the sweep seed: poses and noise derive from it
    tolerance_px = 2.0                     # score matching tolerance, pixels
    crease_deg = 20.0                      # ground-truth crease angle, degrees
    snr_window = 3                         # k of the crease SNR's slope estimate
    detectors = ["gradient", "normal"]     # default: every detector, default thresholds
    # or, instead of the list, a table per detector with its keyword thresholds:
    # [detectors.gradient]
    # threshold = 0.3
    # [detectors.normal]

    [set]                                  # fixed overrides for every scan (same keys as [grid])
    "noise.speckle_contrast" = 0

    [pose]                                 # the cap views are drawn from (rangesim.experiments.poses)
    cap_deg = 20
    distance = [320, 380]

    [grid]                                 # every combination of these values is scanned
    "noise.sigma_px" = [0, 0.1, 0.5]
    "pose.elevation_deg" = [40, 60]
    "object.green_piece.rotate_deg" = [[0, 0, 0], [0, 0, 30]]

Keys of ``[grid]`` and ``[set]``: ``pose.<key>`` (a key of the pose table),
``object.<name>.<key>`` (a key of that ``[[object]]`` table of the scene file, e.g.
``translate``, ``rotate_deg``, ``albedo``, ``params.thickness``), anything else a dotted
sensor key (``noise.sigma_px``, ``laser.baseline``, ``camera.width``, ...).
"""
from __future__ import annotations

import dataclasses
import inspect
import itertools
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.constants import MAX_TOLERANCE_PX
from rangesim.core.errors import RangesimError
from rangesim.core.tomlfile import check_keys, read_toml
from rangesim.experiments.poses import POSE_KEYS, check_pose_table
from rangesim.experiments.scenes import scene_digest
from rangesim.scene.scene import object_names

TOP_KEYS = {
    "name", "description", "scenes", "sensors", "views", "repeats", "seed", "tolerance_px",
    "crease_deg", "snr_window", "detectors", "set", "pose", "grid",
}
DEFAULT_SENSOR = "white_scanner"
#: most scans a sweep may plan (a typo such as views = 10000 fails fast)
MAX_TASKS = 1_000_000


@dataclass(frozen=True)
class SceneRef:
    """A scene of the sweep: ``label`` as written in the file, ``path`` resolved, ``sha1`` of
    the file's bytes (part of every task key), ``objects`` the names of its ``[[object]]``s."""

    label: str
    path: str
    sha1: str
    objects: tuple[str, ...]


@dataclass(frozen=True)
class SensorRef:
    """A sensor of the sweep: ``label`` as written, ``data`` its validated dict (``Sensor.to_dict``)."""

    label: str
    data: dict[str, Any]


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep file (see the module docstring for the keys and their meaning)."""

    path: Path
    name: str
    description: str
    scenes: tuple[SceneRef, ...]
    sensors: tuple[SensorRef, ...]
    grid: dict[str, list[Any]]
    fixed: dict[str, Any]
    pose: dict[str, Any]
    views: int
    repeats: int
    seed: int
    detectors: dict[str, dict[str, Any]]
    tolerance_px: float
    crease_deg: float
    snr_window: int
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def swept_keys(self) -> list[str]:
        """Grid keys with more than one value (each gets its own plot)."""
        return [k for k, values in self.grid.items() if len(values) > 1]

    def combinations(self) -> list[dict[str, Any]]:
        """Every combination of the grid values, in file order (last key fastest)."""
        keys = list(self.grid)
        return [dict(zip(keys, values)) for values in itertools.product(*(self.grid[k] for k in keys))]

    @property
    def n_tasks(self) -> int:
        n = len(self.scenes) * len(self.sensors) * max(self.views, 1) * self.repeats
        for values in self.grid.values():
            n *= len(values)
        return n


def key_kind(key: str) -> tuple[str, str]:
    """(``"pose"`` | ``"object"`` | ``"sensor"``, the key without its ``pose.`` prefix)."""
    if key.startswith("pose."):
        return "pose", key[5:]
    if key.startswith("object."):
        return "object", key[7:]
    return "sensor", key


def split_overrides(values: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any], dict[str, dict[str, Any]]]:
    """(sensor changes, pose changes, object changes {name: {key: value}}) of dotted keys."""
    sensor: dict[str, Any] = {}
    pose: dict[str, Any] = {}
    objects: dict[str, dict[str, Any]] = {}
    for key, value in values.items():
        kind, rest = key_kind(key)
        if kind == "pose":
            pose[rest] = value
        elif kind == "object":
            name, _, sub = rest.partition(".")
            objects.setdefault(name, {})[sub] = value
        else:
            sensor[rest] = value
    return sensor, pose, objects


def _int(data: dict, key: str, default: int, source: Path, minimum: int) -> int:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise RangesimError(f"{key} must be an integer >= {minimum}, got {value!r}", source=source)
    return value


def _float(data: dict, key: str, default: float, source: Path, *, positive: bool = False,
           at_most: float = math.inf) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RangesimError(f"{key} must be a number, got {value!r}", source=source)
    if value < 0 or (positive and value == 0):
        raise RangesimError(f"{key} must be {'positive' if positive else '>= 0'}, got {value!r}", source=source)
    if value > at_most:
        raise RangesimError(f"{key} must be at most {at_most:g}, got {value!r}", source=source)
    return float(value)


def _string_list(data: dict, key: str, default: list[str] | None, source: Path) -> list[str]:
    value = data.get(key, default)
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise RangesimError(f"{key} must be a non-empty list of strings, got {value!r}", source=source)
    return value


def _scene_ref(label: str, base: Path, source: Path) -> SceneRef:
    path = (base / label).resolve()
    if path.suffix.lower() != ".toml":
        from rangesim.scene.scene import MESH_SUFFIXES

        if path.suffix.lower() in MESH_SUFFIXES:  # its objects' names and units are what overrides key on
            raise RangesimError(f"scenes: {label!r} is a mesh; a sweep takes scene .toml files: write one holding it "
                                f"([[object]] with mesh = {path.name!r} and the scene's units)", source=source)
        raise RangesimError(f"scenes: {label!r} is not a scene .toml file", source=source)
    if not path.is_file():
        raise RangesimError(f"scenes: no such scene file {label!r} (looked for {path})", source=source)
    try:
        data = read_toml(path)
    except RangesimError as exc:
        raise RangesimError(f"scenes: {exc}", source=source) from exc
    tables = data.get("object", [])
    tables = [tables] if isinstance(tables, dict) else tables
    try:
        names = tuple(object_names([t for t in tables if isinstance(t, dict)], label))
    except RangesimError as exc:  # two objects of one name: overrides could not tell them apart
        raise RangesimError(f"scenes: {exc}", source=source) from exc
    return SceneRef(label, str(path), scene_digest(path), names)


def _sensor_ref(label: str, base: Path, source: Path) -> SensorRef:
    from rangesim.sensor import load_sensor

    target: Any = label
    if label.lower().endswith(".toml") and (base / label).is_file():
        target = (base / label).resolve()
    try:
        sensor = load_sensor(target)
    except RangesimError as exc:
        raise RangesimError(f"sensors: {exc}", source=source) from exc
    return SensorRef(label, sensor.to_dict())


def _detectors(value: Any, source: Path) -> dict[str, dict[str, Any]]:
    from rangesim.edges import DETECTORS

    if value is None:
        return {name: {} for name in DETECTORS}
    if isinstance(value, list):
        if not all(isinstance(v, str) for v in value):
            raise RangesimError("detectors must be a list of names or a table of tables", source=source)
        value = {name: {} for name in value}
    if not isinstance(value, dict) or not value:
        raise RangesimError("detectors must be a non-empty list of names or a table of tables", source=source)
    out = {}
    probe = None
    for name, params in value.items():
        if name not in DETECTORS:
            raise RangesimError(f"detectors: unknown detector {name!r}; known: {', '.join(DETECTORS)}",
                                source=source)
        if not isinstance(params, dict):
            raise RangesimError(f"detectors.{name} must be a table of keyword thresholds", source=source)
        accepted = list(inspect.signature(DETECTORS[name]).parameters)[1:]  # after the scan
        unknown = sorted(set(params) - set(accepted))
        if unknown:
            raise RangesimError(f"detectors.{name}: unknown parameter(s) {', '.join(unknown)}; "
                                f"known: {', '.join(accepted)}", source=source)
        if params:  # the values too, before any scan: the detector on a small tilted plane
            probe = _probe_scan() if probe is None else probe
            try:
                DETECTORS[name](probe, **params)
            except RangesimError as exc:
                raise RangesimError(f"detectors.{name}: {exc}", source=source) from exc
        out[name] = dict(params)
    return out


def _probe_scan():
    """A 16 x 16 px scan of a plane tilted 30 degrees at 400 mm (pinhole, f = 100 px): enough for
    every detector to check its parameters on."""
    from rangesim.core.rangescan import RangeScan

    n, f = 16, 100.0
    j, i = np.meshgrid(np.arange(n) + 0.5 - n / 2, np.arange(n) + 0.5 - n / 2)
    rays = np.stack([j / f, i / f, np.ones_like(j)], axis=-1)
    normal = np.array([0.0, np.sin(np.radians(30)), -np.cos(np.radians(30))])
    t = (normal @ [0.0, 0.0, 400.0]) / (rays @ normal)  # the plane through (0, 0, 400)
    xyz = (rays * t[..., None]).astype(np.float32)
    zeros = np.zeros((n, n))
    return RangeScan(depth=xyz[..., 2], xyz=xyz, valid=np.ones((n, n), bool),
                     normal=np.broadcast_to(normal, (n, n, 3)).astype(np.float32), intensity=zeros, part=zeros,
                     face=zeros, status=zeros, meta={"K": [[f, 0, n / 2], [0, f, n / 2], [0, 0, 1]]})


def _check_override_keys(table: dict[str, Any], where: str, scenes: tuple[SceneRef, ...], source: Path) -> None:
    from rangesim.scene.scene import OBJECT_KEYS

    for key in table:
        kind, rest = key_kind(key)
        if kind == "pose" and rest not in POSE_KEYS:
            raise RangesimError(f"{where} {key}: unknown pose key; known: pose.{', pose.'.join(POSE_KEYS)}",
                                source=source)
        if kind == "object":
            name, _, sub = rest.partition(".")
            top = sub.split(".")[0]
            if not name or not sub:
                raise RangesimError(f"{where} {key}: object keys read object.<name>.<key>", source=source)
            if top not in OBJECT_KEYS - {"name"} or ("." in sub and top not in ("params", "material")):
                raise RangesimError(f"{where} {key}: {sub!r} is not an [[object]] key; known: "
                                    f"{', '.join(sorted(OBJECT_KEYS - {'name'}))}", source=source)
            for scene in scenes:
                if name not in scene.objects:
                    raise RangesimError(f"{where} {key}: scene {scene.label} has no object {name!r} "
                                        f"(it has {', '.join(scene.objects)})", source=source)


def load_sweep(path: str | Path) -> SweepSpec:
    """Read and validate a sweep file.

    Every sensor combination of the grid is built once here and every detector runs once on a
    small plane with its parameters, so a bad key or value of those fails before any scan with
    one line naming the file and the key. Object overrides are checked for their keys here and
    for their values by the scene each task builds (a bad value fails those tasks, named).

    Parameters
    ----------
    path : str or Path
        The sweep ``.toml``.

    Returns
    -------
    SweepSpec

    Raises
    ------
    RangesimError
        A missing or unreadable file, an unknown key, a value of the wrong type or out of
        range, an unknown scene, sensor, detector, detector parameter or object.
    """
    path = Path(path)
    data = read_toml(path)
    check_keys(data, TOP_KEYS, "the sweep", path)
    base = path.resolve().parent
    if "scenes" not in data:
        raise RangesimError("missing required key scenes (a list of scene .toml files)", source=path)
    scenes = tuple(_scene_ref(label, base, path) for label in _string_list(data, "scenes", None, path))
    sensors = tuple(_sensor_ref(label, base, path)
                    for label in _string_list(data, "sensors", [DEFAULT_SENSOR], path))
    views = _int(data, "views", 1, path, 0)
    repeats = _int(data, "repeats", 1, path, 1)
    seed = _int(data, "seed", 0, path, 0)
    window = _int(data, "snr_window", 3, path, 2)
    tolerance = _float(data, "tolerance_px", 2.0, path, at_most=MAX_TOLERANCE_PX)
    crease = _float(data, "crease_deg", 20.0, path, positive=True, at_most=180.0)
    if crease >= 180.0:  # the ground truth's rule: a dihedral angle strictly between 0 and 180
        raise RangesimError(f"crease_deg must be below 180 degrees, got {crease!r}", source=path)
    detectors = _detectors(data.get("detectors"), path)

    grid = data.get("grid", {})
    fixed = data.get("set", {})
    pose = data.get("pose", {})
    for where, table in (("[grid]", grid), ("[set]", fixed), ("[pose]", pose)):
        if not isinstance(table, dict):
            raise RangesimError(f"{where} must be a table", source=path)
    for key, values in grid.items():
        if isinstance(values, dict):
            raise RangesimError(f"[grid] {key}: a table; quote dotted keys (\"noise.sigma_px\" = [...])",
                                source=path)
        if not isinstance(values, list) or not values:
            raise RangesimError(f"[grid] {key}: values must be a non-empty list, got {values!r}", source=path)
    for key, value in fixed.items():
        if isinstance(value, dict):
            raise RangesimError(f"[set] {key}: a table; quote dotted keys (\"noise.sigma_px\" = 0)", source=path)
    both = sorted(set(grid) & set(fixed))
    if both:
        raise RangesimError(f"{', '.join(both)} in both [grid] and [set]", source=path)
    _check_override_keys(grid, "[grid]", scenes, path)
    _check_override_keys(fixed, "[set]", scenes, path)
    try:
        pose = check_pose_table(pose, source=None)
    except RangesimError as exc:
        raise RangesimError(f"[pose] {exc}", source=path) from exc
    spec = SweepSpec(
        path=path, name=str(data.get("name", path.stem)), description=str(data.get("description", "")),
        scenes=scenes, sensors=sensors, grid=dict(grid), fixed=dict(fixed), pose=pose, views=views,
        repeats=repeats, seed=seed, detectors=detectors, tolerance_px=tolerance, crease_deg=crease,
        snr_window=window, raw=data,
    )
    return check_spec(spec)


def check_spec(spec: SweepSpec) -> SweepSpec:
    """The checks of :func:`load_sweep` on a spec's fields, for a SweepSpec built or changed in
    Python (``dataclasses.replace(spec, views=-1)`` ran one view; ``seed=-1`` and
    ``views=2.5`` failed deep in the planner): its counts, seed, tolerances and pose table,
    the number of tasks, and every sensor and pose combination of the grid. Returns ``spec``
    with its pose table in checked form."""
    if not isinstance(spec, SweepSpec):
        raise RangesimError(f"a sweep is a sweep .toml file or a SweepSpec, got {type(spec).__name__}")
    path = spec.path
    # NumPy numbers as the Python numbers they are (np.int64(2) views; JSON takes only the latter)
    fields = {name: (v.item() if isinstance(v, np.generic) else v) for name in ("views", "repeats", "seed",
              "snr_window", "tolerance_px", "crease_deg") for v in (getattr(spec, name),)}
    _int(fields, "views", 1, path, 0)
    _int(fields, "repeats", 1, path, 1)
    _int(fields, "seed", 0, path, 0)
    _int(fields, "snr_window", 3, path, 2)
    _float(fields, "tolerance_px", 2.0, path, at_most=MAX_TOLERANCE_PX)
    if _float(fields, "crease_deg", 20.0, path, positive=True, at_most=180.0) >= 180.0:
        raise RangesimError(f"crease_deg must be below 180 degrees, got {spec.crease_deg!r}", source=path)
    if not isinstance(spec.pose, dict):
        raise RangesimError("[pose] must be a table", source=path)
    try:
        pose = check_pose_table(spec.pose, source=None)
    except RangesimError as exc:
        raise RangesimError(f"[pose] {exc}", source=path) from exc
    changed = {name: v for name, v in fields.items() if type(v) is not type(getattr(spec, name))}
    if pose != spec.pose or changed:
        spec = dataclasses.replace(spec, pose=pose, **changed)
    if spec.n_tasks > MAX_TASKS:
        raise RangesimError(f"the sweep plans {spec.n_tasks:,} scans (at most {MAX_TASKS:,})", source=path)
    if spec.views == 0 and (spec.pose or any(key_kind(k)[0] == "pose" for k in [*spec.grid, *spec.fixed])):
        raise RangesimError("views = 0 scans from the scene's own view: pose keys have no meaning",
                            source=path)
    _check_values(spec)
    return spec


def _check_values(spec: SweepSpec) -> None:
    """Build every sensor and pose table of the grid once (cheap): bad values fail here."""
    sensor_keys = [k for k in spec.grid if key_kind(k)[0] == "sensor"]
    pose_keys = [k for k in spec.grid if key_kind(k)[0] == "pose"]
    from rangesim.sensor.config import UNUSED_BY_MODE, UnusedSensorKeyWarning, sensor_from_dict

    idle_in: dict[str, list[str]] = {}  # swept key -> the sensors (and modes) that do not read it
    read: set[str] = set()  # swept keys some sensor of some combination reads
    for sensor in spec.sensors:
        base = sensor_from_dict(sensor.data, source=sensor.label)
        for values in itertools.product(*(spec.grid[k] for k in sensor_keys)):
            changes = {**split_overrides(spec.fixed)[0], **dict(zip(sensor_keys, values))}
            if not changes:
                continue
            try:
                with warnings.catch_warnings():  # refused below, by name, where a swept key is unused
                    warnings.simplefilter("ignore", UnusedSensorKeyWarning)
                    made = base.with_params(changes)
            except RangesimError as exc:
                shown = ", ".join(f"{k} = {v!r}" for k, v in changes.items())
                raise RangesimError(f"sensor {sensor.label} with {shown}: {_strip_source(exc)}",
                                    source=spec.path) from exc
            for key in sensor_keys:
                if key in UNUSED_BY_MODE.get(made.mode, ()):
                    idle_in.setdefault(key, []).append(f"{sensor.label} ({made.mode} mode)")
                else:
                    read.add(key)
    for key, where in idle_in.items():
        where = ", ".join(dict.fromkeys(where))
        if key not in read:
            raise RangesimError(f"[grid] varies {key}, which sensor {where} does not use: every value would give "
                                "the same scans", source=spec.path)
        warnings.warn(f"{spec.path}: [grid] varies {key}, which {where} does not use: those scans repeat across "
                      "that axis", stacklevel=3)
    fixed_pose = split_overrides(spec.fixed)[1]
    for values in itertools.product(*(spec.grid[k] for k in pose_keys)):
        table = {**spec.pose, **fixed_pose, **{key_kind(k)[1]: v for k, v in zip(pose_keys, values)}}
        try:
            check_pose_table(table)
        except RangesimError as exc:
            raise RangesimError(f"[grid]/[pose]: {exc}", source=spec.path) from exc


def _strip_source(exc: RangesimError) -> str:
    text = str(exc)
    if exc.source and text.startswith(exc.source + ": "):
        return text[len(exc.source) + 2:]
    return text
