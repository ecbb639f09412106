"""A face the scanner did not measure: creases at both ends of its gap, not a jump.

Scenes of their own kind, not used to choose the rule (:mod:`rangesim.edges._gap_folds`):

* the test's two criteria on analytic pairs of pixels: the face a gap would be is a jump when
  it is steeper than the jump rule (cot 15 deg footprints of depth per footprint across), and
  no face when a pixel the search crossed is anything but a dropout (shadow, no surface: a
  recording's missing pixels, out of range);
* a block 60 x 40 x 20 mm on a table seen from 45 degrees above its front wall, with the
  wall's pixels dropped out (a block matcher's lost wall): the four crease detectors mark
  the wall's top as a convex crease and its foot as a concave one, as the ground truth does,
  and no jump along it; the same gap called laser shadow (the scan's status) leaves the foot
  unmarked, as does a detector without the rule;
* the same block scanned by structured_light_bench from 65 degrees above its front wall,
  which the block matcher itself loses.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import rangesim as rs
import rangesim.edges._discontinuities as D
from rangesim.core.constants import EdgeLabel, Status
from rangesim.core.geometry import look_at
from rangesim.edges import curvature, gradient, line_fit, normal
from rangesim.edges._gap_folds import gap_fold_test
from tests.conftest import world_heights

F = 500.0
K = np.array([[F, 0, 64.0], [0, F, 48.0], [0, 0, 1]])
COT15 = 1.0 / math.tan(math.radians(15.0))


class _Scan:
    """What the test reads of a scan: its status (every pixel a dropout here)."""

    def __init__(self, shape=(96, 128)):
        self.meta = {"K": K}
        self.status = np.full(shape, Status.DROPOUT, np.uint8)


def _call(test, b, a, zb, za):
    """The test on the pair B (row, col) -> A found along the straight line between them."""
    (bi, bj), (ai, aj) = b, a
    steps = max(abs(ai - bi), abs(aj - bj))
    return test(np.array([bi]), np.array([bj]), np.array([zb]), np.array([ai]), np.array([aj]), np.array([za]),
                np.array([(ai - bi) / steps], np.float32), np.array([(aj - bj) / steps], np.float32),
                np.array([float(steps)])).item()


def test_a_face_steeper_than_the_jump_rule_is_a_jump():
    fp = np.full((96, 128), 400.0 / F)            # footprint at 400 mm, mm
    test = gap_fold_test(_Scan(), fp, COT15)
    lateral = 6 * fp[0, 0]                        # B at (40, 40), A 6 px down its column
    for excess, face in ((0.98, True), (1.02, False)):
        assert _call(test, (40, 40), (46, 40), 400.0, 400.0 - excess * COT15 * lateral) == face, excess
    # diagonally, the lateral extent is the pixels' distance (6 sqrt 2)
    assert _call(test, (40, 40), (46, 46), 400.0, 400.0 - 1.4 * COT15 * lateral)
    # what the threshold adds (quanta, noise) is allowed once over the gap
    test = gap_fold_test(_Scan(), fp, COT15, extra=1.0)
    assert _call(test, (40, 40), (46, 40), 400.0, 400.0 - COT15 * lateral - 0.9)
    assert not _call(test, (40, 40), (46, 40), 400.0, 400.0 - COT15 * lateral - 1.1)


@pytest.mark.parametrize("status", [Status.SHADOW, Status.MISS, Status.OUT_OF_RANGE, Status.VALID])
def test_a_gap_that_is_not_all_dropout_is_no_face(status):
    fp = np.full((96, 128), 400.0 / F)
    scan = _Scan()
    assert _call(gap_fold_test(scan, fp, COT15), (40, 40), (47, 44), 400.0, 396.0)
    # one pixel on the search's path of another kind (a fractional direction: row 40 +
    # rint(7/4 k)); one beside it, off the path, does not count
    scan.status[42, 41] = status
    assert not _call(gap_fold_test(scan, fp, COT15), (40, 40), (47, 44), 400.0, 396.0)
    scan.status[42, 41], scan.status[42, 42] = Status.DROPOUT, status
    assert _call(gap_fold_test(scan, fp, COT15), (40, 40), (47, 44), 400.0, 396.0)


def test_no_status_no_test():
    bare = _Scan((4, 4))
    bare.status = None
    assert gap_fold_test(bare, np.ones((4, 4)), COT15) is None


# -- a block's front wall dropped out ------------------------------------------------------------

BLOCK = (60.0, 40.0, 20.0)


@pytest.fixture(scope="module")
def block_scene():
    block = trimesh.creation.box(BLOCK).apply_translation((0, 0, BLOCK[2] / 2))
    table = trimesh.creation.box((400, 400, 2)).apply_translation((0, 0, -1))
    return rs.load_scene([block, table])


@pytest.fixture(scope="module")
def block_scan(block_scene):
    sensor = rs.load_sensor("white_scanner").with_params(
        {"camera.width": 256, "camera.height": 192, "noise.sigma_px": 0.0, "noise.speckle_contrast": 0.0,
         "noise.quantization_px": 0.0})
    # 45 degrees above the front wall (its normal -y): the wall is seen at 45 degrees slant
    eye = (0.0, -260.0, 270.0)
    return rs.scan(block_scene, sensor, pose=look_at(eye, (0.0, 0.0, 10.0), up=(0, 0, 1)), seed=0)


def _dropped(scan, status):
    """The scan with its block's front-wall pixels unmeasured (``status``)."""
    height = world_heights(scan)
    front = (scan.part == 0) & scan.valid & (height > 0.3) & (height < BLOCK[2] - 0.3)
    assert front.sum() > 300, "the wall should be seen"
    valid = scan.valid & ~front
    st = np.asarray(scan.status).copy()
    st[front] = status
    return dataclasses.replace(scan, valid=valid, depth=np.where(valid, scan.depth, np.nan).astype(scan.depth.dtype),
                               status=st), front


def _near(mask, where, px=1.5):
    """Share of the ``where`` pixels with a ``mask`` pixel within ``px``."""
    d = ndimage.distance_transform_edt(~mask)
    return float((d[where] <= px).mean())


@pytest.mark.parametrize("detector", [gradient, normal, line_fit, curvature])
def test_a_dropped_wall_has_a_convex_top_and_a_concave_foot(detector, block_scan, block_scene, monkeypatch):
    scan, front = _dropped(block_scan, Status.DROPOUT)
    truth = rs.evaluate.visible_truth(scan, block_scene)
    ring = ndimage.binary_dilation(front, np.ones((3, 3), bool)) & ~front
    foot = (truth == EdgeLabel.CONCAVE) & ring
    top = (truth == EdgeLabel.CONVEX) & ring
    assert foot.sum() > 40 and top.sum() > 40, "the truth has both creases beside the gap"
    # and no jump but at the wall's two ends, where the side walls turn away
    assert ((truth == EdgeLabel.JUMP) & ring).sum() <= 4
    em = detector(scan)
    assert _near(em.mask & (em.labels == EdgeLabel.CONCAVE), foot) >= 0.8
    assert _near(em.mask & (em.labels == EdgeLabel.CONVEX), top) >= 0.8
    assert _near(em.mask & (em.labels == EdgeLabel.JUMP), top | foot) <= 0.2
    # without the rule the foot is no edge and the top a jump
    monkeypatch.setattr(D, "GAP_FOLDS", False)
    bare = detector(scan)
    assert _near(bare.mask, foot) <= 0.2
    assert _near(bare.mask & (bare.labels == EdgeLabel.JUMP), top) >= 0.8


def test_the_same_gap_in_laser_shadow_leaves_the_foot_alone(block_scan):
    scan, front = _dropped(block_scan, Status.SHADOW)
    ring = ndimage.binary_dilation(front, np.ones((3, 3), bool)) & ~front
    table_side = ring & (world_heights(scan) < 1.0)
    em = gradient(scan)
    assert _near(em.mask, table_side, 1.0) <= 0.2


def test_a_block_matchers_lost_wall_gets_its_creases(block_scene, monkeypatch):
    """structured_light_bench 450 mm from the block, 65 degrees above its front wall: the
    wall, seen at 65 degrees slant, is a few pixels tall and its disparity changes faster
    than the 9 px window resolves, so the matcher loses it (dropout). Without the rule the
    wall's top is a jump and its foot no edge (crease F1 under 0.1); with it both creases
    are found, the jumps are no worse and the scan's F1 rises (0.60 -> 0.71 when written)."""
    e = np.radians(65.0)
    eye = (0.0, -450.0 * np.cos(e), 10.0 + 450.0 * np.sin(e))
    scan = rs.scan(block_scene, rs.load_sensor("structured_light_bench"),
                   pose=look_at(eye, (0.0, 0.0, 10.0), up=(0, 0, 1)), seed=0)
    truth = rs.evaluate.visible_truth(scan, block_scene)
    with_rule = rs.evaluate.score_edges(gradient(scan), scan, truth=truth)
    monkeypatch.setattr(D, "GAP_FOLDS", False)
    without = rs.evaluate.score_edges(gradient(scan), scan, truth=truth)
    for label in ("convex", "concave"):
        assert without["per_label"][label]["f1"] < 0.1
        assert with_rule["per_label"][label]["f1"] > 0.4
    assert with_rule["f1"] > without["f1"] + 0.05
    assert with_rule["per_label"]["jump"]["f1"] >= without["per_label"]["jump"]["f1"]
