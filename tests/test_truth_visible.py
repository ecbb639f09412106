"""Edge truth a benchmark can use (issue 14, item 1): occluding contours as 1-px lines on the
occluding side, steep faces not filled, and one call that scores against what the scan saw.

The scene (an L-block and a wedge on a plate, white_scanner from the front right) was not
used to write the contour rule; its right flank faces the camera at about 80 degrees.
"""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import look_at
from rangesim.evaluate import data_boundary, score_edges, visible_truth


def _prism(profile, length, offset):
    """A closed prism: an x-z profile extruded along y, moved by offset (mm)."""
    n = len(profile)
    faces = np.array([[0, k, k + 1] for k in range(1, n - 1)])
    mesh = trimesh.creation.extrude_triangulation(np.asarray(profile, float), faces, length)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    mesh.apply_translation(offset)
    return mesh


@pytest.fixture(scope="module")
def lblock():
    block = _prism([[0, 0], [60, 0], [60, 15], [25, 15], [25, 40], [0, 40]], 40.0, [-30, 20, 0])
    wedge = _prism([[0, 0], [30, 0], [0, 20]], 30.0, [40, 15, 0])
    plate = trimesh.creation.box((200, 150, 5))
    plate.apply_translation((0, 0, -2.5))
    scene = rs.load_scene([block, wedge, plate])
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 256, "camera.height": 192})
    scan = rs.scan(scene, sensor, pose=look_at((120, -250, 300), (0, 0, 10)), seed=0)
    return scene, scan


def _incidence_deg(scan):
    rays = scan.xyz_true / np.linalg.norm(scan.xyz_true, axis=-1, keepdims=True)
    n = scan.normal.astype(np.float64)
    return np.degrees(np.arccos(np.clip(np.abs(np.sum(rays * n, axis=-1)), 0, 1)))


def test_jumps_are_thin_lines_beside_real_depth_breaks(lblock):
    scene, scan = lblock
    truth = rs.ground_truth_edges(scan, scene)
    jump = truth == EdgeLabel.JUMP
    assert jump.sum() > 200
    # 1 px wide: no 2 x 2 block of jump pixels (a corner may make one)
    blocks = jump[:-1, :-1] & jump[1:, :-1] & jump[:-1, 1:] & jump[1:, 1:]
    assert blocks.sum() <= 4
    # every jump pixel is on the occluding side of a depth break: some 8-neighbour sees
    # nothing, or sees a point at least 3 pixel footprints (z / f) farther along the ray
    z = np.where(scan.part >= 0, scan.xyz_true[..., 2], 1e9)
    zp = np.pad(z, 1, constant_values=-1e9)  # the image border is no break
    h, w = z.shape
    farther = np.zeros((h, w), bool)
    fp = z / scan.K[0, 0]
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            farther |= zp[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] - z > 3 * fp
    assert np.all(farther[jump])
    assert np.all(scan.part[jump] >= 0)


def test_steep_faces_are_not_filled(lblock):
    scene, scan = lblock
    incidence = _incidence_deg(scan)
    steep = (scan.part >= 0) & (incidence > 75)
    # pixels of steep faces off their outline (1 px inside)
    inner = ndimage.binary_erosion(steep)
    assert inner.sum() > 100  # the L-block's flank is there and seen
    new = rs.ground_truth_edges(scan, scene)
    old = rs.ground_truth_edges(scan, scene, jump_rule="pairs")
    assert (old[inner] == EdgeLabel.JUMP).mean() > 0.5  # the former rule filled it
    assert not (new[inner] == EdgeLabel.JUMP).any()


def test_visible_truth_and_one_call_scores(lblock):
    scene, scan = lblock
    truth = visible_truth(scan, scene)
    assert not truth[~scan.valid].any()
    assert (truth == EdgeLabel.JUMP).any() and (truth == EdgeLabel.CONVEX).any() and (truth == EdgeLabel.CONCAVE).any()
    full = rs.ground_truth_edges(scan, scene)
    # the full truth on measured pixels, but for contours whose own pixel was not measured,
    # marked on a measured neighbour (tests/test_truth_data_end.py)
    changed = truth != np.where(scan.valid, full, 0)
    lost = ndimage.binary_dilation((full == EdgeLabel.JUMP) & ~scan.valid, np.ones((3, 3), bool))
    assert np.all(truth[changed] == EdgeLabel.JUMP) and np.all(lost[changed])
    assert changed.sum() < 0.2 * (truth == EdgeLabel.JUMP).sum()
    # the truth scores itself perfectly, per type too
    s = score_edges(rs.edges.EdgeMap(mask=truth != 0, labels=truth, strength=np.zeros(truth.shape), method="truth"), scan, scene)
    assert s["f1"] == 1.0 and all(v["f1"] == 1.0 for v in s["per_label"].values())
    # a prediction along the borders of laser shadows (no geometric edge) is left out, not
    # counted wrong; without that, it costs precision
    shadow_border = data_boundary(scan.valid) & (ndimage.distance_transform_edt(truth == 0) > 3)
    assert shadow_border.sum() > 20
    pred = (truth != 0) | shadow_border
    kept = score_edges(pred, scan, truth=truth)
    assert kept["precision"] == 1.0 and kept["n_ignored"] == shadow_border.sum()
    strict = score_edges(pred, scan, truth=truth, ignore_data_boundary=False)
    assert strict["precision"] < 1.0


def test_data_boundary_and_bad_input():
    valid = np.ones((5, 6), bool)
    valid[2, 3] = False
    b = data_boundary(valid)
    assert b.sum() == 8 and not b[2, 3]
    assert not data_boundary(np.ones((4, 4), bool)).any()  # the image border is no boundary
    with pytest.raises(RangesimError, match="needs the scene"):
        score_edges(np.zeros((4, 4), bool), type("S", (), {"valid": valid})())
    with pytest.raises(RangesimError, match="jump_rule"):
        rs.ground_truth_edges(rs.datasets.plate_scan(), rs.datasets.plate_scene(), jump_rule="nope")
