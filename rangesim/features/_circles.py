"""Circles from edge directions (the paper's section 5): a Hough transform in which every edge
point votes only along its edge normal, both senses, at each radius."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from rangesim.core.conics import fit_circle
from rangesim.core.memory import check_memory
from rangesim.features._edge_points import angular_coverage, edge_points


@dataclass(frozen=True)
class Circle:
    """A circle in the image.

    Attributes
    ----------
    center : (x, y) float, pixels (x = column, y = row, integers at pixel centres)
    radius : float, pixels
    votes : int
        Accumulator votes at the peak.
    support : float
        Fraction of the circumference with an edge pixel within 1 px of the circle, 0..1.
    residual : float
        RMS distance of those edge pixels to the circle, pixels.
    """

    center: tuple[float, float]
    radius: float
    votes: int
    support: float
    residual: float


def circle_hypotheses(
    edge_map: Any,
    radii: tuple[float, float] = (5, 80),
    *,
    angle_tol_deg: float = 4.0,
    threshold: float = 0.25,
    band_px: float = 1.0,
    keep: np.ndarray | None = None,
    max_hypotheses: int = 200,
    cell_px: float = 2.0,
    radius_step: float = 2.0,
) -> list[tuple[np.ndarray, float, int, np.ndarray]]:
    """Directional Hough accumulator, peaks and least-squares refinement (no support test).

    Each edge point p with edge-normal angle t votes, for every integer radius r, at
    p +- r (cos a, sin a) for a = t + k / r, |k / r| <= ``angle_tol_deg``: the angular step
    is 1 / r (one vote per pixel of arc at the centre), so the window is the same at every
    radius. A circle of radius r collects about 2 pi r votes, so the acceptance threshold is
    ``threshold * 2 pi r`` (proportional to r). The accumulator is 3D (radius, centre cells of
    ``cell_px`` pixels, with the angular step ``cell_px / r``), filled by one ``np.bincount``;
    votes are summed over 3 x 3 cells. Peaks are 3D local maxima over (r, y, x) above the
    threshold; each is refined (batched algebraic circle fits, three passes with a narrowing
    band) on the edge points within ``band_px`` (+0.5) of it whose direction is radial within
    20 degrees.

    Returns
    -------
    list of (center (2,), radius, votes, inlier indices into the edge points), best first.
    """
    xy, theta = edge_points(edge_map, keep)
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    H, W = mask.shape
    if len(xy) < 5:
        return []
    cell = float(cell_px)
    Hc, Wc = int(np.ceil(H / cell)), int(np.ceil(W / cell))
    r_bins = np.arange(max(2.0, float(radii[0])), float(radii[1]) + radius_step, radius_step)
    tol = np.deg2rad(angle_tol_deg)
    # every vote at once: (point, radius, angle offset), angle step cell / r (prop. to 1 / r).
    # float32 throughout; cos/sin of (theta + k) from per-point and per-offset tables (angle
    # addition), no trig over the (point, offset) grid; cells by truncation in a padded grid
    # (no bounds masks), integer accumulation with one np.bincount on flat indices.
    n_k = np.maximum(np.ceil(tol * r_bins / cell), 0).astype(int)
    r_of = np.repeat(r_bins, 2 * n_k + 1)
    k_of = np.concatenate([np.arange(-k, k + 1) for k in n_k]) * cell / r_of
    b_of = np.repeat(np.arange(len(r_bins)), 2 * n_k + 1)
    nr = len(r_bins)
    pad = int(np.ceil(r_bins[-1] / cell)) + 2
    Hp, Wp = Hc + 2 * pad, Wc + 2 * pad
    _check_accumulator(nr, Hp, Wp, len(xy) * len(r_of), radii)
    rc = (r_of * np.cos(k_of) / cell).astype(np.float32)
    rs_ = (r_of * np.sin(k_of) / cell).astype(np.float32)
    ct, st = np.cos(theta).astype(np.float32), np.sin(theta).astype(np.float32)
    dxc = ct[:, None] * rc[None, :]
    dxc -= st[:, None] * rs_[None, :]
    dyc = st[:, None] * rc[None, :]
    dyc += ct[:, None] * rs_[None, :]
    xs = ((xy[:, 0] + 0.5) / cell + pad).astype(np.float32)[:, None]
    ys = ((xy[:, 1] + 0.5) / cell + pad).astype(np.float32)[:, None]
    base = (b_of * (Hp * Wp)).astype(np.int32)[None, :]
    flat = np.empty((2,) + dxc.shape, np.int32)
    np.add((ys + dyc).astype(np.int32) * Wp + (xs + dxc).astype(np.int32), base, out=flat[0])
    np.add((ys - dyc).astype(np.int32) * Wp + (xs - dxc).astype(np.int32), base, out=flat[1])
    acc = np.bincount(flat.ravel(), minlength=nr * Hp * Wp)
    acc = acc.reshape(nr, Hp, Wp)[:, pad:pad + Hc, pad:pad + Wc].astype(np.float32)
    # 3 x 3 cell sums (zero outside the image), separable
    box = acc.copy()
    box[:, :, 1:] += acc[:, :, :-1]
    box[:, :, :-1] += acc[:, :, 1:]
    acc = box.copy()
    acc[:, 1:, :] += box[:, :-1, :]
    acc[:, :-1, :] += box[:, 1:, :]
    score = acc / (2 * np.pi * r_bins[:, None, None])  # threshold proportional to r
    # 3D local maxima (3 radii x 5 x 5 cells): a separable maximum filter picks the cells not
    # below any neighbour; the exact test (ties: the first cell in scan order wins) then runs
    # only on those
    mx = acc
    for axis, passes in ((2, 2), (1, 2), (0, 1)):  # widths 5, 5, 3 (zero outside, acc >= 0)
        for _ in range(passes):
            mx = _max3(mx, axis)
    bi, yi, xi = np.nonzero((score >= threshold) & (acc >= mx))
    if len(bi) == 0:
        return []
    v = acc[bi, yi, xi]
    is_max = np.ones(len(bi), bool)
    for ob in (-1, 0, 1):
        for oy in range(-2, 3):
            for ox in range(-2, 3):
                if (ob, oy, ox) >= (0, 0, 0):
                    continue  # later cells: v >= them holds already
                b2, y2, x2 = bi + ob, yi + oy, xi + ox
                inside = (b2 >= 0) & (b2 < nr) & (y2 >= 0) & (y2 < Hc) & (x2 >= 0) & (x2 < Wc)
                nbv = np.zeros(len(bi), np.float32)
                nbv[inside] = acc[b2[inside], y2[inside], x2[inside]]
                is_max &= v > nbv
    bi, yi, xi = bi[is_max], yi[is_max], xi[is_max]
    order = np.argsort(-score[bi, yi, xi])[:max_hypotheses]
    bi, yi, xi = bi[order], yi[order], xi[order]
    c = np.column_stack([xi, yi]).astype(float) * cell + (cell - 1) / 2
    r = r_bins[bi].astype(float)
    votes = acc[bi, yi, xi].astype(int)
    # batched refinement: algebraic circle fits to the in-band, radially oriented edge points,
    # on (hypothesis, point) pairs from a k-d tree (only the points near each circle)
    tree = cKDTree(xy)
    reach = r + band_px + cell + 1
    lists = tree.query_ball_point(c, reach)
    hyp = np.repeat(np.arange(len(c)), [len(l) for l in lists])
    pts = np.fromiter((i for l in lists for i in l), np.int64, count=len(hyp))
    cos20 = np.cos(np.deg2rad(20))
    ct, st = np.cos(theta[pts]), np.sin(theta[pts])
    for band in (band_px + cell, band_px + 0.5, band_px + 0.5):
        d = xy[pts] - c[hyp]
        rho = np.hypot(d[:, 0], d[:, 1])
        radial = np.abs((d[:, 0] * ct + d[:, 1] * st) / np.maximum(rho, 1e-9))
        sel = (np.abs(rho - r[hyp]) <= band) & (radial >= cos20)
        c, r = _batched_kasa(xy[pts[sel]], hyp[sel], len(c), c, r)
    n_in = np.bincount(hyp[sel], minlength=len(c))
    out = []
    for j in np.nonzero(n_in >= 6)[0]:
        out.append((c[j], float(r[j]), int(votes[j]), pts[sel & (hyp == j)]))
    return out


def _max3(a: np.ndarray, axis: int) -> np.ndarray:
    """Running maximum of width 3 along ``axis`` (non-negative input, zero outside)."""
    out = a.copy()
    lo = [slice(None)] * a.ndim
    hi = [slice(None)] * a.ndim
    lo[axis], hi[axis] = slice(1, None), slice(None, -1)
    np.maximum(out[tuple(lo)], a[tuple(hi)], out=out[tuple(lo)])
    np.maximum(out[tuple(hi)], a[tuple(lo)], out=out[tuple(hi)])
    return out


def _batched_kasa(xy: np.ndarray, hyp: np.ndarray, m_hyp: int, c0: np.ndarray,
                  r0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kasa circle fits of many point subsets at once: point k belongs to hypothesis
    ``hyp[k]``; keeps ``c0``/``r0`` where a subset has fewer than 6 points, the system is
    singular or the fit moves more than 3 px."""
    c, r = c0.copy(), r0.copy()
    if len(xy) == 0:
        return c, r
    m = c0[hyp]  # centre each subset on its current estimate (conditioning)
    x, y = (xy - m).T
    z = x * x + y * y

    def s(w):
        return np.bincount(hyp, weights=w, minlength=m_hyp)

    n = np.bincount(hyp, minlength=m_hyp).astype(float)
    Sx, Sy, Sxx, Syy, Sxy, Sz, Sxz, Syz = (s(w) for w in (x, y, x * x, y * y, x * y, z, x * z, y * z))
    A = np.stack([np.stack([2 * Sxx, 2 * Sxy, Sx], -1), np.stack([2 * Sxy, 2 * Syy, Sy], -1),
                  np.stack([2 * Sx, 2 * Sy, n], -1)], 1)
    rhs = np.stack([Sxz, Syz, Sz], -1)
    good = n >= 6
    good &= np.abs(np.linalg.det(A)) > 1e-9 * np.maximum(n, 1) ** 3
    if good.any():
        sol = np.linalg.solve(A[good], rhs[good][..., None])[..., 0]
        cc = sol[:, :2]
        rr = np.sqrt(np.maximum(sol[:, 2] + (cc ** 2).sum(1), 0))
        cc = cc + c0[good]
        jump = (np.hypot(*(cc - c0[good]).T) > 3) | (np.abs(rr - r0[good]) > 3)
        idx = np.nonzero(good)[0][~jump]
        c[idx], r[idx] = cc[~jump], rr[~jump]
    return c, r


def _support(xy: np.ndarray, c: np.ndarray, r: float) -> tuple[np.ndarray, float, float, float, float]:
    """Edge points within 1 px of the circle, coverage, start/end angles of the longest run, RMS."""
    d = xy - c
    rho = np.hypot(d[:, 0], d[:, 1])
    on = np.abs(rho - r) <= 1.0
    ang = np.arctan2(d[on, 1], d[on, 0])
    cov, start, end = angular_coverage(ang, round(2 * np.pi * r))
    rms = float(np.sqrt(np.mean((rho[on] - r) ** 2))) if on.any() else np.inf
    return on, cov, start, end, rms


def _dedupe(items: list, key_c, key_r, dist_px: float) -> list:
    kept = []
    for it in items:
        if all(np.hypot(*(key_c(it) - key_c(k))) > dist_px or abs(key_r(it) - key_r(k)) > dist_px for k in kept):
            kept.append(it)
    return kept


def _check_accumulator(n_radii: int, rows: int, cols: int, n_votes: int, radii) -> None:
    """Refuse (one line, naming the radius range) a Hough accumulator that would not fit in memory."""
    cells = float(n_radii) * rows * cols
    estimate = cells * 28 + float(n_votes) * 40  # int64 counts + float32 copies; int32/float32 vote tables
    check_memory(estimate, f"circle radii {radii[0]:g}..{radii[1]:g} px (--rmin/--rmax, a Hough accumulator of "
                           f"{cells:,.0f} cells)")


def circles(
    edge_map: Any,
    radii: tuple[float, float] = (5, 80),
    *,
    min_support: float = 0.5,
    threshold: float = 0.25,
    angle_tol_deg: float = 4.0,
    max_residual: float = 0.8,
    keep: np.ndarray | None = None,
) -> list[Circle]:
    """Circles in an edge map, by the direction-guided Hough transform.

    Parameters
    ----------
    edge_map : EdgeMap or (H, W) bool
        Edge pixels; ``direction`` (radians, across the edge) is used when present, else it
        is estimated from the mask.
    radii : (rmin, rmax)
        Radius range, pixels.
    min_support : float
        Least fraction of the circumference with an edge pixel within 1 px.
    threshold : float
        Accumulator threshold as a fraction of the 2 pi r votes of a complete circle.
    angle_tol_deg : float
        Half-width of the voting window around the edge normal, degrees.
    max_residual : float
        Largest RMS distance of the supporting edge pixels to the circle, pixels.
    keep : (H, W) bool, optional
        Only these pixels vote.

    Returns
    -------
    list of Circle
        Strongest (largest support) first; near-duplicates (centre and radius within 2 px)
        removed.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> found = rs.features.circles(rs.edges.gradient(scan), radii=(5, 30))
    >>> len(found), round(found[0].radius)                  # the hole's rim, radius in pixels
    (1, 9)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5 (the
       gradient-directed Hough transform).
    .. [2] R. O. Duda, P. E. Hart, "Use of the Hough transformation to detect lines and curves
       in pictures", Communications of the ACM 15(1), 11-15 (1972), doi:10.1145/361237.361242.
    """
    xy, _ = edge_points(edge_map, keep)
    found = []
    for c, r, votes, _ in circle_hypotheses(edge_map, radii, angle_tol_deg=angle_tol_deg,
                                            threshold=threshold, keep=keep):
        on, cov, _, _, rms = _support(xy, c, r)
        if cov >= min_support and rms <= max_residual:
            c2, r2, _ = fit_circle(xy[on])  # final geometric fit on the supporting pixels
            if np.hypot(*(c2 - c)) <= 1.5 and abs(r2 - r) <= 1.5:
                c, r = c2, r2
                _, cov, _, _, rms = _support(xy, c, r)
            found.append(Circle((float(c[0]), float(c[1])), float(r), votes, cov, rms))
    found.sort(key=lambda k: -k.support)
    return _dedupe(found, lambda k: np.array(k.center), lambda k: k.radius, 2.0)
