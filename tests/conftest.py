"""Shared builders for small, fast test scenes and sensors."""
from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.geometry import look_at

#: a noise-free reference sensor: every effect off unless a test turns it on
QUIET_SENSOR = {
    "name": "test_sensor",
    "camera": {"width": 160, "height": 120, "fov_deg": 40.0, "aperture_mm": 6.0},
    "laser": {"baseline": 150.0, "sweep": "rotating", "stripe_width": 0.0, "wavelength_nm": 670.0},
    "range": {"near": 100.0, "far": 1000.0},
    "noise": {"sigma_px": 0.0, "quantization_px": 0.0, "min_signal": 0.0, "speckle_contrast": 0.0},
}


#: a scene file: a 120 x 90 x 50 mm box on a large ground plane (mm)
BOX_SCENE_TOML = """\
units = "mm"

[[object]]
name = "box"
primitive = "box"
size = [120, 90, 50]
translate = [0, 0, 25]
albedo = 0.6

[[object]]
name = "ground"
primitive = "plane"
size = [1200, 1200]
albedo = 0.3
"""


def make_sensor(**changes):
    """The quiet sensor with dotted-key changes, e.g. make_sensor(**{"noise.sigma_px": 0.3})."""
    return rs.load_sensor(copy.deepcopy(QUIET_SENSOR)).with_params(changes)


def plane(size=2000.0, z=0.0):
    """An open square sheet at height z facing +z (world), mm."""
    mesh = trimesh.Trimesh(
        np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float) * [size / 2, size / 2, 1],
        np.array([[0, 1, 2], [0, 2, 3]]),
        process=False,
    )
    mesh.apply_translation([0, 0, z])
    return mesh


def box(lo, hi):
    """A closed axis-aligned box between corners lo and hi (world, mm)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mesh = trimesh.creation.box(extents=hi - lo)
    mesh.apply_translation((lo + hi) / 2)
    return mesh


def top_down_pose(height):
    """Camera at (0, 0, height) looking straight down; camera x = world x, y = -world y."""
    return look_at((0, 0, height), (0, 0, 0), up=(0, 1, 0))


@pytest.fixture
def data_dir() -> Path:
    """The shared recorded data (RANGESIM_DATA or ../shared/data); skips when absent."""
    root = Path(os.environ.get("RANGESIM_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    if not root.is_dir():
        pytest.skip(f"shared data not found at {root} (set RANGESIM_DATA)")
    return root
