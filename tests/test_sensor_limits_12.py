"""Sensor values far outside anything physical are refused when the sensor is made, in one line
naming the key, its range and why (they raised MemoryError, OverflowError or NumPy's 'lam value too
large' deep in a scan); values at the limit still scan."""
from __future__ import annotations

import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.sensor.config import MAX_DOT_SIGMA_PX, MAX_EXPOSURE_E, MAX_RENDER_DEPTH, focal_px


def _sensor(**changes):
    return rs.load_sensor("white_scanner").with_params({"camera.width": 64, "camera.height": 48, **changes})


@pytest.mark.parametrize(("key", "value", "words"), [
    ("noise.correlation_mm", 1e9, ["noise.correlation_mm", "px at the reference distance", "64 px"]),
    ("render.max_depth", 10**6, ["render.max_depth", f"[2, {MAX_RENDER_DEPTH}]"]),
    ("render.max_depth", 1, ["render.max_depth", "[2, "]),
    ("render.exposure_e", 1e30, ["render.exposure_e", "must lie in"]),
    ("structured_light.dot_sigma_px", 1e3, ["structured_light.dot_sigma_px", "at most"]),
    ("noise.speckle_contrast", 50.0, ["noise.speckle_contrast", "[0, 1]", "fully developed speckle"]),
    # dots 3 px apart at 0.1 per pixel: their disks would cover 0.71 of the pattern (placement jams at 0.547)
    ("structured_light.dot_min_spacing_px", 3.0, ["structured_light.dot_min_spacing_px", "0.71", "0.4"]),
    ("noise.signal_contrast", 1.5, ["noise.signal_contrast", "[0, 1]"]),
])
def test_unphysical_values_are_refused(key, value, words):
    with pytest.raises(RangesimError) as info:
        _sensor(**{key: value})
    message = str(info.value)
    assert len(message.splitlines()) == 1
    for word in words:
        assert word in message, message


def test_the_limits_themselves_are_accepted():
    sensor = _sensor()
    r = sensor.params["range"]
    z_mid = 0.5 * (r["near"] + r["far"])
    # a correlation length of exactly the image's larger side (in px at mid-range)
    widest = 64 * z_mid / focal_px(64, sensor.params["camera"]["fov_deg"])
    _sensor(**{"noise.correlation_mm": widest * (1 - 1e-9)})
    with pytest.raises(RangesimError):
        _sensor(**{"noise.correlation_mm": widest * 1.001})
    _sensor(**{"render.max_depth": MAX_RENDER_DEPTH, "render.exposure_e": MAX_EXPOSURE_E,
               "structured_light.dot_sigma_px": MAX_DOT_SIGMA_PX})
    _sensor(**{"noise.speckle_contrast": 1.0, "noise.signal_contrast": 1.0})


def test_a_long_correlation_still_scans_a_plane():
    """At a correlation as long as the image the field varies slowly (neighbours' values correlate
    strongly; a white field's do not), and a scan with it runs and is valid."""
    import numpy as np

    from rangesim.sensor.stripe_noise import correlated_field
    from tests.conftest import plane, top_down_pose

    field = correlated_field(np.random.default_rng(0), (48, 64), (60.0, 60.0))
    assert np.corrcoef(field[:, :-1].ravel(), field[:, 1:].ravel())[0, 1] > 0.8
    sensor = _sensor(**{"noise.correlation_mm": 20.0})
    scan = rs.scan([plane()], sensor, pose=top_down_pose(sensor.reference_distance), seed=3)
    assert scan.valid.mean() > 0.9 and np.isfinite(scan.depth[scan.valid]).all()


@pytest.mark.parametrize(("old", "new", "words"), [
    ('name = "white_scanner"', "name = 5", ["name must be a text", "5"]),
    ('mode = "geometric"', "mode = 1", ["mode must be a text"]),
    ("sigma_px = 0.1", 'sigma_px = "0.1"', ["noise.sigma_px must be a number", "'0.1'", "without quotes"]),
])
def test_sensor_file_values_of_the_wrong_type_are_refused(tmp_path, old, new, words):
    """A quoted number was read as the number, `name = 5` as the name "5": a typo passed silently."""
    base = (rs.sensor.config.PRESET_DIR / "white_scanner.toml").read_text()
    assert base.count(old) == 1
    path = tmp_path / "s.toml"
    path.write_text(base.replace(old, new))
    with pytest.raises(RangesimError) as info:
        rs.load_sensor(path)
    for word in words:
        assert word in str(info.value), str(info.value)
