"""The one local surface fit behind every curvature estimate (meshes and scans alike).

For every centre point ``p0`` with a neighbourhood of 3D points ``q_j`` (weights ``w_j``):

1. a local frame (t1, t2, n): n is a given approximate normal, or the weighted PCA normal of
   the neighbourhood (smallest-variance direction), oriented by ``orient``;
2. local coordinates x = (q - p0).t1, y = (q - p0).t2, z = (q - p0).n, and a weighted
   least-squares fit of the height function

       h(x, y) = a x^2 + b x y + c y^2 + d x + e y + f

   solved for all centres at once as stacked 6 x 6 normal equations (coordinates scaled
   by each neighbourhood's radius so the systems are well conditioned);
3. the exact differential geometry of the Monge patch (x, y, h(x, y)) at x = y = 0:
   fitted normal, Gaussian K, mean H, principal curvatures k1 >= k2 and principal
   directions (the linear terms d, e mean the frame need not be exactly tangent).

Sign convention (used throughout ``rangesim.curvature``)
--------------------------------------------------------
Curvatures are measured against the unit normal ``m`` of the fitted surface, which lies on
the same side as the frame normal: for scans it faces the camera, for meshes it points
outwards. A normal curvature is the second fundamental form over the first,
``k = (r'' . m) / |r'|^2``, so it is **positive where the surface bends towards its
normal** (concave, seen from the normal's side) and **negative where it bends away**
(convex). Hence a sphere of radius r seen from outside (outward normal, or a scan of it)
has ``k1 = k2 = -1/r``, ``H = -1/r``, ``K = 1/r^2``; a convex cylinder has
``k1 = 0``, ``k2 = -1/r``, ``H = -1/(2r)``, ``K = 0``. This is Besl and Jain's
convention for range images (height towards the viewer, normal (-f_x, -f_y, 1)/w), in
which a peak has H < 0, and it is what ``L = S_uu . n`` gives on a parametric (e.g.
B-spline) surface with ``n = S_u x S_v / |S_u x S_v|`` pointing out of the solid -- the
convention of ``rangesim.cad.bspline.surface_curvatures``, whose numbers
:func:`monge_curvature` reproduces (tests/test_curvature_data.py checks it). Units: curvature in 1/length of the input (1/mm for rangesim data), K in 1/length^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike

from rangesim.core.errors import RangesimError

__all__ = [
    "QuadricFit", "fit_quadric", "pca_normals", "tangent_frames", "monge_curvature",
    "DEFAULT_CHUNK",
]

#: centres solved per batch (bounds the (k, chunk) per-neighbour temporaries)
DEFAULT_CHUNK = 65536
#: a fit is rejected when the Hadamard ratio det(A) / prod(diag A) of its (scaled) 6 x 6
#: normal equations falls below this (1 for orthogonal monomials, 0 for degenerate layouts)
RCOND = 1e-10


@dataclass
class QuadricFit:
    """Per-centre results of :func:`fit_quadric` (N centres); NaN where ``ok`` is False.

    Attributes
    ----------
    K : (N,) float64
        Gaussian curvature k1 * k2, 1/length^2.
    H : (N,) float64
        Mean curvature (k1 + k2) / 2, 1/length (negative on a convex bump, see module doc).
    k1, k2 : (N,) float64
        Principal curvatures, k1 >= k2, 1/length.
    dir1, dir2 : (N, 3) float64
        Unit principal directions of k1 and k2 (tangent to the fit; (dir1, dir2, normal)
        is right-handed). Arbitrary at umbilics (k1 == k2).
    normal : (N, 3) float64
        Unit normal of the fitted surface, on the side of the frame normal.
    point : (N, 3) float64
        The fitted surface point above the centre (p0 + f n), where the curvatures hold.
    coeffs : (N, 6) float64
        (a, b, c, d, e, f) of h(x, y) in the local frame, length units.
    frame : (N, 3, 3) float64
        Rows t1, t2, n of the local frame.
    n_points : (N,) int64
        Neighbours with positive weight.
    ok : (N,) bool
        Enough neighbours and a well-conditioned fit.
    """

    K: np.ndarray
    H: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    dir1: np.ndarray
    dir2: np.ndarray
    normal: np.ndarray
    point: np.ndarray
    coeffs: np.ndarray
    frame: np.ndarray
    n_points: np.ndarray
    ok: np.ndarray


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / norm


def tangent_frames(normals: np.ndarray) -> np.ndarray:
    """Orthonormal frames with the given normals as third axis.

    Parameters
    ----------
    normals : (N, 3) array
        Normals (need not be unit length; zero or NaN rows give NaN frames).

    Returns
    -------
    (N, 3, 3) float64
        Rows t1, t2, n with t1 x t2 = n.
    """
    n = _unit(np.asarray(normals, dtype=np.float64))
    # helper axis: the coordinate axis least aligned with n
    helper = np.zeros_like(n)
    axis = np.argmin(np.abs(np.nan_to_num(n)), axis=1)
    helper[np.arange(len(n)), axis] = 1.0
    t1 = _unit(np.cross(helper, n))
    t2 = np.cross(n, t1)
    return np.stack([t1, t2, n], axis=1)


def _smallest_eigvec_sym3(c00, c01, c02, c11, c12, c22):
    """Unit eigenvector of the smallest eigenvalue of symmetric 3x3 matrices, closed form.

    Entries are (n,) arrays. Eigenvalues by the trigonometric method, the eigenvector as
    the largest cross product of two rows of (C - lambda_min I). NaN where C is a multiple
    of the identity (no preferred direction) or not finite.
    """
    q = (c00 + c11 + c22) / 3.0
    p1 = c01 * c01 + c02 * c02 + c12 * c12
    p2 = (c00 - q) ** 2 + (c11 - q) ** 2 + (c22 - q) ** 2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        b00, b11, b22 = (c00 - q) / p, (c11 - q) / p, (c22 - q) / p
        b01, b02, b12 = c01 / p, c02 / p, c12 / p
    det_b = (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
             + b02 * (b01 * b12 - b11 * b02))
    phi = np.arccos(np.clip(det_b / 2.0, -1.0, 1.0)) / 3.0
    lam = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    r0 = np.stack([c00 - lam, c01, c02], axis=-1)
    r1 = np.stack([c01, c11 - lam, c12], axis=-1)
    r2 = np.stack([c02, c12, c22 - lam], axis=-1)
    cands = np.stack([np.cross(r0, r1), np.cross(r0, r2), np.cross(r1, r2)], axis=1)
    norms = np.linalg.norm(cands, axis=-1)
    best = np.argmax(np.nan_to_num(norms, nan=-1.0), axis=1)
    idx = np.arange(len(best))
    vec = cands[idx, best]
    good = norms[idx, best] > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        vec = vec / norms[idx, best][:, None]
    vec[~good] = np.nan
    return vec


def _pca_normals_components(rel: np.ndarray, w: np.ndarray) -> np.ndarray:
    """PCA normals from (3, k, n) coordinates (zeros where w == 0) and (k, n) weights."""
    return _smallest_eigvec_sym3(*_weighted_covariance(rel, w))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _weighted_covariance(rel, w):  # pragma: no cover - compiled
    """The 6 distinct entries (n,) of each neighbourhood's weighted covariance: the weighted
    mean, then sums over k of ``w d_i d_j`` with ``d = (rel - mean) [w > 0]``, sequential
    over k (NumPy's sums over a contiguous k were pairwise: equal to about 1e-16)."""
    _, k, n = rel.shape
    out = np.zeros((6, n))
    for m in range(n):
        wsum = 0.0
        s0 = s1 = s2 = 0.0
        for q in range(k):
            wsum += w[q, m]
            s0 += rel[0, q, m] * w[q, m]
            s1 += rel[1, q, m] * w[q, m]
            s2 += rel[2, q, m] * w[q, m]
        m0, m1, m2 = s0 / wsum, s1 / wsum, s2 / wsum
        c00 = c01 = c02 = c11 = c12 = c22 = 0.0
        for q in range(k):
            on = 1.0 if w[q, m] > 0 else 0.0
            d0, d1, d2 = (rel[0, q, m] - m0) * on, (rel[1, q, m] - m1) * on, (rel[2, q, m] - m2) * on
            wq = w[q, m]
            c00 += (d0 * wq) * d0
            c01 += (d0 * wq) * d1
            c02 += (d0 * wq) * d2
            c11 += (d1 * wq) * d1
            c12 += (d1 * wq) * d2
            c22 += (d2 * wq) * d2
        out[0, m], out[1, m], out[2, m], out[3, m], out[4, m], out[5, m] = c00, c01, c02, c11, c12, c22
    return out[0], out[1], out[2], out[3], out[4], out[5]


def pca_normals(points: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted PCA normals: the least-variance direction of each neighbourhood (unoriented).

    Parameters
    ----------
    points : (N, k, 3) array
        Neighbourhoods (entries with zero weight may be NaN).
    weights : (N, k) array
        Non-negative weights.

    Returns
    -------
    (N, 3) float64
        Unit normals, sign arbitrary; NaN where the total weight is 0 or the spread has no
        least-variance direction.
    """
    w = np.asarray(weights, dtype=np.float64).T
    rel = np.asarray(points, dtype=np.float64).transpose(2, 1, 0)
    rel = np.where(w > 0, rel, 0.0)
    return _pca_normals_components(rel, w)


def monge_curvature(coeffs: np.ndarray) -> dict[str, np.ndarray]:
    """Curvature of h(x, y) = a x^2 + b xy + c y^2 + d x + e y + f at x = y = 0.

    Parameters
    ----------
    coeffs : (N, 6) array
        (a, b, c, d, e, f), length units (a, b, c in 1/length).

    Returns
    -------
    dict
        ``K``, ``H``, ``k1``, ``k2`` (N,); ``dir1``, ``dir2``, ``normal`` (N, 3) in the
        local frame (x, y, height); sign convention as in the module docstring.
    """
    a, b, c, d, e = (coeffs[:, i] for i in range(5))
    # Monge patch S(x, y) = (x, y, h): S_x = (1, 0, d), S_y = (0, 1, e), S_xx = (0, 0, 2a),
    # S_xy = (0, 0, b), S_yy = (0, 0, 2c); n = S_x x S_y / |.| = (-d, -e, 1) / w
    zeros, ones = np.zeros_like(d), np.ones_like(d)
    w = np.sqrt(1.0 + d * d + e * e)  # |S_x x S_y|
    E, F = 1.0 + d * d, d * e
    L, M, N = 2 * a / w, b / w, 2 * c / w
    # shape operator in the orthonormal tangent frame e1 = S_x / |S_x|, e2 = n x e1: the
    # symmetric [[p, q], [q, r]] (same formulas as rangesim.cad.bspline.surface_curvatures),
    # free of the sqrt(H^2 - K) cancellation at umbilics
    p = L / E
    q = (E * M - F * L) / (E * w)
    r = (E * E * N - 2.0 * E * F * M + F * F * L) / (E * w * w)
    H = 0.5 * (p + r)
    root = np.hypot(0.5 * (p - r), q)
    K = p * r - q * q
    normal = np.stack([-d, -e, ones], axis=-1) / w[:, None]
    e1 = _unit(np.stack([ones, zeros, d], axis=-1))
    e2 = np.cross(normal, e1)
    theta = 0.5 * np.arctan2(2.0 * q, p - r)  # eigenvector of the larger eigenvalue
    dir1 = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
    dir2 = np.cross(normal, dir1)
    return {"K": K, "H": H, "k1": H + root, "k2": H - root, "dir1": dir1, "dir2": dir2,
            "normal": normal}


#: exponents (p, q) of the basis x^p y^q of h: a x^2 + b xy + c y^2 + d x + e y + f
_BASIS = ((2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _relative(coords, weights, centres_t):  # pragma: no cover - compiled
    """``w`` (k, n): the weights of neighbours with finite coordinates (0 elsewhere);
    ``rel`` (3, k, n): their offsets from the centre (0 where w is 0); ``n_points`` (n,)."""
    _, k, n = coords.shape
    w = np.zeros((k, n))
    rel = np.zeros((3, k, n))
    n_points = np.zeros(n, np.int64)
    for q in range(k):
        for m in range(n):
            c0, c1, c2 = coords[0, q, m], coords[1, q, m], coords[2, q, m]
            wq = weights[q, m]
            if np.isfinite(c0) and np.isfinite(c1) and np.isfinite(c2) and wq > 0:
                w[q, m] = wq
                rel[0, q, m] = c0 - centres_t[0, m]
                rel[1, q, m] = c1 - centres_t[1, m]
                rel[2, q, m] = c2 - centres_t[2, m]
                n_points[m] += 1
    return w, rel, n_points


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _normal_equations(rel, w, fr):  # pragma: no cover - compiled
    """The least-squares system of ``h = a x^2 + b xy + c y^2 + d x + e y + f`` per centre.

    ``rel`` (3, k, n) neighbour offsets, ``w`` (k, n) weights, ``fr`` (n, 3, 3) frames
    (rows t1, t2, n; NaN as 0). Coordinates in the frame over ``s``, the weighted RMS
    tangent radius (1 where that is 0 or undefined); every sum sequential over k (as
    NumPy's over the non-contiguous k of a batch; a one-centre batch summed pairwise).

    Returns
    -------
    A : (n, 6, 6), rhs : (n, 6), s : (n,)
    """
    _, k, n = rel.shape
    A = np.empty((n, 6, 6))
    rhs = np.empty((n, 6))
    s_out = np.empty(n)
    x = np.empty(k)
    y = np.empty(k)
    z = np.empty(k)
    S = np.empty((5, 5))
    for m in range(n):
        wsum = 0.0
        r2 = 0.0
        for q in range(k):
            a0, a1, a2 = rel[0, q, m], rel[1, q, m], rel[2, q, m]
            x[q] = (fr[m, 0, 0] * a0 + fr[m, 0, 1] * a1) + fr[m, 0, 2] * a2
            y[q] = (fr[m, 1, 0] * a0 + fr[m, 1, 1] * a1) + fr[m, 1, 2] * a2
            z[q] = (fr[m, 2, 0] * a0 + fr[m, 2, 1] * a1) + fr[m, 2, 2] * a2
            wsum += w[q, m]
            r2 += w[q, m] * (x[q] * x[q] + y[q] * y[q])
        s = np.sqrt(r2 / wsum)
        s = s if s > 0 else 1.0
        s_out[m] = s
        S[:, :] = 0.0
        t20 = t11 = t02 = t10 = t01 = t00 = 0.0
        for q in range(k):
            xq, yq, zq = x[q] / s, y[q] / s, z[q] / s
            wx = w[q, m]
            y2 = yq * yq
            ypow = (1.0, yq, y2, y2 * yq, y2 * y2)
            for p in range(5):
                for qq in range(5 - p):
                    S[p, qq] += wx if qq == 0 else wx * ypow[qq]
                wx = wx * xq
            wz = w[q, m] * zq
            wzx, wzy = wz * xq, wz * yq
            t20 += wzx * xq
            t11 += wzx * yq
            t02 += wzy * yq
            t10 += wzx
            t01 += wzy
            t00 += wz
        basis = ((2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0))
        for i in range(6):
            pi, qi = basis[i]
            for j in range(6):
                pj, qj = basis[j]
                A[m, i, j] = S[pi + pj, qi + qj]
        rhs[m, 0], rhs[m, 1], rhs[m, 2], rhs[m, 3], rhs[m, 4], rhs[m, 5] = t20, t11, t02, t10, t01, t00
    return A, rhs, s_out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _cholesky_solve(A, rhs):  # pragma: no cover - compiled
    """Solutions of the symmetric systems ``A[n] x = rhs[n]`` (n, m, m), (n, m) by Cholesky,
    and each Hadamard ratio ``det(A) / prod(diag A)`` (the product of the squared pivots over
    the diagonal's). A system that is not positive definite, or holds a non-finite entry,
    gets ratio 0 and solution 0."""
    n, m = rhs.shape
    sol = np.zeros((n, m))
    ratio = np.zeros(n)
    L = np.empty((m, m))
    y = np.empty(m)
    for t in range(n):
        good = True
        r = 1.0
        for i in range(m):
            for j in range(i + 1):
                acc = A[t, i, j]
                for k in range(j):
                    acc -= L[i, k] * L[j, k]
                if i == j:
                    if not (acc > 0.0) or not np.isfinite(acc) or not (A[t, i, i] > 0.0):
                        good = False
                        break
                    r *= acc / A[t, i, i]
                    L[i, i] = np.sqrt(acc)
                else:
                    L[i, j] = acc / L[j, j]
            if not good:
                break
        if not good or not np.isfinite(r):
            continue
        for i in range(m):
            acc = rhs[t, i]
            for k in range(i):
                acc -= L[i, k] * y[k]
            y[i] = acc / L[i, i]
        for i in range(m - 1, -1, -1):
            acc = y[i]
            for k in range(i + 1, m):
                acc -= L[k, i] * sol[t, k]
            sol[t, i] = acc / L[i, i]
        ratio[t] = r
    return sol, ratio


def _fit_chunk(centres, coords, weights, normals, orient):
    """fit_quadric on one batch, neighbour-major layout (sums over k run on contiguous rows).

    centres (n, 3); coords (3, k, n) neighbour coordinates; weights (k, n); normals (n, 3)
    or None; orient (n, 3). All float64.
    """
    # weights (0 for non-finite neighbours) and coordinates relative to the centre (0 where
    # excluded), compiled
    w, rel, n_points = _relative(coords, weights, np.ascontiguousarray(centres.T))
    if normals is None:
        normals = _pca_normals_components(rel, w)
        flip = np.einsum("ni,ni->n", normals, orient) < 0
        normals[flip] *= -1
    frame = tangent_frames(normals)
    # in the tangent frame, scaled by the neighbourhood's RMS tangent radius s (so the 6x6
    # systems are O(1)): the weighted moments S[p, q] = sum w x^p y^q (p + q <= 4) and
    # T[p, q] = sum w z x^p y^q, as the normal equations A (n, 6, 6) and rhs (n, 6)
    A, rhs, s = _normal_equations(rel, w, np.nan_to_num(frame))
    # conditioning: Hadamard ratio det(A) / prod(diag A) in (0, 1], ~0 when degenerate; the
    # solution and the determinant from one compiled Cholesky factorisation (A is a Gram
    # matrix: symmetric, positive definite unless degenerate)
    sol, ratio = _cholesky_solve(A, rhs)
    ok = (n_points >= 6) & np.isfinite(frame).all(axis=(1, 2)) & (ratio > RCOND)
    # back to length units: a, b, c scale 1/s; d, e unitless; f scales s
    one = np.ones_like(s)
    coeffs = sol * np.stack([1 / s, 1 / s, 1 / s, one, one, s], axis=-1)
    coeffs[~ok] = np.nan
    geo = monge_curvature(coeffs)
    to_world = lambda v: np.einsum("ni,nij->nj", v, frame)  # noqa: E731
    point = centres + coeffs[:, 5:6] * frame[:, 2]
    return dict(
        K=geo["K"], H=geo["H"], k1=geo["k1"], k2=geo["k2"],
        dir1=to_world(geo["dir1"]), dir2=to_world(geo["dir2"]), normal=to_world(geo["normal"]),
        point=point, coeffs=coeffs, frame=frame, n_points=n_points, ok=ok,
    )


def fit_quadric(
    centres: ArrayLike,
    points: ArrayLike,
    weights: ArrayLike | None = None,
    normals: ArrayLike | None = None,
    orient: ArrayLike | None = None,
    min_points: int = 6,
    chunk: int = DEFAULT_CHUNK,
) -> QuadricFit:
    """Fit a local quadric height function around every centre; curvature and normal.

    Vectorised over centres (stacked 6 x 6 normal equations, batches of ``chunk``).
    Neighbourhoods of different sizes are padded to a common k with zero weight (or NaN
    points, which count as weight 0).

    Parameters
    ----------
    centres : (N, 3) array
        Points where curvature is wanted; the origin of each local frame.
    points : (N, k, 3) array
        Neighbourhood of each centre (normally including the centre itself).
    weights : (N, k) array, optional
        Non-negative least-squares weights; 0 excludes a neighbour. Default: 1 for every
        finite point.
    normals : (N, 3) array, optional
        Approximate normals: they set both the local frame and the side the curvature sign
        refers to. Default: weighted PCA normals oriented by ``orient``.
    orient : (N, 3) or (3,) array, optional
        Only without ``normals``: PCA normals are flipped to have a positive dot product with
        these vectors. Default: towards the origin (``-centres``), i.e. the camera of a scan.
    min_points : int
        Least number of neighbours with positive weight (at least 6, the unknowns).
    chunk : int
        Centres per batch.

    Returns
    -------
    QuadricFit
        Curvatures (sign convention in the module docstring), directions, fitted normals;
        NaN where there are fewer than ``min_points`` neighbours or the fit is degenerate
        (e.g. all neighbours on a line).

    Examples
    --------
    >>> import numpy as np
    >>> from rangesim.curvature import fit_quadric
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(-5, 5, (200, 2))
    >>> points = np.c_[xy, (xy ** 2).sum(1) / (2 * 100.0)]     # a paraboloid of radius 100 mm at 0
    >>> fit = fit_quadric([[0.0, 0.0, 0.0]], points[None], orient=[[0.0, 0.0, 1.0]])   # one centre, 200 points
    >>> round(float(fit.H[0]), 4), round(float(fit.K[0]) * 1e4, 3)
    (0.01, 1.0)

    References
    ----------
    .. [1] P. J. Besl, R. C. Jain, "Invariant surface characteristics for 3D object recognition
       in range images", Computer Vision, Graphics, and Image Processing 33(1), 33-80 (1986),
       doi:10.1016/0734-189X(86)90220-3.
    """
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    points = np.asarray(points, dtype=np.float64)
    n = len(centres)
    if points.ndim != 3 or points.shape[0] != n or points.shape[2] != 3:
        raise RangesimError(f"points must be (N, k, 3) with N = {n}, got {points.shape}")
    weights = (np.ones(points.shape[:2]) if weights is None
               else np.broadcast_to(np.asarray(weights, dtype=np.float64), points.shape[:2]))
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64).reshape(n, 3)
    orient = -centres if orient is None else np.broadcast_to(
        np.asarray(orient, dtype=np.float64), (n, 3))
    min_points = max(int(min_points), 6)

    out = _empty(n)
    for i0 in range(0, n, max(int(chunk), 1)):
        sl = slice(i0, min(i0 + chunk, n))
        _store(out, sl, _fit_chunk(
            centres[sl], np.ascontiguousarray(points[sl].transpose(2, 1, 0)),
            np.ascontiguousarray(weights[sl].T), None if normals is None else normals[sl],
            orient[sl]), min_points)
    return QuadricFit(**out)


def _empty(n: int) -> dict[str, np.ndarray]:
    """NaN / zero / False result arrays for n centres."""
    out = {key: np.full(n, np.nan) for key in ("K", "H", "k1", "k2")}
    out.update({key: np.full((n, 3), np.nan) for key in ("dir1", "dir2", "normal", "point")})
    out.update(coeffs=np.full((n, 6), np.nan), frame=np.full((n, 3, 3), np.nan),
               n_points=np.zeros(n, np.int64), ok=np.zeros(n, bool))
    return out


def _store(out: dict, where, res: dict, min_points: int) -> None:
    """Copy a batch result into ``out[key][where]``, NaN where the fit is rejected."""
    ok = res["ok"] & (res["n_points"] >= min_points)
    for key, val in res.items():
        if key not in ("ok", "n_points", "frame"):
            val[~ok] = np.nan
        out[key][where] = val
    out["ok"][where] = ok


def fit_quadric_grid_batch(
    centres: np.ndarray, coords: np.ndarray, weights: np.ndarray, orient: np.ndarray,
    min_points: int,
) -> dict[str, np.ndarray]:
    """:func:`fit_quadric` for callers that hold neighbours in (3, k, N) layout already.

    Parameters
    ----------
    centres : (N, 3) float64
    coords : (3, k, N) float64
        Neighbour coordinates, component-major (NaN allowed: weight 0).
    weights : (k, N) float64
    orient : (N, 3) float64
        PCA normals are turned to a positive dot product with these.
    min_points : int

    Returns
    -------
    dict
        The fields of :class:`QuadricFit` as arrays.
    """
    out = _empty(len(centres))
    _store(out, slice(None), _fit_chunk(centres, coords, weights, None, orient),
           max(int(min_points), 6))
    return out
