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


# -- the clearance a laser stripe's width needs, and the noise beside a broken pair -----------------
@pytest.mark.parametrize(("fwhm", "footprint", "clearance"), [
    (0.5, 0.27, 2),    # White Scanner: sigma_w 0.21 mm, 1.83 px of mixing reach -> 1 mixed px past the jump pixel
    (1.0, 0.5, 2),     # Cyberware: 0.42 mm, 1.98 px
    (1.5, 1.45, 1),    # INRIA: 0.64 mm, 1.02 px: the stripe images under a pixel wide, no pixel past the jump's
    (3.0, 0.5, 6),     # a wide stripe: 1.27 mm, 5.93 px -> 5 mixed pixels
    (0.0, 0.3, 1),     # no stripe width: only the operator's own reach
])
def test_stripe_clearance_follows_the_stripe_width(fwhm, footprint, clearance):
    """1 + max(0, ceil(2.326 sigma_w / footprint - 3/2)) pixels, sigma_w = FWHM / 2.355: the pixels
    k + 1/2 from the step that the sheet's profile reaches beyond 1 %, past the jump's own pixel,
    plus the 3 x 3 operator's reach."""
    from types import SimpleNamespace

    from rangesim.edges._thinning import stripe_clearance

    scan = SimpleNamespace(meta={"sensor": {"mode": "geometric", "laser": {"stripe_width": fwhm}}})
    fp = np.full((8, 8), footprint, np.float32)
    valid = np.ones((8, 8), bool)
    assert stripe_clearance(scan, fp, valid) == clearance
    # no stripe in the scan's meta (a recording, a block matcher's depth): the fixed clearance
    for meta in ({}, {"sensor": {"mode": "structured_light", "laser": {"stripe_width": fwhm}}}):
        assert stripe_clearance(SimpleNamespace(meta=meta), fp, valid) == JUMP_CLEARANCE


@pytest.mark.filterwarnings("ignore:.*fits the view from")   # the plate's table, cropped: no matter here
def test_gradient_takes_the_presets_clearance():
    """At the presets' own resolutions (the clearance is the stripe's width in pixels)."""
    scene = rs.datasets.plate_scene()
    for name, expected in (("white_scanner", 2), ("inria_laser", 1)):
        scan = rs.scan(scene, rs.load_sensor(name), seed=0)
        assert rs.edges.gradient(scan).params["jump_clearance"] == expected
    assert rs.edges.gradient(scan, jump_clearance=3).params["jump_clearance"] == 3


def test_step_noise_gain_is_the_response_noise_beside_a_broken_pair():
    """The gain profile (seeded, 64 x 64 draws) against an independent measurement (another
    seed, 4x the samples) of the same ratio: the RMS of the four operators' largest |response|
    on step-smoothed white noise d px from a broken pair over its RMS far away, at sigma 1.75
    px (the INRIA preset's noise): about 9 at the pair's own pixel (the smoothing cannot reach
    across, and the pixel's reflected taps cancel its neighbours' along the row), 2.2 / 1.7 /
    1.2 at 1 / 2 / 3 px; 1 beyond ceil(sigma) in the per-pixel gain."""
    from rangesim.edges._gradient import step_gain_profile, step_noise_gain

    sigma = 1.75
    profile = step_gain_profile(sigma)
    rows, w = 256, 64
    c = w // 2 - 1
    pairs = np.zeros((4, rows, w), bool)
    pairs[0][:, c] = True
    rng = np.random.default_rng(7)
    acc = np.zeros(w)
    for _ in range(64):
        resp = second_differences(step_smooth(rng.standard_normal((rows, w)).astype(np.float32), pairs, sigma), pairs)
        mag = np.fmax.reduce(np.abs(np.stack(resp)), axis=0)     # (a NaN operator at the pair: the others)
        acc += (np.nan_to_num(mag[4:-4].astype(np.float64)) ** 2).sum(axis=0)
    rms = np.sqrt(acc)
    far = rms[6:c - 8].mean()
    measured = np.maximum(rms[c::-1][:4] / far, rms[c + 1:][:4] / far)
    np.testing.assert_allclose(profile[:4], measured, rtol=0.08)
    assert profile[0] > 6 and np.all(np.diff(profile[:5]) <= 0.02) and profile.min() >= 1.0
    touching = np.zeros((12, 12), bool)
    touching[:, 0] = True
    gain = step_noise_gain(touching, sigma)
    np.testing.assert_allclose(gain[0, :3], profile[:3])
    assert (gain[:, 3:] == 1.0).all()                      # beyond ceil(1.75) = 2 px


@pytest.mark.filterwarnings("ignore:.*fits the view from")
def test_inria_creases_beside_jumps_are_kept():
    """The INRIA preset's stripe images under a pixel wide, so a crease 2 px from a jump (the
    far rim of a small hole seen obliquely, the top of a thin wall) is no mixing artefact:
    with the stripe's clearance (1 px) gradient finds about twice the true creases within
    2.5 px of a true jump that the fixed 2 px kept, and its F1 does not fall."""
    from scipy import ndimage

    scene = rs.load_scene([rs.cad.machined_part(5).mesh])
    scan = rs.scan(scene, rs.load_sensor("inria_laser"), seed=0)
    truth = rs.evaluate.visible_truth(scan, scene)
    creases = np.isin(truth, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
    beside = creases & (ndimage.distance_transform_edt(truth != EdgeLabel.JUMP) <= 2.5)
    assert beside.sum() >= 30
    found, f1 = {}, {}
    for clearance in (None, 2):
        em = rs.edges.gradient(scan, jump_clearance=clearance)
        pred = em.mask & np.isin(em.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
        found[clearance] = (ndimage.distance_transform_edt(~pred)[beside] <= 1).mean()
        f1[clearance] = rs.evaluate.score_edges(em, scan, scene)["f1"]
    assert found[None] >= 1.5 * found[2] and found[None] >= 0.35, found
    assert f1[None] >= f1[2], f1
