"""Scans too big for the memory budget are made in bands of rows, and equal the scan in one piece.

The budget is set with RANGESIM_MEMORY_LIMIT so that a small image needs several bands; no
test allocates a large image.
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import look_at
from rangesim.sensor import bands
from rangesim.sensor._scan import BASE_BYTES, BYTES_PER_PIXEL

FIELDS = ("depth", "xyz", "valid", "normal", "intensity", "part", "face", "status", "xyz_true", "sigma")


def _limit_for(sensor, rows: int) -> int:
    """A memory limit (bytes) under which ``sensor`` scans in bands of ``rows`` rows."""
    w, h = sensor.width, sensor.height
    return int(BASE_BYTES + w * h * (bands.RESULT_BYTES_PER_PIXEL + 4)
               + (rows + 2 * bands.MARGIN_ROWS) * w * BYTES_PER_PIXEL["geometric"] + 1)


def _assert_same(a, b):
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and x.dtype == y.dtype, name
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name


@pytest.fixture(scope="module")
def green():
    return rs.load_scene("scenes/green_piece.toml")


def test_big_scan_runs_in_bands_equal_to_one_piece(green, monkeypatch):
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 256, "camera.height": 240})
    whole = rs.scan(green, sensor, seed=5)
    assert "bands" not in whole.meta
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", str(_limit_for(sensor, 40)))
    banded = rs.scan(green, sensor, seed=5)
    assert banded.meta["bands"] == 6  # ceil(240 / 40)
    assert banded.valid.sum() > 10_000
    _assert_same(whole, banded)
    assert banded.meta["K"] == whole.meta["K"]


def test_bands_keep_correlated_noise_and_speckle_dropouts(green):
    # cyberware_3030: correlated noise field, partial stripes; with a speckle dropout probability
    sensor = rs.load_sensor("cyberware_3030").with_params(
        {"camera.width": 200, "camera.height": 180, "noise.signal_contrast": 1.0, "noise.min_signal": 0.05})
    pose = look_at((0.0, -250.0, 650.0), (0.0, 0.0, 0.0))
    whole = rs.scan(green, sensor, pose=pose, seed=2)
    assert whole.valid.sum() > 2_000 and (whole.status == rs.Status.DROPOUT).sum() > 0
    _assert_same(whole, bands.scan_in_bands(green, sensor, pose, 2, 30))


def test_band_count_is_not_written_to_scan_files(green, monkeypatch, tmp_path):
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 400, "camera.height": 300})
    rs.scan(green, sensor, seed=1).save(tmp_path / "whole.exr")
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", str(_limit_for(sensor, 50)))
    banded = rs.scan(green, sensor, seed=1)
    assert banded.meta["bands"] == 6
    banded.save(tmp_path / "banded.exr")
    assert (tmp_path / "whole.exr").read_bytes() == (tmp_path / "banded.exr").read_bytes()


def test_too_big_even_in_bands_is_refused_with_the_estimate(green, monkeypatch):
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 4000, "camera.height": 4000})
    monkeypatch.setenv("RANGESIM_MEMORY_LIMIT", "1G")  # the result alone needs 1 GB
    with pytest.raises(RangesimError, match=r"4,000 x 4,000 px \(even in bands of rows\) needs about"):
        rs.scan(green, sensor, seed=0)


def test_band_rows_planning():
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 1000, "camera.height": 1000})
    per_row = 1000 * 500
    base = 300e6 + 1000 * 1000 * bands.RESULT_BYTES_PER_PIXEL
    assert bands.band_rows(sensor, base + (300 + 2 * bands.MARGIN_ROWS) * per_row, 300e6, 500) == 300
    assert bands.band_rows(sensor, base + (bands.MIN_BAND_ROWS - 1 + 2 * bands.MARGIN_ROWS) * per_row, 300e6, 500) is None
