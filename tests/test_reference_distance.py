"""``range.reference``: the distance at which the photometry and the noise terms are stated.

Given, it belongs to the device: a surface at a fixed distance returns the same signal and
carries the same noise whatever the working range. Left out, it is mid-range and moves with
``range.near`` / ``range.far``; the return then scales as the fourth power of the reference
distance (signal = albedo cos i cos e (z_ref / d_L)^2 (z_ref / d_C)^2, ``rangesim.sensor.signal``).
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.sensor.config import preset_names
from tests.conftest import make_sensor, plane, top_down_pose

NOISY = {"noise.signal_px": 0.1, "noise.correlation_mm": 1.0, "laser.stripe_width": 1.0, "noise.sigma_px": 0.05}


def _scan(**changes):
    return rs.scan([plane()], make_sensor(**NOISY, **changes), pose=top_down_pose(400.0), seed=3)


def test_a_given_reference_keeps_the_signal_and_noise_when_the_range_changes():
    a = _scan(**{"range.reference": 550.0})
    b = _scan(**{"range.reference": 550.0, "range.far": 1500.0})
    assert a.valid.all() and b.valid.all()
    np.testing.assert_array_equal(a.intensity, b.intensity)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    assert make_sensor(**{"range.reference": 550.0}).reference_distance == 550.0


def test_without_a_reference_the_return_follows_mid_range_to_the_fourth_power():
    a = _scan()  # mid-range (100 + 1000) / 2 = 550 mm
    b = _scan(**{"range.far": 1500.0})  # 800 mm
    assert make_sensor(**{"range.far": 1500.0}).reference_distance == 800.0
    np.testing.assert_allclose(b.intensity / a.intensity, (800.0 / 550.0) ** 4, rtol=1e-5)
    assert not np.array_equal(a.sigma, b.sigma)


@pytest.mark.parametrize("value", [0.0, -10.0, float("nan"), "350", True])
def test_a_reference_that_is_no_positive_distance_is_refused(value):
    with pytest.raises(RangesimError, match="range.reference"):
        make_sensor(**{"range.reference": value})


def test_every_shipped_preset_states_its_reference_at_mid_range():
    names = preset_names()
    assert {"white_scanner", "cyberware_3030", "inria_laser", "kinect_v1", "structured_light_bench"} <= set(names)
    for name in names:
        r = rs.load_sensor(name).params["range"]
        assert r["reference"] == pytest.approx(0.5 * (r["near"] + r["far"])), name
