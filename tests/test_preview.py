"""Preview pictures: status colours, depth colour mapping, the PNG and its atomic write."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.image import imread

from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.viz import STATUS_COLORS, depth_limits, depth_rgb, save_preview, status_colors

H, W = 40, 60
SHADOW_ROWS, SHADOW_COLS = slice(5, 15), slice(38, 58)  # a 10 x 20 block
MISS_ROWS, MISS_COLS = slice(28, 40), slice(0, 12)


def make_scan(h: int = H, w: int = W, normals: bool = False) -> RangeScan:
    """The plane z = 350 + 0.68 x (mm; depth 300 mm at the left edge, 420 at the right)
    with a 3 mm pit, a shadow block, a miss block and scattered dropouts."""
    K = np.array([[120.0, 0, w / 2], [0, 120.0, h / 2], [0, 0, 1]])
    ii, jj = np.mgrid[0:h, 0:w]
    # pixel (i, j) sees x = r z with r = (j + 0.5 - cx) / fx; on the plane z = z0 + a r z
    depth = 350.0 / (1.0 - 0.68 * (jj + 0.5 - K[0, 2]) / K[0, 0])
    depth += 3.0 * (np.hypot(ii - 0.6 * h, jj - 0.5 * w) < 0.1 * h)  # a small pit
    status = np.zeros((h, w), np.uint8)
    if (h, w) == (H, W):
        status[SHADOW_ROWS, SHADOW_COLS] = Status.SHADOW
        status[MISS_ROWS, MISS_COLS] = Status.MISS
        status[20:26, 30:50][::2, ::3] = Status.DROPOUT
    valid = status == Status.VALID
    depth[~valid] = np.nan
    rays = np.stack([jj + 0.5, ii + 0.5, np.ones_like(depth)], -1) @ np.linalg.inv(K).T
    xyz = rays * depth[..., None]
    normal = np.full((h, w, 3), np.nan)
    if normals:
        normal[valid] = (0.0, 0.0, -1.0)  # facing the camera
    return RangeScan(
        depth=depth, xyz=xyz, valid=valid, normal=normal,
        intensity=valid.astype(float), part=np.where(valid, 0, -1),
        face=np.where(valid, 0, -1), status=status,
        meta={"K": K.tolist(), "sensor": {"name": "test-sensor"}},
    )


def test_status_colors_are_distinct_and_copied():
    colors = status_colors()
    assert set(colors) == {Status.MISS, Status.SHADOW, Status.DROPOUT, Status.OUT_OF_RANGE}
    rgb = np.array(list(colors.values()))
    assert ((rgb >= 0) & (rgb <= 1)).all()
    d = np.linalg.norm(rgb[:, None] - rgb[None], axis=-1)
    assert d[~np.eye(len(rgb), dtype=bool)].min() > 0.1
    colors[Status.MISS] = (1.0, 0.0, 0.0)
    assert STATUS_COLORS[Status.MISS] != (1.0, 0.0, 0.0)


def test_depth_limits_ignore_phantom_points():
    scan = make_scan()
    clean = depth_limits(scan)
    scan.depth[0, :3] = 5000.0  # three phantom points far behind
    lo, hi = depth_limits(scan)
    assert 299.0 < lo < hi < 425.0
    np.testing.assert_allclose((lo, hi), clean, atol=1.0)


def test_depth_rgb_unshaded_is_colormap_and_status_colours():
    scan = make_scan()
    lo, hi = depth_limits(scan)
    rgb = depth_rgb(scan, shade=False)
    assert rgb.shape == (H, W, 3)
    for code in (Status.SHADOW, Status.MISS, Status.DROPOUT):
        mask = scan.status == code
        assert mask.any()
        assert (rgb[mask] == STATUS_COLORS[code]).all()
    expected = colormaps["turbo"](np.clip((scan.depth[scan.valid] - lo) / (hi - lo), 0, 1))
    np.testing.assert_allclose(rgb[scan.valid], expected[:, :3])


def test_depth_rgb_shading():
    # one normal everywhere, whatever its tilt: no relief, so the colours stay those of
    # the colour bar (shading is relative to the scan's median shade)
    scan = make_scan(normals=True)
    np.testing.assert_allclose(depth_rgb(scan), depth_rgb(scan, shade=False))
    scan.normal[scan.valid] = np.array([0.5, -0.2, -1.0]) / np.linalg.norm([0.5, -0.2, -1.0])
    np.testing.assert_allclose(depth_rgb(scan), depth_rgb(scan, shade=False))
    # normals from the geometry (NaN in scan.normal): the plane keeps its colours, the
    # pit's rim changes shade, status pixels never do, pixels isolated between dropouts
    # (no normal) are filled in
    scan = make_scan()
    shaded, flat = depth_rgb(scan), depth_rgb(scan, shade=False)
    assert np.isfinite(shaded).all() and ((shaded >= 0) & (shaded <= 1)).all()
    changed = ~np.isclose(shaded, flat, atol=1e-6).all(axis=-1)
    assert 0 < changed[scan.valid].sum() < 0.2 * scan.valid.sum()
    assert (shaded[~scan.valid] == flat[~scan.valid]).all()


def _color_mask(img: np.ndarray, rgb, tol: float = 2.5 / 255) -> np.ndarray:
    return (np.abs(img[..., :3] - np.asarray(rgb)) <= tol).all(axis=-1)


def test_save_preview_png(tmp_path: Path):
    scan = make_scan()
    out = save_preview(scan, tmp_path / "sub" / "scan.png")
    assert out == tmp_path / "sub" / "scan.png" and out.is_file()
    assert os.listdir(out.parent) == ["scan.png"]  # no temporary file left behind

    img = imread(out)
    assert img.ndim == 3 and img.shape[2] in (3, 4)
    assert img.shape[1] > img.shape[0]  # a wide scan gives a wide picture

    # the shadow block is drawn with the status colour and square pixels: its bounding
    # box (the legend swatch is far smaller, so it drops out of the half-max cut) has
    # the block's 20:10 proportions
    shadow = _color_mask(img, STATUS_COLORS[Status.SHADOW])
    assert shadow.sum() > 100
    rows = np.flatnonzero(shadow.sum(axis=1) >= shadow.sum(axis=1).max() / 2)
    cols = np.flatnonzero(shadow.sum(axis=0) >= shadow.sum(axis=0).max() / 2)
    ratio = (np.ptp(cols) + 1) / (np.ptp(rows) + 1)
    assert ratio == pytest.approx(20 / 10, rel=0.05)
    assert _color_mask(img, STATUS_COLORS[Status.MISS]).sum() > 100


def test_save_preview_odd_shapes(tmp_path: Path):
    # no invalid pixels (no legend) and a tall, narrow scan
    scan = make_scan(h=90, w=12)
    out = save_preview(scan, tmp_path / "tall.PNG", title="custom", shade=False, dpi=80)
    img = imread(out)
    assert img.shape[0] > img.shape[1] * 0.6


def test_save_preview_rejects_other_extensions(tmp_path: Path):
    with pytest.raises(RangesimError, match=r"\.png"):
        save_preview(make_scan(), tmp_path / "scan.jpg")
    assert os.listdir(tmp_path) == []
