"""One sweep task, run in a worker: scan -> ground truth -> SNR -> detectors -> rows.

Pure computation: the function reads the scene file and returns plain data (and the scan
when it is to be kept); the driver writes the files.
"""
from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

#: result columns that are run times (seconds): differ between runs, excluded from comparisons
TIMING_COLUMNS = ("scan_s", "truth_s", "detector_s")
#: per-label score columns: <label>_<score>
LABEL_SCORES = ("precision", "recall", "f1", "n_gt")


def task_pose(payload: dict[str, Any], scene, sensor) -> tuple[np.ndarray, dict[str, float]]:
    """The camera pose of a task and its description (distance, angles).

    ``payload["pose"]`` None: the scene's own view (:func:`rangesim.default_pose`); else a
    pose table, resolved against the scene and sensor and sampled with the task's pose seed.
    """
    from rangesim.experiments.poses import resolve_pose_table, sample_view
    from rangesim.sensor import default_pose

    if payload["pose"] is None:
        pose = default_pose(scene, sensor)
        centre = scene.objects[0].mesh.bounds.mean(axis=0)
        d = pose[:3, 3] - centre
        dist = float(np.linalg.norm(d))
        info = {"pose_distance_mm": dist, "pose_polar_deg": 0.0,
                "pose_elevation_deg": math.degrees(math.asin(float(np.clip(d[2] / dist, -1, 1)))),
                "pose_azimuth_deg": math.degrees(math.atan2(d[1], d[0]))}
        return pose, info
    resolved = resolve_pose_table(payload["pose"], scene, sensor)
    view = sample_view(resolved, np.random.default_rng(payload["pose_seed"]))
    return view.pose, {"pose_distance_mm": view.distance_mm, "pose_polar_deg": view.polar_deg,
                       "pose_elevation_deg": view.elevation_deg, "pose_azimuth_deg": view.azimuth_deg}


def _detector_params(payload: dict[str, Any]) -> dict[str, dict[str, Any]]:
    from rangesim.experiments.executors import single_threaded

    params = {name: dict(p) for name, p in payload["detectors"].items()}
    if single_threaded() and "line_fit" in params:
        params["line_fit"].setdefault("workers", 1)  # its k-d tree queries: one core per worker
    return params


def run_sweep_task(payload: dict[str, Any]) -> dict[str, Any]:
    """Run one sweep task.

    Parameters
    ----------
    payload : dict
        ``key``; ``scene_path`` and ``objects`` (object overrides); ``sensor`` (a sensor
        dict); ``pose`` (pose table, or None for the scene's view), ``pose_seed``,
        ``noise_seed``; ``detectors`` ({name: thresholds}), ``tolerance_px``,
        ``crease_deg``, ``snr_window``; ``keep_scan``; ``columns`` (copied into each row).

    Returns
    -------
    dict
        ``key``; ``rows``: one dict per detector with the parameter columns, the pose
        description, ``valid_fraction``, the SNR columns (:class:`EdgeSNR.as_row`), the
        scores (``precision``, ``recall``, ``f1``, ``fom``, ``n_pred``, ``n_gt``,
        ``matched`` and ``<jump|convex|concave>_<precision|recall|f1|n_gt>``) and the run
        times ``scan_s``, ``truth_s``, ``detector_s`` (detection without scoring);
        ``scan``: the RangeScan if ``keep_scan``, else None.
    """
    from rangesim.evaluate._edge_scores import undefined_as_nan
    from rangesim.evaluate.runs import run_detectors, scan_truth
    from rangesim.experiments.scenes import load_task_scene
    from rangesim.experiments.snr import edge_snr
    from rangesim.sensor import load_sensor
    from rangesim.sensor import scan as make_scan

    scene = load_task_scene(payload["scene_path"], payload["objects"])
    with warnings.catch_warnings():  # said (or refused) when the sweep was planned
        from rangesim.sensor.config import UnusedSensorKeyWarning

        warnings.simplefilter("ignore", UnusedSensorKeyWarning)
        sensor = load_sensor(payload["sensor"])
    pose, pose_info = task_pose(payload, scene, sensor)
    t0 = time.perf_counter()
    scan = make_scan(scene, sensor, pose=pose, seed=payload["noise_seed"])
    t1 = time.perf_counter()
    truth = scan_truth(scan, scene, crease_deg=payload["crease_deg"])
    t2 = time.perf_counter()
    snr = edge_snr(scan, truth.labels, window=payload["snr_window"])
    results = run_detectors(scan, list(payload["detectors"]), truth, tolerance_px=payload["tolerance_px"],
                            params=_detector_params(payload))
    common = {**payload["columns"], **pose_info,
              "valid_fraction": float(np.count_nonzero(scan.valid)) / scan.valid.size, **snr.as_row()}
    rows = []
    for method, r in results.items():
        s = r["scores"]
        row = {**common, "detector": method}
        for name in ("precision", "recall", "f1", "fom", "n_pred", "n_gt", "matched"):
            row[name] = s[name]
        undefined_as_nan(row, "", s["n_pred"], s["n_gt"], ("fom",))
        for label, ls in s.get("per_label", {}).items():
            for name in LABEL_SCORES:
                row[f"{label}_{name}"] = ls[name]
            undefined_as_nan(row, f"{label}_", ls.get("n_pred", 1), ls["n_gt"])
        row.update(scan_s=t1 - t0, truth_s=t2 - t1, detector_s=r["seconds"])
        rows.append(_plain_row(row))
    return {"key": payload["key"], "rows": rows, "scan": scan if payload.get("keep_scan") else None}


def _plain_row(row: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in row.items():
        if isinstance(v, np.integer):
            v = int(v)
        elif isinstance(v, np.floating):
            v = float(v)
        out[k] = v
    return out
