"""Fitting the twin's sensor geometry and noise to a recording.

Geometry (camera angle theta, laser angle alpha, grazing threshold min_cos): maximise the
IoU of the valid masks of twin and recording, by a coarse grid search then a 1-degree
refinement around the best. Every angle costs one ``ray_test`` (cached by the stage), and
every combination is a few NumPy mask operations, so the search is cheap.

Noise (sigma): the robust std (1.4826 x MAD) of the signed distance along z between the
recorded points and the twin's noise-free hits in the same cells.
"""
from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.twin.stage import TwinStage

__all__ = ["calibrate", "robust_std", "range_residuals", "mask_iou"]

FITTABLE = ("theta_deg", "alpha_deg", "sigma_mm", "min_cos")
THETA_COARSE = np.arange(-40.0, 40.0 + 1e-9, 5.0)
ALPHA_COARSE = np.arange(-30.0, 30.0 + 1e-9, 5.0)
MIN_COS_GRID = np.array([0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3])


def robust_std(values: np.ndarray) -> float:
    """1.4826 x the median absolute deviation from the median (NaN for no values)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


def range_residuals(scan: RangeScan, truth: np.ndarray) -> np.ndarray:
    """Signed z of ``scan``'s valid points minus the noise-free hits ``truth`` (H, W, 3)."""
    ok = scan.valid & np.isfinite(truth).all(axis=2)
    return (scan.xyz[ok, 2].astype(np.float64) - truth[ok, 2].astype(np.float64))


def _search(stage: TwinStage, recorded_valid: np.ndarray, thetas, alphas, cosines) -> tuple[float, tuple]:
    """Best (IoU, (theta, alpha, min_cos)) over the grid."""
    idx = stage.hit_index
    rec_hit = recorded_valid[idx]
    rec_outside = int(np.count_nonzero(recorded_valid)) - int(np.count_nonzero(rec_hit))
    best = (-1.0, (0.0, 0.0, 0.0))
    for theta in thetas:
        seen, cos_c = stage._reach("camera", float(theta))
        for alpha in alphas:
            lit, cos_l = stage._reach("laser", float(alpha))
            base = seen & lit
            low = np.minimum(cos_c, cos_l)
            for c in cosines:
                v = base & (low >= c)
                inter = np.count_nonzero(v & rec_hit)
                union = np.count_nonzero(v | rec_hit) + rec_outside
                iou = inter / union if union else 1.0
                # ties: prefer the smaller |angles| found first (grids run from - to +)
                if iou > best[0] + 1e-12:
                    best = (iou, (float(theta), float(alpha), float(c)))
    return best


def calibrate(recorded: RangeScan, mesh: Any, sensor: Any = None,
              params: Iterable[str] = ("theta_deg", "alpha_deg", "sigma_mm"), *,
              initial: dict[str, float] | None = None, stage: TwinStage | None = None,
              theta_grid: Iterable[float] | None = None, alpha_grid: Iterable[float] | None = None,
              refine: bool = True) -> dict[str, Any]:
    """Estimate the twin's parameters by matching the recording.

    Parameters
    ----------
    recorded : RangeScan
        The recorded organized scan (scanner frame, ``pose`` set).
    mesh : trimesh.Trimesh or path
        The object in the world frame.
    sensor : str or Sensor, optional
        Preset giving the starting values of parameters that are not fitted.
    params : iterable of str
        Which of ``theta_deg``, ``alpha_deg``, ``sigma_mm``, ``min_cos`` to fit. The
        grazing threshold ``min_cos`` is fitted with the angles whenever an angle is.
    initial : dict, optional
        Values of parameters that are not fitted (override the sensor's).
    stage : TwinStage, optional
        Prepared stage (reuses the ray casts).
    theta_grid, alpha_grid : iterable of float, optional
        Coarse search grids (default -40..40 and -30..30 in 5-degree steps).
    refine : bool
        Refine the angles in 1-degree steps (+-4) around the coarse optimum.

    Returns
    -------
    dict
        ``theta_deg``, ``alpha_deg``, ``sigma_mm``, ``min_cos`` (fitted or given), ``iou``
        (valid-mask IoU of the noise-free geometry), ``fitted`` (names fitted),
        ``recorded_noise_mm`` (robust std of the recorded residuals), ``side`` and the
        ``stage`` (for :func:`rangesim.twin.twin`).
    """
    params = tuple(params)
    unknown = [p for p in params if p not in FITTABLE]
    if unknown:
        raise RangesimError(f"cannot fit {', '.join(unknown)}: choose from {', '.join(FITTABLE)}")
    if stage is None:
        stage = TwinStage(recorded, mesh, sensor)
    values = stage.params(**(initial or {}))
    recorded_valid = recorded.valid.reshape(-1)

    fit_theta, fit_alpha = "theta_deg" in params, "alpha_deg" in params
    fit_cos = "min_cos" in params or fit_theta or fit_alpha
    thetas = np.asarray(list(theta_grid), float) if theta_grid is not None else THETA_COARSE
    alphas = np.asarray(list(alpha_grid), float) if alpha_grid is not None else ALPHA_COARSE
    theta_set = thetas if fit_theta else [values["theta_deg"]]
    alpha_set = alphas if fit_alpha else [values["alpha_deg"]]
    cos_set = MIN_COS_GRID if fit_cos else [values["min_cos"]]
    iou, (theta, alpha, cmin) = _search(stage, recorded_valid, theta_set, alpha_set, cos_set)
    if refine and (fit_theta or fit_alpha):
        theta_set = theta + np.arange(-4.0, 4.0 + 1e-9) if fit_theta else [theta]
        alpha_set = alpha + np.arange(-4.0, 4.0 + 1e-9) if fit_alpha else [alpha]
        iou, (theta, alpha, cmin) = _search(stage, recorded_valid, theta_set, alpha_set, cos_set)
    values.update(theta_deg=theta, alpha_deg=alpha, min_cos=cmin)

    # noise: recorded points against the twin's noise-free hits
    noise_free = stage.scan(theta_deg=theta, alpha_deg=alpha, min_cos=cmin, quiet=True)
    rec_noise = robust_std(range_residuals(recorded, noise_free.xyz_true))
    if "sigma_mm" in params:
        if not np.isfinite(rec_noise):
            raise RangesimError("no recorded point lies on the mesh: cannot fit sigma_mm")
        values["sigma_mm"] = rec_noise
    return {
        **{k: float(values[k]) for k in FITTABLE},
        "iou": float(iou),
        "fitted": list(params) + (["min_cos"] if fit_cos and "min_cos" not in params else []),
        "recorded_noise_mm": float(rec_noise),
        "side": int(stage.side),
        "stage": stage,
    }
