"""Mixed pixels: a stripe of finite width straddling a depth edge gives phantom points.

Physical model. The sheet has a Gaussian thickness profile (``laser.stripe_width`` is its
full width at half maximum, mm, sigma_w = FWHM / 2.355). In the frame where the sheet's
centre passes through the point P seen by pixel (v, u), the camera sees in row v the stripe
light reflected by every lit surface point Q near the sheet, with intensity
signal(Q) * exp(-d^2 / (2 sigma_w^2)), d = n . (Q - P) the distance of Q from the sheet's
centre plane (mm). The peak detector takes the intensity centroid over a window of +-W
columns around u. On a surface whose d grows linearly along the row (by ``a`` mm per
pixel) the profile is symmetric and the centroid is u itself; where the window holds a
depth edge, light from the foreground and the background mixes, the centroid moves by a
fraction of a pixel to several pixels, and triangulating that column against the sheet
puts a phantom point between the surfaces.

Which pixels mix. At a step between row neighbours u, u + 1 the stripe's image jumps by
``delta / a`` pixels, ``delta`` (mm) being how far n . (P[u+1] - P[u]) lies outside the
range of the neighbouring increments n . (P[u] - P[u-1]) and n . (P[u+2] - P[u+1]) (so a
crease, where the increment changes from one value to the other, is no step). For a step
small against the stripe (delta << sigma_w), first-order perturbation of the centroid gives
the shift of the pixel m columns from the edge as (delta / a) * T(m), T the fraction of the
stripe image's second moment beyond the edge (T = 1/2 at the edge, falling off over
sigma_w / a pixels): the step is blurred over the stripe's image width, with an amplitude of
at most half the step. The centroid is computed for the pixels within W columns of a step
whose largest shift, delta / (2 a), exceeds ``min_shift_px`` (default 0.01 px, below the
peak resolution of every preset: 1/16 px quantisation, 0.03-0.2 px noise), in depth a step
of about 2 * min_shift_px * dz/du (0.01-0.05 mm for the presets) -- whatever the range, and
whatever the stripe's width, which sets how many pixels mix (about 2 sigma_w / a per row and
edge), not whether they do. Pixels within W columns of a lit/unlit boundary (a stripe cut by
a shadow or an outline) are computed too. Elsewhere the shift is 0 (the centroid bias of a
smoothly curved surface, second order in the pixel size, is not modelled).

Limits, measured by an independent review (white_scanner, a 15 mm step at 350 mm): the
profile is sampled at the pixels' centres, not integrated over them, so where the stripe's
image is under about a pixel wide (a coarse image, a thin sheet) the edge pixel's centroid sees
almost none of the cut, and the phantoms shrink with the resolution (largest error 0 / 0.11 /
0.27 / 0.35 / 0.40 mm at 128 / 256 / 512 / 1024 / 2048 px wide; a real camera's peak on so
narrow a stripe locks to the pixel too, but the optics' blur, ``camera.psf_px``, which would
widen it, is not applied here); and the window is capped at :data:`MAX_WINDOW_PX`, so at high
resolution with a wide sheet light farther along the row does not mix.

All of it runs as Dr.Jit kernels: a break mask over the image, then the windowed centroid
over the compacted list of pixels near a break.
"""
from __future__ import annotations

import math

import drjit as dr

from rangesim.core.backend import mitsuba, opaque_scalar
from rangesim.core.constants import FWHM_PER_SIGMA

FWHM_TO_SIGMA = 1.0 / FWHM_PER_SIGMA
MAX_WINDOW_PX = 16
#: smallest centroid shift (pixels) that counts as mixing: below the peak resolution of every
#: preset (1/16 px quantisation, 0.03-0.2 px noise)
MIN_SHIFT_PX = 0.01
#: steps under this fraction of the depth are float32 rounding of the points (1e-6 z is a
#: few ulps), never a surface
ROUNDING_RELATIVE = 1e-6


def peak_window_px(stripe_width: float, focal_px: float, near: float) -> int:
    """Half-width W (pixels) of the detector's centroid window: two stripe FWHMs at ``near``."""
    if stripe_width <= 0:
        return 0
    return int(min(max(math.ceil(2.0 * stripe_width * focal_px / near), 1), MAX_WINDOW_PX))


def row_steps(points, sheet_normal, lit, width: int, min_shift_px: float = MIN_SHIFT_PX):
    """mi.Bool per pixel: a depth step between it and its right neighbour, both lit.

    A step between u and u + 1: the sheet-normal increment ``n . (P[u+1] - P[u])`` lies by
    ``delta`` (mm) outside the range of the increments on either side, and
    ``delta > 2 min_shift_px a`` with ``a`` the smaller of those increments (mm per pixel): the
    largest centroid shift it causes, ``delta / (2 a)`` pixels, is above ``min_shift_px``. A
    crease (the increment changes from one value to the other) is no step. There the stripe
    breaks: its light beyond the step lands on the other surface, elsewhere in the image.
    """
    mi = mitsuba()
    n = dr.width(lit)
    index = dr.arange(mi.Int32, n)
    width = opaque_scalar(width, "Int32")  # a new image size compiles nothing
    col = index % width

    def neighbour(k: int):
        ok = (col + k >= 0) & (col + k < width)
        ok &= dr.gather(mi.Bool, lit, mi.UInt32(index + k), ok)
        return ok, dr.gather(mi.Vector3f, points, mi.UInt32(index + k), ok)

    has_right, p_right = neighbour(1)
    has_left, p_left = neighbour(-1)
    has_next, p_next = neighbour(2)
    normal = sheet_normal
    mid = dr.dot(normal, p_right - points)
    left = dr.dot(normal, points - p_left)
    nxt = dr.dot(normal, p_next - p_right)
    big = mi.Float(3.0e38)
    lo = dr.minimum(dr.select(has_left, left, big), dr.select(has_next, nxt, big))
    hi = dr.maximum(dr.select(has_left, left, -big), dr.select(has_next, nxt, -big))
    delta = dr.maximum(dr.maximum(lo - mid, mid - hi), 0.0)  # how far outside the neighbours' range
    a = dr.minimum(dr.select(has_left, dr.abs(left), big), dr.select(has_next, dr.abs(nxt), big))
    floor = opaque_scalar(ROUNDING_RELATIVE) * dr.abs(points.z)
    return lit & has_right & (has_left | has_next) & (delta > dr.maximum(opaque_scalar(2.0 * min_shift_px) * a, floor))


def _near_break(points, sheet_normal, lit, measured, width: int, window: int, min_shift_px: float):
    """Flat indices (mi.UInt32) of measured pixels with a step (:func:`row_steps`) or a lit/unlit
    break in their window."""
    mi = mitsuba()
    n = dr.width(lit)
    index = dr.arange(mi.Int32, n)
    step = row_steps(points, sheet_normal, lit, width, min_shift_px)
    width = opaque_scalar(width, "Int32")
    col = index % width
    lit_right = dr.gather(mi.Bool, lit, mi.UInt32(index + 1), col < width - 1)
    brk = step | ((col < width - 1) & (lit ^ lit_right))  # break between a pixel and its right neighbour
    # a break within the window (clipped to the row): the running count of breaks rises
    # across it (two gathers of a prefix sum instead of one gather per window offset)
    count = dr.cumsum(mi.UInt32(brk))
    window = opaque_scalar(window, "Int32")
    first = index - col + dr.maximum(col - window, 0)
    last = index - col + dr.minimum(col + window, width - 1)
    before = dr.gather(mi.UInt32, count, mi.UInt32(first - 1), first > 0)
    near = dr.gather(mi.UInt32, count, mi.UInt32(last)) > before
    return dr.compress(measured & near)


def stripe_mixing_shift(points, sheet_normal, lit, signal, measured, width: int,
                        stripe_width: float, window: int, min_shift_px: float = MIN_SHIFT_PX):
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
    min_shift_px : float
        Smallest shift that counts as mixing, pixels: steps whose largest shift
        (``delta / (2 a)``, see the module docstring) is below it leave the centroid alone.

    Returns
    -------
    mi.Float of column shifts, pixels, 0 away from steps and lit/unlit boundaries.

    Examples
    --------
    A fronto-parallel step of 0.2 mm seen through a sheet at 45 deg, 0.5 mm per pixel along
    the row: the stripe's image jumps by 0.2 sin 45 / (0.5 cos 45) = 0.4 px, the two pixels
    beside the step move by half that (in opposite directions), the next ones by less.

    >>> import numpy as np
    >>> from rangesim.core.backend import mitsuba
    >>> mi = mitsuba()
    >>> u = np.arange(16.0)
    >>> z = np.where(u < 8, 300.0, 300.2)
    >>> pts = mi.Vector3f(0.5 * u, 0 * u, z)
    >>> normal = mi.Vector3f(np.full(16, 0.7071), np.zeros(16), np.full(16, 0.7071))
    >>> lit = mi.Bool(np.ones(16, bool))
    >>> shift = stripe_mixing_shift(pts, normal, lit, mi.Float(np.ones(16)), lit, 16, 1.5, 6)
    >>> np.round(np.asarray(shift)[6:10], 2)
    array([-0.16, -0.2 ,  0.2 ,  0.16], dtype=float32)
    """
    mi = mitsuba()
    shift = dr.zeros(mi.Float, dr.width(lit))
    if stripe_width <= 0 or window <= 0:
        return shift
    pixels = _near_break(points, sheet_normal, lit, measured, width, window, min_shift_px)
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
