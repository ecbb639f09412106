"""Mixed pixels: a stripe of finite width straddling a depth edge gives phantom points.

Physical model. The sheet has a Gaussian thickness profile (``laser.stripe_width`` is its
full width at half maximum, mm, sigma_w = FWHM / 2.355). In the frame where the sheet's
centre passes through the point P seen by pixel (v, u), the camera sees in row v the stripe
light reflected by every lit surface point Q near the sheet, with intensity
signal(Q) * exp(-d^2 / (2 sigma_w^2)), d = n . (Q - P) the distance of Q from the sheet's
centre plane. The peak detector takes the intensity centroid over a window of +-W columns
around u. On a surface whose depth is locally linear the profile is symmetric and the
centroid is u itself; where the window holds a depth edge, light from the foreground and
the background mixes, the centroid moves by a fraction of a pixel to several pixels, and
triangulating that column against the sheet puts a phantom point between the surfaces.

So the shift is evaluated only for pixels within W columns of a depth discontinuity
(|dz| > 0.5 % of z between neighbours) or of a lit/unlit boundary; elsewhere it is 0.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))
JUMP_RELATIVE = 0.005


def peak_window_px(stripe_width: float, focal_px: float, near: float) -> int:
    """Half-width W (pixels) of the detector's centroid window: two stripe FWHMs at ``near``."""
    if stripe_width <= 0:
        return 0
    return int(np.clip(math.ceil(2.0 * stripe_width * focal_px / near), 1, 16))


def stripe_mixing_shift(points, sheet_normal, lit, signal, measured, stripe_width, window):
    """Peak shift (pixels along the row) caused by a finite stripe width at depth edges.

    Parameters
    ----------
    points : (H, W, 3) float array
        True surface points, camera frame, mm (NaN on a miss).
    sheet_normal : (H, W, 3) float array
        Unit normal of the sheet that lights each pixel's point.
    lit : (H, W) bool
        The laser reaches the point (it can contribute stripe light).
    signal : (H, W) float array
        Return signal of each point.
    measured : (H, W) bool
        Pixels that report a point (the shift is computed for these only).
    stripe_width : float
        FWHM of the sheet profile, mm (0: no mixing).
    window : int
        Detector window half-width W, pixels.

    Returns
    -------
    (H, W) float array of column shifts, 0 away from edges.
    """
    height, width = lit.shape
    shift = np.zeros((height, width))
    if stripe_width <= 0 or window <= 0:
        return shift
    z = points[..., 2]
    lit_z = np.where(lit, z, np.nan)
    with np.errstate(invalid="ignore"):
        jump = np.abs(np.diff(lit_z, axis=1)) > JUMP_RELATIVE * np.fmin(lit_z[:, 1:], lit_z[:, :-1])
    brk = jump | (lit[:, 1:] != lit[:, :-1])
    marks = np.zeros_like(lit)
    marks[:, 1:] |= brk
    marks[:, :-1] |= brk
    near_edge = ndimage.maximum_filter1d(marks, size=2 * window + 1, axis=1)
    rows, cols = np.nonzero(measured & near_edge)
    if len(rows) == 0:
        return shift
    offsets = np.arange(-window, window + 1)
    cc = cols[:, None] + offsets[None, :]
    inside = (cc >= 0) & (cc < width)
    cc = np.clip(cc, 0, width - 1)
    rr = np.broadcast_to(rows[:, None], cc.shape)
    centre = points[rows, cols]
    normal = sheet_normal[rows, cols]
    d = np.einsum("nkj,nj->nk", points[rr, cc] - centre[:, None, :], normal)
    sigma = stripe_width * FWHM_TO_SIGMA
    weight = np.where(inside & lit[rr, cc], signal[rr, cc], 0.0) * np.exp(-0.5 * (d / sigma) ** 2)
    weight = np.nan_to_num(weight)
    shift[rows, cols] = (weight @ offsets) / weight.sum(axis=1)
    return shift
