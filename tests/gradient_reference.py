"""Array and image forms of gradient's compiled kernels, kept as the tests' references.

Each is what :mod:`rangesim.edges._gradient` computed before its kernels were fused or
compiled (the fourth session of 2026-12-03); ``tests/test_gradient_kernels.py`` holds the
kernels to these, bit for bit. Not part of the package: nothing in it runs in a detector.
"""
from __future__ import annotations

import numba
import numpy as np

from rangesim.edges._gradient import _SQRT2


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _col3(a, i, j, h):  # pragma: no cover - compiled
    """``(up + mid) + down`` of column ``j`` around row ``i`` of a float32 image, with zeros
    outside the image and in place of NaN."""
    zero = np.float32(0)
    up = a[i - 1, j] if i >= 1 else zero
    mid = a[i, j]
    dn = a[i + 1, j] if i + 1 < h else zero
    up = up if up == up else zero      # NaN counts as 0
    mid = mid if mid == mid else zero
    dn = dn if dn == dn else zero
    return (up + mid) + dn


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _hessian(r0, r45, r90, r135):  # pragma: no cover - compiled
    """The second-derivative tensor from the four responses, summed over 3x3 (float32):
    ``Dxx`` from 0 deg, ``Dyy`` from 90, ``Dxy`` from the diagonals' difference times
    sqrt(2) / 6; its eigenvalues ``mean +- rad`` (rad by the square root of the squares:
    float32 cannot overflow here), whether the minor one dominates, and the arctan2 terms
    ``2 Dxy`` and ``Dxx - Dyy``.

    The 3x3 sums (zeros outside the image and in place of NaN: column sums ``(up + mid) +
    down``, then ``(left + centre) + right``) are made a row at a time, so no full-size
    sum image is stored (``scipy.ndimage.uniform_filter(a, 3, mode="constant") * 9`` gives
    the same sums to 1e-6)."""
    h, w = r0.shape
    zero = np.float32(0)
    k = np.float32(np.sqrt(2.0) / 6.0)
    two = np.float32(2)
    mean = np.empty((h, w), np.float32)
    rad = np.empty((h, w), np.float32)
    minor = np.empty((h, w), np.bool_)
    two_dxy = np.empty((h, w), np.float32)
    dxx_dyy = np.empty((h, w), np.float32)
    cxx = np.zeros(w + 2, np.float32)       # column sums, a zero column either side
    cyy = np.zeros(w + 2, np.float32)
    cxy = np.zeros(w + 2, np.float32)
    for i in range(h):
        for j in range(w):
            cxx[j + 1] = _col3(r0, i, j, h)
            cyy[j + 1] = _col3(r90, i, j, h)
            up = (r45[i - 1, j] - r135[i - 1, j]) if i >= 1 else zero
            mid = r45[i, j] - r135[i, j]
            dn = (r45[i + 1, j] - r135[i + 1, j]) if i + 1 < h else zero
            up = up if up == up else zero
            mid = mid if mid == mid else zero
            dn = dn if dn == dn else zero
            cxy[j + 1] = (up + mid) + dn
        for j in range(w):
            xx = (cxx[j] + cxx[j + 1]) + cxx[j + 2]
            yy = (cyy[j] + cyy[j + 1]) + cyy[j + 2]
            xy = ((cxy[j] + cxy[j + 1]) + cxy[j + 2]) * k
            m = (xx + yy) / two
            hd = (xx - yy) / two
            r = np.sqrt(hd * hd + xy * xy)
            mean[i, j], rad[i, j] = m, r
            minor[i, j] = abs(m - r) > abs(m + r)
            two_dxy[i, j] = two * xy
            dxx_dyy[i, j] = xx - yy
    return mean, rad, minor, two_dxy, dxx_dyy


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _to_direction(theta, minor, mag):  # pragma: no cover - compiled
    """In place: the dominant eigenvector's angle in [0, pi) (a quarter turn where the minor
    eigenvalue dominates), NaN where no operator responded."""
    quarter, half = np.float32(np.pi / 2), np.float32(np.pi)
    for i in range(theta.shape[0]):
        for j in range(theta.shape[1]):
            t = theta[i, j] + quarter if minor[i, j] else theta[i, j] + np.float32(0)
            if t < 0:
                t = t + half
            theta[i, j] = np.float32(np.nan) if np.isnan(mag[i, j]) else t


def _second_differences_at(p: np.ndarray, pairs: np.ndarray | None, idx: np.ndarray,
                           w: int) -> list[np.ndarray]:
    """The exact rule of :func:`second_differences` at the flat pixel indices ``idx``.

    ``p`` is the depth padded by 1 with NaN; every part whose pixels are not all valid, or
    one of whose steps crosses a broken pair, is dropped, and the response is the sum of
    the remaining parts over the sum of their steps (NaN if too few remain), with the
    same operations in the same order as the dense pass, so that both agree to the bit.
    (The array form of :func:`_exact_at`, kept as its reference.)
    """
    stride = w + 2
    flat = p.ravel()
    r_, c_ = np.divmod(idx, w)
    base = (r_ + 1) * stride + (c_ + 1)
    jp = None
    if pairs is not None:
        jp = [np.pad(pairs[a], 1, constant_values=False).ravel() for a in range(4)]

    def g(dr: int, dc: int) -> np.ndarray:
        return flat[base + dr * stride + dc]

    def cut(part: np.ndarray, breaks: tuple[tuple[int, int, int], ...]) -> np.ndarray:
        # NaN where one of the part's steps (axis, dr, dc) crosses a discontinuity
        if jp is not None:
            bad = np.zeros(part.shape, bool)
            for a, dr, dc in breaks:
                bad |= jp[a][base + dr * stride + dc]
            np.copyto(part, np.nan, where=bad)
        return part

    def mean_of(parts: list[np.ndarray], step: np.float32, least: int) -> np.ndarray:
        # sum of the valid parts over the sum of their steps, NaN below `least` parts
        total = np.zeros(idx.size, np.float32)
        count = np.zeros(idx.size, np.int8)
        for part in parts:
            ok = ~np.isnan(part)
            np.copyto(part, 0, where=~ok)
            total += part
            count += ok
        with np.errstate(invalid="ignore", divide="ignore"):
            res = total / (count * step) if step != 1 else total / count
        np.copyto(res, np.nan, where=count < least)
        return res

    one = np.float32(1)
    r0 = mean_of([cut(g(k, -1) - 2 * g(k, 0) + g(k, 1), ((0, k, -1), (0, k, 0)))
                  for k in (-1, 0, 1)], one, 2)
    r90 = mean_of([cut(g(-1, k) - 2 * g(0, k) + g(1, k), ((2, -1, k), (2, 0, k)))
                   for k in (-1, 0, 1)], one, 2)
    c2 = 2 * g(0, 0)
    s4 = g(-1, 0) + g(0, -1)
    s4 += g(0, 1)
    s4 += g(1, 0)
    diag = []
    # (centre diagonal, its steps), (L-pair ends, the L's four steps), for 45 and 135 deg
    for (a, b), cbreaks, (e0, e1), lbreaks in (
        (((-1, -1), (1, 1)), ((1, -1, -1), (1, 0, 0)), ((-1, 1), (1, -1)),
         ((0, -1, 0), (2, -1, 1), (2, 0, -1), (0, 1, -1))),
        (((-1, 1), (1, -1)), ((3, -1, 1), (3, 0, 0)), ((-1, -1), (1, 1)),
         ((0, -1, -1), (2, -1, -1), (2, 0, 1), (0, 1, 0))),
    ):
        centre = cut(g(*a) - c2 + g(*b), cbreaks)
        ell = cut(s4 - 2 * (g(*e0) + g(*e1)), lbreaks)    # two half-step L's, step sqrt 2
        diag.append(mean_of([centre, ell], _SQRT2, 1))
    return [r0, diag[0], r90, diag[1]]
