"""Synthetic datasets: many views of a scene from random poses, with ground truth per view.

Layout of a dataset folder (``stem`` = ``<index:06d>_<key[:10]>``, the key derived from the
view's parameters as for sweep tasks)::

    manifest.json                 what a loader reads (see below)
    views/<stem>.exr              the scan (RangeScan; .npz with format="npz"): measured
                                  depth / xyz / valid / intensity / status, and the noise-free
                                  truth xyz_true, normal, part (object), face (triangle)
    views/<stem>_truth.npz        edges (H, W) uint8 EdgeLabel (0 none, 1 jump, 2 convex,
                                  3 concave; exact, from the geometry, not restricted to
                                  valid pixels), subpart (H, W) int32 (index into the
                                  manifest's subpart_names, -1 none), depth_true (H, W)
                                  float32 mm (NaN where nothing is hit)
    views/<stem>.json             the view's record (written last: the view is done)

``manifest.json``: ``scene`` (file, sha1, objects, subpart_names), ``sensor`` (every key),
``K`` (3x3), ``width``, ``height``, ``seed``, ``cap`` (the resolved pose cap: target, axis,
cap_deg, distance [min, max]), ``crease_deg``, ``edge_labels``, ``status_codes``, and
``views``: per view ``index``, ``key``, ``scan``, ``truth`` (paths relative to the folder),
``pose`` (4x4 camera-to-world), ``seed`` (noise), ``pose_seed``, ``distance_mm``,
``polar_deg`` (from the cap axis), ``elevation_deg``, ``azimuth_deg``, ``valid_fraction``
and ``features`` (the scene's analytic circles and segments projected into the view:
ellipses with centre, axes, angle (radians, from +x towards +y), visible fraction; segments with end points, visible
fraction).

Views are resumable and deterministic like sweep tasks: a rerun skips views whose record
exists, and view ``i`` has the same pose and noise whatever the worker count.
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.errors import RangesimError
from rangesim.core.progress import Progress
from rangesim.core.version import __version__
from rangesim.experiments.executors import Executor
from rangesim.experiments.grid import code_fingerprint, derive_seed, task_key
from rangesim.experiments.poses import (
    DEFAULT_CAP_DEG,
    check_distance_in_range,
    check_pose_table,
    resolve_pose_table,
    sample_view,
)
from rangesim.experiments.results import write_json
from rangesim.io.atomic import atomic_path

#: bump when the files of a view change meaning
DATASET_FORMAT = 1
SCAN_FORMATS = ("exr", "npz")
VIEWS_DIR = "views"
MANIFEST = "manifest.json"
#: most views one dataset may have
MAX_VIEWS = 10_000_000


@dataclass
class DatasetRun:
    """What :func:`make_dataset` did: the folder, its manifest, views run now and reused,
    wall time and where the views ran."""

    out: Path
    manifest: Path
    n_views: int
    n_run: int
    n_reused: int
    seconds: float
    executor: str
    records: list[dict[str, Any]] = field(default_factory=list, repr=False)
    #: (view index, why it is empty) of the views rendered now with no (or almost no) valid pixel
    empty: list[tuple[int, str]] = field(default_factory=list)
    #: views of another plan (scene, sensor, seed, views, format) the folder held, now removed
    replaced: int = 0


def _json_features(features: dict[str, list]) -> dict[str, list[dict[str, Any]]]:
    out = {}
    for kind, items in features.items():
        rows = []
        for item in items:
            d = dataclasses.asdict(item)
            rows.append({k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else
                             (v.item() if isinstance(v, np.generic) else v)) for k, v in d.items()})
        out["ellipses" if kind == "circles" else kind] = rows
    return out


def run_dataset_view(payload: dict[str, Any]) -> dict[str, Any]:
    """Make one view of a dataset (in a worker): pose, scan, ground truth, features.

    Parameters
    ----------
    payload : dict
        ``index``, ``key``, ``scene_path``, ``sensor`` (dict), ``pose`` (a pose table),
        ``pose_seed``, ``noise_seed``, ``crease_deg``.

    Returns
    -------
    dict
        ``scan`` (RangeScan), ``truth`` ({edges, subpart, depth_true} arrays) and
        ``record`` (the manifest entry without file names).
    """
    from rangesim.evaluate.ground_truth import ground_truth_edges, ground_truth_features
    from rangesim.experiments.scenes import load_task_scene
    from rangesim.sensor import load_sensor
    from rangesim.sensor import scan as make_scan

    scene = load_task_scene(payload["scene_path"])
    sensor = load_sensor(payload["sensor"])
    resolved = resolve_pose_table(payload["pose"], scene, sensor)
    view = sample_view(resolved, np.random.default_rng(payload["pose_seed"]))
    import warnings

    from rangesim.sensor._scan import EmptyScanWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", EmptyScanWarning)
        scan = make_scan(scene, sensor, pose=view.pose, seed=payload["noise_seed"])
    empty = None
    for w in caught:  # an empty view is reported once, by make_dataset, not as a raw Python warning
        if issubclass(w.category, EmptyScanWarning):
            empty = " ".join(str(w.message).split())
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    edges = ground_truth_edges(scan, scene, crease_deg=payload["crease_deg"])
    truth = {
        "edges": edges.astype(np.uint8),
        "subpart": scene.subpart_image(scan.part, scan.face).astype(np.int32),
        "depth_true": scan.xyz_true[..., 2].astype(np.float32),
    }
    features = _json_features(ground_truth_features(scan, scene))
    record = {
        "index": payload["index"], "key": payload["key"], "pose": view.pose.tolist(),
        "seed": payload["noise_seed"], "pose_seed": payload["pose_seed"],
        "distance_mm": view.distance_mm, "polar_deg": view.polar_deg,
        "elevation_deg": view.elevation_deg, "azimuth_deg": view.azimuth_deg,
        "valid_fraction": float(np.count_nonzero(scan.valid)) / scan.valid.size,
        "features": features,
    }
    return {"scan": scan, "truth": truth, "record": record, "empty": empty}


def _stem(index: int, key: str) -> str:
    return f"{index:06d}_{key[:10]}"


def make_dataset(scene: str | Path, sensor: Any = "white_scanner", views: int = 500, out: str | Path = "data", *,
                 fmt: str = "exr", seed: int = 0, cap_deg: float = DEFAULT_CAP_DEG,
                 distance: float | tuple[float, float] | None = None, axis: Any = None, target: Any = None,
                 sensor_changes: dict[str, Any] | None = None, crease_deg: float = 20.0,
                 workers: int | None = None, scheduler: str | None = None,
                 progress: bool | None = None) -> DatasetRun:
    """Render ``views`` views of a scene from random poses on a spherical cap, with ground truth.

    Parameters
    ----------
    scene : str or Path
        Scene ``.toml`` or mesh file (the first object is the part the cap is centred on).
    sensor : str, Path, dict or Sensor
        Anything :func:`rangesim.load_sensor` accepts.
    views : int
        Number of views (>= 1).
    out : str or Path
        Output folder (see the module docstring for its layout).
    fmt : {"exr", "npz"}
        Scan file format.
    seed : int
        Dataset seed; view poses and noise derive from it and the view's parameters.
    cap_deg : float
        Half-angle of the cap of view directions, degrees (uniform in solid angle).
    distance : float or (min, max), optional
        Camera-to-target distance, mm; default from the sensor's working range.
    axis, target : (3,) array_like, optional
        Cap axis (towards the camera) and target point, world mm; defaults as in
        :mod:`rangesim.experiments.poses`.
    sensor_changes : dict, optional
        Dotted sensor keys to change (``{"camera.width": 128}``).
    crease_deg : float
        Ground-truth crease angle, degrees.
    workers, scheduler, progress
        As for :func:`rangesim.experiments.run_sweep`.

    Returns
    -------
    DatasetRun
    """
    from rangesim.experiments.scenes import load_task_scene, scene_digest
    from rangesim.sensor import load_sensor

    start = time.perf_counter()
    if fmt not in SCAN_FORMATS:
        raise RangesimError(f"format must be one of {', '.join(SCAN_FORMATS)}, got {fmt!r}")
    if isinstance(views, bool) or not isinstance(views, int) or not 1 <= views <= MAX_VIEWS:
        raise RangesimError(f"views must be an integer in 1..{MAX_VIEWS:,}, got {views!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise RangesimError(f"seed must be a non-negative integer, got {seed!r}")
    # the ground truth's own check, before any view is rendered
    P.number(crease_deg, "crease_deg", 0, 180, lo_open=True, hi_open=True, what="angle", unit="degrees")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RangesimError("output must be a directory", source=out)
    scene_path = Path(scene)
    if not scene_path.is_file():
        raise RangesimError("no such scene or mesh file", source=scene_path)
    sensor_obj = load_sensor(sensor)
    if sensor_changes:
        sensor_obj = sensor_obj.with_params(sensor_changes)
    table: dict[str, Any] = {"cap_deg": cap_deg}
    if distance is not None:
        table["distance"] = list(distance) if isinstance(distance, (list, tuple)) else distance
    if axis is not None:
        table["axis"] = list(np.asarray(axis, dtype=float))
    if target is not None:
        table["target"] = list(np.asarray(target, dtype=float))
    pose_table = check_pose_table(table, source="dataset")
    scene_obj = load_task_scene(scene_path)
    cap = resolve_pose_table(pose_table, scene_obj, sensor_obj)
    check_distance_in_range(cap, scene_obj, sensor_obj, source="dataset")

    sensor_data = sensor_obj.to_dict()
    scene_id = {"file": scene_path.name, "sha1": scene_digest(scene_path)}
    payloads = []
    for i in range(views):
        pose_id = {"scene": scene_id, "pose": pose_table, "view": i}
        pose_seed = derive_seed(seed, pose_id)
        noise_seed = derive_seed(seed, {**pose_id, "sensor": sensor_data})
        key = task_key({"format": DATASET_FORMAT, "code": code_fingerprint(), "seed": seed, **pose_id, "sensor": sensor_data,
                        "crease_deg": crease_deg, "scan_format": fmt})
        payloads.append({"index": i, "key": key, "scene_path": str(scene_path.resolve()), "sensor": sensor_data,
                         "pose": pose_table, "pose_seed": pose_seed, "noise_seed": noise_seed,
                         "crease_deg": crease_deg})
    views_dir = out / VIEWS_DIR
    # a view is done when its record and both files it names are there (the record is written last)
    todo = [p for p in payloads if not all((views_dir / f"{_stem(p['index'], p['key'])}{end}").is_file()
                                           for end in (".json", f".{fmt}", "_truth.npz"))]
    failures: list[tuple[dict, BaseException]] = []
    empty: list[tuple[int, str]] = []
    executor = Executor(workers, scheduler, max_tasks=len(todo))
    where = executor.describe() if todo else "nowhere (every view was finished)"
    if todo:
        # the folder is made (and must take files) before any view is rendered, not after the first
        views_dir.mkdir(parents=True, exist_ok=True)
        if not os.access(views_dir, os.W_OK):
            raise RangesimError("cannot write here (permission denied)", source=views_dir)
        with executor, Progress(views, "dataset", unit="view", initial=views - len(todo), enabled=progress) as bar:
            for i, result, error in executor.run(run_dataset_view, todo):
                if error is not None:
                    failures.append((todo[i], error))
                else:
                    _write_view(views_dir, todo[i], result, fmt)
                    if result.get("empty"):
                        empty.append((todo[i]["index"], result["empty"]))
                bar.update(1)
    if failures:
        payload, error = min(failures, key=lambda f: f[0]["index"])
        text = str(error) if isinstance(error, RangesimError) else f"{type(error).__name__}: {error}"
        raise RangesimError(f"{len(failures)} of {len(todo)} views failed; first (view {payload['index']}): "
                            f"{text}; finished views are kept, a rerun (once the cause is fixed) does only the others", source=out)
    records = []
    for p in payloads:
        path = views_dir / f"{_stem(p['index'], p['key'])}.json"
        try:
            records.append(json.loads(path.read_text(encoding="utf-8")))
        except (OSError, ValueError) as exc:
            raise RangesimError(f"unreadable view record ({exc}); delete it and rerun", source=path) from exc
    from rangesim.core.constants import EDGE_LABEL_NAMES, STATUS_NAMES

    manifest = {
        "format": "rangesim-dataset", "format_version": DATASET_FORMAT, "rangesim_version": __version__,
        "scene": {"file": str(scene_path), **scene_id, "objects": [o.name for o in scene_obj.objects],
                  "subpart_names": scene_obj.subpart_names},
        "sensor": sensor_data, "K": sensor_obj.K.tolist(), "width": sensor_obj.width, "height": sensor_obj.height,
        "seed": seed, "cap": cap, "crease_deg": crease_deg, "scan_format": fmt,
        "edge_labels": {str(int(k)): v for k, v in EDGE_LABEL_NAMES.items()},
        "status_codes": {str(int(k)): v for k, v in STATUS_NAMES.items()},
        "views": records,
    }
    manifest_path = write_json(out / MANIFEST, manifest)
    replaced = _remove_stale_views(views_dir, [_stem(p["index"], p["key"]) for p in payloads], fmt)
    return DatasetRun(out, manifest_path, views, len(todo), views - len(todo), time.perf_counter() - start,
                      where, records, sorted(empty), replaced)


#: the files a dataset writes in its views folder (:func:`_stem`: index, then the key's first
#: 10 hex digits): only these are ever removed from a reused folder
_VIEW_FILE = re.compile(r"\d{6}_[0-9a-f]{10}(_truth\.npz|\.exr|\.npz|\.json)")


def _remove_stale_views(views_dir: Path, stems: list[str], fmt: str) -> int:
    """Delete view files of an earlier plan (other views, counts or formats) left in a reused
    folder, and no other file; the number of views (their records) removed."""
    keep = {name for stem in stems for name in (f"{stem}.{fmt}", f"{stem}_truth.npz", f"{stem}.json")}
    removed = 0
    for path in views_dir.glob("*"):
        if path.is_file() and path.name not in keep and _VIEW_FILE.fullmatch(path.name):
            removed += path.suffix == ".json"
            path.unlink(missing_ok=True)
    return removed


def _write_view(views_dir: Path, payload: dict[str, Any], result: dict[str, Any], fmt: str) -> None:
    """The scan, the truth arrays, then the record (each atomically; the record last)."""
    from rangesim.io import save_scan

    stem = _stem(payload["index"], payload["key"])
    scan_file = views_dir / f"{stem}.{fmt}"
    truth_file = views_dir / f"{stem}_truth.npz"
    save_scan(result["scan"], scan_file)
    with atomic_path(truth_file) as tmp:
        np.savez_compressed(tmp, **result["truth"])
    record = {**result["record"], "scan": f"{VIEWS_DIR}/{scan_file.name}", "truth": f"{VIEWS_DIR}/{truth_file.name}"}
    write_json(views_dir / f"{stem}.json", record)
