"""Edge truth of what a scan could see, and one call that scores an edge map against it.

The exact truth of :func:`~rangesim.evaluate.ground_truth.ground_truth_edges` holds every
edge the camera looks at, also where the scanner measured nothing (laser shadow, dropout,
out of range): no detector can find those. :func:`visible_truth` keeps the truth on
measured pixels; :func:`score_edges` scores a detector against it in one call.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from rangesim.core import params as P
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.evaluate._edge_scores import RIM, _as_mask_labels, check_tolerance, edge_scores
from rangesim.evaluate.ground_truth import JUMP_ANGLE_DEG, ground_truth_edges

__all__ = ["visible_truth", "data_boundary", "score_edges"]


#: the keyword options visible_truth passes on to ground_truth_edges
TRUTH_OPTIONS = ("jump_angle_deg", "depth_tol_px", "jump_rule")


def visible_truth(scan: Any, scene: Any, crease_deg: float = 20.0, **options: Any) -> np.ndarray:
    """Ground-truth edge labels where the scanner measured a point.

    :func:`~rangesim.evaluate.ground_truth.ground_truth_edges` (occluding contours one
    pixel wide on the occluding side, visible creases one pixel wide, contact creases),
    with every pixel that ``scan.valid`` does not hold set to NONE: an edge inside a laser
    shadow, a dropout or beyond the working range is nobody's to find. One exception: an
    occluding contour whose own pixel is unmeasured (a block matcher's window straddling the
    step, a dropout at the silhouette) while its neighbour on the occluding surface is
    measured is marked on that neighbour, where the data end within a pixel of it
    (:func:`_contours_at_data_end`).

    Label types (:class:`~rangesim.core.constants.EdgeLabel`): 0 none; 1 jump (an occluding
    contour, the near side of a depth discontinuity, also against empty space); 2 convex
    crease (material angle below 180 deg, a roof); 3 concave crease (a valley, also where
    two objects touch).

    Parameters
    ----------
    scan : RangeScan
        A synthetic scan (``xyz_true``, ``part``, ``face``, ``normal``, ``valid``).
    scene : Scene or anything :func:`rangesim.load_scene` accepts
        The scene the scan was made of.
    crease_deg : float
        Smallest dihedral angle that makes a crease, degrees.
    **options
        Passed to :func:`~rangesim.evaluate.ground_truth.ground_truth_edges`
        (``jump_angle_deg``, ``depth_tol_px``, ``jump_rule``).

    Returns
    -------
    (H, W) uint8
        EdgeLabel per pixel, 0 wherever ``scan.valid`` is False; equal to the full truth on
        measured pixels but for the contours moved onto the data's end.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan, scene = rs.datasets.plate_scan(), rs.datasets.plate_scene()
    >>> truth = rs.evaluate.visible_truth(scan, scene)
    >>> bool(truth[~scan.valid].any()), bool((truth == 1).any())
    (False, True)
    """
    unknown = sorted(set(options) - set(TRUTH_OPTIONS))
    if unknown:  # (else a TypeError naming ground_truth_edges, which the caller never called)
        raise RangesimError(f"visible_truth got unknown option(s) {', '.join(unknown)}: it takes crease_deg and "
                            f"{', '.join(TRUTH_OPTIONS)}")
    labels = ground_truth_edges(scan, scene, crease_deg, **options)
    # measured = valid with a depth, as the detectors read it (a pixel marked valid without a
    # depth is a hole to them; truth kept there was unfindable)
    measured = np.asarray(scan.valid, dtype=bool) & np.isfinite(np.asarray(scan.depth, dtype=np.float64))
    lost = (labels == EdgeLabel.JUMP) & ~measured
    labels[~measured] = EdgeLabel.NONE
    if lost.any():
        jump_angle = float(options.get("jump_angle_deg", JUMP_ANGLE_DEG))
        _contours_at_data_end(labels, lost, measured, scan, 1.0 / np.tan(np.radians(jump_angle)))
    return labels


#: 8-neighbour offsets (row, column), the 4-neighbours first
_NEIGHBOURS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))


def _contours_at_data_end(labels: np.ndarray, lost: np.ndarray, measured: np.ndarray, scan: Any,
                          jump_steps: float) -> None:
    """Mark the occluding contours whose own pixel the scanner lost on the data's end beside them.

    A block matcher's window that straddles a depth step returns no depth, or a dropout at
    grazing incidence takes the outermost pixel of a silhouette: the contour pixel is not
    measured, while its neighbour on the occluding surface is. The scan then shows the
    contour there, within a pixel of the true one; dropping it from the truth would count
    the detector that finds it as wrong. Each lost contour pixel goes to its measured
    8-neighbour (4-neighbours first) on the same surface -- the true points less than the
    jump rule's ``jump_steps`` pixel footprints apart, the continuation of the occluder, not
    the background beyond the step -- unless that pixel holds a label already. So the contour
    stays one line where the data's end runs a pixel inside it (its measured pixels beside
    the moved ones, 8-connected). In place.
    """
    h, w = labels.shape
    xyz = np.asarray(scan.xyz_true, dtype=np.float64)
    fx = float(np.asarray(scan.K)[0, 0])
    lr, lc = np.nonzero(lost)
    reach = jump_steps * np.abs(xyz[lr, lc, 2]) / fx  # mm: the jump rule at the contour's depth
    target = np.full(lr.size, -1, np.int64)
    for dr, dc in _NEIGHBOURS:
        r, c = lr + dr, lc + dc
        ok = (target < 0) & (r >= 0) & (r < h) & (c >= 0) & (c < w)
        r, c = np.where(ok, r, 0), np.where(ok, c, 0)
        with np.errstate(invalid="ignore"):
            ok &= measured[r, c] & (labels[r, c] == EdgeLabel.NONE)
            ok &= np.linalg.norm(xyz[r, c] - xyz[lr, lc], axis=-1) < reach
        target[ok] = r[ok] * w + c[ok]
    labels.ravel()[target[target >= 0]] = EdgeLabel.JUMP


def data_boundary(valid: np.ndarray) -> np.ndarray:
    """(H, W) bool: measured pixels with an unmeasured 8-neighbour (image borders excluded).

    Where the data stops (a laser shadow on a flat floor, a dropout) the scan cannot tell
    whether the surface breaks; :func:`score_edges` leaves predictions there that match no
    true edge out of precision.

    Parameters
    ----------
    valid : (H, W) bool
        Measured pixels.

    Returns
    -------
    (H, W) bool

    Examples
    --------
    >>> import numpy as np
    >>> valid = np.ones((3, 4), bool); valid[:, 3] = False
    >>> data_boundary(valid).astype(int)
    array([[0, 0, 1, 0],
           [0, 0, 1, 0],
           [0, 0, 1, 0]])
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim != 2:
        raise RangesimError(f"valid must be an (H, W) mask, got shape {valid.shape}")
    # pad with True: the image border is no boundary of the data
    missing = ndimage.binary_dilation(~np.pad(valid, 1, constant_values=True),
                                      structure=np.ones((3, 3), bool))[1:-1, 1:-1]
    return valid & missing


def _truth_labels(truth: Any) -> np.ndarray:
    """``truth`` as a (H, W) uint8 label map (:class:`EdgeLabel` values, or a detector's
    :data:`~rangesim.evaluate._edge_scores.RIM`, scored as a jump as :func:`edge_scores` does;
    NaN in a float map is no edge), refused with a one-line message when it is not one."""
    a = np.asarray(truth)
    if a.dtype.kind not in "biuf" or a.ndim != 2:
        raise RangesimError(f"truth must be an (H, W) label map, got {a.dtype} of shape {a.shape}")
    if a.dtype.kind == "f":
        a = np.nan_to_num(a, nan=0.0)
    labels = np.asarray(a, np.int64)
    if np.any(labels != a) or labels.min(initial=0) < 0 or labels.max(initial=0) > RIM:
        raise RangesimError(f"truth labels must be whole numbers 0-{RIM} "
                            f"({', '.join(k.name.lower() for k in EdgeLabel)}, rim)")
    return labels.astype(np.uint8)


def score_edges(
    edges: Any,
    scan: Any,
    scene: Any = None,
    *,
    truth: np.ndarray | None = None,
    tolerance_px: float = 2.0,
    crease_deg: float = 20.0,
    ignore_data_boundary: bool = True,
) -> dict[str, Any]:
    """Score an edge map against what the scan could see, in one call.

    The truth is :func:`visible_truth` (computed from ``scene``, or given as ``truth``);
    the scores are :func:`~rangesim.evaluate.edge_scores` with labels (overall and per
    type: jump, convex, concave). With ``ignore_data_boundary``, predicted pixels on
    :func:`data_boundary` farther than ``tolerance_px`` from every true edge are left out
    (counted neither right nor wrong): the scan ends there, and whether the surface does
    cannot be told from it. ``n_ignored`` says how many.

    Parameters
    ----------
    edges : EdgeMap or (H, W) array
        The detector's output (nonzero = edge; an EdgeMap's labels are used).
    scan : RangeScan
        The synthetic scan the edges were found on.
    scene : Scene or anything :func:`rangesim.load_scene` accepts, optional
        The scene behind the scan; needed unless ``truth`` is given.
    truth : (H, W) uint8, optional
        Precomputed :func:`visible_truth` (saves the ray casting when scoring many maps).
    tolerance_px : float
        Largest matching distance, pixels.
    crease_deg : float
        Smallest dihedral angle of a true crease, degrees.
    ignore_data_boundary : bool
        Leave unmatched predictions at the border of the measured data out of precision.

    Returns
    -------
    dict
        As :func:`~rangesim.evaluate.edge_scores` (``precision``, ``recall``, ``f1``, ``fom``,
        counts, ``per_label``), plus ``n_ignored``.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan, scene = rs.datasets.plate_scan(), rs.datasets.plate_scene()
    >>> s = rs.evaluate.score_edges(rs.edges.gradient(scan), scan, scene)
    >>> sorted(s["per_label"]), bool(s["f1"] > 0.7)
    (['concave', 'convex', 'jump'], True)
    """
    ignore_data_boundary = P.flag(ignore_data_boundary, "ignore_data_boundary")
    if not hasattr(scan, "valid"):
        raise RangesimError(f"score_edges takes the RangeScan the edges were found on, got {type(scan).__name__}")
    if truth is None:
        if scene is None:
            raise RangesimError("score_edges needs the scene behind the scan, or truth=")
        truth = visible_truth(scan, scene, crease_deg)
    truth = _truth_labels(truth)
    pred, labels = _as_mask_labels(edges, "edges")
    shape = np.shape(scan.valid)
    if pred.shape != shape:
        raise RangesimError(f"edge map {pred.shape} and scan {shape} differ in shape")
    if truth.shape != shape:
        raise RangesimError(f"truth {truth.shape} and scan {shape} differ in shape")
    tolerance_px = check_tolerance(tolerance_px)
    n_ignored = 0
    if ignore_data_boundary:
        far = ndimage.distance_transform_edt(truth == EdgeLabel.NONE) > tolerance_px
        drop = pred & far & data_boundary(scan.valid)
        n_ignored = int(drop.sum())
        pred = pred & ~drop
    scores = edge_scores(pred, truth != EdgeLabel.NONE, tolerance_px,
                         pred_labels=None if labels is None else np.where(pred, labels, 0), gt_labels=truth)
    scores["n_ignored"] = n_ignored
    return scores
