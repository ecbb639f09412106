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
(|dz| > 0.5 % of z between row neighbours) or of a lit/unlit boundary; elsewhere it is 0.
All of it runs as Dr.Jit kernels: a break mask over the image, then the windowed centroid
over the compacted list of pixels near a break.
"""
from __future__ import annotations

import math

import drjit as dr

from rangesim.core.backend import mitsuba, opaque_scalar

FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))
JUMP_RELATIVE = 0.005
MAX_WINDOW_PX = 16


def peak_window_px(stripe_width: float, focal_px: float, near: float) -> int:
    """Half-width W (pixels) of the detector's centroid window: two stripe FWHMs at ``near``."""
    if stripe_width <= 0:
        return 0
    return int(min(max(math.ceil(2.0 * stripe_width * focal_px / near), 1), MAX_WINDOW_PX))


def _near_break(points, lit, measured, width: int, window: int):
    """Flat indices (mi.UInt32) of measured pixels with a depth or lit/unlit break in their window."""
    mi = mitsuba()
    n = dr.width(lit)
    index = dr.arange(mi.Int32, n)
    width = opaque_scalar(width, "Int32")  # a new image size compiles nothing
    col = index % width
    has_right = col < width - 1
    right = mi.UInt32(index + 1)
    lit_right = dr.gather(mi.Bool, lit, right, has_right)
    z, z_right = points.z, dr.gather(mi.Float, points.z, right, has_right)
    nearer = dr.select(z < z_right, z, z_right)
    jump = lit & lit_right & (dr.abs(z_right - z) > JUMP_RELATIVE * nearer)
    brk = has_right & (jump | (lit ^ lit_right))  # break between a pixel and its right neighbour
    dr.eval(brk)
    near = dr.zeros(mi.Bool, n)
    for k in range(-window, window + 1):
        inside = (col + k >= 0) & (col + k < width)
        near |= dr.gather(mi.Bool, brk, mi.UInt32(index + k), inside)
    return dr.compress(measured & near)


def stripe_mixing_shift(points, sheet_normal, lit, signal, measured, width: int,
                        stripe_width: float, window: int):
    """Peak shift (pixels along the row) caused by a finite stripe width at depth edges.

    Parameters
    ----------
    points : mi.Vector3f, N = H * W pixels row-major
        True surface points, camera frame, mm.
    sheet_normal : mi.Vector3f
        Unit normal of the sheet that lights each pixel's point.
    lit : mi.Bool
        The laser reaches the point (it can contribute stripe light).
    signal : mi.Float
        Return signal of each point (0 where unlit).
    measured : mi.Bool
        Pixels that report a point (the shift is computed for these only).
    width : int
        Image width W, pixels.
    stripe_width : float
        FWHM of the sheet profile, mm (0: no mixing).
    window : int
        Detector window half-width, pixels.

    Returns
    -------
    mi.Float of column shifts, 0 away from edges.
    """
    mi = mitsuba()
    shift = dr.zeros(mi.Float, dr.width(lit))
    if stripe_width <= 0 or window <= 0:
        return shift
    pixels = _near_break(points, lit, measured, width, window)
    if dr.width(pixels) == 0:
        return shift
    width = opaque_scalar(width, "Int32")
    col = mi.Int32(pixels) % width
    centre = dr.gather(mi.Vector3f, points, pixels)
    normal = dr.gather(mi.Vector3f, sheet_normal, pixels)
    gauss = -0.5 / (stripe_width * FWHM_TO_SIGMA) ** 2
    total = dr.zeros(mi.Float, dr.width(pixels))
    moment = dr.zeros(mi.Float, dr.width(pixels))
    for k in range(-window, window + 1):
        other = mi.UInt32(mi.Int32(pixels) + k)
        ok = (col + k >= 0) & (col + k < width)
        ok &= dr.gather(mi.Bool, lit, other, ok)
        d = dr.dot(normal, dr.gather(mi.Vector3f, points, other, ok) - centre)
        weight = dr.select(ok, dr.gather(mi.Float, signal, other, ok) * dr.exp(gauss * d * d), 0.0)
        total += weight
        moment += k * weight
    dr.scatter(shift, moment / total, pixels)
    return shift
