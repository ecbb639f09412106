"""Compiled neighbour-pair tests of the jump rule (Numba): for every pixel and each of the four
axes, whether it and its neighbour are either side of a depth jump, with the fold test, in one
pass over the image (the array version pads and sweeps the image about forty times); and the
march of the search across NaN gaps (:func:`search_gaps`).

Arithmetic is float32, as the array version's, so the result is the same to the bit.
"""
from __future__ import annotations

import numba
import numpy as np

from rangesim.edges._grid import AXES

_AXES = np.array(AXES, np.int64)
_ONE = np.float32(1)
_TWO = np.float32(2)
_NAN = np.float32(np.nan)
#: pairs per block of the sparse pass of :func:`pair_tests`
_BLOCK = 32


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _at(a, i, j):  # pragma: no cover - compiled
    """``a[i, j]``, NaN outside the image (as the array version's NaN padding)."""
    if 0 <= i < a.shape[0] and 0 <= j < a.shape[1]:
        return a[i, j]
    return _NAN


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _fold(zn_i, zn_j, zf_i, zf_j, dr, dc, z, thr, perspective):  # pragma: no cover - compiled
    """Whether the broken pair (near pixel n, far pixel f = n + (dr, dc)) is a fold of one
    continuous surface: the far surface continued back reaches the near pixel, or the near
    surface continued forward reaches the far one (in inverse depth with ``perspective``)."""
    z_n, z_f = z[zn_i, zn_j], z[zf_i, zf_j]
    t_n = thr[zn_i, zn_j]
    zt_n = z_n + t_n
    beyond = _at(z, zf_i + dr, zf_j + dc)        # behind the far pixel, on its side
    behind = _at(z, zn_i - dr, zn_j - dc)        # behind the near pixel, on its side
    if perspective:
        far_back = _TWO * (_ONE / z_f) - _ONE / beyond      # 1 / (far surface at n)
        if far_back * zt_n >= _ONE:                            # pred <= zt_n, pred > 0
            return True
        near_fwd = _TWO * (_ONE / z_n) - _ONE / behind     # 1 / (near surface at f)
        return near_fwd * (z_f - t_n) <= _ONE                  # a receding surface reaches it
    if _TWO * z_f - beyond <= zt_n:
        return True
    return _TWO * z_n - behind >= z_f - t_n


@numba.njit(cache=True, nogil=True, error_model="numpy")
def pair_tests(z, thr, zt, folds, perspective, conn4, dominant):  # pragma: no cover - compiled
    """The jump rule's neighbour tests.

    Parameters
    ----------
    z, thr, zt : (H, W) float32
        Depth (NaN invalid), the per-pixel jump threshold and ``z + thr``, mm.
    folds, perspective, conn4, dominant : bool
        As :func:`~rangesim.edges._discontinuities.find_discontinuities` (``conn4``:
        connectivity 4; diagonal pairs then only enter ``pairs``).

    Returns
    -------
    occluding, occluded : (H, W) bool
    pairs : (4, H, W) bool
        Pairs (p, p + AXES[a]) broken by a jump, stored at p.
    far, near : (H, W) float32
        With ``dominant``: the largest depth difference to a farther / nearer neighbour
        (-inf where none); otherwise (1, 1) placeholders.
    """
    h, w = z.shape
    occluding = np.zeros((h, w), np.bool_)
    occluded = np.zeros((h, w), np.bool_)
    pairs = np.zeros((4, h, w), np.bool_)
    shape = (h, w) if dominant else (1, 1)
    far = np.full(shape, -np.inf, np.float32)
    near = np.full(shape, -np.inf, np.float32)
    for a in range(4):
        dr, dc = _AXES[a, 0], _AXES[a, 1]
        marks = not (conn4 and dr != 0 and dc != 0)
        j0, j1 = max(0, -dc), min(w, w - dc)
        for i in range(max(0, -dr), min(h, h - dr)):
            qi = i + dr
            zr, zqr, ztr, ztqr, pr = z[i], z[qi], zt[i], zt[qi], pairs[a, i]
            # a plain pass first (vectorised: jumps are a few per cent of the pairs) on row
            # slices aligned to the pair, so that no index is offset by the runtime dc (an
            # offset index kept LLVM from vectorising the loop: 4.5x slower) ...
            zs, zqs, zts, ztqs, ps = zr[j0:j1], zqr[j0 + dc:j1 + dc], ztr[j0:j1], ztqr[j0 + dc:j1 + dc], pr[j0:j1]
            broken = 0
            for k in range(j1 - j0):
                b = (zqs[k] > zts[k]) | (zs[k] > ztqs[k])     # NaN compares False
                ps[k] = b
                broken += b
            if dominant and marks:
                for j in range(j0, j1):
                    e = zqr[j + dc] - zr[j]                           # neighbour minus pixel
                    if e == e:
                        far[i, j] = max(far[i, j], e)
                        near[i, j] = max(near[i, j], -e)
                        far[qi, j + dc] = max(far[qi, j + dc], -e)
                        near[qi, j + dc] = max(near[qi, j + dc], e)
            # ... then the fold test and the marks on the broken pairs only: rows without one
            # skipped, the rest scanned in blocks of _BLOCK pairs (a vectorised count) up to
            # the row's last broken pair (a branch on every pair cost twice the plain pass)
            left = broken
            for c0 in range(j0, j1, _BLOCK):
                if left == 0:
                    break
                c1 = min(c0 + _BLOCK, j1)
                n = 0
                for j in range(c0, c1):
                    n += pr[j]
                if n == 0:
                    continue
                left -= n
                for j in range(c0, c1):
                    if not pr[j]:
                        continue
                    qj = j + dc
                    fwd = zqr[qj] > ztr[j]                    # p near, q far
                    bwd = zr[j] > ztqr[qj]                    # q near, p far
                    if folds:
                        if fwd and _fold(i, j, qi, qj, dr, dc, z, thr, perspective):
                            fwd = False
                        if bwd and _fold(qi, qj, i, j, -dr, -dc, z, thr, perspective):
                            bwd = False
                    pr[j] = fwd or bwd
                    if marks:
                        if fwd:
                            occluding[i, j] = True
                            occluded[qi, qj] = True
                        if bwd:
                            occluded[i, j] = True
                            occluding[qi, qj] = True
    return occluding, occluded, pairs, far, near


@numba.njit(cache=True, nogil=True, error_model="numpy")
def search_gaps(z, thr, shade, use_shade, si, sj, sx, sy, max_search):  # pragma: no cover - compiled
    """The search across NaN gaps of :func:`~rangesim.edges._discontinuities.find_discontinuities`:
    from each pixel (si, sj) step ``s`` = 1, 2, ... to ``(si, sj) + rint((sy, sx) * s)``
    (float32 products, rounded half to even, as the array form's) until a valid pixel, the
    image's edge or ``max_search`` steps; one pass per pixel instead of some ten NumPy calls
    per step on the shrinking set of active ones.

    Returns
    -------
    found_z, found_t : (N,) float64
        Depth and jump threshold of the valid pixel found (NaN: none).
    found_s : (N,) float64
        Its step (0: none).
    unlit_s : (N,) intp
        With ``use_shade``: the step of the first ``shade`` pixel passed before it (0: none).
    """
    n = si.size
    h, w = z.shape
    found_z = np.full(n, np.nan)
    found_t = np.full(n, np.nan)
    found_s = np.zeros(n)
    unlit_s = np.zeros(n, np.intp)
    for k in range(n):
        for s in range(1, max_search + 1):
            fs = np.float32(s)
            ri = si[k] + np.intp(np.rint(sy[k] * fs))
            rj = sj[k] + np.intp(np.rint(sx[k] * fs))
            if ri < 0 or ri >= h or rj < 0 or rj >= w:
                break
            zq = z[ri, rj]
            if np.isfinite(zq):
                found_z[k] = zq
                found_t[k] = thr[ri, rj]
                found_s[k] = s
                break
            if use_shade and unlit_s[k] == 0 and shade[ri, rj]:
                unlit_s[k] = s
    return found_z, found_t, found_s, unlit_s
