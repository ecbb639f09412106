"""Gaps that a steep face the scanner did not measure explains: creases at both ends, not a jump.

A gap of unmeasured pixels between a near surface and a far one is either an occlusion or a
face. Across an occlusion the camera looks past the near surface's edge onto the far one;
the pixels between are missing because the light did not reach them (a shadow) or because a
block matcher lost them beside the step. Across a face, the camera looks at a wall joining
the two that the scanner did not measure (a wall seen at 45-75 degrees that a block matcher's
window cannot resolve, or whose return dropped out): the truth there is two creases, convex at
the near end (the top of the wall) and concave at the far end (its foot), and no jump at all
(:func:`rangesim.evaluate.ground_truth_edges` marks occluding contours only where the surface
turns away from the camera).

The test (:func:`gap_fold_test`) takes the gap for a face when all of these hold:

* the face joining the two measured points is no steeper than the jump rule: over the gap's
  lateral extent (the pixels between them times their footprint) its depth changes by at
  most cot 15 deg footprints a footprint (:data:`~._discontinuities.JUMP_THRESHOLD`; plus,
  once, what the jump threshold adds for quanta and noise). A steeper one is what the truth
  calls an occluding contour;
* every pixel of the gap, as the search crossed it, is one the scan's status calls a dropout
  (a surface the camera saw and the scanner did not measure): a shadow's gap is not a face
  (its far end is where the light comes back, beyond a face turned from the light too, not
  the face's foot), nor is a gap that saw no surface.

So it needs a scan that says why its pixels are missing: a synthetic one. A recording's
status says only that a return is missing (MISS), and there the two ends of a shadow's gap
look like a face's: the light's path from the gap beside the far end grazes the near
surface's edge (that is where the shadow ends), so neither the ray through the two ends nor
a march towards the light tells them apart within a pixel's tolerance (tried: on a laser scan
with its shadows unmarked, most shadow gaps passed as faces). It cannot tell a face from
pixels a block matcher lost beside a true occluding step where no shadow falls (the far
surface on the projector's side of the step) either: the two measured ends look alike.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rangesim.core.constants import Status

#: FoldTest(bi, bj, zb, ai, aj, za, sy, sx, steps) -> (N,) bool: True where the gap between
#: the measured pixel (bi, bj) at depth zb (mm), which searched, and the measured pixel
#: (ai, aj) at za it found ``steps`` steps of (sy, sx) away (the search of
#: :func:`~._discontinuities.find_discontinuities`: pixel ``rint((sy, sx) * k)``, float32
#: products) is a face the scanner did not measure
FoldTest = Callable[..., np.ndarray]


def gap_fold_test(scan: Any, footprint: np.ndarray, slope_limit: float, extra: np.ndarray | float = 0.0
                  ) -> FoldTest | None:
    """The test of :mod:`._gap_folds` for one scan; None where the scan has no status.

    Parameters
    ----------
    scan : RangeScan
        Needs ``status``: gaps of DROPOUT pixels only can be faces (a recording's are MISS).
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
    fp = np.asarray(footprint, np.float64)
    status = getattr(scan, "status", None)
    if status is None or np.shape(status) != fp.shape:
        return None
    dropout = np.asarray(status) == Status.DROPOUT
    extra_img = np.broadcast_to(np.asarray(extra, np.float64), fp.shape)

    def test(bi, bj, zb, ai, aj, za, sy, sx, steps):
        zb, za = np.asarray(zb, np.float64), np.asarray(za, np.float64)
        sy, sx = np.asarray(sy, np.float32), np.asarray(sx, np.float32)
        steps = np.asarray(steps).astype(np.intp)
        lateral = np.hypot(ai - bi, aj - bj) * 0.5 * (fp[bi, bj] + fp[ai, aj])
        allowed = slope_limit * lateral + np.maximum(extra_img[bi, bj], extra_img[ai, aj])
        face = np.abs(za - zb) <= allowed
        # the gap's pixels as the search crossed them: rint((sy, sx) * k), float32 products
        for k in range(1, int(steps.max(initial=0))):
            on = np.flatnonzero(face & (k < steps))
            if on.size == 0:
                break
            kk = np.float32(k)
            gi = bi[on] + np.rint(sy[on] * kk).astype(np.intp)
            gj = bj[on] + np.rint(sx[on] * kk).astype(np.intp)
            face[on] = dropout[gi, gj]
        return face

    return test
