"""Scores of found features (circles, arcs, ellipses, segments) against the analytic ground
truth of a synthetic scan (:func:`~rangesim.evaluate.ground_truth.ground_truth_features`)."""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.errors import RangesimError

#: the keys of a ``found`` dict that :func:`feature_scores` scores
FOUND_KINDS = ("circles", "arcs", "ellipses", "segments")


def _check_feature(f: Any, kind: str, k: int) -> None:
    """A round feature has a centre and a radius or semi-axes; a segment its two end points."""
    if kind == "segments":
        ok = hasattr(f, "start") and hasattr(f, "end")
        what = "start and end points"
    else:
        ok = hasattr(f, "center") and (hasattr(f, "radius") or hasattr(f, "axes"))
        what = "a center and a radius or axes"
    if not ok:
        raise RangesimError(f"found {kind}[{k}] is not a feature (needs {what}): {f!r}")


def _found_groups(found: Any) -> dict[str, list]:
    """The found features as ``{"round": [...], "segments": [...]}``, checked."""
    if isinstance(found, (list, tuple)):
        groups = {"round": [f for f in found if hasattr(f, "center")],
                  "segments": [f for f in found if not hasattr(f, "center")]}
    elif isinstance(found, dict):
        unknown = sorted(set(found) - set(FOUND_KINDS))
        if unknown:
            raise RangesimError(f"found has unknown feature kinds {unknown}; known: {', '.join(FOUND_KINDS)}")
        for kind in FOUND_KINDS:
            if not isinstance(found.get(kind, []), (list, tuple)):
                raise RangesimError(f"found[{kind!r}] must be a list of features, got {type(found[kind]).__name__}")
        groups = {"round": [*found.get("circles", []), *found.get("arcs", []), *found.get("ellipses", [])],
                  "segments": list(found.get("segments", []))}
    else:
        raise RangesimError(f"found must be a dict of feature lists or one list of features, got {type(found).__name__}")
    for kind, items in (("round features", groups["round"]), ("segments", groups["segments"])):
        for k, f in enumerate(items):
            _check_feature(f, "segments" if kind == "segments" else kind, k)
    return groups


def _size(f: Any) -> np.ndarray:
    """(a, b) semi-axes of a found circle/arc (radius, radius) or ellipse (axes), pixels."""
    if hasattr(f, "radius"):
        return np.array([f.radius, f.radius], float)
    return np.asarray(f.axes, float)


def _footprint(scan: Any, xy: np.ndarray, reach: float) -> float:
    """mm per pixel near an image position: median valid depth within ``reach`` px over f."""
    if scan is None or scan.K is None:
        return float("nan")
    H, W = scan.shape
    r0, c0 = int(round(xy[1])), int(round(xy[0]))
    k = int(np.ceil(reach)) + 2
    win = np.asarray(scan.depth)[max(0, r0 - k):r0 + k + 1, max(0, c0 - k):c0 + k + 1]
    z = win[np.isfinite(win)]
    return float(np.median(z) / scan.K[0, 0]) if len(z) else float("nan")


def _greedy(cost: np.ndarray, ok: np.ndarray) -> list[tuple[int, int]]:
    """One-to-one matches (i found, j truth), cheapest first, among allowed pairs."""
    pairs = []
    c = np.where(ok, cost, np.inf)
    while np.isfinite(c).any():
        i, j = np.unravel_index(np.argmin(c), c.shape)
        pairs.append((int(i), int(j)))
        c[i, :] = np.inf
        c[:, j] = np.inf
    return pairs


def feature_scores(
    found: dict[str, list] | list,
    truth: dict[str, list],
    scan: Any = None,
    *,
    center_tol_px: float = 2.0,
    size_tol: float = 0.2,
    segment_tol_px: float = 5.0,
    min_visible: float = 0.5,
) -> dict[str, Any]:
    """Recall, precision and errors of found features against ground truth.

    Round features (found circles, arcs and ellipses) match truth ellipses (``ImageEllipse``,
    ``visible >= min_visible``) one-to-one, nearest centre first, when the centres are within
    ``center_tol_px`` and the mean semi-axes within ``size_tol`` (relative). Segments match
    truth segments when both end points (either order) are within ``segment_tol_px``.

    Parameters
    ----------
    found : dict or list
        ``{"circles": [...], "arcs": [...], "ellipses": [...], "segments": [...]}`` (any
        subset) or one list of features.
    truth : dict
        ``ground_truth_features(scan, scene)``.
    scan : RangeScan, optional
        For errors in mm (pixel error times the footprint z / f near the feature).

    center_tol_px, segment_tol_px : float
        Largest centre / end-point distance of a match, pixels (finite, >= 0).
    size_tol : float
        Largest relative difference of the mean semi-axes (finite, >= 0).
    min_visible : float
        Least visible share (0..1) of a true feature that is scored.

    Returns
    -------
    dict
        ``round`` and ``segments`` sub-dicts: ``recall``, ``precision``, ``matched``,
        ``n_found``, ``n_truth``, ``center_error_px`` / ``radius_error_px`` (mean, max) and
        mm equivalents, ``endpoint_error_px``; ``matches`` lists (found index, truth name, error).
        ``recall`` is NaN when no true feature is scored and ``precision`` NaN when the scene
        has no feature of the kind at all (nothing to judge the found ones by) or when none was
        found (undefined: a features list is short, and a 1.0 there would read as a result;
        :func:`~rangesim.evaluate.edge_scores` counts pixels and calls those cases 1.0).

    Raises
    ------
    RangesimError
        ``found`` or ``truth`` of the wrong kind (unknown feature kinds, items that are not
        features), a tolerance that is negative or not finite, ``min_visible`` outside 0..1,
        a ``scan`` that is not a range scan.
    """
    groups = _found_groups(found)
    if not isinstance(truth, dict):
        raise RangesimError(f"truth must be the dict of ground_truth_features(scan, scene), got {type(truth).__name__}")
    center_tol_px = P.number(center_tol_px, "center_tol_px", 0, unit="pixels")
    size_tol = P.number(size_tol, "size_tol", 0)
    segment_tol_px = P.number(segment_tol_px, "segment_tol_px", 0, unit="pixels")
    min_visible = P.number(min_visible, "min_visible", 0, 1, what="share")
    if scan is not None and not (hasattr(scan, "K") and hasattr(scan, "depth") and hasattr(scan, "shape")):
        raise RangesimError(f"scan must be a RangeScan (for errors in mm) or None, got {type(scan).__name__}")
    for key, attrs in (("circles", ("center", "axes", "visible", "name")), ("segments", ("xyxy", "visible", "name"))):
        items = truth.get(key, [])
        bad = next((t for t in items if not all(hasattr(t, a) for a in attrs)), None) \
            if isinstance(items, (list, tuple)) else items
        if bad is not None:  # found features passed as truth (arguments swapped, or two runs compared)
            raise RangesimError(f"truth[{key!r}] must hold ground_truth_features' items (with {', '.join(attrs)}), "
                                f"got {type(bad).__name__}: pass ground_truth_features(scan, scene) as truth")
    out: dict[str, Any] = {}
    # -- round features vs truth ellipses --
    tr = [t for t in truth.get("circles", []) if t.visible >= min_visible]
    fr = groups["round"]
    res: dict[str, Any] = {"n_found": len(fr), "n_truth": len(tr), "matches": []}
    if fr and tr:
        fc = np.array([f.center for f in fr], float)
        tc = np.array([t.center for t in tr], float)
        d = np.linalg.norm(fc[:, None] - tc[None], axis=-1)
        fs = np.array([_size(f).mean() for f in fr])
        ts = np.array([np.mean(t.axes) for t in tr])
        ok = (d <= center_tol_px) & (np.abs(fs[:, None] - ts[None]) <= size_tol * ts[None])
        pairs = _greedy(d, ok)
    else:
        pairs = []
    ce = np.array([np.linalg.norm(np.asarray(fr[i].center) - tr[j].center) for i, j in pairs])
    re = np.array([abs(_size(fr[i]).mean() - np.mean(tr[j].axes)) for i, j in pairs])
    fp = np.array([_footprint(scan, tr[j].center, tr[j].axes[0]) for i, j in pairs])
    res.update(
        matched=len(pairs), recall=len(pairs) / len(tr) if tr else float("nan"),
        # a scene with no round feature at all (primitives, a plain mesh) judges nothing found
        precision=len(pairs) / len(fr) if fr and truth.get("circles") else float("nan"),
        center_error_px={"mean": float(ce.mean()) if len(ce) else None, "max": float(ce.max()) if len(ce) else None},
        radius_error_px={"mean": float(re.mean()) if len(re) else None, "max": float(re.max()) if len(re) else None},
    )
    if scan is not None and len(ce):
        res["center_error_mm"] = {"mean": float(np.nanmean(ce * fp)), "max": float(np.nanmax(ce * fp))}
        res["radius_error_mm"] = {"mean": float(np.nanmean(re * fp)), "max": float(np.nanmax(re * fp))}
    res["matches"] = [(i, tr[j].name, float(e)) for (i, j), e in zip(pairs, ce)]
    out["round"] = res
    # -- segments --
    ts_ = [t for t in truth.get("segments", []) if t.visible >= min_visible]
    fs_ = groups["segments"]
    res = {"n_found": len(fs_), "n_truth": len(ts_)}
    if fs_ and ts_:
        F = np.array([[*f.start, *f.end] for f in fs_], float).reshape(-1, 2, 2)
        T = np.array([t.xyxy for t in ts_], float).reshape(-1, 2, 2)
        same = np.maximum(np.linalg.norm(F[:, None, 0] - T[None, :, 0], axis=-1),
                          np.linalg.norm(F[:, None, 1] - T[None, :, 1], axis=-1))
        swap = np.maximum(np.linalg.norm(F[:, None, 0] - T[None, :, 1], axis=-1),
                          np.linalg.norm(F[:, None, 1] - T[None, :, 0], axis=-1))
        d = np.minimum(same, swap)
        pairs = _greedy(d, d <= segment_tol_px)
        ee = np.array([d[i, j] for i, j in pairs])
    else:
        pairs, ee = [], np.zeros(0)
    res.update(
        matched=len(pairs), recall=len(pairs) / len(ts_) if ts_ else float("nan"),
        precision=len(pairs) / len(fs_) if fs_ and truth.get("segments") else float("nan"),
        endpoint_error_px={"mean": float(ee.mean()) if len(ee) else None, "max": float(ee.max()) if len(ee) else None},
        matches=[(i, ts_[j].name, float(e)) for (i, j), e in zip(pairs, ee)],
    )
    out["segments"] = res
    return out
