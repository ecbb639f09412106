"""Line fitting on noisy scans: the lines through a pixel drawn ``s`` pixels out.

The angle noise of the unit vector from a point to a neighbour one pixel footprint away is
about ``sqrt(2) noise`` radians (``noise`` the depth noise in footprints), so on a noisy scan
the opposite-pair tolerance of the paper's test must grow until no crease is bent enough to
be found (46 degrees at the White Scanner preset's 0.25 footprints, 60 on the INRIA preset's
0.75). Drawn to the pixels ``s`` steps away, the same vector's angle noise falls as ``1 / s``
for independent errors (as measured, :func:`~rangesim.edges._noise.stride_gain`, for others):
each pixel gets the stride that brings its tolerance back to the noise-free one, as far as a
window of ``2 s + 1`` pixels around it holds no invalid pixel and no depth jump (where it
does, its neighbourhood would be one-sided and the jump rule decides instead).
"""
from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage

__all__ = ["ring_strides", "ring_edges"]

#: the half of the 8-neighbourhood whose opposites complete it: (row, column) steps
_COMPASS = np.array([(0, 1), (1, 0), (1, 1), (1, -1)], np.int64)


def ring_strides(noise_fp: np.ndarray, k: float | np.ndarray, blocked: np.ndarray, tol_deg: float,
                 gain: np.ndarray) -> np.ndarray:
    """Stride (pixels) of each pixel's line test: the least stride ``s`` whose bend noise
    ``k sqrt(2) noise_fp gain[s]`` (radians) is within ``tan(tol_deg)``, else the one with the
    least ``gain``; never farther than the largest window free of ``blocked`` pixels.

    Parameters
    ----------
    noise_fp : (H, W) float
        Depth noise per pixel, pixel footprints.
    k : float or (H, W) float
        Noise multiple of the tolerance (as :func:`~rangesim.edges._line_fit._pixel_noise`).
    blocked : (H, W) bool
        Invalid pixels and pixels either side of a depth jump: no window holds one.
    tol_deg : float
        The tolerance the stride should bring the test to, degrees.
    gain : (S + 1,) float
        :func:`~rangesim.edges._noise.stride_gain`: the bend noise at stride ``s`` over that
        at stride 1 (``1 / s`` for independent errors); strides up to ``S``.

    Returns
    -------
    (H, W) int64
        0 at blocked pixels; else 1..S (1: the neighbours next to the pixel).
    """
    h, w = blocked.shape
    gain = np.asarray(gain, np.float64)
    # only strides that beat every shorter one are worth their longer reach
    best = np.minimum.accumulate(np.concatenate([[1.0], gain[1:]]))
    useful = np.concatenate([[False, True], best[2:] < best[1:-1]])
    steps = np.nonzero(useful)[0]                       # increasing strides, decreasing gains
    need = np.tan(np.radians(tol_deg)) / np.maximum(np.asarray(k) * np.sqrt(2) * noise_fp, 1e-12)
    # the first useful stride whose gain is within ``need``, else the last
    pick = np.searchsorted(-gain[steps], -np.nan_to_num(need, nan=np.inf), side="left")
    want = steps[np.minimum(pick, len(steps) - 1)]
    # the largest half-window free of blocked pixels: Chebyshev distance to the nearest one
    # less one, and no farther than the image's border
    if blocked.any():
        free = ndimage.distance_transform_cdt(~blocked, metric="chessboard").astype(np.int64) - 1
    else:                                   # (the transform of an image without any is -1)
        free = np.full((h, w), max(h, w), np.int64)
    ii, jj = np.ogrid[:h, :w]
    border = np.minimum(np.minimum(ii, h - 1 - ii), np.minimum(jj, w - 1 - jj))
    reach = np.minimum(free, border)
    # a window too small for the wanted stride: the longest useful stride that fits
    fits = steps[np.maximum(np.searchsorted(steps, np.maximum(reach, 1), side="right") - 1, 0)]
    stride = np.minimum(want, fits)
    stride[blocked] = 0
    return stride.astype(np.int64)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def ring_edges(xyz, stride, cos_opp, cos_sep):  # pragma: no cover - compiled
    """Whether each pixel with a stride of 2 or more has no two distinct lines through it.

    The lines are the opposite pairs of its 8-neighbourhood stretched ``s = stride[i, j]``
    times: ``(i + s dr, j + s dc)`` and ``(i - s dr, j - s dc)`` for the four compass
    directions, straight when the cosine of their unit vectors from the pixel is below
    ``-cos_opp[i, j]``; two lines distinct when their directions' |cosine| is below
    ``cos_sep``. The same four directions, 45 degrees apart, as the nearest neighbours of a
    grid: all the pixels of the ring would give lines a few degrees either side of a
    crease, straight and more than ``cos_sep`` apart, so a crease would need ~4 times the
    tolerance to be found instead of ~1.4 times.

    Parameters
    ----------
    xyz : (H, W, 3) float32, mm
    stride : (H, W) int64
        Pixels under 2 are left False. The ring must lie inside the image and hold finite
        points (:func:`ring_strides` sees to both).
    cos_opp : (H, W) float32
    cos_sep : float

    Returns
    -------
    (H, W) bool
    """
    h, w = stride.shape
    out = np.zeros((h, w), np.bool_)
    dirs = np.empty((4, 3))
    for i in range(h):
        for j in range(w):
            s = stride[i, j]
            if s < 2:
                continue
            px, py, pz = float(xyz[i, j, 0]), float(xyz[i, j, 1]), float(xyz[i, j, 2])
            n = 0
            # the four compass pairs: right-left, down-up and the two diagonals, each pixel
            # with its opposite
            for t in range(4):
                dr, dc = _COMPASS[t, 0] * s, _COMPASS[t, 1] * s
                a0, a1, a2 = xyz[i + dr, j + dc, 0] - px, xyz[i + dr, j + dc, 1] - py, xyz[i + dr, j + dc, 2] - pz
                b0, b1, b2 = xyz[i - dr, j - dc, 0] - px, xyz[i - dr, j - dc, 1] - py, xyz[i - dr, j - dc, 2] - pz
                na = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
                nb = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
                if (a0 * b0 + a1 * b1 + a2 * b2) < -cos_opp[i, j] * na * nb:
                    d0, d1, d2 = a0 - b0, a1 - b1, a2 - b2
                    nd = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    dirs[n, 0], dirs[n, 1], dirs[n, 2] = d0 / nd, d1 / nd, d2 / nd
                    n += 1
            found = False
            for p in range(n):
                for q in range(p + 1, n):
                    if abs(dirs[p, 0] * dirs[q, 0] + dirs[p, 1] * dirs[q, 1] + dirs[p, 2] * dirs[q, 2]) < cos_sep:
                        found = True
                        break
                if found:
                    break
            out[i, j] = not found
    return out
