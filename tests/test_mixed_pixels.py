"""Mixed pixels (``rangesim.sensor.mixed_pixels``) against the first-order analytic model: a
step ``delta`` (mm along the sheet normal) on a surface advancing ``a`` mm per pixel moves the
stripe centroid of the pixel ``m`` columns from it by ``(delta / a) * T(m)``, ``T`` the share
of the stripe image's second moment beyond the step; the gate opens where the largest shift,
``delta / (2 a)``, passes ``MIN_SHIFT_PX`` (issue 14 item 6: not at a fixed 0.5 % of the range)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.backend import mitsuba
from rangesim.sensor.mixed_pixels import FWHM_TO_SIGMA, MIN_SHIFT_PX, stripe_mixing_shift
from tests.conftest import box, make_sensor, plane, top_down_pose

WIDTH, ROWS, EDGE = 64, 3, 32  # the step lies between columns EDGE - 1 and EDGE
PITCH, THETA, Z0 = 0.25, math.radians(30.0), 300.0  # mm per pixel along the row, sheet tilt, range


def step_rows(dz: float, sigma_px: float) -> tuple[np.ndarray, float, float, int]:
    """The kernel's shift (ROWS, WIDTH) on a fronto-parallel step of ``dz`` mm, seen through a
    sheet with normal (cos t, 0, sin t) whose image is ``sigma_px`` pixels wide (sigma).
    Returns the shift, delta (mm), a (mm/px) and the window."""
    mi = mitsuba()
    u = np.tile(np.arange(WIDTH, dtype=float), ROWS)
    z = Z0 + dz * (u % WIDTH >= EDGE)
    points = mi.Vector3f(PITCH * u, np.repeat(np.arange(ROWS, dtype=float), WIDTH), z)
    n = len(u)
    normal = mi.Vector3f(np.full(n, math.cos(THETA)), np.zeros(n), np.full(n, math.sin(THETA)))
    a = PITCH * math.cos(THETA)
    stripe_fwhm = sigma_px * a / FWHM_TO_SIGMA
    window = int(math.ceil(4.7 * sigma_px))  # the detector's 2 FWHM
    ones = mi.Bool(np.ones(n, bool))
    shift = stripe_mixing_shift(points, normal, ones, mi.Float(np.ones(n)), ones, WIDTH, stripe_fwhm, window)
    return np.asarray(shift).reshape(ROWS, WIDTH), dz * math.sin(THETA), a, window


def first_order_shift(delta: float, a: float, sigma_px: float, window: int) -> np.ndarray:
    """(WIDTH,) analytic shift, pixels: -(delta / a) T(m) on the near side, +(delta / a) T on the far."""
    j = np.arange(-window, window + 1)
    w = np.exp(-0.5 * (j / sigma_px) ** 2)
    out = np.zeros(WIDTH)
    for col in range(WIDTH):
        beyond = (col + j >= EDGE) if col < EDGE else (col + j < EDGE)
        inside = (col + j >= 0) & (col + j < WIDTH)
        tail = (j ** 2 * w * (beyond & inside)).sum() / (sigma_px ** 2 * (w * inside).sum())
        out[col] = (-1.0 if col < EDGE else 1.0) * delta / a * tail
    return out


def threshold_dz() -> float:
    """The step (mm of depth) whose largest shift delta / (2 a) is MIN_SHIFT_PX."""
    return 2.0 * MIN_SHIFT_PX * PITCH * math.cos(THETA) / math.sin(THETA)


def test_a_step_just_under_the_threshold_mixes_nothing_just_over_it_mixes():
    dz0 = threshold_dz()  # 0.0087 mm here
    under, _, _, _ = step_rows(0.9 * dz0, 2.0)
    assert not under.any()
    over, delta, a, window = step_rows(1.1 * dz0, 2.0)
    assert np.count_nonzero(over) > 0
    expected = first_order_shift(delta, a, 2.0, window)
    # the two pixels beside the step move by half the stripe image's jump, in opposite directions
    np.testing.assert_allclose(over[:, EDGE - 1:EDGE + 1], np.tile(expected[EDGE - 1:EDGE + 1], (ROWS, 1)),
                               rtol=0.03)
    assert abs(abs(over[0, EDGE]) - 1.1 * MIN_SHIFT_PX) < 0.1 * MIN_SHIFT_PX
    # far from the step nothing moves
    assert not over[:, :EDGE - window - 1].any() and not over[:, EDGE + window + 1:].any()


@pytest.mark.parametrize("sigma_px", [1.5, 3.0])
def test_shift_profile_follows_the_first_order_model(sigma_px):
    delta_over_a = 0.02 * sigma_px  # a step small against the stripe: first order holds
    dz = delta_over_a * PITCH * math.cos(THETA) / math.sin(THETA)
    shift, delta, a, window = step_rows(dz, sigma_px)
    expected = first_order_shift(delta, a, sigma_px, window)
    big = np.abs(expected) > 0.05 * np.abs(expected).max()
    np.testing.assert_allclose(shift[:, big], np.tile(expected[big], (ROWS, 1)), rtol=0.05)
    for row in shift[1:]:
        np.testing.assert_array_equal(row, shift[0])  # rows do not leak into each other


def test_mixed_pixel_count_scales_with_the_stripe_image_width():
    counts = []
    for sigma_px in (1.5, 3.0):
        dz = 20 * threshold_dz()  # largest shift 10 x MIN_SHIFT_PX
        shift, delta, a, window = step_rows(dz, sigma_px)
        mixed = np.count_nonzero(np.abs(shift[0]) > MIN_SHIFT_PX)
        predicted = np.count_nonzero(np.abs(first_order_shift(delta, a, sigma_px, window)) > MIN_SHIFT_PX)
        assert abs(mixed - predicted) <= 2  # one pixel per side
        counts.append(mixed)
    # T(m) is a function of m / sigma_px: twice the stripe, twice the mixed band
    assert 1.7 < counts[1] / counts[0] < 2.3


def test_mixing_is_continuous_across_the_old_half_percent_gate():
    # issue 14 item 6: a 1.5 mm stripe at 300 mm, steps of 1.45 and 1.5 mm (0.5 % of the
    # range: the old gate gave 0 and 752 mixed pixels at such a step)
    sensor = make_sensor(**{"camera.width": 240, "camera.height": 120, "laser.stripe_width": 1.5})

    def mixed(height):
        scan = rs.scan([plane(), box([-20, -40, 0], [40, 40, height])], sensor, pose=top_down_pose(300.0 + height))
        err = np.linalg.norm(scan.xyz - scan.xyz_true, axis=2)
        return int((scan.valid & (err > 0.02)).sum()), float(np.nanmax(np.where(scan.valid, err, np.nan)))

    (n_under, e_under), (n_over, e_over) = mixed(1.45), mixed(1.5)
    assert n_under > 100 and abs(n_under - n_over) < 0.1 * n_over
    assert abs(e_under - e_over) < 0.05 * e_over
    assert 0.2 < e_over < 0.75  # about half the step at the edge pixel, never beyond the step
    # a step far under what the peak detector resolves mixes nothing
    assert mixed(0.005) == (0, pytest.approx(0.0, abs=1e-3))
