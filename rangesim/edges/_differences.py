"""Discontinuity-aware finite differences and normals of depth and point images.

Analysis layer: pure NumPy over arrays. Differences never cross a NaN or a depth
discontinuity (the ``pairs`` of :class:`~rangesim.edges._discontinuities.Discontinuities`):
:func:`central_difference` falls back to the one-sided difference that is usable,
:func:`eno_tangent` blends the two sides with WENO weights so that tangents stay those of
the pixel's own face up to a crease, and :func:`measured_normals` crosses those tangents
into unit normals facing the camera, sharp at creases.
"""
from __future__ import annotations

import numba
import numpy as np

from rangesim.edges._discontinuities import segment_broken
from rangesim.edges._grid import AXES, pad_last2, padded_view

__all__ = ["central_difference", "eno_tangent", "measured_normals", "normals_from_tangents", "dot3"]


def side_samples(a: np.ndarray, ok: np.ndarray, pairs: np.ndarray | None, axis: int,
                 s: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``a(p + s d)`` and ``a(p - s d)`` along ``AXES[axis]`` (NaN outside the image) and
    whether each side is usable: ``ok`` at both ends and no discontinuity (``pairs``) on the
    ``s`` steps between. ``a`` is (..., H, W), ``ok`` (H, W)."""
    dr, dc = AXES[axis]
    shape = ok.shape
    okp = pad_last2(ok, s, False)
    fok = padded_view(okp, s, s * dr, s * dc, shape) & ok
    bok = padded_view(okp, s, -s * dr, -s * dc, shape) & ok
    if pairs is not None:
        fok &= ~segment_broken(pairs, axis, 0, s)
        bok &= ~segment_broken(pairs, axis, -s, 0)
    ap = pad_last2(a, s, np.nan)
    return padded_view(ap, s, s * dr, s * dc, shape), padded_view(ap, s, -s * dr, -s * dc, shape), fok, bok


def _sides(a: np.ndarray, axis: int, pairs: np.ndarray | None, step: int) -> tuple[np.ndarray, ...]:
    """End points of the discontinuity-aware difference of ``a`` (..., H, W) along an axis.

    Returns (A, B, n): ``A`` is ``a(p + s d)`` where that side is usable (valid, no jump in
    between) else ``a(p)``, ``B`` likewise on the minus side, ``n`` the number of usable
    sides (0, 1, 2) as float32, so ``(A - B) / (s n)`` is the central or one-sided difference.
    """
    ok = ~np.isnan(a if a.ndim == 2 else a[0])
    fwd, bwd, fok, bok = side_samples(a, ok, pairs, axis, int(step))
    A = np.where(fok, fwd, a)
    B = np.where(bok, bwd, a)
    return A, B, fok.view(np.int8) + bok.view(np.int8)


def central_difference(
    a: np.ndarray, axis: int, pairs: np.ndarray | None, step: int = 1
) -> np.ndarray:
    """Derivative of ``a`` per pixel along ``AXES[axis]`` (0: x, 2: y; any of the four).

    Central difference ``(a(p + s d) - a(p - s d)) / 2s`` where both sides are valid and no
    discontinuity lies between; otherwise the one-sided difference that is; NaN if neither.

    Parameters
    ----------
    a : (H, W) or (C, H, W) float array
        Image or component-major stack (a pixel is valid where ``a`` (its first component)
        is not NaN).
    axis : int
        Index into ``AXES``.
    pairs : (4, H, W) bool or None
        Discontinuity pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`);
        differences never cross them.
    step : int
        Half-width s, pixels.

    Returns
    -------
    array like ``a``
    """
    if a.ndim == 2 and a.dtype.kind == "f":
        return _central_difference_2d(a, axis, pairs, int(step))
    A, B, n = _sides(a, axis, pairs, step)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = (A - B) / (n * np.asarray(step, a.dtype))
    return d.astype(a.dtype, copy=False)


def _central_difference_2d(a: np.ndarray, axis: int, pairs: np.ndarray | None, s: int) -> np.ndarray:
    """:func:`central_difference` of an image: plainly, then exactly where a side is unusable.

    The central difference is computed for every pixel; only pixels with an invalid
    neighbour (a NaN result) or a broken pair on either side, a few percent, take the rule
    of :func:`_sides` (sparse, the same operations, so both agree to the bit).
    """
    dr, dc = AXES[axis]
    if s == 1 and dr * dc == 0:
        # the image axes at one pixel: one compiled pass (about 1.6x faster at 1024^2)
        broken = np.zeros((1, 1), bool) if pairs is None else np.ascontiguousarray(pairs[axis])
        return _axis_difference(np.ascontiguousarray(a), broken, pairs is not None, dr, dc)
    shape = a.shape
    ap = pad_last2(a, s, np.nan)
    d = padded_view(ap, s, s * dr, s * dc, shape) - padded_view(ap, s, -s * dr, -s * dc, shape)
    two_s = np.asarray(2 * s, a.dtype)
    d /= two_s
    ok = ~np.isnan(a)
    redo = np.isnan(d)
    if pairs is not None:
        fbroken = segment_broken(pairs, axis, 0, s)
        bbroken = segment_broken(pairs, axis, -s, 0)
        redo |= fbroken
        redo |= bbroken
    redo &= ok
    np.copyto(d, np.nan, where=~ok)
    idx = np.flatnonzero(redo)
    if idx.size == 0:
        return d
    h, w = shape
    r_, c_ = np.divmod(idx, w)
    stride = w + 2 * s
    base = (r_ + s) * stride + (c_ + s)
    off = s * dr * stride + s * dc
    flat = ap.ravel()
    centre = flat[base]
    fwd, bwd = flat[base + off], flat[base - off]
    fok, bok = ~np.isnan(fwd), ~np.isnan(bwd)
    if pairs is not None:
        fok &= ~fbroken.ravel()[idx]
        bok &= ~bbroken.ravel()[idx]
    A = np.where(fok, fwd, centre)
    B = np.where(bok, bwd, centre)
    n = fok.view(np.int8) + bok.view(np.int8)
    with np.errstate(invalid="ignore", divide="ignore"):
        d.ravel()[idx] = (A - B) / (n * np.asarray(s, a.dtype))
    return d


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _axis_difference(a, broken, use_pairs, dr, dc):  # pragma: no cover - compiled
    """:func:`_central_difference_2d` along x (``dr, dc = 0, 1``) or y (1, 0) at one pixel:
    first the central difference at every pixel (plain loops that vectorise), then the
    rule of :func:`_sides` where a side is missing or broken, in ``a``'s dtype (the same
    bits as the array version)."""
    h, w = a.shape
    out = np.empty((h, w), a.dtype)
    nan = a.dtype.type(np.nan)
    two = a.dtype.type(2)
    for i in range(h):
        o = out[i]
        if dr == 0:
            row = a[i]
            o[0] = nan
            o[w - 1] = nan
            fw, bw, oc = row[2:w], row[0:w - 2], o[1:w - 1]     # aligned slices: vectorises
            for j in range(w - 2):
                oc[j] = (fw[j] - bw[j]) / two
        elif i == 0 or i == h - 1:
            o[:] = nan
        else:
            up, dn = a[i - 1], a[i + 1]
            for j in range(w):
                o[j] = (dn[j] - up[j]) / two
    # the pixels to redo, flagged a row at a time by loops that vectorise, then visited in
    # blocks of _BLOCK (a vectorised count skips clear ones: a branch on every pixel cost
    # five times the plain pass)
    flag = np.empty(w, np.uint8)
    for i in range(h):
        o, row = out[i], a[i]
        for j in range(w):
            flag[j] = (o[j] != o[j]) | (row[j] != row[j])
        if use_pairs:
            b = broken[i]
            for j in range(w):
                flag[j] |= b[j]
            if dr == 0:
                bp, fs = b[0:w - 1], flag[1:w]        # the pair (i, j - 1)-(i, j)
                for j in range(w - 1):
                    fs[j] |= bp[j]
            elif i >= 1:
                bp = broken[i - 1]                    # the pair (i - 1, j)-(i, j)
                for j in range(w):
                    flag[j] |= bp[j]
        left = 0
        for j in range(w):
            left += flag[j]
        for c0 in range(0, w, _BLOCK):
            if left == 0:
                break
            c1 = min(c0 + _BLOCK, w)
            n = 0
            for j in range(c0, c1):
                n += flag[j]
            if n == 0:
                continue
            left -= n
            for j in range(c0, c1):
                if flag[j]:
                    _redo_difference(a, broken, use_pairs, dr, dc, out, i, j)
    return out


#: pixels per block of :func:`_axis_difference`'s sparse pass
_BLOCK = 32


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _redo_difference(a, broken, use_pairs, dr, dc, out, i, j):  # pragma: no cover - compiled
    """The rule of :func:`_sides` at pixel (i, j) of :func:`_axis_difference` (in place)."""
    h, w = a.shape
    nan = a.dtype.type(np.nan)
    two, one = a.dtype.type(2), a.dtype.type(1)
    c = a[i, j]
    if c != c:
        out[i, j] = nan
        return
    fi, fj, bi, bj = i + dr, j + dc, i - dr, j - dc
    f = a[fi, fj] if fi < h and fj < w else nan
    b = a[bi, bj] if bi >= 0 and bj >= 0 else nan
    fok = f == f and not (use_pairs and broken[i, j])
    bok = b == b and not (use_pairs and broken[bi, bj])
    if fok and bok:
        out[i, j] = (f - b) / two
    else:
        n = (1 if fok else 0) + (1 if bok else 0)
        out[i, j] = ((f if fok else c) - (b if bok else c)) / (n * one)


#: WENO regulariser, relative to the squared step length (smaller: sharper side choice)
_WENO_EPS = 1e-4


def eno_tangent(xyz: np.ndarray, axis: int, pairs: np.ndarray | None, step: int = 1) -> np.ndarray:
    """Edge-preserving tangent of a point image along an axis (WENO-weighted differences).

    The forward difference ``P(p + s d) - P(p)`` and the backward one ``P(p) - P(p - s d)``
    are blended with weights ``1 / (eps + S)^2``, S the squared norm of the second
    difference that continues each side (``P(p + 2s d) - 2 P(p + s d) + P(p)``, and its
    mirror): on a smooth surface both are small and the blend is the central difference;
    next to a crease the side that straddles it has a large S and drops out, so the
    tangent (and the normal) stays that of the pixel's own face right up to the crease
    instead of mixing both faces over ``s`` pixels. Sides that are invalid or cross a
    discontinuity are not used; a side whose continuation is unknown has S = infinity.

    Parameters
    ----------
    xyz : (3, H, W) float array
        Points, component-major, NaN where invalid.
    axis : int
        Index into ``AXES`` (0: x, 2: y).
    pairs : (4, H, W) bool or None
        Discontinuity pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`).
    step : int
        Difference step s, pixels.

    Returns
    -------
    (3, H, W) array
        Tangent per pixel step (mm / px); NaN where neither side is usable.
    """
    dr, dc = AXES[axis]
    s = int(step)
    shape = xyz.shape[-2:]
    # the compiled blend reads components 0-2 and indexes ok_step by xyz's image: unchecked
    # there (no bounds checks), so a point stack of another shape is refused here
    if xyz.ndim != 3 or xyz.shape[0] != 3 or (pairs is not None and np.shape(pairs)[-2:] != shape):
        raise ValueError(f"eno_tangent needs (3, H, W) points and (4, H, W) pairs, got {xyz.shape} and "
                         f"{None if pairs is None else np.shape(pairs)}")
    if pairs is not None:
        ok_step = np.stack([~segment_broken(pairs, axis, k * s, (k + 1) * s) for k in (-2, -1, 0, 1)])
    else:
        ok_step = np.ones((4,) + shape, bool)
    return _weno_blend(np.ascontiguousarray(xyz), ok_step, s * dr, s * dc)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _energy(xyz, ai, aj, bi, bj, ci, cj):  # pragma: no cover - compiled
    """``|P(a) - 2 P(b) + P(c)|^2`` in the array form's order: ``((a - 2 b) + c)`` per
    component, the squares summed x, y, then z."""
    two = np.float32(2)
    v0 = (xyz[0, ai, aj] - two * xyz[0, bi, bj]) + xyz[0, ci, cj]
    v1 = (xyz[1, ai, aj] - two * xyz[1, bi, bj]) + xyz[1, ci, cj]
    v2 = (xyz[2, ai, aj] - two * xyz[2, bi, bj]) + xyz[2, ci, cj]
    return (v0 * v0 + v1 * v1) + v2 * v2


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _weno_blend(xyz, ok_step, dr, dc):  # pragma: no cover - compiled
    """:func:`eno_tangent` per pixel, in xyz's precision and the order of operations of its
    array form (to the bit): sides ``fwd = P(p + d) - P(p)``, ``bwd = P(p) - P(p - d)``
    where usable (valid, ``ok_step`` of the step), continuation energies ``f2``, ``b2``
    (1e30 where unknown), weights ``1 / (eps + S)^2`` normalised, blended."""
    _, h, w = xyz.shape
    out = np.empty_like(xyz)
    # float32 constants, as the array form's (float64 points promote them, as NumPy does)
    one, zero = np.float32(1), np.float32(0)
    big, weno, tiny = np.float32(1e30), np.float32(_WENO_EPS), np.float32(1e-30)
    f = np.empty(3, xyz.dtype)
    b = np.empty(3, xyz.dtype)
    for i in range(h):
        for j in range(w):
            ok = not np.isnan(xyz[0, i, j])
            i1, j1, i2, j2 = i + dr, j + dc, i + 2 * dr, j + 2 * dc
            k1, l1, k2, l2 = i - dr, j - dc, i - 2 * dr, j - 2 * dc
            op1 = 0 <= i1 < h and 0 <= j1 < w and not np.isnan(xyz[0, i1, j1])
            op2 = 0 <= i2 < h and 0 <= j2 < w and not np.isnan(xyz[0, i2, j2])
            om1 = 0 <= k1 < h and 0 <= l1 < w and not np.isnan(xyz[0, k1, l1])
            om2 = 0 <= k2 < h and 0 <= l2 < w and not np.isnan(xyz[0, k2, l2])
            fok = ok and op1 and ok_step[2, i, j]
            bok = ok and om1 and ok_step[1, i, j]
            for c in range(3):
                f[c] = xyz[c, i1, j1] - xyz[c, i, j] if fok else zero
                b[c] = xyz[c, i, j] - xyz[c, k1, l1] if bok else zero
            # continuation energies |a - 2 b + c|^2 of each side (1e30 where unknown)
            f2 = _energy(xyz, i2, j2, i1, j1, i, j) if fok and op2 and ok_step[3, i, j] else big
            b2 = _energy(xyz, i, j, k1, l1, k2, l2) if bok and om2 and ok_step[0, i, j] else big
            ff = (f[0] * f[0] + f[1] * f[1]) + f[2] * f[2]
            bb = (b[0] * b[0] + b[1] * b[1]) + b[2] * b[2]
            eps = weno * (ff + bb) + tiny
            df, db = eps + f2, eps + b2
            wf = (one if fok else zero) / (df * df)
            wb = (one if bok else zero) / (db * db)
            total = wf + wb
            wf /= total
            wb /= total
            for c in range(3):
                out[c, i, j] = f[c] * wf + b[c] * wb
    return out


def measured_normals(xyz: np.ndarray, pairs: np.ndarray | None, step: int = 1) -> np.ndarray:
    """Unit surface normals from the measured points, facing the camera, sharp at creases.

    The cross product of the edge-preserving tangents along image y and x
    (:func:`eno_tangent`): on smooth surfaces the central-difference normal over
    ``step`` pixels each side, next to a crease the normal of the pixel's own face (one-sided
    differences away from the crease), so normals change abruptly where the surface does.
    Differences never cross a NaN or a depth discontinuity.

    Parameters
    ----------
    xyz : (3, H, W) float array
        Points, component-major, camera frame (origin at the viewpoint), NaN where invalid.
    pairs : (4, H, W) bool or None
        Discontinuity pairs (:class:`~rangesim.edges._discontinuities.Discontinuities`);
        differences never cross them.
    step : int
        Difference step, pixels (larger: smoother normals on noisy data).

    Returns
    -------
    (3, H, W) array of xyz's dtype
        Unit normals with ``n . p <= 0`` (towards the camera); NaN where a tangent is missing.
    """
    return normals_from_tangents(eno_tangent(xyz, 0, pairs, step), eno_tangent(xyz, 2, pairs, step), xyz)


def normals_from_tangents(tx: np.ndarray, ty: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Unit normals ``ty x tx`` of (3, H, W) x- and y-tangents, turned towards the camera.

    ``ty x tx`` points towards the camera (-z) for an image of a visible surface; where it
    does not (``n . p > 0``, ``xyz`` the points) it is flipped. NaN where the cross product
    vanishes or a tangent is missing.
    """
    n = np.stack([ty[1] * tx[2] - ty[2] * tx[1],
                  ty[2] * tx[0] - ty[0] * tx[2],
                  ty[0] * tx[1] - ty[1] * tx[0]])
    norm = np.sqrt(dot3(n, n))
    facing = dot3(n, xyz)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(facing > 0, -1, 1).astype(n.dtype) / norm
    np.copyto(scale, np.nan, where=~(norm > 0))
    n *= scale
    return n


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel dot product of component-major (3, H, W) stacks."""
    out = a[0] * b[0]
    out += a[1] * b[1]
    out += a[2] * b[2]
    return out
