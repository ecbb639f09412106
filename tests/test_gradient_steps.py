"""Creases beside depth steps on noisy scans (issue 14): the gradient detector's smoothing
does not average across a broken pair (:mod:`rangesim.edges._gradient_steps`).

Model: smoothing a step of ``H`` footprints by ``sigma`` px gives second differences of about
``H g(d / sigma) / sigma^2`` at ``d`` px from it (``g`` the Gaussian's derivative), so the
detector used to drop every response within ``ceil(2 sigma)`` px of a jump, creases there
included. Smoothing each side with the other side replaced by its own surface continued
(point reflection about the run's last pixel) keeps planes exact up to the step and a crease
``d`` px away at its full response once ``2 d`` is a few sigma.
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.edges._gradient import _nan_gaussian, second_differences
from rangesim.edges._gradient_steps import smoothing_weights, step_smooth
from rangesim.edges._thinning import JUMP_CLEARANCE
from tests.conftest import pinhole_scan


def _scan(z_fp: np.ndarray, noise_fp: float, seed: int, f: float = 300.0, z0: float = 400.0) -> RangeScan:
    """A scan whose depth is ``z0 + footprint * z_fp`` (footprint ``z0 / f`` mm) plus Gaussian
    noise of ``noise_fp`` footprints, which its ``sigma`` (mm) carries as a laser scan's does."""
    h, w = z_fp.shape
    fp = z0 / f
    depth = z0 + fp * z_fp + noise_fp * fp * np.random.default_rng(seed).standard_normal(z_fp.shape)
    return pinhole_scan(depth, f, noise_fp * fp)


def _roof_beside_step(d: int, step: float, size: int = 96, crease: int = 40) -> np.ndarray:
    """Depth in footprints: frontal up to column ``crease``, then turning 45 degrees away
    (a convex crease at that column's centre), and ``step`` footprints further away from
    column ``crease + d`` on (the crease's pixel is ``d - 1`` px from the step's near pixel)."""
    col = np.arange(size, dtype=float)
    z = np.maximum(col - crease, 0.0)
    z = np.where(col >= crease + d, z + step, z)
    return np.repeat(z[None, :], size, 0)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("d", [4, 6])
def test_crease_beside_a_step_is_found(seed, d):
    """A 45-degree crease ``d - 1`` px from the near pixel of a 10-footprint step (broken in
    every row under the noise-aware jump rule) at the INRIA preset's noise (0.8 footprints,
    ~1.75 px smoothing): found within 1 px in most rows. At 3 px (d = 4) the old rule, which
    dropped every response within ceil(2 sigma) = 4 px of the step's pixels, found it in
    none of the rows (seeds 0-2); 0.71-1.00 of them at 5 px, as now."""
    em = rs.edges.gradient(_scan(_roof_beside_step(d, 10.0), 0.8, seed))
    sigma = em.params["sigma"]
    assert 1.5 <= sigma <= 2.0
    assert JUMP_CLEARANCE < d - 1
    rows = slice(8, -8)
    convex = em.mask & (em.labels == EdgeLabel.CONVEX)
    assert convex[rows, 39:42].any(axis=1).mean() >= 0.6
    jump = em.mask & (em.labels == EdgeLabel.JUMP)
    assert jump[rows, 40 + d - 1].mean() >= 0.9                # the step itself is the jump


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("step", [10.0, 30.0])
def test_no_crease_from_a_step(seed, step):
    """A plane slanted 45 degrees (slope 1 footprint / px) that steps ``step`` footprints
    away at column 48, at 0.8 footprints of noise: no crease pixel anywhere (the old
    smoothing's ramp would answer ``step g(d / sigma) / sigma^2`` beside it; the image border,
    where the smoothing renormalises a slanted plane, is left out)."""
    col = np.arange(96, dtype=float)
    z = np.repeat((col + np.where(col >= 48, step, 0.0))[None, :], 96, 0)
    em = rs.edges.gradient(_scan(z, 0.8, seed))
    crease = em.mask & np.isin(em.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
    assert crease[8:-8, 8:-8].sum() <= 3
    assert not crease[:, 40:56].any()
    assert (em.mask & (em.labels == EdgeLabel.JUMP))[8:-8, 47].mean() >= 0.9


@pytest.mark.parametrize("sigma", [1.0, 1.07, 1.75, 2.5])
def test_planes_beside_steps_stay_exact(sigma):
    """Each side of a diagonal step keeps its plane to rounding, up to the step (the taps across
    it continue the side's own surface), so the operators respond 0 on both."""
    yy, xx = np.mgrid[0:40, 0:50].astype(np.float64)
    plane = 0.7 * xx - 1.3 * yy + 100
    far = xx + 0.5 * yy > 25
    z = (plane + 50 * far).astype(np.float32)
    pairs = np.zeros((4,) + z.shape, bool)
    pairs[0, :, :-1] = far[:, :-1] != far[:, 1:]
    pairs[2, :-1, :] = far[:-1, :] != far[1:, :]
    pairs[1, :-1, :-1] = far[:-1, :-1] != far[1:, 1:]
    pairs[3, :-1, 1:] = far[:-1, 1:] != far[1:, :-1]
    r = len(smoothing_weights(sigma)) - 1
    inner = (slice(r, -r), slice(r, -r))                      # open image borders renormalise
    zs = step_smooth(z, pairs, sigma)
    assert np.abs(zs - (plane + 50 * far))[inner].max() < 1e-4
    resp = second_differences(zs, pairs)
    inner = (slice(r + 1, -r - 1), slice(r + 1, -r - 1))      # the operators reach 1 px further
    assert max(np.nanmax(np.abs(x[inner])) for x in resp) < 1e-3


def test_same_as_the_plain_smoothing_away_from_steps_and_gaps():
    """Without broken pairs it is the detector's old smoothing (normalised at gaps and the
    border, to float rounding), beside a gap too (there with the joint 2-D weights, not per
    pass: per pass, a slanted face's one-sided means make false creases at a gap's corners)."""
    rng = np.random.default_rng(3)
    z = rng.normal(size=(50, 60)).astype(np.float32)
    z[20:24, 30:36] = np.nan
    pairs = np.zeros((4,) + z.shape, bool)
    for sigma in (1.0, 1.75):
        a, b = step_smooth(z, pairs, sigma), _nan_gaussian(z, sigma)
        assert np.array_equal(np.isnan(a), np.isnan(b))
        far = np.ones(z.shape, bool)
        far[10:34, 20:46] = False
        assert np.abs(a - b)[far].max() < 1e-6
        assert np.nanmax(np.abs(a - b)) < 1e-6


def test_a_crease_near_a_break_keeps_its_response():
    """1-D law: a roof ``m`` px from the last pixel before a broken pair keeps its smoothed
    second difference (its mirror image lies ``2 m`` px away) once ``2 m >= 3 sigma``; the old
    smoothing across the step adds ``H`` times the ramp's second difference there."""
    sigma, size, crease = 1.75, 64, 30
    col = np.arange(size, dtype=float)
    base = np.repeat(np.maximum(col - crease, 0.0)[None, :], 21, 0)
    ref = second_differences(_nan_gaussian(base.astype(np.float32), sigma))[0][10, crease]
    for d in (3, 4, 5):
        z = base + np.where(col >= crease + d, 8.0, 0.0)
        pairs = np.zeros((4,) + z.shape, bool)
        pairs[0, :, crease + d - 1] = True
        z = z.astype(np.float32)
        new = second_differences(step_smooth(z, pairs, sigma), pairs)[0][10, crease]
        old = second_differences(_nan_gaussian(z, sigma), pairs)[0][10, crease]
        m = d - 1
        assert new == pytest.approx(ref, rel=0.02 if 2 * m >= 3 * sigma else 0.1)
        assert abs(old - ref) > 0.05 * ref
