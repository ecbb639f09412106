"""Compiled conic arithmetic: Halir-Flusser direct ellipse fits from moments (one set at a
time, with no LAPACK) and the centre, axes and angle of conics.

The fit reduces to the 3 x 3 eigenproblem of ``M = C1^-1 (S1 - S2 S3^-1 S2^T)``: the ellipse is
the eigenvector ``a`` with ``4 a0 a2 - a1^2 > 0``. Its eigenvalues are the roots of the
characteristic cubic (closed form, then polished by Newton steps) and each eigenvector is
the cross product of two rows of ``M - lambda I``: a few hundred flops per fit, against
about 3 us of call overhead for one batched ``np.linalg.eig`` row. The eigenvalues are real
in theory (``M`` is similar to a symmetric pencil), not always in floating point: a complex
pair is handled as LAPACK's ``geev`` returns it (unit eigenvectors whose largest component
is real), of which the fit uses the real part, as ``np.real(np.linalg.eig(M)[1])`` did.

Everything here is scalar arithmetic on small fixed arrays, so a batch of thousands of fits
costs about as much as NumPy's fixed cost of one call.
"""
from __future__ import annotations

import numba
import numpy as np

#: the 6 x 6 scatter matrix of a conic fit from its 15 moments: S[a, b] = mom[SCATTER[a, b]]
#: (rows and columns x^2, xy, y^2, x, y, 1; the moments x^i y^j in the order of
#: :data:`rangesim.core.conics.MOMENT_POWERS`, i + j <= 4, i major)
SCATTER = np.array([[(i1 + i2) * 5 - ((i1 + i2) * (i1 + i2 - 1)) // 2 + (j1 + j2)
                     for (i2, j2) in ((2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0))]
                    for (i1, j1) in ((2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0))], np.int64)

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@numba.njit(**_JIT)
def _cross_rows(R, out):  # pragma: no cover - compiled
    """The largest cross product of two rows of the (3, 3) ``R`` (real or complex) into
    ``out``: a null vector of ``R`` when its rank is 2. Returns its squared norm."""
    best = -1.0
    for i, j in ((0, 1), (0, 2), (1, 2)):
        c0 = R[i, 1] * R[j, 2] - R[i, 2] * R[j, 1]
        c1 = R[i, 2] * R[j, 0] - R[i, 0] * R[j, 2]
        c2 = R[i, 0] * R[j, 1] - R[i, 1] * R[j, 0]
        n2 = abs(c0) ** 2 + abs(c1) ** 2 + abs(c2) ** 2
        if n2 > best:
            best = n2
            out[0], out[1], out[2] = c0, c1, c2
    return best


@numba.njit(**{**_JIT, "inline": "always"})
def _keep_ellipse(x0, x1, x2, best, a1):  # pragma: no cover - compiled
    """Keep the eigenvector (x0, x1, x2) in ``a1`` (unit norm) if it is an ellipse's
    (``4 a0 a2 - a1^2 > 0``) more so than ``best`` (of unit norm); returns the new best and
    whether it was kept."""
    n2 = x0 * x0 + x1 * x1 + x2 * x2
    if not n2 > 0:
        return best, False
    cond = (4 * x0 * x2 - x1 * x1) / n2
    if cond > 0 and cond > best:
        nrm = np.sqrt(n2)
        a1[0], a1[1], a1[2] = x0 / nrm, x1 / nrm, x2 / nrm
        return cond, True
    return best, False


@numba.njit(**{**_JIT, "inline": "always"})
def _polish_root(lam, tr, c1, det):  # pragma: no cover - compiled
    """Two Newton steps on ``lambda^3 - tr lambda^2 + c1 lambda - det`` from ``lam`` (real or
    complex): the closed form loses digits near double roots."""
    for _ in range(2):
        f = ((lam - tr) * lam + c1) * lam - det
        df = (3 * lam - 2 * tr) * lam + c1
        if df == 0:
            break
        lam = lam - f / df
    return lam


@numba.njit(**_JIT)
def _real_ellipse_vector(A, tr, c1, det, p, q, a1):  # pragma: no cover - compiled
    """:func:`_ellipse_vector` when the cubic's three roots are real (most fits):
    :func:`_real_ellipse_vector9` of the (3, 3) ``A``'s entries."""
    return _real_ellipse_vector9(A[0, 0], A[0, 1], A[0, 2], A[1, 0], A[1, 1], A[1, 2], A[2, 0], A[2, 1], A[2, 2],
                                 tr, c1, det, p, q, a1)


@numba.njit(**_JIT)
def _ellipse_vector(M, a1):  # pragma: no cover - compiled
    """The eigenvector of the (3, 3) ``M`` with ``4 a0 a2 - a1^2 > 0`` into ``a1`` (unit norm;
    of several, the one with the largest such value, normalised). False when none has."""
    scale = 0.0
    for i in range(3):
        for j in range(3):
            scale = max(scale, abs(M[i, j]))
    if not (scale > 0 and np.isfinite(scale)):
        return False
    A = M / scale  # eigenvectors do not change; the cubic's coefficients stay near 1
    tr = A[0, 0] + A[1, 1] + A[2, 2]
    c1 = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0] + A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
          + A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
    det = (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]) - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
           + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))
    # lambda^3 - tr lambda^2 + c1 lambda - det = 0; lambda = t + tr / 3: t^3 + p t + q = 0
    p = c1 - tr * tr / 3
    q = -2 * tr ** 3 / 27 + tr * c1 / 3 - det
    disc = q * q / 4 + p ** 3 / 27
    if disc <= 0:  # three real roots (trigonometric form; p <= 0 here)
        return _real_ellipse_vector(A, tr, c1, det, p, q, a1)
    # one real root and a complex pair (Cardano)
    roots = np.empty(3, np.complex128)
    sq = np.sqrt(disc)
    u, v = np.cbrt(-q / 2 + sq), np.cbrt(-q / 2 - sq)
    roots[0] = tr / 3 + u + v
    roots[1] = tr / 3 - (u + v) / 2 + 1j * (np.sqrt(3.0) / 2) * (u - v)
    roots[2] = np.conj(roots[1])
    best, found = -np.inf, False
    R = np.empty((3, 3), np.complex128)
    w = np.empty(3, np.complex128)
    for k in range(3):
        lam = roots[k]
        lam = _polish_root(lam, tr, c1, det)
        for i in range(3):
            for j in range(3):
                R[i, j] = A[i, j]
            R[i, i] = A[i, i] - lam
        if not _cross_rows(R, w) > 1e-28:
            continue  # a double root (rank 1): no unique eigenvector; a degenerate set
        # geev's normalisation: unit norm, largest component real (then the real part is used)
        big = 0
        for i in range(1, 3):
            if abs(w[i]) > abs(w[big]):
                big = i
        ph = np.conj(w[big]) / abs(w[big])
        x0, x1, x2 = (w[0] * ph).real, (w[1] * ph).real, (w[2] * ph).real
        best, kept = _keep_ellipse(x0, x1, x2, best, a1)
        found = found or kept
    return found


@numba.njit(**_JIT)
def _real_ellipse_vector9(A00, A01, A02, A10, A11, A12, A20, A21, A22, tr, c1, det, p, q,
                          a1):  # pragma: no cover - compiled
    """:func:`_ellipse_vector` when the cubic's three roots are real (most fits), in real
    arithmetic, with the (3, 3) ``A`` as nine scalars (no array to allocate per fit): the
    complex form's values to the bit (every imaginary part there is a signed zero, which adds,
    multiplies and divides out exactly), without its complex products and the hypot of each
    complex modulus."""
    r = np.sqrt(max(-p / 3, 0.0))
    phi = 0.0
    if r != 0:
        arg = min(max(-q / (2 * r ** 3), -1.0), 1.0)
        phi = np.arccos(arg) / 3
    best, found = -np.inf, False
    for k in range(3):
        lam = tr / 3 if r == 0 else tr / 3 + 2 * r * np.cos(phi - 2 * np.pi * k / 3)
        lam = _polish_root(lam, tr, c1, det)
        # the largest cross product of two rows of A - lam I (_cross_rows)
        R00, R01, R02 = A00 - lam, A01, A02
        R10, R11, R12 = A10, A11 - lam, A12
        R20, R21, R22 = A20, A21, A22 - lam
        n_best, w0, w1, w2 = -1.0, 0.0, 0.0, 0.0
        for pair in range(3):
            if pair == 0:
                a0, a1_, a2, b0, b1, b2 = R00, R01, R02, R10, R11, R12
            elif pair == 1:
                a0, a1_, a2, b0, b1, b2 = R00, R01, R02, R20, R21, R22
            else:
                a0, a1_, a2, b0, b1, b2 = R10, R11, R12, R20, R21, R22
            e0 = a1_ * b2 - a2 * b1
            e1 = a2 * b0 - a0 * b2
            e2 = a0 * b1 - a1_ * b0
            n2 = abs(e0) ** 2 + abs(e1) ** 2 + abs(e2) ** 2
            if n2 > n_best:
                n_best, w0, w1, w2 = n2, e0, e1, e2
        if not n_best > 1e-28:
            continue  # a double root (rank 1): no unique eigenvector; a degenerate set
        # geev's normalisation: the largest component positive
        wb = w0
        if abs(w1) > abs(wb):
            wb = w1
        if abs(w2) > abs(wb):
            wb = w2
        ph = wb / abs(wb)
        x0, x1, x2 = w0 * ph, w1 * ph, w2 * ph
        best, kept = _keep_ellipse(x0, x1, x2, best, a1)
        found = found or kept
    return found


@numba.njit(**_JIT)
def _ellipse_vector9(M00, M01, M02, M10, M11, M12, M20, M21, M22, a1):  # pragma: no cover - compiled
    """:func:`_ellipse_vector` of nine scalars: the real-root case (most fits) without an
    array; the complex case (rare) builds ``M`` and calls :func:`_ellipse_vector`."""
    scale = 0.0
    for x in (M00, M01, M02, M10, M11, M12, M20, M21, M22):
        scale = max(scale, abs(x))
    if not (scale > 0 and np.isfinite(scale)):
        return False
    A00, A01, A02 = M00 / scale, M01 / scale, M02 / scale
    A10, A11, A12 = M10 / scale, M11 / scale, M12 / scale
    A20, A21, A22 = M20 / scale, M21 / scale, M22 / scale
    tr = A00 + A11 + A22
    c1 = (A00 * A11 - A01 * A10 + A00 * A22 - A02 * A20
          + A11 * A22 - A12 * A21)
    det = (A00 * (A11 * A22 - A12 * A21) - A01 * (A10 * A22 - A12 * A20)
           + A02 * (A10 * A21 - A11 * A20))
    p = c1 - tr * tr / 3
    q = -2 * tr ** 3 / 27 + tr * c1 / 3 - det
    disc = q * q / 4 + p ** 3 / 27
    if disc <= 0:
        return _real_ellipse_vector9(A00, A01, A02, A10, A11, A12, A20, A21, A22, tr, c1, det, p, q, a1)
    M = np.empty((3, 3))
    M[0, 0], M[0, 1], M[0, 2] = M00, M01, M02
    M[1, 0], M[1, 1], M[1, 2] = M10, M11, M12
    M[2, 0], M[2, 1], M[2, 2] = M20, M21, M22
    return _ellipse_vector(M, a1)


@numba.njit(**{**_JIT, "inline": "always"})
def _t_entry(i0, i1, i2, mom, k, det3):  # pragma: no cover - compiled
    """T[r, k] = -sum_j inv[r, j] S2[k, j] / det3 (the sum from 0.0, j in order)."""
    acc = 0.0
    acc += i0 * mom[SCATTER[k, 3]]
    acc += i1 * mom[SCATTER[k, 4]]
    acc += i2 * mom[SCATTER[k, 5]]
    return -acc / det3


@numba.njit(**{**_JIT, "inline": "always"})
def _mr_entry(mom, r, k, t0, t1, t2):  # pragma: no cover - compiled
    """(S1 + S2 T)[r, k], the sum from S1[r, k], j in order."""
    acc = mom[SCATTER[r, k]]
    acc += mom[SCATTER[r, 3]] * t0
    acc += mom[SCATTER[r, 4]] * t1
    acc += mom[SCATTER[r, 5]] * t2
    return acc


@numba.njit(**_JIT)
def direct_fit(mom, m0, m1, s, conic, v):  # pragma: no cover - compiled
    """Direct ellipse fit of one set from its 15 moments in the frame ``(xy - m) / s``.

    Writes the unit-norm pixel conic into ``conic`` (6,) and the normalised-frame solution
    into ``v`` (6,). Returns the fit's approximate RMS geometric residual, pixels (see
    :func:`rangesim.core.conics.fit_conics_moments`), or -1 when there is no fit (fewer than
    5 points, a singular linear block, no ellipse-specific eigenvector). (All scalar: the
    scatter matrix is read from ``mom`` through :data:`SCATTER`, the 3 x 3 blocks are locals,
    so a fit allocates nothing; ``conic`` and ``v`` may hold anything after a failed fit.)
    """
    if not mom[0] >= 5:
        return -1.0
    a, b, c = mom[SCATTER[3, 3]], mom[SCATTER[3, 4]], mom[SCATTER[3, 5]]
    d, e, f = mom[SCATTER[4, 3]], mom[SCATTER[4, 4]], mom[SCATTER[4, 5]]
    g, h, i = mom[SCATTER[5, 3]], mom[SCATTER[5, 4]], mom[SCATTER[5, 5]]
    C0, C1, C2 = e * i - f * h, f * g - d * i, d * h - e * g
    det3 = a * C0 + b * C1 + c * C2
    big = max(abs(a), abs(b), abs(c), abs(d), abs(e), abs(f), abs(g), abs(h), abs(i))
    if not (abs(det3) > 1e-12 and abs(det3) > 1e-13 * big ** 3):  # (near) singular: collinear points
        return -1.0
    i00, i01, i02 = C0, c * h - b * i, b * f - c * e
    i10, i11, i12 = C1, a * i - c * g, c * d - a * f
    i20, i21, i22 = C2, b * g - a * h, a * e - b * d
    T00, T01, T02 = _t_entry(i00, i01, i02, mom, 0, det3), _t_entry(i00, i01, i02, mom, 1, det3), \
        _t_entry(i00, i01, i02, mom, 2, det3)
    T10, T11, T12 = _t_entry(i10, i11, i12, mom, 0, det3), _t_entry(i10, i11, i12, mom, 1, det3), \
        _t_entry(i10, i11, i12, mom, 2, det3)
    T20, T21, T22 = _t_entry(i20, i21, i22, mom, 0, det3), _t_entry(i20, i21, i22, mom, 1, det3), \
        _t_entry(i20, i21, i22, mom, 2, det3)
    # M = C1^-1 (S1 + S2 T): rows (r2 / 2, -r1, r0 / 2)
    M00 = _mr_entry(mom, 2, 0, T00, T10, T20) / 2
    M01 = _mr_entry(mom, 2, 1, T01, T11, T21) / 2
    M02 = _mr_entry(mom, 2, 2, T02, T12, T22) / 2
    M10 = -_mr_entry(mom, 1, 0, T00, T10, T20)
    M11 = -_mr_entry(mom, 1, 1, T01, T11, T21)
    M12 = -_mr_entry(mom, 1, 2, T02, T12, T22)
    M20 = _mr_entry(mom, 0, 0, T00, T10, T20) / 2
    M21 = _mr_entry(mom, 0, 1, T01, T11, T21) / 2
    M22 = _mr_entry(mom, 0, 2, T02, T12, T22) / 2
    if not (np.isfinite(M00) and np.isfinite(M01) and np.isfinite(M02) and np.isfinite(M10)
            and np.isfinite(M11) and np.isfinite(M12) and np.isfinite(M20) and np.isfinite(M21)
            and np.isfinite(M22)):
        return -1.0
    if not _ellipse_vector9(M00, M01, M02, M10, M11, M12, M20, M21, M22, v):  # v[:3]: the eigenvector
        return -1.0
    a0, a1, a2 = v[0], v[1], v[2]
    v[3] = T00 * a0 + T01 * a1 + T02 * a2
    v[4] = T10 * a0 + T11 * a1 + T12 * a2
    v[5] = T20 * a0 + T21 * a1 + T22 * a2
    A, B, C = v[0] / s ** 2, v[1] / s ** 2, v[2] / s ** 2
    D, E, F = v[3] / s, v[4] / s, v[5]
    conic[0], conic[1], conic[2] = A, B, C
    conic[3] = D - 2 * A * m0 - B * m1
    conic[4] = E - 2 * C * m1 - B * m0
    conic[5] = F + A * m0 ** 2 + B * m0 * m1 + C * m1 ** 2 - D * m0 - E * m1
    n2 = 0.0
    for k in range(6):
        n2 += conic[k] ** 2
    nrm = np.sqrt(n2)
    if not (np.isfinite(nrm) and nrm > 0):
        return -1.0
    for k in range(6):
        conic[k] /= nrm
    # residual: sum f^2 = v S v; the gradient (2A x + B y + D, B x + 2C y + E) is linear in
    # (x, y, 1), so sum |grad|^2 = g P g + h P h with P = S[3:, 3:]
    f2 = 0.0
    for r in range(6):
        for k in range(6):
            f2 += v[r] * mom[SCATTER[r, k]] * v[k]
    g0, g1, g2 = 2 * v[0], v[1], v[3]
    h0, h1, h2 = v[1], 2 * v[2], v[4]
    grad2 = 0.0
    for r, (gr, hr) in enumerate(((g0, h0), (g1, h1), (g2, h2))):
        for k, (gk, hk) in enumerate(((g0, h0), (g1, h1), (g2, h2))):
            grad2 += (gr * gk + hr * hk) * mom[SCATTER[3 + r, 3 + k]]
    rms = s * np.sqrt(max(f2, 0.0) / grad2) if grad2 > 0 else np.inf
    return rms if np.isfinite(rms) else np.inf


@numba.njit(**_JIT)
def direct_fits(mom, m, s):  # pragma: no cover - compiled
    """:func:`direct_fit` of K sets: conics (K, 6), ok (K,), rms (K,) (inf where no fit)."""
    K = mom.shape[0]
    conics = np.zeros((K, 6))
    ok = np.zeros(K, np.bool_)
    rms = np.full(K, np.inf)
    v = np.empty(6)
    for k in range(K):
        r = direct_fit(mom[k], m[k, 0], m[k, 1], s[k], conics[k], v)
        if r >= 0:
            ok[k] = True
            rms[k] = r
        else:
            conics[k] = 0.0
    return conics, ok, rms


@numba.njit(**_JIT)
def ellipse_row(q):  # pragma: no cover - compiled
    """Centre, semi-axes and angle of one conic ``q`` (6,): (ok, cx, cy, a, b, angle), the
    row of :func:`rangesim.core.conics.ellipse_params` (the same arithmetic)."""
    sgn = -1.0 if q[0] < 0 else 1.0
    a, b, c, d, e, f = sgn * q[0], sgn * q[1], sgn * q[2], sgn * q[3], sgn * q[4], sgn * q[5]
    h, gx, gy = b / 2, d / 2, e / 2
    det = a * c - h * h
    cx = (h * gy - c * gx) / det
    cy = (h * gx - a * gy) / det
    f0 = cx * gx + cy * gy + f  # the form's value at the centre
    mean, half = (a + c) / 2, np.hypot((a - c) / 2, h)
    lo, hi = mean - half, mean + half  # eigenvalues, lo <= hi; the major axis goes with lo
    ok = det > 0 and lo > 0 and f0 < 0  # not a parabola, hyperbola, imaginary ellipse or point
    ax, bx = np.sqrt(-f0 / lo), np.sqrt(-f0 / hi)
    # eigenvector of lo: (h, lo - a) or (lo - c, h), whichever is better conditioned
    v1x, v1y, v2x, v2y = h, lo - a, lo - c, h
    if v1x * v1x + v1y * v1y >= v2x * v2x + v2y * v2y:
        vx, vy = v1x, v1y
    else:
        vx, vy = v2x, v2y
    if vx == 0 and vy == 0:
        vx = 1.0  # a circle: any direction
    angle = (np.arctan2(vy, vx) + np.pi / 2) % np.pi - np.pi / 2  # an axis, not a vector
    return ok, cx, cy, ax, bx, angle


@numba.njit(**_JIT)
def ellipse_rows(conics):  # pragma: no cover - compiled
    """:func:`ellipse_row` of (K, 6) conics: centre (K, 2), axes (K, 2), angle (K,), ok (K,)."""
    K = conics.shape[0]
    center, axes = np.empty((K, 2)), np.empty((K, 2))
    angle, ok = np.empty(K), np.empty(K, np.bool_)
    for k in range(K):
        ok[k], center[k, 0], center[k, 1], axes[k, 0], axes[k, 1], angle[k] = ellipse_row(conics[k])
    return center, axes, angle, ok
