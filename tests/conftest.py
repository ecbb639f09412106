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


def holed_plate(length, width, thick, holes):
    """A plate ``length`` x ``width`` x ``thick`` (mm) standing on z = 0, centred on the z axis,
    with vertical through-holes ``holes`` ((x, y, radius), mm)."""
    plate = trimesh.creation.box((length, width, thick))
    for x, y, r in holes:
        plate = plate.difference(trimesh.creation.cylinder(r, 4 * thick).apply_translation((x, y, 0)))
    return plate.apply_translation((0, 0, thick / 2))


def circle_px(scan, cx: float, cy: float, r: float, z: float, n: int = 720) -> np.ndarray:
    """(n, 2) pixel coordinates (u, v; pixel (i, j) centred at (j + .5, i + .5)) of the
    horizontal world circle of centre (cx, cy, z) and radius r (mm), through the scan's
    pose and ``meta["K"]``."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.stack([cx + r * np.cos(t), cy + r * np.sin(t), np.full(n, z), np.ones(n)], 1)
    pc = (np.linalg.inv(scan.pose) @ pts.T).T[:, :3]
    uv = (np.asarray(scan.meta["K"]) @ pc.T).T
    return uv[:, :2] / uv[:, 2:]


def pixels_inside(uv: np.ndarray, px: float = 1.5) -> np.ndarray:
    """(n, 2) (row, col) of the pixels ``px`` pixels inside the closed image curve ``uv``,
    towards its centroid."""
    inward = uv.mean(0) - uv
    inside = uv + px * inward / np.linalg.norm(inward, axis=1, keepdims=True)
    return np.floor(inside[:, ::-1]).astype(int)


def pixel_centres(mask: np.ndarray) -> np.ndarray:
    """(n, 2) (u, v) image coordinates of the centres of the mask's pixels."""
    ii, jj = np.nonzero(mask)
    return np.stack([jj + 0.5, ii + 0.5], 1)


def world_heights(scan) -> np.ndarray:
    """(H, W) world z of each pixel's measured point, mm (0 where none)."""
    h, w = scan.shape
    return (scan.pose[:3, :3] @ np.nan_to_num(scan.xyz).reshape(-1, 3).T).T[:, 2].reshape(h, w) + scan.pose[2, 3]


@pytest.fixture
def data_dir() -> Path:
    """The shared recorded data (RANGESIM_DATA or ../shared/data); skips when absent."""
    root = Path(os.environ.get("RANGESIM_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    if not root.is_dir():
        pytest.skip(f"shared data not found at {root} (set RANGESIM_DATA)")
    return root


def pinhole_scan(depth: np.ndarray, f: float, sigma_mm: float | None = None):
    """A laser-stripe-like RangeScan of a (H, W) ``depth`` image (mm along the optical axis)
    seen by a pinhole of focal length ``f`` px with its principal point at the image centre:
    every pixel valid, its point on the pixel's ray; ``sigma_mm``: the noise model's depth
    std attached as ``scan.sigma`` (as a simulated laser-stripe scan carries it)."""
    from rangesim.core.rangescan import RangeScan

    h, w = depth.shape
    K = np.array([[f, 0.0, w / 2], [0.0, f, h / 2], [0.0, 0.0, 1.0]])
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rays = np.stack([(jj - w / 2) / f, (ii - h / 2) / f, np.ones_like(jj)], axis=-1)
    xyz = (rays * depth[..., None]).astype(np.float32)
    shape = depth.shape
    return RangeScan(
        depth=xyz[..., 2], xyz=xyz, valid=np.ones(shape, bool),
        normal=np.full(shape + (3,), np.nan, np.float32), intensity=np.ones(shape, np.float32),
        part=np.zeros(shape, np.int32), face=np.zeros(shape, np.int32),
        status=np.zeros(shape, np.uint8), meta={"K": K.tolist()},
        sigma=None if sigma_mm is None else np.full(shape, sigma_mm, np.float32),
    )


def grid_recording(h: int = 120, w: int = 140, dx: float = 0.5, dy: float = 0.7, x0: float = -35.0,
                   y0: float = -42.0):
    """A 'recorded' orthographic grid in the scanner's frame (no ground truth): every cell
    valid near z = 0 (3 mm bumps on every 7th diagonal), columns ``dx`` and rows ``dy`` mm
    apart from (``x0``, ``y0``)."""
    from rangesim.core.rangescan import RangeScan

    i, j = np.indices((h, w))
    xyz = np.stack([x0 + dx * j, y0 + dy * i, np.where((i + j) % 7 == 0, 3.0, 0.0)], axis=-1).astype(np.float32)
    n = np.full((h, w, 3), np.nan, np.float32)
    return RangeScan(depth=xyz[..., 2], xyz=xyz, valid=np.ones((h, w), bool), normal=n,
                     intensity=np.zeros((h, w)), part=np.zeros((h, w)), face=np.zeros((h, w)),
                     status=np.zeros((h, w)), meta={"frame": "scanner"})
