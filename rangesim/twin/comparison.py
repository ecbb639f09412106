"""Metrics comparing a recorded scan with its simulated twin.

All metrics are computed on the common grid (same H x W, same frame):

* ``iou``: valid-mask IoU between recording and twin;
* ``hole_recall``: of the recorded holes (invalid cells inside the object's silhouette, the
  cells whose sample line hits the mesh), the fraction the twin leaves invalid too;
* ``residuals``: recorded and twin points against the twin's noise-free hits on the mesh,
  signed distance along the range axis (mm): median, std, robust std, 95th percentile of
  |distance|, count;
* ``noise_std_ratio``: robust std of the twin's residuals over the recording's;
* ``iou_no_physics``: the IoU of a twin without shadows, dropouts or grazing limit (valid
  wherever the mesh is hit), the baseline the physics must beat;
* ``realism``: :func:`rangesim.twin.realism.realism_stats` of recording and twin (robust
  std per incidence bin, neighbour correlation along rows and columns, 99th percentile
  |residual|, share more than 0.5 mm off) of recording and twin on the cells both
  measured, their ratios, and the dropout share per incidence bin of both (incidence: the
  hit's normal against the range axis z);
* ``edges``: per detector of :data:`rangesim.edges.DETECTORS`, precision / recall / F1 of the
  twin's edge map against the recording's (tolerance 2 px).
"""
from __future__ import annotations

import warnings
from typing import Any, Iterable

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.progress import Progress
from rangesim.core.rangescan import RangeScan
from rangesim.twin.calibration import calibrate, check_overlap, mask_iou, range_residuals
from rangesim.twin.realism import dropout_by_bin, incidence_deg, realism_stats, residual_grid, robust_std
from rangesim.twin.stage import TwinStage, twin

__all__ = ["compare", "compare_scans", "residual_stats", "edge_agreement"]

#: the range axis of a twin's grid (the incidence of a cell is its normal against it)
RANGE_AXIS = np.array([0.0, 0.0, 1.0])
#: matching tolerance (pixels) of the edge-map agreement
EDGE_TOLERANCE_PX = 2.0


def residual_stats(residuals: np.ndarray) -> dict[str, float]:
    """median, std, robust_std, p95_abs (mm) and count of signed residuals."""
    r = np.asarray(residuals, dtype=np.float64)
    r = r[np.isfinite(r)]
    if r.size == 0:
        nan = float("nan")
        return {"median": nan, "std": nan, "robust_std": nan, "p95_abs": nan, "count": 0}
    return {
        "median": float(np.median(r)), "std": float(np.std(r)), "robust_std": robust_std(r),
        "p95_abs": float(np.percentile(np.abs(r), 95)), "count": int(r.size),
    }


def check_detector_names(detectors: Iterable[str] | None) -> list[str]:
    """The detector names asked for (all when None), refused in one line when one is unknown."""
    from rangesim.edges import DETECTORS

    if detectors is None:
        return list(DETECTORS)
    names = [detectors] if isinstance(detectors, str) else list(detectors)
    unknown = [n for n in names if n not in DETECTORS]
    if unknown:
        raise RangesimError(f"unknown detector(s) {', '.join(map(repr, unknown))}; known: {', '.join(DETECTORS)}")
    return names


def edge_agreement(recorded: RangeScan, twin_scan: RangeScan, detectors: Iterable[str] | None = None,
                   tolerance_px: float = EDGE_TOLERANCE_PX, edge_maps: dict | None = None) -> dict[str, dict]:
    """Per detector: scores of the twin's edge map against the recording's.

    ``edge_maps``, if given, receives ``{name: (recorded_map, twin_map)}``.
    """
    from rangesim.edges import DETECTORS
    from rangesim.evaluate import edge_scores

    out = {}
    for name in check_detector_names(detectors):
        # the twin shares the recording's grid: a detector's note on it (pcl_organized on a
        # scanner-frame grid) is said once, not once per scan
        with warnings.catch_warnings(record=True) as notes:
            warnings.simplefilter("always")
            rec_map = DETECTORS[name](recorded)
            twin_map = DETECTORS[name](twin_scan)
        for text, category in dict.fromkeys((str(n.message), n.category) for n in notes):
            warnings.warn(text, category, stacklevel=2)
        pred, gt = np.asarray(twin_map.mask, bool), np.asarray(rec_map.mask, bool)
        s = edge_scores(pred, gt, tolerance_px)
        out[name] = {
            "f1": float(s["f1"]), "precision": float(s["precision"]), "recall": float(s["recall"]),
            "recorded_edges": int(np.count_nonzero(rec_map.mask)), "twin_edges": int(np.count_nonzero(twin_map.mask)),
        }
        if edge_maps is not None:
            edge_maps[name] = (rec_map, twin_map)
    return out


def realism_comparison(recorded: RangeScan, twin_scan: RangeScan) -> dict[str, Any]:
    """Realism statistics of recording and twin against the twin's noise-free hits, and their ratios."""
    truth = twin_scan.xyz_true
    surface = np.isfinite(truth).all(axis=2)
    incidence = incidence_deg(twin_scan.normal, RANGE_AXIS)
    # like with like: the noise of both on the cells both measured (the masks' disagreement is the IoU's)
    common = recorded.valid & twin_scan.valid
    stats = {name: realism_stats(np.where(common, residual_grid(scan, truth), np.nan), incidence)
             for name, scan in (("recorded", recorded), ("twin", twin_scan))}
    rec, tw = stats["recorded"], stats["twin"]
    ratio = lambda a, b: float(a / b) if b and np.isfinite(a) and np.isfinite(b) else float("nan")  # noqa: E731
    return {
        **stats,
        "std_ratio_by_incidence": {k: ratio(tw["by_incidence"][k]["robust_std"], v["robust_std"])
                                   for k, v in rec["by_incidence"].items()},
        "correlation_difference": {k: float(tw["neighbour_correlation"][k] - v)
                                   for k, v in rec["neighbour_correlation"].items()},
        "p99_ratio": ratio(tw["p99_abs"], rec["p99_abs"]),
        "dropout_by_incidence": {"recorded": dropout_by_bin(recorded.valid, surface, incidence),
                                 "twin": dropout_by_bin(twin_scan.valid, surface, incidence)},
    }


def compare_scans(recorded: RangeScan, twin_scan: RangeScan, *, detectors: Iterable[str] | None = None,
                  edge_maps: dict | None = None) -> dict[str, Any]:
    """Metrics of a recorded scan against its twin (the twin must carry ``xyz_true``)."""
    if recorded.shape != twin_scan.shape:
        raise RangesimError(f"grids differ: recorded {recorded.shape}, twin {twin_scan.shape}")
    if twin_scan.xyz_true is None:
        raise RangesimError("the twin has no xyz_true (noise-free hits)")
    truth = twin_scan.xyz_true
    silhouette = np.isfinite(truth).all(axis=2)
    holes = silhouette & ~recorded.valid
    n_holes = int(np.count_nonzero(holes))
    rec_res = residual_stats(range_residuals(recorded, truth))
    twin_res = residual_stats(range_residuals(twin_scan, truth))
    ratio = (twin_res["robust_std"] / rec_res["robust_std"]
             if rec_res["robust_std"] and np.isfinite(rec_res["robust_std"]) else float("nan"))
    return {
        "iou": mask_iou(recorded.valid, twin_scan.valid),
        "iou_no_physics": mask_iou(recorded.valid, silhouette),
        "realism": realism_comparison(recorded, twin_scan),
        "hole_recall": float(np.count_nonzero(holes & ~twin_scan.valid) / n_holes) if n_holes else 1.0,
        "recorded_holes": n_holes,
        "valid": {"recorded": int(recorded.valid.sum()), "twin": int(twin_scan.valid.sum()),
                  "both": int(np.count_nonzero(recorded.valid & twin_scan.valid))},
        "residuals": {"recorded": rec_res, "twin": twin_res},
        "noise_std_ratio": float(ratio),
        "edges": edge_agreement(recorded, twin_scan, detectors, edge_maps=edge_maps),
        "edge_tolerance_px": EDGE_TOLERANCE_PX,
    }


def compare(recorded: RangeScan, mesh: Any, sensor: Any = None, *, params: dict[str, float] | None = None,
            fit: Iterable[str] | str | None = "auto", seed: int = 0,
            detectors: Iterable[str] | None = None, return_scans: bool = False, stage: TwinStage | None = None):
    """Twin the recording (calibrating the parameters in ``fit`` first) and compare.

    Parameters
    ----------
    recorded : RangeScan
    mesh : trimesh.Trimesh or path, world frame
    sensor : str or Sensor, optional
    params : dict, optional
        Fixed twin parameters (used as given; not refitted unless named in ``fit``).
    fit : iterable of str, "auto" or None
        Parameters to calibrate on this view (None or empty: none). ``"auto"``: none when the
        sensor carries a calibration (a ``[twin]`` table with ``theta_deg``, as
        ``rangesim calibrate`` writes), else the legacy single-view fit of ``theta_deg``,
        ``alpha_deg`` and ``sigma_mm``.
    seed : int
        Noise seed of the twin.
    detectors : iterable of str, optional
        Edge detectors to compare (default all).
    return_scans : bool
        Also return the twin scan and the edge maps: ``(metrics, twin, edge_maps)``.
    stage : TwinStage, optional
        A prepared stage of this recording (reuses the ray casts).

    Returns
    -------
    dict
        :func:`compare_scans` metrics plus ``params`` (the twin's parameters) and
        ``calibration`` (the fit's IoU and fitted names, when fitted).
    """
    check_detector_names(detectors)  # before the stage's ray casts and the calibration
    bar = Progress(4, "compare", unit="step")  # stage, calibration, twin scan, metrics
    with bar:
        if stage is None:
            stage = TwinStage(recorded, mesh, sensor)
        bar.update()
        values = stage.params(**(params or {}))
        calibration = None
        if isinstance(fit, str) and fit == "auto":
            calibrated = stage.sensor is not None and stage.sensor.params.get("twin", {}).get("theta_deg") is not None
            fit = None if calibrated else ("theta_deg", "alpha_deg", "sigma_mm")
        if fit:
            result = calibrate(recorded, mesh, sensor, params=fit, initial=params, stage=stage)
            values = {k: result[k] for k in ("theta_deg", "alpha_deg", "sigma_mm", "min_cos")}
            calibration = {"iou": result["iou"], "fitted": result["fitted"],
                           "recorded_noise_mm": result["recorded_noise_mm"]}
        bar.update()
        twin_scan = twin(recorded, mesh, sensor, seed=seed, stage=stage, **values)
        # (without a fit nothing else checks it: a mesh 1 km off once gave IoU 0 and "hole recall 1")
        silhouette = np.isfinite(twin_scan.xyz_true).all(axis=2)
        check_overlap(mask_iou(recorded.valid, silhouette), "the mesh's silhouette's IoU with the recorded pixels")
        bar.update()
        edge_maps: dict = {}
        metrics = compare_scans(recorded, twin_scan, detectors=detectors, edge_maps=edge_maps)
        bar.update()
    metrics["params"] = {**{k: None if v is None else float(v) for k, v in values.items()}, "side": int(stage.side),
                         "seed": int(seed), "noise": twin_scan.meta["twin"]["noise"]}
    if calibration is not None:
        metrics["calibration"] = calibration
    if return_scans:
        return metrics, twin_scan, edge_maps
    return metrics
