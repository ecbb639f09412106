"""Keys a sensor's mode does not read are named, not silently ignored.

The structured-light mode's noise comes from its IR image and block matcher, so the laser
stripe's peak-error keys (``noise.sigma_px``, ``noise.quantization_px``, ...), its sweep and
stripe width change nothing in its scans: a new-user review swept ``noise.sigma_px`` over
``structured_light_bench`` and got a table and plots of identical scans, without a word.
"""
from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.sensor.config import UNUSED_BY_MODE, UnusedSensorKeyWarning, preset_names
from tests.conftest import BOX_SCENE_TOML


def test_setting_a_key_the_mode_does_not_read_warns_and_changes_nothing():
    small = {"camera.width": 160, "camera.height": 120}
    base = rs.load_sensor("structured_light_bench").with_params(small)
    with pytest.warns(UnusedSensorKeyWarning, match=r"structured_light mode does not use noise\.sigma_px, "
                                                    r"noise\.quantization_px"):
        changed = base.with_params({"noise.sigma_px": 3.0, "noise.quantization_px": 3.0})
    plate = rs.datasets.plate_scene()
    pose = rs.datasets.plate_scan().pose
    a = rs.scan(plate, base, pose=pose, seed=0)
    b = rs.scan(plate, changed, pose=pose, seed=0)
    np.testing.assert_array_equal(a.depth, b.depth)  # what the warning says
    assert {"noise.sigma_px", "laser.stripe_width", "render.spp"} <= set(UNUSED_BY_MODE["structured_light"])


def test_the_geometric_mode_names_the_other_modes_keys():
    """``render.spp`` or ``structured_light.window`` on a laser-stripe preset changed nothing (a
    sweep over ``render.spp`` on white_scanner made a plot of one scan, its F1 moved only by
    the seed) and was not named."""
    small = {"camera.width": 160, "camera.height": 120}
    base = rs.load_sensor("white_scanner").with_params(small)
    with pytest.warns(UnusedSensorKeyWarning, match=r"geometric mode does not use camera\.read_noise_e, "
                                                    r"render\.spp, structured_light\.window"):
        changed = base.with_params({"render.spp": 2, "structured_light.window": 11, "camera.read_noise_e": 30.0})
    plate = rs.datasets.plate_scene()
    pose = rs.datasets.plate_scan().pose
    a = rs.scan(plate, base, pose=pose, seed=0)
    b = rs.scan(plate, changed, pose=pose, seed=0)
    for field in ("depth", "valid", "sigma"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_no_shipped_preset_sets_a_key_its_mode_does_not_read():
    for name in preset_names():
        with warnings.catch_warnings():
            warnings.simplefilter("error", UnusedSensorKeyWarning)
            rs.load_sensor(name)


def test_a_sweep_over_a_key_the_mode_does_not_read_is_refused(tmp_path):
    from rangesim.experiments.sweep_file import load_sweep

    (tmp_path / "scene.toml").write_text(BOX_SCENE_TOML)
    (tmp_path / "sweep.toml").write_text('name = "idle"\nscenes = ["scene.toml"]\nsensors = ["structured_light_bench"]\n'
                                         'views = 1\n\n[detectors.gradient]\n\n[grid]\n"noise.sigma_px" = [0, 0.5]\n')
    with pytest.raises(RangesimError, match=r"varies noise\.sigma_px, which sensor structured_light_bench "
                                            r"\(structured_light mode\) does not use"):
        load_sweep(tmp_path / "sweep.toml")


def test_the_cli_says_so_in_one_line(tmp_path):
    out = subprocess.run([sys.executable, "-m", "rangesim", "scan", "scenes/green_piece.toml", "--sensor", "kinect_v1",
                          "--set", "noise.sigma_px=5", "--set", "camera.width=64", "--set", "camera.height=48",
                          "--out", str(tmp_path / "k.npz")], capture_output=True, text=True)
    lines = [line for line in out.stderr.splitlines() if "does not use" in line]
    assert len(lines) == 1 and "noise.sigma_px" in lines[0], out.stderr



def test_switching_a_presets_mode_is_no_news():
    """The README's rendered-mode workflow (white_scanner with mode = rendered) keeps the
    preset's own stripe-noise keys, which the rendered mode ignores as documented: no warning;
    a key the change itself sets still gets one."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnusedSensorKeyWarning)
        rs.load_sensor("white_scanner").with_params({"mode": "rendered", "camera.width": 96})
    with pytest.warns(UnusedSensorKeyWarning, match=r"rendered mode does not use noise\.sigma_px:"):
        rs.load_sensor("white_scanner").with_params({"mode": "rendered", "noise.sigma_px": 0.3})


def test_a_sweep_key_some_sensors_read_warns_for_the_others(tmp_path):
    """Comparing sensors: noise.sigma_px swept over white_scanner and kinect_v1 matters for the
    first; the plan warns that the Kinect's scans repeat along it instead of refusing the sweep."""
    from rangesim.experiments.sweep_file import load_sweep

    (tmp_path / "scene.toml").write_text(BOX_SCENE_TOML)
    (tmp_path / "sweep.toml").write_text('name = "mixed"\nscenes = ["scene.toml"]\n'
                                         'sensors = ["white_scanner", "kinect_v1"]\nviews = 1\n\n'
                                         '[detectors.gradient]\n\n[grid]\n"noise.sigma_px" = [0, 0.5]\n')
    with pytest.warns(UserWarning, match=r"varies noise\.sigma_px, which kinect_v1 \(structured_light mode\) does not "
                                         r"use: those scans repeat"):
        load_sweep(tmp_path / "sweep.toml")
