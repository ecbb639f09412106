"""One calibration per scanner, fitted jointly over several recordings of it.

Every recording is a view of the same mesh through the same scanner: the views differ only by
their pose (the recording's own ``pose``, from a ``.conf`` file for the Stanford scans).
:func:`calibrate_views` fits one parameter set to all of them at once, in three stages, each
maximising an objective summed over the views:

1. **Geometry** (``twin.theta_deg``, ``twin.alpha_deg``, ``twin.min_cos``, ``twin.camera_views``):
   the valid-mask IoU of the noise-free twins, summed over views (intersections and unions
   added up), by a coarse grid and a 1-degree refinement, with the stripe watched by one
   camera view or by two, one on either side of the sheet
   (:func:`rangesim.twin.calibration.search_geometry`).
2. **Dropout curve** (``noise.min_signal``, ``noise.signal_contrast``): the joint valid-mask
   IoU of twins whose dropouts are drawn with P(valid) from
   :func:`rangesim.sensor.stripe_noise.detection_probability` (fixed seeds), over a grid
   that includes the hard threshold (contrast 0); the Bernoulli log-likelihood of the
   recorded masks is reported beside it.
3. **Range error** (``noise.sigma_px``, ``noise.signal_px``, ``camera.aperture_mm`` for the
   speckle, ``camera.psf_px`` (the blur that sets where the stripe's width starts to grow
   with incidence), ``noise.correlation_mm``, ``noise.edge_gain``, and ``twin.registration_mm``,
   the recordings' misregistration to the mesh): the twins' residual statistics
   matched to the recordings' (:mod:`rangesim.twin.realism`): log ratio of the robust std in
   every incidence bin with enough cells, the neighbour correlations along rows and columns,
   and the log ratio of the 99th percentile, by Nelder-Mead on log parameters with fixed
   seeds (common random numbers, so the objective is smooth).

The result carries a :class:`~rangesim.sensor.Sensor` with the fitted values, which
``scan()``, ``twin()`` and sweeps take like any preset, and its TOML text.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Sequence

import numpy as np
from scipy import optimize

from rangesim.core import params as P
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.stripe_noise import StripeNoise, detection_probability, partial_stripe_fraction
from rangesim.twin.calibration import MIN_SENSOR_FIT_IOU, check_overlap
from rangesim.twin.comparison import RANGE_AXIS
from rangesim.twin.realism import MIN_BIN_CELLS, binned_robust_std, incidence_deg, neighbour_correlation
from rangesim.twin.stage import Registration, TwinOptics, TwinStage

__all__ = ["calibrate_views", "sensor_toml", "fit_dropout_curve", "fit_range_error"]

MIN_SIGNAL_GRID = np.concatenate([[0.0], np.geomspace(1e-3, 0.3, 31)])
SIGNAL_CONTRAST_GRID = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
#: weight of a neighbour-correlation difference against a log std ratio in the noise fit
CORRELATION_WEIGHT = 4.0
#: log std ratio a bin may miss by before the steep penalty starts (ratio 1.12), and its weight
BAND_LOG = math.log(1.12)
BAND_WEIGHT = 20.0
#: seeds of the noise fit's simulated twins (common random numbers)
FIT_SEED = 12345
#: the fewest measurable cells (recorded and twin both valid) the range-error fit needs: one
#: incidence bin's worth (:data:`rangesim.twin.realism.MIN_BIN_CELLS`), else its cost is NaN
MIN_MEASURABLE_CELLS = MIN_BIN_CELLS


def _views(stages: Sequence[TwinStage], geometry: dict[str, float]) -> list[dict[str, Any]]:
    """Per view: recorded residuals, incidence and the measurable mask under ``geometry``."""
    out = []
    for st in stages:
        quiet = st.scan(**geometry, quiet=True)
        rec = st.recorded
        truth = quiet.xyz_true
        incidence = incidence_deg(quiet.normal, RANGE_AXIS)  # as compare measures it
        residual = np.full(st.shape, np.nan)
        both = rec.valid & quiet.valid & np.isfinite(rec.xyz).all(axis=2)
        residual[both] = rec.xyz[both, 2].astype(np.float64) - truth[both, 2].astype(np.float64)
        out.append({"stage": st, "quiet": quiet, "incidence": incidence, "residual": residual, "cells": both})
    return out


def fit_dropout_curve(views: list[dict[str, Any]], seed: int = FIT_SEED) -> dict[str, float]:
    """The ``min_signal`` and ``signal_contrast`` that maximise the joint valid-mask IoU of drawn twins.

    Every pair on the grid is tried with the same seeds (the dropout draw of
    :func:`rangesim.sensor.stripe_noise.draw_detected` on each view); the Bernoulli
    log-likelihood of the recordings' masks under the chosen curve is reported beside it.
    """
    from rangesim.sensor.stripe_noise import draw_detected

    prepared = []
    for v in views:
        st, quiet = v["stage"], v["quiet"]
        cells = st.stripe_cells(quiet.meta["twin"], quiet.status.reshape(-1), st.noise)
        # the truncated stripe's share of light multiplies S, as in the scan itself
        signal = cells["signal"] * partial_stripe_fraction(cells["border_mm"], cells["cos_laser"],
                                                           st.noise.stripe_width_mm)
        prepared.append((st, signal, cells["candidate"], st.recorded.valid.reshape(-1), cells["corr_px"]))
    best = (-1.0, 0.0, 0.0)
    for c in SIGNAL_CONTRAST_GRID:
        for smin in MIN_SIGNAL_GRID:
            inter = union = 0
            for st, signal, cand, rec, corr in prepared:
                p = np.where(cand, detection_probability(signal, smin, c), 0.0)
                drawn = cand & draw_detected(np.random.default_rng(seed), st.shape, p, corr)
                inter += np.count_nonzero(drawn & rec)
                union += np.count_nonzero(drawn | rec)
            iou = inter / union if union else 1.0
            if iou > best[0] + 1e-9:
                best = (float(iou), float(smin), float(c))
    signals = np.concatenate([sig[cand] for _, sig, cand, _, _ in prepared])
    outcomes = np.concatenate([rec[cand] for _, _, cand, rec, _ in prepared])
    p = np.clip(detection_probability(signals, best[1], best[2]), 1e-6, 1 - 1e-6)
    ll = float(np.sum(np.where(outcomes, np.log(p), np.log1p(-p))))
    return {"min_signal": best[1], "signal_contrast": best[2], "iou": best[0], "log_likelihood": ll,
            "cells": int(signals.size), "recorded_valid_share": float(np.mean(outcomes)) if outcomes.size else float("nan")}


def _noise_objective(views, base: StripeNoise, names, log_values) -> float:
    values = dict(zip(names, np.exp(log_values)))
    total = 0.0
    for v in views:
        st = v["stage"]
        noise, optics = _with_values(base, st.optics, values)
        reg = replace(st.registration, std_mm=float(values.get("registration_mm", st.registration.std_mm)))
        geo = v["quiet"].meta["twin"]
        _, error, _ = st.draw({**geo, "sigma_mm": None}, seed=FIT_SEED, noise=replace(noise, signal_contrast=0.0),
                              registration=reg, optics=optics)
        sim = np.where(v["cells"], error.reshape(st.shape), np.nan)
        total += _mismatch(v, sim)
    return total


def _mismatch(view: dict[str, Any], simulated: np.ndarray) -> float:
    rec_bins = view.setdefault("_rec_bins", binned_robust_std(view["residual"], view["incidence"]))
    rec_corr = view.setdefault("_rec_corr", neighbour_correlation(view["residual"]))
    rec_p99 = view.setdefault("_rec_p99", float(np.nanpercentile(np.abs(view["residual"]), 99)))
    sim_bins = binned_robust_std(simulated, view["incidence"])
    cost = 0.0
    for key, rec in rec_bins.items():
        if rec["count"] >= MIN_BIN_CELLS and sim_bins[key]["robust_std"] > 0:
            miss = abs(math.log(sim_bins[key]["robust_std"] / rec["robust_std"]))
            # squared log ratio, and a steep penalty beyond the tolerance so no bin is given up
            cost += miss**2 + BAND_WEIGHT * max(0.0, miss - BAND_LOG) ** 2
    sim_corr = neighbour_correlation(simulated)
    for axis in ("row", "column"):
        if np.isfinite(sim_corr[axis]) and np.isfinite(rec_corr[axis]):
            cost += CORRELATION_WEIGHT * (sim_corr[axis] - rec_corr[axis]) ** 2
    sim_p99 = float(np.nanpercentile(np.abs(simulated), 99))
    if sim_p99 > 0:
        cost += math.log(sim_p99 / rec_p99) ** 2
    return cost


NOISE_PARAMS = ("sigma_px", "signal_px", "aperture_mm", "psf_px", "correlation_mm", "edge_gain", "registration_mm")
#: where each fitted value lives in the sensor file (others: [noise])
PARAM_TABLE = {"aperture_mm": "camera", "psf_px": "camera", "registration_mm": "twin"}


def _with_values(base: StripeNoise, optics: TwinOptics, values: dict[str, float]) -> tuple[StripeNoise, TwinOptics]:
    """The noise model and the twin optics with fitted values (the aperture moves the speckle term)."""
    noise = replace(base, **{k: float(v) for k, v in values.items() if k not in PARAM_TABLE or k == "psf_px"})
    if "aperture_mm" in values:
        noise = replace(noise, aperture_mm=float(values["aperture_mm"]))
        scale = base.aperture_mm / noise.aperture_mm  # sigma ~ 1 / sin u ~ 1 / D for D << distance
        optics = replace(optics, speckle_px=optics.speckle_px * scale)
    return noise, optics


def fit_range_error(views: list[dict[str, Any]], base: StripeNoise, *, max_evaluations: int = 300,
                    registration: bool = True) -> dict[str, float]:
    """Nelder-Mead over the log of :data:`NOISE_PARAMS`; returns the fitted values and the cost."""
    start = {
        "sigma_px": max(base.sigma_px, 0.01), "signal_px": max(base.signal_px, 0.02),
        "aperture_mm": base.aperture_mm, "psf_px": max(base.psf_px, 0.5), "correlation_mm": max(base.correlation_mm, 0.5),
        "edge_gain": max(base.edge_gain, 0.1),
        "registration_mm": max(views[0]["stage"].registration.std_mm, 0.05),
    }
    if not registration:
        start.pop("registration_mm")
    if base.speckle_contrast <= 0:  # no speckle to scale: the aperture is not identifiable
        start.pop("aperture_mm")
    if base.stripe_width_mm <= 0:  # no footprint: neither the partial stripes nor the blur's share matter
        start.pop("edge_gain")
        start.pop("psf_px")
    names = tuple(start)
    x0 = np.log([start[k] for k in names])
    result = optimize.minimize(lambda x: _noise_objective(views, base, names, x), x0, method="Nelder-Mead",
                               options={"maxfev": max_evaluations, "xatol": 1e-3, "fatol": 1e-5,
                                        "initial_simplex": x0 + np.vstack([np.zeros(len(x0)), np.eye(len(x0)) * 0.7])})
    fitted = {k: float(v) for k, v in zip(names, np.exp(result.x))}
    fitted["cost"] = float(result.fun)
    fitted["evaluations"] = int(result.nfev)
    return fitted


def calibrate_views(recordings: Sequence[RangeScan], mesh: Any, sensor: Any, *,
                    stages: Sequence[TwinStage] | None = None, names: Sequence[str] | None = None,
                    fit_noise: bool = True, max_evaluations: int = 300, registration: bool = True) -> dict[str, Any]:
    """Fit one twin geometry, dropout curve and range-error model to several recordings.

    Parameters
    ----------
    recordings : sequence of RangeScan
        Organized recorded scans of one scanner, each with its ``pose`` (scanner-to-world).
    mesh : trimesh.Trimesh or path
        The object, world frame (the same for every view).
    sensor : str, Sensor or dict
        The scanner's preset: the starting values and everything not fitted.
    stages : sequence of TwinStage, optional
        Prepared stages, one per recording (reuses the ray casts).
    names : sequence of str, optional
        Names of the views for the report (default: the recordings' sources).
    fit_noise : bool
        Fit the range-error terms (stage 3); else keep the sensor's.
    max_evaluations : int
        Budget of the noise fit.
    registration : bool
        Also fit ``twin.registration_mm``, the recordings' misregistration against the mesh
        (:class:`rangesim.twin.stage.Registration`), which is not a scanner effect.

    Returns
    -------
    dict
        ``sensor`` (the calibrated Sensor), ``toml`` (its file text), ``geometry``,
        ``dropout``, ``noise`` (fitted values and cost), ``iou`` (the joint noise-free IoU),
        ``views`` (names) and ``stages``.
    """
    from rangesim.sensor import load_sensor
    from rangesim.twin.calibration import search_geometry

    if isinstance(recordings, RangeScan) or len(recordings) == 0:
        raise RangesimError("calibrate_views needs a list of one or more recorded scans")
    names = list(names) if names is not None else [str(r.meta.get("source", f"view {k}")) for k, r in
                                                    enumerate(recordings)]
    if len(names) != len(recordings) or (stages is not None and len(stages) != len(recordings)):
        raise RangesimError(f"calibrate_views got {len(recordings)} recordings but {len(names)} names"
                            + ("" if stages is None else f" and {len(stages)} stages") + ": one each")
    max_evaluations = P.whole(max_evaluations, "max_evaluations", 1)
    base_sensor = load_sensor(sensor)
    if stages is None:
        stages = [TwinStage(rec, mesh, base_sensor) for rec in recordings]
    iou, (theta, alpha, min_cos, views) = search_geometry(stages, views=(1, 2))
    check_overlap(iou, "the best twin's valid-mask IoU", plural=True, minimum=MIN_SENSOR_FIT_IOU)
    geometry = {"theta_deg": theta, "alpha_deg": alpha, "min_cos": min_cos, "camera_views": views}
    if len(stages) > 1:  # one view off (a pose left out) hides in the joint figure
        for st, name in zip(stages, names):
            view_iou = search_geometry([st], fixed=geometry, refine=False)[0]
            check_overlap(view_iou, "its twin's valid-mask IoU at the joint fit", view=name)
    views = _views(stages, geometry)
    measurable = sum(int(np.count_nonzero(v["cells"])) for v in views)
    if measurable < MIN_MEASURABLE_CELLS:
        raise RangesimError(
            f"the mesh and the recording(s) hardly overlap: {measurable} measurable cells (recorded and twin "
            f"both valid; at least {MIN_MEASURABLE_CELLS} needed); check the mesh, the poses and the units")
    dropout = fit_dropout_curve(views)
    base = replace(stages[0].noise, min_signal=dropout["min_signal"], signal_contrast=dropout["signal_contrast"])
    fitted: dict[str, float] = {}
    if fit_noise:
        fitted = fit_range_error(views, base, max_evaluations=int(max_evaluations), registration=registration)
        if not all(math.isfinite(v) for v in fitted.values()):
            raise RangesimError(f"the range-error fit did not converge to finite values (cost {fitted['cost']}); "
                                "no sensor file is written")
    changes: dict[str, Any] = {f"twin.{k}": (int(v) if k == "camera_views" else float(v)) for k, v in geometry.items()}
    changes.update({"noise.min_signal": dropout["min_signal"], "noise.signal_contrast": dropout["signal_contrast"]})
    for key in NOISE_PARAMS:
        if key in fitted:
            changes[f"{PARAM_TABLE.get(key, 'noise')}.{key}"] = round(fitted[key], 6)
    calibrated = base_sensor.with_params(changes)
    calibrated = replace(calibrated, source=f"calibrated from {base_sensor.name}")
    for st in stages:  # the stages now stand for the calibrated sensor
        st.sensor, st.noise = calibrated, StripeNoise.from_params(calibrated.params)
        st.optics = TwinOptics.from_sensor(calibrated, st.noise)
        st.registration = Registration.from_sensor(calibrated)
        st.defaults.update({k: v for k, v in geometry.items()}, sigma_mm=None)
    report = {"geometry": geometry, "iou": float(iou), "dropout": dropout, "noise": fitted, "views": names}
    return {**report, "sensor": calibrated, "toml": sensor_toml(calibrated, report), "stages": list(stages)}


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(round(float(value), 6))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    raise TypeError(f"cannot write {value!r} to TOML")


def sensor_toml(sensor: Any, report: dict[str, Any] | None = None) -> str:
    """TOML text of a sensor (every table and key with a value), with a header on its calibration."""
    lines = []
    if report is not None:
        noise = [k for k in NOISE_PARAMS if k in report["noise"]]
        # (geometry only: no range-error fit, no cost, no noise keys fitted)
        cost = (f"; range-error fit cost {report['noise']['cost']:.4f}" if "cost" in report["noise"]
                else "; range error not fitted (geometry only)")
        lines += [
            f"# Calibrated by `rangesim calibrate` jointly on {len(report['views'])} recording(s): "
            + ", ".join(str(v) for v in report["views"]) + ".",
            f"# Joint noise-free valid-mask IoU {report['iou']:.4f}; dropout fit on "
            f"{report['dropout']['cells']:,} measurable cells{cost}.",
            "# Fitted: [twin] theta_deg, alpha_deg, min_cos; noise.min_signal, noise.signal_contrast"
            + ("; " + ", ".join(noise) if noise else "") + ".",
        ]
    d = sensor.to_dict()
    for key in ("name", "description", "mode"):
        lines.append(f"{key} = {_toml_value(d[key])}")
    for table, values in d.items():
        if not isinstance(values, dict) or not values:
            continue
        if table == "structured_light" and d["mode"] != "structured_light":
            continue  # the projector's defaults: a laser-stripe scanner has no use for them
        lines += ["", f"[{table}]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"
