"""Gaps that a steep face the scanner did not measure explains: creases at both ends, not a jump.

A gap of unmeasured pixels between a near surface (A) and a far one (B) is either an
occlusion or a face. Across an occlusion the camera looks past A's edge onto B; the pixels
between are missing because the light did not reach them (a shadow, whose end on B lies on
the light's ray grazing A) or because the matcher lost them beside the step. Across a face,
the camera looks at a wall joining A to B that the scanner did not measure (a wall seen at
60-75 degrees, which a block matcher's window cannot resolve and a stripe dims on): the
truth there is two creases, convex at A (the top of the wall) and concave at B (its foot),
and no jump at all (:func:`rangesim.evaluate.ground_truth_edges` marks occluding contours
only where the surface turns away from the camera).

Which it is follows from the two measured points alone. The face the gap would be joins
A's point to B's: over the gap's lateral extent (the pixels between them times their
footprint) its depth changes by ``|z_A - z_B|``. A face steeper than the jump rule (seen at
more than 75 degrees slant, :data:`~._discontinuities.JUMP_THRESHOLD` footprints a pixel)
is what the truth calls an occluding contour, and stays a jump; so does a gap whose two
ends lie on one ray of the light (a shadow: the ray grazing A lands on B, within
:data:`SHADOW_LINE_PX` footprints), and one that holds pixels the scan's status calls shadow
(a shadow's far end is where the light comes back, beyond a face turned from the light
too, not the face's foot; a block matcher widens a projector shadow by the pixels it loses
beside it, which moves its ends off the ray). What is left is a face: its near end is a convex
crease and its far end a concave one (the near surface continued passes in front of B,
the far one behind A; :func:`~._discontinuities.find_discontinuities` calls them occluding
and occluded).

The rule needs the camera (``meta["K"]``) and the light (``meta["sensor"]``,
:func:`rangesim.core.light.light_sources`): without them a shadow's gap cannot be told
from a face's, and the test is not made.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rangesim.core.light import light_sources

#: a gap's two ends lie on one ray of the light (a shadow) when B's point lies within this
#: many footprints of the ray from the light through A's point: each end's pixel centre is
#: up to half a pixel from the edge it stands for, and a block matcher moves the near end by
#: a pixel or two more
SHADOW_LINE_PX = 2.0

#: FoldTest(bi, bj, zb, ai, aj, za) -> (N,) bool: True where the gap between the measured
#: pixels B (rows bi, cols bj, depth zb, mm) and A (ai, aj, za) is a face the scanner did
#: not measure
#: RangeScan.status of a pixel in the light's shadow (:class:`rangesim.core.constants.Status`)
STATUS_SHADOW = 2

FoldTest = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def gap_fold_test(scan: Any, footprint: np.ndarray, slope_limit: float, extra: np.ndarray | float = 0.0
                  ) -> FoldTest | None:
    """The test of :mod:`._gap_folds` for one scan; None where the scan lacks its camera or light.

    Parameters
    ----------
    scan : RangeScan
        Needs ``meta["K"]`` (depth is camera z) and ``meta["sensor"]`` (where the light is).
    footprint : (H, W) float
        Pixel footprint, mm.
    slope_limit : float
        Most depth change per footprint of lateral extent of a face (the jump rule's
        :data:`~._discontinuities.JUMP_THRESHOLD`, cot 15 deg).
    extra : float or (H, W) float
        What the jump threshold adds to ``slope_limit`` footprints at a pixel (depth quanta,
        noise), mm: allowed once over the gap.

    Returns
    -------
    FoldTest or None
    """
    meta = getattr(scan, "meta", None) or {}
    K, sensor = meta.get("K"), meta.get("sensor")
    if K is None or not isinstance(sensor, dict) or light_sources(np.zeros((1, 3)), sensor) is None:
        return None
    K = np.asarray(K, np.float64)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    fp = np.asarray(footprint, np.float64)
    status = getattr(scan, "status", None)
    shadow = (np.asarray(status) == STATUS_SHADOW) if status is not None and np.shape(status) == fp.shape else None
    extra_img = np.broadcast_to(np.asarray(extra, np.float64), fp.shape)

    def points(rows: np.ndarray, cols: np.ndarray, depth: np.ndarray) -> np.ndarray:
        return np.column_stack([(cols + 0.5 - cx) / fx * depth, (rows + 0.5 - cy) / fy * depth, depth])

    def test(bi, bj, zb, ai, aj, za):
        zb, za = np.asarray(zb, np.float64), np.asarray(za, np.float64)
        lateral = np.hypot(ai - bi, aj - bj) * 0.5 * (fp[bi, bj] + fp[ai, aj])
        allowed = slope_limit * lateral + np.maximum(extra_img[bi, bj], extra_img[ai, aj])
        face = np.abs(za - zb) <= allowed
        if shadow is not None:
            # a gap with shadow in it is a shadow's: its far end is where the light comes
            # back (beyond a face turned from the light, too), not the face's foot. The gap's
            # pixels as the search stepped over them (one pixel along its larger axis a step)
            steps = np.maximum(np.abs(ai - bi), np.abs(aj - bj))
            di, dj = (ai - bi) / steps, (aj - bj) / steps
            for k in range(1, int(steps.max(initial=0))):
                on = face & (k < steps)
                gi = bi[on] + np.rint(k * di[on]).astype(np.intp)
                gj = bj[on] + np.rint(k * dj[on]).astype(np.intp)
                face[on] = ~shadow[gi, gj]
        if face.any():
            b, a = points(bi, bj, zb), points(ai, aj, za)
            # the light's ray through A (the edge that would cast the shadow) and B's
            # distance from it
            light = light_sources(a, sensor)
            ray = a - light
            ray /= np.linalg.norm(ray, axis=1, keepdims=True)
            off = np.linalg.norm(np.cross(b - light, ray), axis=1)
            face &= off > SHADOW_LINE_PX * np.maximum(fp[bi, bj], fp[ai, aj])
        return face

    return test
