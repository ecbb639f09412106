"""Fitting the twin's sensor geometry and noise to a recording.

Geometry (camera angle theta, laser angle alpha, grazing threshold min_cos): maximise the
IoU of the valid masks of twin and recording, by a coarse grid search then a 1-degree
refinement around the best. Every angle costs one ``ray_test`` (cached by the stage), and
every combination is a few NumPy mask operations, so the search is cheap.

Noise (sigma): the robust std (1.4826 x MAD) of the signed distance along z between the
recorded points and the twin's noise-free hits in the same cells.
"""
from __future__ import annotations

import warnings
from typing import Any, Iterable, Sequence

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.twin.realism import robust_std
from rangesim.twin.stage import TwinStage, check_twin_param

__all__ = ["calibrate", "robust_std", "range_residuals", "mask_iou", "search_geometry"]

FITTABLE = ("theta_deg", "alpha_deg", "sigma_mm", "min_cos")
#: the least valid-mask IoU of twin and recording that a calibration or comparison accepts. A
#: twin of the right mesh in the recording's pose covers most of what the scanner recorded
#: whatever the angles (shadows and the grazing cut-off remove a share of the surface, not all of
#: it: good fits reach 0.9 and more); below 0.1 the mesh and the recordings do not overlap
#: (another object, a wrong pose, wrong units) and every later stage would fit noise to nothing.
MIN_CALIBRATION_IOU = 0.1
#: a twin whose valid-mask IoU with its recording is under this overlaps it only in part: a
#: wrong pose (a view of the bunny without its bun.conf pose, 45 degrees off: 0.44, against
#: 0.97 posed), another part or wrong units. Its statistics compare unlike cells (a noise std
#: ratio of 0.004), and one such view in a joint calibration pulls the range-error terms 60x
#: off, so it is warned about, naming the view
POOR_OVERLAP_IOU = 0.8


#: the least valid-mask IoU of the joint fit that ``rangesim calibrate`` writes a sensor file
#: from: under it most of what the scanner recorded is not the mesh (an unrelated part reached
#: 0.16, a pose 45 degrees off 0.44), and the file would hold a fit to another object
MIN_SENSOR_FIT_IOU = 0.5


def check_overlap(iou: float, what: str, *, plural: bool = False, view: str | None = None,
                  minimum: float = MIN_CALIBRATION_IOU) -> None:
    """Refuse a twin that does not overlap its recording(s): ``iou`` (``what`` it is) under
    ``minimum`` (:data:`MIN_CALIBRATION_IOU`), or NaN; warn when it is under
    :data:`POOR_OVERLAP_IOU`. ``view``: the recording's name, said in the message."""
    recording, poses = ("recording(s)", "recordings' poses") if plural else ("recording", "recording's pose")
    if view is not None:
        recording, poses = f"recording '{view}'", "recording's pose"
    if not iou >= minimum:  # NaN included
        overlap = "overlap too little to calibrate on" if iou >= MIN_CALIBRATION_IOU else "do not overlap"
        raise RangesimError(
            f"the mesh and the {recording} {overlap}: {what} is {float(iou):.4f} (at least "
            f"{minimum} needed); check the mesh, the {poses} and the units")
    if iou < POOR_OVERLAP_IOU:
        warnings.warn(f"the mesh and the {recording} overlap only in part: {what} is {float(iou):.4f} (a posed "
                      f"twin of the right mesh reaches {POOR_OVERLAP_IOU} and more); check the mesh, the {poses} "
                      "and the units", RuntimeWarning, stacklevel=3)
THETA_COARSE = np.arange(-40.0, 40.0 + 1e-9, 5.0)
ALPHA_COARSE = np.arange(-30.0, 30.0 + 1e-9, 5.0)
MIN_COS_GRID = np.array([0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3])
#: :func:`search_geometry` refines around every coarse grid point whose joint IoU is within this of
#: the best (about 4 cells of a 40,000-cell view)
REFINE_TOL = 1e-4


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


def range_residuals(scan: RangeScan, truth: np.ndarray) -> np.ndarray:
    """Signed z of ``scan``'s valid points minus the noise-free hits ``truth`` (H, W, 3)."""
    ok = scan.valid & np.isfinite(truth).all(axis=2)
    return (scan.xyz[ok, 2].astype(np.float64) - truth[ok, 2].astype(np.float64))


def _search(stages: Sequence[TwinStage], thetas, alphas, cosines, views=(1,), *, every: bool = False):
    """Best (joint IoU, (theta, alpha, min_cos, views)) over the grid; intersections and unions add
    up over views. With ``every``, the list of the best (over ``cosines``) of every (views, theta,
    alpha) grid point, in grid order, instead."""
    prepared = []
    for st in stages:
        rec_valid = st.recorded.valid.reshape(-1)
        rec_hit = rec_valid[st.hit_index]
        prepared.append((st, rec_hit, int(np.count_nonzero(rec_valid)) - int(np.count_nonzero(rec_hit))))
    best = (-1.0, (0.0, 0.0, 0.0, 1))
    points = []
    for n_views in views:
        for theta in thetas:
            for alpha in alphas:
                inter = np.zeros(len(cosines))
                union = np.zeros(len(cosines))
                for st, rec_hit, rec_outside in prepared:
                    seen, cos_c = st.camera_reach(float(theta), n_views)
                    lit, cos_l = st._reach("laser", float(alpha))
                    base = seen & lit
                    low = np.minimum(cos_c, cos_l)
                    for k, c in enumerate(cosines):
                        v = base & (low >= c)
                        inter[k] += np.count_nonzero(v & rec_hit)
                        union[k] += np.count_nonzero(v | rec_hit) + rec_outside
                here = (-1.0, (0.0, 0.0, 0.0, 1))
                for k, c in enumerate(cosines):
                    iou = inter[k] / union[k] if union[k] else 1.0
                    # ties: prefer one view and the smaller |angles| found first (grids run from - to +)
                    if iou > here[0] + 1e-12:
                        here = (float(iou), (float(theta), float(alpha), float(c), int(n_views)))
                points.append(here)
                if here[0] > best[0] + 1e-12:
                    best = here
    return points if every else best


def search_geometry(stages: Sequence[TwinStage], *, theta_grid: Iterable[float] | None = None,
                    alpha_grid: Iterable[float] | None = None, cosines: Iterable[float] | None = None,
                    fixed: dict[str, float] | None = None, refine: bool = True, views: Iterable[int] = (1,)
                    ) -> tuple[float, tuple]:
    """The camera angle, laser angle and grazing cut-off that maximise the joint valid-mask IoU.

    A coarse grid (5-degree steps) and, with ``refine``, 1-degree steps (+-4) around each coarse
    point within :data:`REFINE_TOL` of its best (the IoU is flat near its optimum). Names in ``fixed`` (``theta_deg``, ``alpha_deg``, ``min_cos``, ``camera_views``)
    are held at the given value; ``views`` lists the camera-view counts tried (1, or 2 for a
    head watching the stripe from both sides). Returns
    ``(iou, (theta_deg, alpha_deg, min_cos, camera_views))``.
    """
    fixed = fixed or {}
    thetas = [fixed["theta_deg"]] if "theta_deg" in fixed else (
        np.asarray(list(theta_grid), float) if theta_grid is not None else THETA_COARSE)
    alphas = [fixed["alpha_deg"]] if "alpha_deg" in fixed else (
        np.asarray(list(alpha_grid), float) if alpha_grid is not None else ALPHA_COARSE)
    cos_set = [fixed["min_cos"]] if "min_cos" in fixed else (
        np.asarray(list(cosines), float) if cosines is not None else MIN_COS_GRID)
    view_set = [int(fixed["camera_views"])] if "camera_views" in fixed else [int(v) for v in views]
    coarse = _search(stages, thetas, alphas, cos_set, view_set, every=True)
    best = max(coarse, key=lambda point: point[0])  # the first of equals: grid order
    if not (refine and ("theta_deg" not in fixed or "alpha_deg" not in fixed)):
        return best
    # the valid-mask IoU is flat near its optimum (a view's outline moves by a cell or two per
    # degree): grid points a few cells apart lie 5-10 degrees apart, so the refinement starts from
    # every coarse point within REFINE_TOL of the best, not from the best alone (on the bunny's
    # bun045 the coarse best, -40 degrees, beat -35 by 2e-5, and the 1-degree optimum, -33, lay
    # outside its +-4 window)
    refined = []
    for iou, (theta, alpha, _, nv) in coarse:
        if iou < best[0] - REFINE_TOL:
            continue
        around_t = [theta] if "theta_deg" in fixed else theta + np.arange(-4.0, 4.0 + 1e-9)
        around_a = [alpha] if "alpha_deg" in fixed else alpha + np.arange(-4.0, 4.0 + 1e-9)
        refined.append(_search(stages, around_t, around_a, cos_set, [nv]))
    return max(refined, key=lambda point: point[0])


def calibrate(recorded: RangeScan | Sequence[RangeScan], mesh: Any, sensor: Any = None,
              params: Iterable[str] = ("theta_deg", "alpha_deg", "sigma_mm"), *,
              initial: dict[str, float] | None = None, stage: TwinStage | None = None,
              theta_grid: Iterable[float] | None = None, alpha_grid: Iterable[float] | None = None,
              refine: bool = True) -> dict[str, Any]:
    """Estimate the twin's parameters by matching the recording(s).

    Given a list of recordings, fits one parameter set to all of them jointly (geometry,
    dropout curve and range-error terms; :func:`rangesim.twin.joint.calibrate_views`, whose
    result holds the calibrated ``sensor`` and its ``toml``). Given one RangeScan, fits the
    geometry and the legacy white noise ``sigma_mm`` to that view alone (described below).

    Parameters
    ----------
    recorded : RangeScan or sequence of RangeScan
        The recorded organized scan(s) (scanner frame, ``pose`` set).
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

    Examples
    --------
    Needs the shared data (``../shared/data``, or ``$RANGESIM_DATA``), so not run as a test:

    >>> import rangesim as rs
    >>> bunny = "../shared/data/stanford-bunny/"
    >>> views = [rs.load_scan(bunny + f"{v}.ply", conf=bunny + "bun.conf") for v in ("bun000", "bun045")]  # doctest: +SKIP
    >>> fit = rs.calibrate(views, bunny + "reconstruction/bun_zipper.ply",
    ...                    "sensors/uncalibrated/cyberware_3030.toml")                                   # doctest: +SKIP
    >>> calibrated = fit["sensor"]   # a Sensor; fit["toml"] is its file text                      # doctest: +SKIP

    References
    ----------
    .. [1] R. G. Dorsch, G. Haeusler, J. M. Herrmann, "Laser triangulation: fundamental
       uncertainty in distance measurement", Applied Optics 33(7), 1306-1314 (1994),
       doi:10.1364/AO.33.001306.
    .. [2] B. Curless, M. Levoy, "Better optical triangulation through spacetime analysis", ICCV
       1995, 987-994, doi:10.1109/ICCV.1995.466772.
    """
    if not isinstance(recorded, RangeScan):  # several views: one joint calibration
        from rangesim.twin.joint import calibrate_views

        return calibrate_views(list(recorded), mesh, sensor)
    params = (params,) if isinstance(params, str) else tuple(params)  # "sigma_mm" is one name, not 8
    unknown = [p for p in params if p not in FITTABLE]
    if unknown:
        raise RangesimError(f"cannot fit {', '.join(unknown)}: choose from {', '.join(FITTABLE)}")
    for name, grid in (("theta_deg", theta_grid), ("alpha_deg", alpha_grid)):
        for value in (() if grid is None else grid):  # a grid of 1e6 degrees came back as the fit
            check_twin_param(name, value)
    if stage is None:
        stage = TwinStage(recorded, mesh, sensor)
    values = stage.params(**(initial or {}))

    fit_theta, fit_alpha = "theta_deg" in params, "alpha_deg" in params
    fit_cos = "min_cos" in params or fit_theta or fit_alpha
    fixed = {k: values[k] for k, fit in (("theta_deg", fit_theta), ("alpha_deg", fit_alpha), ("min_cos", fit_cos))
             if not fit}
    fixed.setdefault("camera_views", int(values.get("camera_views", 1)))
    iou, (theta, alpha, cmin, _) = search_geometry([stage], theta_grid=theta_grid, alpha_grid=alpha_grid,
                                                   fixed=fixed, refine=refine)
    check_overlap(iou, "the best twin's valid-mask IoU")
    values.update(theta_deg=theta, alpha_deg=alpha, min_cos=cmin)

    # noise: recorded points against the twin's noise-free hits
    noise_free = stage.scan(theta_deg=theta, alpha_deg=alpha, min_cos=cmin, quiet=True)
    rec_noise = robust_std(range_residuals(recorded, noise_free.xyz_true))
    if "sigma_mm" in params:
        if not np.isfinite(rec_noise):
            raise RangesimError("no recorded point lies on the mesh: cannot fit sigma_mm")
        values["sigma_mm"] = rec_noise
    return {
        # sigma_mm stays None when not fitted and the sensor's noise model applies (float(None) raised)
        **{k: None if values[k] is None else float(values[k]) for k in FITTABLE},
        "iou": float(iou),
        "fitted": list(params) + (["min_cos"] if fit_cos and "min_cos" not in params else []),
        "recorded_noise_mm": float(rec_noise),
        "side": int(stage.side),
        "stage": stage,
    }
