"""Conics in the image plane: least-squares fits of circles and ellipses (direct, batched),
algebraic conic <-> centre / semi-axes / angle, and distances and normals of points to a conic.

Conics are ``(a, b, c, d, e, f)`` of ``a x^2 + b x y + c y^2 + d x + e y + f = 0``; image
coordinates are x = column, y = row, integers at pixel centres (pixels).
"""
from __future__ import annotations

import numpy as np

from rangesim.core._conic_kernels import direct_fit, direct_fits, ellipse_rows


def fit_circle(xy: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Algebraic (Kasa) least-squares circle, then Gauss-Newton on the geometric distance.

    Parameters
    ----------
    xy : (N, 2) float, N >= 3, pixels

    Returns
    -------
    center : (2,) float, radius : float, rms : float
        Centre, radius and RMS geometric residual, pixels.
    """
    m = xy.mean(axis=0)
    p = xy - m
    A = np.column_stack([2 * p, np.ones(len(p))])
    sol, *_ = np.linalg.lstsq(A, (p ** 2).sum(1), rcond=None)
    c = sol[:2]
    r = float(np.sqrt(max(sol[2] + c @ c, 1e-12)))
    for _ in range(5):  # geometric refinement
        d = p - c
        rho = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        J = np.column_stack([-d / rho[:, None], -np.ones(len(p))])
        res = rho - r
        step, *_ = np.linalg.lstsq(J, -res, rcond=None)
        c, r = c + step[:2], r + float(step[2])
        if np.abs(step).max() < 1e-6:
            break
    res = np.linalg.norm(p - c, axis=1) - r
    return c + m, abs(r), float(np.sqrt(np.mean(res ** 2)))


def fit_conic(xy: np.ndarray) -> np.ndarray | None:
    """Fitzgibbon-Pilu-Fisher direct least-squares ellipse (Halir-Flusser stable form).

    Parameters
    ----------
    xy : (N, 2) float, N >= 5, pixels

    Returns
    -------
    (6,) float or None
        Conic ``a x^2 + b x y + c y^2 + d x + e y + f = 0`` in pixel coordinates, normalised
        to unit norm, or None when no ellipse fits.

    Notes
    -----
    The points are centred and scaled to [-1, 1]; the fit is that of their moments
    (:func:`fit_conics_moments`, compiled in :mod:`rangesim.core._conic_kernels`).
    """
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(xy) < 5:
        return None
    m = xy.mean(axis=0)
    q = xy - m
    s = max(float(np.abs(q).max()), 1e-9)
    conic, v = np.empty(6), np.empty(6)
    if direct_fit(conic_monomials(q / s).sum(0), float(m[0]), float(m[1]), s, conic, v) < 0:
        return None
    return conic


def conic_matrix(conic: np.ndarray) -> np.ndarray:
    """3x3 symmetric matrix of a conic given as (a, b, c, d, e, f)."""
    a, b, c, d, e, f = conic
    return np.array([[a, b / 2, d / 2], [b / 2, c, e / 2], [d / 2, e / 2, f]])


def ellipse_from_conic(conic: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(center (2,), semi-axes (a >= b), major-axis angle in [-pi/2, pi/2)) or None.

    One row of :func:`ellipse_params` (closed form of the 2 x 2 algebra); None for a parabola,
    a hyperbola, an imaginary ellipse or a point.
    """
    c, axes, angle, ok = ellipse_params(np.asarray(conic, float).reshape(1, 6))
    if not ok[0]:
        return None
    return c[0], axes[0], float(angle[0])


def sampson_distance(conic: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(N,) first-order geometric distance (pixels) of points to a conic."""
    a, b, c, d, e, f = conic
    x, y = xy[:, 0], xy[:, 1]
    q = a * x * x + b * x * y + c * y * y + d * x + e * y + f
    gx = 2 * a * x + b * y + d
    gy = b * x + 2 * c * y + e
    return np.abs(q) / np.maximum(np.hypot(gx, gy), 1e-12)


def conic_normal_angle(conic: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(N,) direction (radians) of the conic's gradient at the points: the normal to the curve."""
    a, b, c, d, e, f = conic
    x, y = xy[:, 0], xy[:, 1]
    return np.arctan2(b * x + 2 * c * y + e, 2 * a * x + b * y + d)


def fit_circles_batched(xy: np.ndarray, group: np.ndarray, n_groups: int, center: np.ndarray,
                        radius: np.ndarray, *, iterations: int = 2, max_step: float = 3.0,
                        min_points: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geometric least-squares circles of many point groups at once (Gauss-Newton).

    Parameters
    ----------
    xy : (N, 2) float, pixels
        Points; point k belongs to group ``group[k]`` (0 <= group < n_groups).
    group : (N,) int
    n_groups : int
    center : (n_groups, 2) float, radius : (n_groups,) float, pixels
        Starting circles.
    iterations : int
        Gauss-Newton steps on the sum of squared geometric distances ``|p - c| - r``.
    max_step : float, pixels
        A group whose step would move its centre or radius further keeps its start.
    min_points : int
        Groups with fewer points (or a singular system) keep their start.

    Returns
    -------
    center : (n_groups, 2) float, radius : (n_groups,) float
    rms : (n_groups,) float
        RMS geometric residual at the returned circle, pixels (inf for an empty group).
    """
    c = np.array(center, float, copy=True).reshape(n_groups, 2)
    r = np.array(radius, float, copy=True).reshape(n_groups)
    n = np.bincount(group, minlength=n_groups)
    for _ in range(iterations):
        if len(xy) == 0:
            break
        d = xy - c[group]
        rho = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        u = d / rho[:, None]
        e = rho - r[group]
        # J = [-ux, -uy, -1]; normal equations J^T J step = -J^T e, all sums in one pass
        w = np.column_stack([u[:, 0] * u[:, 0], u[:, 1] * u[:, 1], u[:, 0] * u[:, 1], u, e[:, None] * u, e])
        sums = _group_sums(w, group, n_groups)
        ones = n.astype(float)
        jtj = np.stack([sums[:, 0], sums[:, 2], sums[:, 3], sums[:, 2], sums[:, 1], sums[:, 4],
                        sums[:, 3], sums[:, 4], ones], 1).reshape(n_groups, 3, 3)
        good = n >= min_points
        good &= np.abs(np.linalg.det(jtj)) > 1e-9 * np.maximum(n, 1) ** 3
        if not good.any():
            break
        step = np.linalg.solve(jtj[good], sums[good, 5:8, None])[..., 0]  # = -(J^T J)^-1 J^T (-e)
        ok = np.abs(step).max(1) <= max_step
        idx = np.nonzero(good)[0][ok]
        c[idx] += step[ok, :2]
        r[idx] += step[ok, 2]
    d = xy - c[group]
    e = np.hypot(d[:, 0], d[:, 1]) - r[group] if len(xy) else np.zeros(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.bincount(group, weights=e * e, minlength=n_groups) / n)
    rms[n == 0] = np.inf
    return c, r, rms


def _group_sums(w: np.ndarray, group: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups, k) column sums of ``w`` (P, k) per group: one ``np.add.reduceat`` when the
    groups are sorted (as the circle finder's pairs are), else a bincount per column."""
    if len(group) and np.all(group[1:] >= group[:-1]):
        starts = np.searchsorted(group, np.arange(n_groups))
        # a row of zeros after the last, so that trailing empty groups start inside the array
        # and the last non-empty group keeps its last row
        padded = np.concatenate([w, np.zeros((1,) + w.shape[1:], w.dtype)])
        out = np.add.reduceat(padded, starts, axis=0)
        out[np.bincount(group, minlength=n_groups) == 0] = 0.0
        return out
    return np.column_stack([np.bincount(group, weights=w[:, j], minlength=n_groups) for j in range(w.shape[1])])


def fit_conics_grouped(xy: np.ndarray, group: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_conic` on many point groups at once (one scatter matrix per group).

    Parameters
    ----------
    xy : (N, 2) float, pixels
    group : (N,) int
        Group of each point, sorted (0 <= group < n_groups).
    n_groups : int

    Returns
    -------
    conics : (n_groups, 6) float
        Unit-norm conics in pixel coordinates (zeros where no fit: fewer than 5 points, or no
        ellipse-specific solution).
    ok : (n_groups,) bool
    """
    n = np.bincount(group, minlength=n_groups)
    if len(xy) == 0:
        return np.zeros((n_groups, 6)), np.zeros(n_groups, bool)
    m = _group_sums(xy, group, n_groups) / np.maximum(n, 1)[:, None]
    q = xy - m[group]
    starts = np.minimum(np.searchsorted(group, np.arange(n_groups)), len(group) - 1)
    s = np.maximum(np.maximum.reduceat(np.abs(q).max(1), starts), 1e-9)
    s[n == 0] = 1.0
    q = q / s[group, None]
    conics, ok, _ = fit_conics_moments(_group_sums(conic_monomials(q), group, n_groups), m, s)
    return conics, ok


#: exponents (i, j) of the 15 monomials x^i y^j, i + j <= 4, whose sums make a conic's scatter matrix
MOMENT_POWERS = [(i, j) for i in range(5) for j in range(5 - i)]


def conic_monomials(q: np.ndarray) -> np.ndarray:
    """(N, 15) monomials x^i y^j of :data:`MOMENT_POWERS` at points ``q`` (N, 2).

    Their sums over a set of points (the moments) are additive: the moments of a union of sets
    in one frame are the sums of theirs, so fits of unions cost no pass over the points.
    """
    x, y = q[:, 0], q[:, 1]
    xp = [np.ones_like(x), x, x * x, x * x * x, x * x * x * x]
    yp = [np.ones_like(y), y, y * y, y * y * y, y * y * y * y]
    return np.column_stack([xp[i] * yp[j] for i, j in MOMENT_POWERS])


def fit_conics_moments(mom: np.ndarray, m: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direct ellipse fits from moments (Halir-Flusser), with their approximate residuals.

    Parameters
    ----------
    mom : (K, 15) float
        Sums of :func:`conic_monomials` of each set's points in its frame ``q = (xy - m) / s``.
    m : (K, 2) float, pixels
        Frame origins.
    s : (K,) float, pixels
        Frame scales (the points should have ``|q| <= 1`` or so, for conditioning).

    Returns
    -------
    conics : (K, 6) float
        Unit-norm conics in pixel coordinates (zeros where no fit).
    ok : (K,) bool
        Fitted: an ellipse-specific solution exists and there are at least 5 points.
    rms : (K,) float, pixels
        ``s * sqrt(sum f^2 / sum |grad f|^2)`` of the fitted form f: the gradient-weighted
        algebraic residual, a first-order estimate of the RMS geometric distance (from the
        moments alone).
    """
    mom = np.ascontiguousarray(mom, np.float64).reshape(-1, 15)
    m = np.ascontiguousarray(m, np.float64).reshape(-1, 2)
    s = np.ascontiguousarray(s, np.float64).reshape(-1)
    return direct_fits(mom, m, s)


def real_ellipses(conics: np.ndarray) -> np.ndarray:
    """(K,) bool: which conics are real ellipses (as :func:`ellipse_from_conic` accepts)."""
    return ellipse_params(conics)[3]


def sampson_distance_rows(conics: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(N,) :func:`sampson_distance` of each point to its own conic (``conics`` (N, 6))."""
    a, b, c, d, e, f = conics.T
    x, y = xy[:, 0], xy[:, 1]
    q = a * x * x + b * x * y + c * y * y + d * x + e * y + f
    gx = 2 * a * x + b * y + d
    gy = b * x + 2 * c * y + e
    return np.abs(q) / np.maximum(np.hypot(gx, gy), 1e-12)


def ellipse_params(conics: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`ellipse_from_conic` of many conics at once.

    Parameters
    ----------
    conics : (K, 6) float

    Returns
    -------
    center : (K, 2) float, pixels
    axes : (K, 2) float
        Semi-axes a >= b, pixels.
    angle : (K,) float
        Major-axis angle, radians in [-pi/2, pi/2).
    ok : (K,) bool
        Real ellipses; the other rows hold NaN or meaningless values.
    """
    return ellipse_rows(np.ascontiguousarray(conics, np.float64).reshape(-1, 6))
