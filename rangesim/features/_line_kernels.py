"""Compiled loops of the line finder (Numba): the accumulator's local maxima, looked for only
at cells over the threshold, and the greedy suppression of peaks near stronger ones."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, error_model="numpy")
def window_maxima(acc, threshold, rd, ra):  # pragma: no cover - compiled
    """Cells (row-major order) of ``acc`` (H, A) at least ``threshold`` and no smaller than any
    cell of their (2 rd + 1) x (2 ra + 1) window (clipped to the array): what
    ``np.nonzero((acc == maximum_filter(acc, size, mode="constant")) & (acc >= threshold))``
    gives for a non-negative accumulator, visiting the window of the cells over the
    threshold only."""
    H, A = acc.shape
    di = np.empty(H * A, np.int64)
    ai = np.empty(H * A, np.int64)
    n = 0
    for i in range(H):
        for j in range(A):
            v = acc[i, j]
            if not v >= threshold:
                continue
            peak = True
            for ii in range(max(i - rd, 0), min(i + rd, H - 1) + 1):
                for jj in range(max(j - ra, 0), min(j + ra, A - 1) + 1):
                    if acc[ii, jj] > v:
                        peak = False
                        break
                if not peak:
                    break
            if peak:
                di[n] = i
                ai[n] = j
                n += 1
    return di[:n], ai[:n]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def suppress_near(di, ai, rd, ra, num_peaks):  # pragma: no cover - compiled
    """Indices of the peaks (strongest first) kept greedily: each more than ``rd`` rows or
    ``ra`` columns from every kept one; at most ``num_peaks``."""
    kept = np.empty(min(len(di), max(num_peaks, 0)), np.int64)
    m = 0
    for j in range(len(di)):
        if m == num_peaks:
            break
        near = False
        for q in range(m):
            k = kept[q]
            if abs(di[k] - di[j]) <= rd and abs(ai[k] - ai[j]) <= ra:
                near = True
                break
        if not near:
            kept[m] = j
            m += 1
    return kept[:m]
