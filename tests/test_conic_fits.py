"""The compiled direct ellipse fit (``rangesim.core._conic_kernels``): exact on exact points,
the Halir-Flusser solution that LAPACK's eigenvectors give on noisy ones, and refusals on
sets that hold no ellipse."""
from __future__ import annotations

import numpy as np
import pytest

from rangesim.core.conics import (
    MOMENT_POWERS,
    conic_monomials,
    ellipse_params,
    fit_conic,
    fit_conics_moments,
)


def _ellipse_points(a, b, angle, centre, t):
    x, y = a * np.cos(t), b * np.sin(t)
    ca, sa = np.cos(angle), np.sin(angle)
    return np.column_stack([x * ca - y * sa, x * sa + y * ca]) + centre


def _halir_flusser_lapack(xy):
    """The reference: Halir-Flusser with np.linalg.eig (the form the kernel replaced)."""
    m = xy.mean(0)
    s = np.abs(xy - m).max()
    q = (xy - m) / s
    x, y = q[:, 0], q[:, 1]
    D1 = np.column_stack([x * x, x * y, y * y])
    D2 = np.column_stack([x, y, np.ones_like(x)])
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    T = -np.linalg.solve(S3, S2.T)
    M = S1 + S2 @ T
    M = np.array([M[2] / 2, -M[1], M[0] / 2])
    v = np.real(np.linalg.eig(M)[1])
    a1 = v[:, np.nonzero(4 * v[0] * v[2] - v[1] ** 2 > 0)[0][0]]
    A, B, C = a1 / s ** 2
    Dd, E = (T @ a1)[:2] / s
    F = (T @ a1)[2]
    mx, my = m
    c = np.array([A, B, C, Dd - 2 * A * mx - B * my, E - 2 * C * my - B * mx,
                  F + A * mx ** 2 + B * mx * my + C * my ** 2 - Dd * mx - E * my])
    return c / np.linalg.norm(c)


@pytest.mark.parametrize("a, b, angle, span", [(40.0, 25.0, 0.3, 2 * np.pi), (7.0, 6.5, -1.2, 2.0),
                                               (120.0, 30.0, 1.0, 1.2), (15.0, 15.0, 0.0, np.pi)])
def test_exact_points_give_the_exact_ellipse(a, b, angle, span):
    centre = np.array([233.0, 141.5])
    xy = _ellipse_points(a, b, angle, centre, np.linspace(0.4, 0.4 + span, 60))
    c, axes, ang, ok = ellipse_params(fit_conic(xy)[None])
    assert ok[0]
    np.testing.assert_allclose(c[0], centre, atol=1e-7)
    np.testing.assert_allclose(axes[0], [a, b], rtol=1e-8)
    if a != b:  # a circle has no axis
        assert abs((ang[0] - angle + np.pi / 2) % np.pi - np.pi / 2) < 1e-7


def test_noisy_arcs_match_the_lapack_solution():
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(200):
        a, b = rng.uniform(3, 150, 2)
        t = rng.uniform(0, 2 * np.pi) + rng.uniform(0, rng.uniform(0.5, 2 * np.pi), 80)
        xy = _ellipse_points(a, b, rng.uniform(0, np.pi), rng.uniform(0, 500, 2), t)
        xy = np.round(xy + rng.normal(0, 0.3, xy.shape))  # integer pixels, as edge maps give
        ours, ref = fit_conic(xy), _halir_flusser_lapack(xy)
        worst = max(worst, min(np.abs(ours - ref).max(), np.abs(ours + ref).max()))  # the sign is free
    assert worst < 1e-8


def test_moments_of_unions_fit_as_the_union_and_report_the_residual():
    # moments add: the fit of two arcs' summed moments is the fit of their points together
    rng = np.random.default_rng(3)
    xy = _ellipse_points(30, 18, 0.5, np.array([100.0, 80.0]), rng.uniform(0, 2 * np.pi, 90))
    noisy = xy + rng.normal(0, 0.5, xy.shape)
    m, s = noisy.mean(0), np.abs(noisy - noisy.mean(0)).max()
    q = (noisy - m) / s
    parts = conic_monomials(q[:40]).sum(0) + conic_monomials(q[40:]).sum(0)
    conics, ok, rms = fit_conics_moments(np.stack([parts, conic_monomials(q).sum(0)]), np.stack([m, m]),
                                         np.array([s, s]))
    assert ok.all()
    assert min(np.abs(conics[0] - conics[1]).max(), np.abs(conics[0] + conics[1]).max()) < 1e-10
    # the residual estimate is the RMS geometric distance to first order: about the noise
    # (0.5 px in each axis; the normal component is what a fit leaves)
    assert 0.35 < rms[0] < 0.65


def test_sets_without_an_ellipse_are_refused():
    line = np.column_stack([np.arange(30.0), 2.0 * np.arange(30.0) + 5])  # collinear: singular
    few = np.array([[0, 0], [1, 0], [0, 1], [1, 1.0]])  # under 5 points
    assert fit_conic(line) is None and fit_conic(few) is None
    mom = np.zeros((2, 15))
    mom[1, MOMENT_POWERS.index((0, 0))] = 3.0
    conics, ok, rms = fit_conics_moments(mom, np.zeros((2, 2)), np.ones(2))
    assert not ok.any() and np.isinf(rms).all() and (conics == 0).all()
