"""Normals of least-squares planes fitted to square blocks of measured points, the noise
each fitted normal carries, and the bend between the blocks on either side of a pixel.

Analysis layer: compiled loops over arrays (Numba), used by :func:`rangesim.edges.normal`
on noisy scans.

The noise law. A plane ``z = a x + b y + c`` fitted by least squares to ``n`` points of a
block, each with depth noise ``sigma`` (mm), has slopes of covariance
``sigma^2 M^-1``, where ``M`` is the 2 x 2 scatter matrix of the points' lateral positions
about their centroid. For a full square block of side ``b`` pixels of footprint ``s`` (mm)
seen head-on, ``M = n s^2 (b^2 - 1) / 12`` per axis, so each slope has the standard
deviation

    sigma / (s sqrt(n) e),   e = sqrt((b^2 - 1) / 12) pixels (the RMS extent about the centre)

radians, ``sqrt(12) sigma / (s b^2)`` for large blocks: a normal quietens as the square of
the block's side (a 3 x 3 block's normal is 2.4 times noisier per axis than a 5 x 5's at the
same depth noise, 5.2 times than a 7 x 7's). A face slanted by ``t`` from the view keeps
``cos t`` of a slope error across the slant and ``cos^2 t`` along it (the unit normal
``(a, b, -1) / sqrt(1 + a^2 + b^2)``): the angle variance of a fitted normal is

    v = (tr C - g' C g / q^2) / q^2,   C = sigma^2 M^-1,  g = (a, b),  q^2 = 1 + |g|^2

(:func:`block_planes`, with ``sigma^2`` the mean predicted variance of the block's points).
Two blocks fitted to one plane give normals whose angle is, for small independent errors,
Rayleigh-like with ``angle^2 / (v_A + v_B)`` about exponential: ``P(angle > k sqrt(v_A +
v_B)) = exp(-k^2)``, so the detector's ``k = 4`` (:data:`~rangesim.edges._normal_blocks.BLOCK_K`)
is a false alarm rate of ``1e-7`` per pair.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["block_planes", "block_pair_bends", "normal_angle_std", "noise_gain", "MAX_SLOPE_VAR"]

#: largest predicted slope variance (rad^2, both axes summed) of a block that is fitted: the
#: law is linearised and holds for small slope errors; a block whose slopes scatter by an RMS
#: 0.7 rad is degenerate (a sliver of pixels at the image border); 0.1 cost F1 on tuning seeds)
MAX_SLOPE_VAR = 1.0


def normal_angle_std(sigma: float, spacing: float, b: int) -> float:
    """The predicted RMS angle (radians) of the normal of a plane fitted to a full ``b x b``
    block seen head-on, depth noise ``sigma`` and pixel footprint ``spacing`` (same units):
    ``sqrt(2) sigma / (spacing sqrt(n) e)`` with ``n = b^2`` and ``e = sqrt((b^2 - 1) / 12)``
    (two slopes, each ``sigma / (spacing sqrt(n) e)``)."""
    n = b * b
    e = np.sqrt((b * b - 1) / 12.0)
    return float(np.sqrt(2.0) * sigma / (spacing * np.sqrt(n) * e))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _own_side(xyz, use, bad, s2, ref, i, j, r, q, stack, seen):  # pragma: no cover - compiled
    """The sums of :func:`block_planes` (``q[0..9]``) over the pixels of the block centred
    at ``(i, j)`` (half side ``r``) that are joined to its centre inside the block by
    4-neighbour steps through used pixels that are not ``bad``: the centre's own side of a
    depth jump (whose pixels either side are bad) or of a gap (unmeasured pixels). False
    where the centre itself is unused or bad."""
    _, h, w = xyz.shape
    if not use[i, j] or bad[i, j]:
        return False
    b = 2 * r + 1
    seen[:] = False
    for k in range(10):
        q[k] = 0.0
    top = 0
    stack[0] = r * b + r
    seen[r * b + r] = True
    top = 1
    while top > 0:
        top -= 1
        cell = stack[top]
        di, dj = cell // b, cell % b
        y0, x0 = i - r + di, j - r + dj
        x = xyz[0, y0, x0] - ref[0]
        y = xyz[1, y0, x0] - ref[1]
        z = xyz[2, y0, x0] - ref[2]
        q[0] += 1.0
        q[1] += x
        q[2] += y
        q[3] += z
        q[4] += x * x
        q[5] += x * y
        q[6] += y * y
        q[7] += x * z
        q[8] += y * z
        q[9] += s2[y0, x0]
        for ei, ej in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            ni, nj = di + ei, dj + ej
            if ni < 0 or ni >= b or nj < 0 or nj >= b:
                continue
            c2 = ni * b + nj
            if seen[c2]:
                continue
            seen[c2] = True
            yy, xx = i - r + ni, j - r + nj
            if yy < 0 or yy >= h or xx < 0 or xx >= w:
                continue
            if use[yy, xx] and not bad[yy, xx]:
                stack[top] = c2
                top += 1
    return True


@numba.njit(cache=True, nogil=True, error_model="numpy")
def block_planes(xyz, use, bad, s2, b, min_fill, normal, var, centroid, max_slope_var=MAX_SLOPE_VAR):  # pragma: no cover - compiled
    """Least-squares planes ``z = a x + b y + c`` on the ``b x b`` block centred at every pixel.

    Parameters
    ----------
    xyz : (3, H, W) float32
        Measured points, camera frame, mm.
    use : (H, W) bool
        Points that enter the fits (valid).
    bad : (H, W) bool
        Points beside a depth jump. A block holding one, or cut by unmeasured pixels (away
        from the image border), is fitted on its centre's own side only: the points joined
        to the centre inside the block through used, not bad points (:func:`_own_side`); a
        bad or unused centre is not fitted.
    s2 : (H, W) float32
        Predicted depth variance of each point, mm^2 (0: noise-free).
    b : int
        Odd block side, pixels.
    min_fill : float
        Least share of the block's pixels that must be used.
    normal, var, centroid : float32 arrays
        Written (below).

    Returns
    -------
    normal : (3, H, W) float32
        Unit normal facing the camera; NaN where the block is not fitted.
    var : (H, W) float32
        The normal's predicted angle variance, rad^2 (module docstring); NaN where the
        block is not fitted, +inf where its slopes are too noisy (:data:`MAX_SLOPE_VAR`).
    centroid : (3, H, W) float32
        Mean of the block's used points.
    """
    _, h, w = xyz.shape
    r = b // 2
    # a reference point near the data: the block sums are of small numbers
    ref = np.zeros(3)
    cnt = 0
    for i in range(0, h, 7):
        for j in range(0, w, 7):
            if use[i, j]:
                for c in range(3):
                    ref[c] += xyz[c, i, j]
                cnt += 1
    if cnt > 0:
        ref /= cnt
    nq = 11
    col = np.zeros((nq, w))            # sums over the rows i - r .. i + r, per column
    q = np.zeros(nq)
    normal[...] = np.nan
    var[...] = np.nan
    centroid[...] = np.nan
    need = max(3.0, min_fill * b * b)
    full = b * b - 0.5
    side = np.zeros(nq)
    stack = np.empty(b * b, np.int64)
    seen = np.zeros(b * b, np.bool_)
    for i in range(-r, h + r):
        # add row i + r, drop row i - r - 1
        for sgn, row in ((1.0, i + r), (-1.0, i - r - 1)):
            if row < 0 or row >= h:
                continue
            for j in range(w):
                if bad[row, j]:
                    col[10, j] += sgn
                if not use[row, j]:
                    continue
                x = xyz[0, row, j] - ref[0]
                y = xyz[1, row, j] - ref[1]
                z = xyz[2, row, j] - ref[2]
                col[0, j] += sgn
                col[1, j] += sgn * x
                col[2, j] += sgn * y
                col[3, j] += sgn * z
                col[4, j] += sgn * x * x
                col[5, j] += sgn * x * y
                col[6, j] += sgn * y * y
                col[7, j] += sgn * x * z
                col[8, j] += sgn * y * z
                col[9, j] += sgn * s2[row, j]
        if i < 0 or i >= h:
            continue
        for k in range(nq):
            q[k] = 0.0
        for j in range(-r, w + r):
            jn, jo = j + r, j - r - 1
            if jn < w:
                for k in range(nq):
                    q[k] += col[k, jn]
            if jo >= 0:
                for k in range(nq):
                    q[k] -= col[k, jo]
            if j < 0 or j >= w:
                continue
            qq = q
            if q[10] > 0.5 or (q[0] < full and i >= r and i < h - r and j >= r and j < w - r):
                # cut by a jump or a gap: only the centre's own side is fitted
                if not _own_side(xyz, use, bad, s2, ref, i, j, r, side, stack, seen):
                    continue
                qq = side
            n = qq[0]
            if n < need:
                continue
            mx, my, mz = qq[1] / n, qq[2] / n, qq[3] / n
            cxx = qq[4] - qq[1] * mx
            cxy = qq[5] - qq[1] * my
            cyy = qq[6] - qq[2] * my
            cxz = qq[7] - qq[1] * mz
            cyz = qq[8] - qq[2] * mz
            det = cxx * cyy - cxy * cxy
            if not det > 1e-12 * (cxx + cyy) * (cxx + cyy):
                continue
            ga = (cxz * cyy - cyz * cxy) / det
            gb = (cyz * cxx - cxz * cxy) / det
            q2 = 1.0 + ga * ga + gb * gb
            sq = np.sqrt(q2)
            px, py, pz = mx + ref[0], my + ref[1], mz + ref[2]
            nx, ny, nz = ga / sq, gb / sq, -1.0 / sq
            if nx * px + ny * py + nz * pz > 0:
                nx, ny, nz = -nx, -ny, -nz
            sig2 = max(qq[9], 0.0) / n
            # C = sig2 M^-1, M^-1 = [[cyy, -cxy], [-cxy, cxx]] / det
            tr = sig2 * (cxx + cyy) / det
            if tr > max_slope_var:
                # the linearised noise holds for small slope errors only (a noisy slope
                # makes the fitted face look slanted, and slanted faces look quiet): a
                # normal this noisy is of no use for a crease anyway (infinite: too noisy,
                # where NaN is not fitted)
                var[i, j] = np.inf
                continue
            normal[0, i, j] = nx
            normal[1, i, j] = ny
            normal[2, i, j] = nz
            centroid[0, i, j] = px
            centroid[1, i, j] = py
            centroid[2, i, j] = pz
            gcg = sig2 * (ga * ga * cyy - 2 * ga * gb * cxy + gb * gb * cxx) / det
            var[i, j] = (tr - gcg / q2) / q2
    return normal, var, centroid


@numba.njit(cache=True, nogil=True, error_model="numpy")
def block_pair_bends(normals, variances, centroids, halves, floors, k):  # pragma: no cover - compiled
    """Bend between the blocks either side of each pixel, along the four axes, at the
    smallest block whose noise allows the floor, and the crease test.

    For each axis ``d`` of ``AXES`` and each block size (ascending; ``normals[s]`` etc. from
    :func:`block_planes` with half side ``halves[s]``), the pair is the blocks centred at
    ``p - r d`` and ``p + r d`` (both hold ``p``: a crease through ``p`` separates them
    cleanly, one a pixel away puts a row of the other face into one block, so the bend
    peaks on the crease). The pair's threshold is ``t = max(floors[s], k sqrt(v_A + v_B))``
    (rad). The first size whose pair is fitted and whose noise term is at most its floor is
    taken; failing that the fitted size with the least threshold. Bends are compared as
    chords ``|n_A - n_B| = 2 sin(angle / 2)`` (against ``2 sin(t / 2)``; no arc cosine per
    pair).

    Returns
    -------
    chord : (4, H, W) float32
        ``|n_A - n_B|`` per axis (0 where no size has a fitted pair): the bend's rank.
    strength : (H, W) float32
        Bend, degrees, of the axis with the largest bend over threshold (NaN where no axis
        has a pair).
    ratio : (H, W) float32
        That axis's chord over its threshold's (-1 where no axis has a pair).
    concave : (H, W) bool
        ``(c_B - c_A) . (n_A - n_B) > 0`` on that axis (c the blocks' centroids): a valley;
        negative on a roof (convex).
    """
    ns, _, h, w = normals.shape
    chord = np.zeros((4, h, w), np.float32)
    ratio = np.full((h, w), -1.0, np.float32)
    pick = np.zeros((h, w), np.int8)      # 4 * size + axis of the best pair
    k2 = np.float32(k * k)
    fl2 = np.empty(ns, np.float32)
    for s in range(ns):
        fl2[s] = floors[s] * floors[s]
    best = np.empty(w, np.float32)
    sel = np.empty(w, np.int64)
    done = np.empty(w, np.bool_)
    for a in range(4):  # one axis, one row at a time: contiguous runs of pixels
        dr, dc = (0, 1) if a == 0 else (1, 1) if a == 1 else (1, 0) if a == 2 else (1, -1)
        for i in range(h):
            best[:] = np.inf
            sel[:] = -1
            done[:] = False
            for s in range(ns):
                r = halves[s]
                ia, ib = i - r * dr, i + r * dr
                if ia < 0 or ib >= h:
                    continue
                j0, j1 = r * abs(dc), w - r * abs(dc)
                va, vb = variances[s, ia], variances[s, ib]
                for j in range(j0, j1):
                    if done[j]:
                        continue
                    n2 = k2 * (va[j - r * dc] + vb[j + r * dc])
                    if not n2 >= 0:
                        continue
                    t2 = max(fl2[s], n2)
                    if t2 < best[j]:
                        best[j] = t2
                        sel[j] = s
                    if n2 <= fl2[s]:
                        done[j] = True
            for j in range(w):
                sa = sel[j]
                if sa < 0:
                    continue
                r = halves[sa]
                ia, ja, ib, jb = i - r * dr, j - r * dc, i + r * dr, j + r * dc
                d0 = normals[sa, 0, ia, ja] - normals[sa, 0, ib, jb]
                d1 = normals[sa, 1, ia, ja] - normals[sa, 1, ib, jb]
                d2 = normals[sa, 2, ia, ja] - normals[sa, 2, ib, jb]
                c = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                chord[a, i, j] = c
                t = np.sqrt(best[j])
                q = c / (t - t * t * t / np.float32(24))    # 2 sin(t / 2), to 1e-4 at 1 rad
                if q > ratio[i, j]:
                    ratio[i, j] = q
                    pick[i, j] = 4 * sa + a
    strength = np.full((h, w), np.nan, np.float32)
    concave = np.zeros((h, w), np.bool_)
    deg = np.float32(360.0 / np.pi)
    for i in range(h):
        for j in range(w):
            if ratio[i, j] < 0:
                continue
            sa, a = pick[i, j] // 4, pick[i, j] % 4
            dr, dc = (0, 1) if a == 0 else (1, 1) if a == 1 else (1, 0) if a == 2 else (1, -1)
            r = halves[sa]
            ia, ja, ib, jb = i - r * dr, j - r * dc, i + r * dr, j + r * dc
            strength[i, j] = deg * np.arcsin(min(np.float32(1), np.float32(0.5) * chord[a, i, j]))
            sd = np.float32(0)
            for cc in range(3):
                sd += ((centroids[sa, cc, ib, jb] - centroids[sa, cc, ia, ja])
                       * (normals[sa, cc, ia, ja] - normals[sa, cc, ib, jb]))
            concave[i, j] = sd > 0
    return chord, strength, ratio, concave


#: median of ``angle / sqrt(v_A + v_B)`` for two fits of one plane (Rayleigh: sqrt(ln 2))
RAYLEIGH_MEDIAN = float(np.sqrt(np.log(2.0)))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pair_ratios(normal, var, r, stride):  # pragma: no cover - compiled
    """``angle / sqrt(v_A + v_B)`` of the row and column pairs (blocks at ``p -+ r d``) on
    every ``stride``-th row and column, where both blocks are fitted and carry noise."""
    _, h, w = normal.shape
    out = np.empty(2 * ((h + stride - 1) // stride) * ((w + stride - 1) // stride), np.float32)
    m = 0
    for i in range(0, h, stride):
        for j in range(0, w, stride):
            for dr, dc in ((0, 1), (1, 0)):
                ia, ja, ib, jb = i - r * dr, j - r * dc, i + r * dr, j + r * dc
                if ia < 0 or ja < 0 or ib >= h or jb >= w:
                    continue
                v = var[ia, ja] + var[ib, jb]
                if not (v > 0 and v < np.inf):
                    continue
                c = (normal[0, ia, ja] * normal[0, ib, jb] + normal[1, ia, ja] * normal[1, ib, jb]
                     + normal[2, ia, ja] * normal[2, ib, jb])
                out[m] = np.arccos(min(1.0, max(-1.0, c))) / np.sqrt(v)
                m += 1
    return out[:m]


def noise_gain(normal: np.ndarray, var: np.ndarray, r: int, stride: int = 2) -> float:
    """How much noisier the fitted normals are than predicted, measured on the scan: the
    median of ``angle / sqrt(v_A + v_B)`` over pairs of blocks either side of the pixels,
    over its value for independent errors (:data:`RAYLEIGH_MEDIAN`), squared (a variance
    factor), at least 1. Creases cover a few percent of the pixels and barely move the
    median; errors correlated over the block (a sensor whose noise field is smoothed over
    its speckle grains) do not average down as ``1 / n`` and raise it."""
    ratios = _pair_ratios(normal, var, int(r), int(stride))
    if ratios.size < 100:
        return 1.0
    return max(1.0, float(np.median(ratios)) / RAYLEIGH_MEDIAN) ** 2
