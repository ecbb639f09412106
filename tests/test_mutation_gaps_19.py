"""Properties no test held before a mutation audit (nineteenth session): each test here fails
when the rule it names is removed or changed, as the audit's hand-made mutations showed."""
from __future__ import annotations

import math

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.edges._discontinuities import JUMP_THRESHOLD, QUANTUM_STEPS
from tests.conftest import pinhole_scan


# -- the jump rule allows for depth quanta ---------------------------------------------------
def _rounded_ramp(q: float, step_mm: float = 0.0):
    """A plane rising 5 mm per column at 1000 mm (2.5 footprints of f = 500 px), its depth
    rounded to ``q`` mm and one in ten pixels a whole level off (+-q: a block matcher's level
    error); with ``step_mm``, the right half of the rows 20-39 that much further."""
    h, w = 60, 64
    jj = np.arange(w) - w / 2 + 0.5
    z = np.tile(1000.0 + 5.0 * jj, (h, 1))
    z[20:40, w // 2:] += step_mm
    rng = np.random.default_rng(0)
    level = np.where(rng.random((h, w)) < 0.1, rng.choice([-1.0, 1.0], (h, w)), 0.0)
    return pinhole_scan((np.round(z / q) + level) * q, f=500.0)


def test_rounding_steps_on_a_steep_plane_are_no_jumps():
    """Rounded to q = 4 mm with level errors, neighbours differ by up to 5 + 3 q = 17 mm: up to
    10 footprints (1.7-2.3 mm here), over the jump rule's cot 15 deg = 3.73 and over what the
    rounding's noise (q / sqrt 12 per pixel) adds. Rounding moves two neighbours' difference
    by at most one quantum and a matcher errs by whole levels on top, so the threshold holds
    QUANTUM_STEPS quanta beyond the footprints (the term's removal left every test passing)."""
    assert math.isclose(JUMP_THRESHOLD, 1 / math.tan(math.radians(15)), rel_tol=1e-3) and QUANTUM_STEPS >= 2
    em = rs.edges.gradient(_rounded_ramp(4.0))
    assert np.count_nonzero(em.mask & (em.labels == EdgeLabel.JUMP)) == 0
    # a true step of 60 mm (about 30 footprints, 15 quanta) still is one, all along it
    em = rs.edges.gradient(_rounded_ramp(4.0, step_mm=60.0))
    jumps = em.mask & (em.labels == EdgeLabel.JUMP)
    rows = np.nonzero(jumps.any(axis=1))[0]
    assert set(range(22, 38)) <= set(rows.tolist())
    cols = np.nonzero(jumps[22:38].any(axis=0))[0]
    assert cols.min() >= 30 and cols.max() <= 33


# -- the block matcher's left-right check and uniqueness rule ---------------------------------
def _pair(period: int | None = None, seed: int = 0):
    """A reference texture (30 x 80 px grid, 20 px margins) and an image of it at disparity 10
    left of column 40 and 12 from there on (a step two disparities high: the reference
    columns 28-29 are seen twice, by image columns 38-39 and 40-41); ``period``: a texture
    repeating every ``period`` px along the rows instead of a random one."""
    from rangesim.sensor.block_matching import block_match  # noqa: F401  (the unit under test)

    rng = np.random.default_rng(seed)
    h, w, m = 30, 80, 20
    if period is None:
        ref = rng.random((h, w + 2 * m))
    else:
        ref = np.tile(rng.random((h, period)), (1, (w + 2 * m) // period + 1))[:, :w + 2 * m]
    j = np.arange(w)
    image = ref[:, m + j - np.where(j < 40, 10, 12)]
    return image, ref


def test_left_right_check_rejects_the_copy_seen_twice():
    """Matched back from the reference, a column seen twice returns to one copy; the other copy's
    disparity then differs by 2 px from the back-match and is rejected (tolerance 1 px)."""
    from rangesim.sensor.block_matching import block_match

    image, ref = _pair()
    inner = np.s_[2:-2]  # rows whose 3 x 3 window fits
    off, _ = block_match(image, ref, 5, 16, window=3, uniqueness=0.0, lr_check=False)
    on, _ = block_match(image, ref, 5, 16, window=3, uniqueness=0.0, lr_check=True)
    rejected_off = (~np.isfinite(off[inner])).sum(axis=0)
    rejected_on = (~np.isfinite(on[inner])).sum(axis=0)
    # one copy, two columns, is rejected in (nearly) every row; without the check, all matched
    assert np.count_nonzero(rejected_on[36:44] >= 24) == 2
    assert rejected_off[36:44].max() <= 3
    # away from the step nothing is rejected either way, and the disparities are right (to the
    # sub-pixel fit's error on a 3 x 3 white-noise texture, whose score peak is no Gaussian)
    assert rejected_on[5:30].sum() == 0 and rejected_on[50:75].sum() == 0
    assert np.abs(on[inner][:, 5:30] - 10).max() < 0.5 and np.abs(on[inner][:, 50:75] - 12).max() < 0.5


def test_uniqueness_rejects_a_repeating_texture():
    """A texture repeating every 4 px matches equally well 4 px away: (1 - second) is not above
    (1 + uniqueness)(1 - best), so no pixel is accepted; a random texture passes."""
    from rangesim.sensor.block_matching import block_match

    inner = np.s_[2:-2, 20:60]
    periodic, ref_p = _pair(period=4)
    disparity, _ = block_match(periodic, ref_p, 5, 16, window=3, uniqueness=0.1, lr_check=False)
    assert np.isfinite(disparity[inner]).mean() == 0.0
    random_image, ref_r = _pair()
    disparity, _ = block_match(random_image, ref_r, 5, 16, window=3, uniqueness=0.1, lr_check=False)
    assert np.isfinite(disparity[inner][:, 4:15]).all() and np.isfinite(disparity[inner][:, 25:36]).all()


# -- the dropout law's speckle statistics at contrasts other than 1 ---------------------------
@pytest.mark.parametrize("contrast", [0.5, 1 / math.sqrt(2)])
def test_detection_probability_is_the_erlang_survival(contrast):
    """The detected amplitude is S X, X a unit-mean Gamma of contrast c: shape k = 1 / c^2,
    scale c^2. For integer k that is an Erlang variable, whose survival is closed-form:
    P(X >= t) = exp(-k t) sum_{n < k} (k t)^n / n!, so P(S X >= S_min) at t = S_min / S.
    (Only c = 1, the exponential, was checked exactly: k = 1 / c instead of 1 / c^2 passed.)"""
    from rangesim.sensor.stripe_noise import detection_probability

    k = round(1 / contrast**2)
    signal = np.array([0.02, 0.05, 0.1, 0.3])
    t = 0.05 / signal
    erlang = np.exp(-k * t) * sum((k * t) ** n / math.factorial(n) for n in range(k))
    np.testing.assert_allclose(detection_probability(signal, 0.05, contrast), erlang, rtol=1e-10)
    if k == 4:  # at S = S_min: exp(-4) (1 + 4 + 8 + 32 / 3)
        assert math.isclose(float(detection_probability(np.array([0.05]), 0.05, 0.5)[0]), 0.43347, abs_tol=1e-5)


# -- the circle fit is the geometric least-squares circle --------------------------------------
def test_fit_circle_meets_the_geometric_optimality_conditions():
    """On a noisy 60-degree arc the algebraic (Kasa) circle is biased (too small); the geometric
    fit minimises sum (rho_i - r)^2, whose gradient vanishes at the optimum:
    sum (rho_i - r) = 0 and sum (rho_i - r) (p_i - c) / rho_i = 0. Clean full circles, the
    only ones tested before, are fitted exactly by Kasa alone."""
    from rangesim.core.conics import fit_circle

    rng = np.random.default_rng(3)
    t = np.linspace(0.0, math.radians(60), 80)
    xy = np.c_[200 + 50 * np.cos(t), 120 + 50 * np.sin(t)] + rng.normal(0, 0.5, (80, 2))
    centre, radius, rms = fit_circle(xy)
    d = xy - centre
    rho = np.linalg.norm(d, axis=1)
    res = rho - radius
    assert abs(res.sum()) < 1e-6 * len(xy)
    np.testing.assert_allclose((res[:, None] * d / rho[:, None]).sum(axis=0), 0.0, atol=1e-6 * len(xy))
    assert math.isclose(rms, float(np.sqrt(np.mean(res**2))), rel_tol=1e-9)
    assert abs(radius - 50) < 3 and np.hypot(*(centre - (200, 120))) < 3


# -- status precedence: out of range over shadow ----------------------------------------------
def test_a_face_turned_from_the_laser_beyond_the_range_is_out_of_range():
    """Status codes rank miss > out of range > shadow > dropout (RangeScan). A plane tilted
    80 degrees about the y axis, its normal towards -x, faces the camera above it everywhere
    but turns away from the laser on the camera's +x side everywhere (tan 80 > 700 / 150):
    where it lies within the working range it is SHADOW; beyond ``range.far`` it is
    OUT_OF_RANGE (swapping the two ranks passed every test: only a surface out of range and
    facing away from the laser has both)."""
    import trimesh

    from rangesim.core.constants import Status
    from rangesim.sensor._scan import EmptyScanWarning
    from tests.conftest import make_sensor, plane, top_down_pose

    sheet = plane(3000.0)
    sheet.apply_transform(trimesh.transformations.rotation_matrix(math.radians(80), [0, -1, 0]))
    with pytest.warns(EmptyScanWarning, match="the laser cannot reach"):  # it measures nothing
        scan = rs.scan([sheet], make_sensor(**{"range.far": 600.0}), pose=top_down_pose(700.0), seed=0)
    z = scan.xyz_true[..., 2]
    beyond = np.isfinite(z) & (z > 600.0)
    within = np.isfinite(z) & (z < 590.0)
    assert beyond.sum() > 200 and within.sum() > 200
    assert np.all(scan.status[beyond] == Status.OUT_OF_RANGE)
    assert np.all(scan.status[within] == Status.SHADOW)


# -- ground truth of an open sheet seen from its back ------------------------------------------
@pytest.mark.parametrize(("eye_z", "label"), [(300.0, EdgeLabel.CONVEX), (-300.0, EdgeLabel.CONCAVE)])
def test_an_open_roof_is_a_ridge_from_above_and_a_valley_from_below(eye_z, label):
    """An open sheet folded into a roof (two 100 x 60 mm panels meeting at a ridge along y,
    dropping 25 mm to either side) is seen from either side: from above its fold is a convex
    crease, from below a concave one (mesh convexity is the front's; from the back it swaps).
    No test scanned an open mesh from behind: not swapping passed, and from below the fold was
    no crease at all (the faces' normals were compared with the scan's, which face the camera)."""
    import trimesh

    from rangesim.core.geometry import look_at
    from tests.conftest import make_sensor

    v = np.array([[-50, -30, -25], [0, -30, 0], [50, -30, -25], [-50, 30, -25], [0, 30, 0], [50, 30, -25]], float)
    roof = trimesh.Trimesh(v, np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]]), process=False)
    scene = rs.load_scene(roof)
    assert not scene.objects[0].watertight
    pose = look_at((0.0, 0.0, eye_z), (0.0, 0.0, -12.0), up=(0, 1, 0))
    scan = rs.scan(scene, make_sensor(), pose=pose, seed=0)
    truth = rs.evaluate.visible_truth(scan, scene)
    creases = np.isin(truth, (EdgeLabel.CONVEX, EdgeLabel.CONCAVE))
    assert creases.sum() > 40  # the fold, across the image
    assert np.all(truth[creases] == label)


# -- a rim seen whole counts as seen whole ------------------------------------------------------
def test_open_hole_rims_seen_head_on_are_wholly_visible():
    """Head-on, nothing hides the Green Piece's top rims; yet half the pixels a rim's points land
    on see past it, into the hole. A point counts as seen when any of the 2 x 2 pixels around it
    sees its surface (the slack of ``_visible``): every top rim is then 1.0 visible, while the
    bottom rims, hidden by the walls where the view does not reach down the hole, are not.
    (Testing the one pixel a point lands on passed every test.)"""
    from pathlib import Path

    from rangesim.core.geometry import look_at

    scene = rs.load_scene(Path(__file__).resolve().parents[1] / "scenes" / "green_piece.toml")
    sensor = rs.load_sensor("white_scanner").with_params(
        {"camera.width": 256, "camera.height": 240, "noise.sigma_px": 0, "noise.speckle_contrast": 0})
    scan = rs.scan(scene, sensor, pose=look_at((0, 0, 300), (0, 0, 0), up=(0, 1, 0)), seed=0)
    circles = rs.evaluate.ground_truth_features(scan, scene)["circles"]
    tops = [c for c in circles if c.name.endswith("_rim_top")]
    bottoms = [c for c in circles if c.name.endswith("_rim_bottom")]
    assert len(tops) == 11 and len(bottoms) == 11
    assert all(c.visible == 1.0 for c in tops), [(c.name, c.visible) for c in tops]
    assert all(c.visible < 0.35 for c in bottoms)
