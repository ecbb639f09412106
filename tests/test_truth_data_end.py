"""Occluding contours where the scanner lost the contour pixel itself (a block matcher's window
straddling the step, a dropout at a silhouette): the truth marks them on the data's end beside
them, and the detectors mark a surface that ends in a short unmeasured gap before nothing."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import rangesim as rs
from rangesim.core.constants import EdgeLabel, Status
from rangesim.core.geometry import look_at
from rangesim.edges._discontinuities import EMPTY_GAP_PX, JUMP_THRESHOLD
from rangesim.evaluate import score_edges, visible_truth


@pytest.fixture(scope="module")
def box_on_table():
    """A 300 x 200 x 150 mm box on a 2 m table seen by a 320 x 240 Kinect from 1.4 m: the table's
    far edge stands against empty space, the box against the table."""
    table = trimesh.creation.box(extents=(2000, 2000, 20))
    table.apply_translation((0, 0, -10))
    box = trimesh.creation.box(extents=(300, 200, 150))
    box.apply_translation((0, 0, 75))
    scene = rs.load_scene([table, box])
    sensor = rs.load_sensor("kinect_v1").with_params({"camera.width": 320, "camera.height": 240})
    scan = rs.scan(scene, sensor, pose=look_at((0, -900, 1100), (0, 0, 60), up=(0, 0, 1)), seed=0)
    return scene, scan


def test_lost_contours_move_onto_the_occluders_data_end(box_on_table):
    scene, scan = box_on_table
    full = rs.ground_truth_edges(scan, scene)
    truth = visible_truth(scan, scene)
    measured = scan.valid
    lost = (full == EdgeLabel.JUMP) & ~measured
    # the matcher loses most of the contour pixels themselves: their windows straddle the step
    assert lost.sum() > 0.4 * (full == EdgeLabel.JUMP).sum()
    assert np.all(scan.status[lost] == Status.DROPOUT)
    assert not truth[~measured].any()
    changed = truth != np.where(measured, full, 0)
    moved = changed & (truth == EdgeLabel.JUMP)
    assert np.array_equal(changed, moved) and moved.sum() > 0.5 * lost.sum()
    # each moved pixel is beside a lost contour pixel, on the occluder: its true point within
    # the jump rule (cot 15 degrees pixel footprints) of that pixel's, never on the background
    xyz, fx = scan.xyz_true.astype(np.float64), float(scan.K[0, 0])
    for r, c in zip(*np.nonzero(moved)):
        rr, cc = np.nonzero(lost[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2])
        rr, cc = rr + max(r - 1, 0), cc + max(c - 1, 0)
        gap = np.linalg.norm(xyz[rr, cc] - xyz[r, c], axis=-1)
        assert np.any(gap < JUMP_THRESHOLD * xyz[rr, cc, 2] / fx)
    assert set(np.unique(scan.part[moved])) == {0, 1}  # the table's far edge and the box's outline


def test_a_surface_ending_in_a_short_gap_before_nothing_is_a_rim(box_on_table):
    """The table's far edge: its last measured row, a dropout row, then the camera rays hit
    nothing. The gradient detector marks that last measured row (a rim: it scores as a jump),
    and scored against the truth, the table's edge is found."""
    scene, scan = box_on_table
    truth = visible_truth(scan, scene)
    edges = rs.edges.gradient(scan)
    empty = ~scan.valid & (scan.status == Status.MISS)
    reach = ndimage.binary_dilation(empty, np.ones((3, 3), bool), iterations=EMPTY_GAP_PX + 1)
    assert EMPTY_GAP_PX == 1  # the contour pixel lost, as visible_truth moves it
    table_end = (truth == EdgeLabel.JUMP) & (scan.part == 0) & reach
    assert table_end.sum() > 100
    found = ndimage.distance_transform_edt(~edges.mask)[table_end] <= 2
    assert found.mean() > 0.9
    s = score_edges(edges, scan, truth=truth)
    assert s["per_label"]["jump"]["recall"] > 0.85 and s["per_label"]["jump"]["precision"] > 0.9


def _chamfered_plate():
    """A 100 x 60 x 12 mm plate whose top edges are chamfered 3 mm at 45 degrees (the
    machined parts' chamfer: a frustum on a box, touching)."""
    import manifold3d

    L, W, T, c = 100.0, 60.0, 12.0, 3.0
    low = manifold3d.Manifold.cube((L, W, T - c)).translate((-L / 2, -W / 2, 0))
    cap = manifold3d.Manifold.extrude(manifold3d.CrossSection.square((L, W), True), c, 0, 0.0,
                                      ((L - 2 * c) / L, (W - 2 * c) / W)).translate((0, 0, T - c))
    m = (low + cap).to_mesh()
    return trimesh.Trimesh(m.vert_properties[:, :3], m.tri_verts)


@pytest.mark.parametrize(("elevation", "azimuth"), [(50.0, 35.0), (60.0, 30.0)])
def test_a_silhouette_whose_seen_face_is_nearly_edge_on_is_a_jump(elevation, azimuth):
    """A chamfered plate alone in view: every pixel of it beside one that sees nothing lies on
    its occluding contour, which the truth marks as a jump on that (near) side. Where the seen
    face at the contour is a chamfer nearly edge-on, a small step into it projects mostly along
    the contour's image line; the side was taken from the raw image coordinate, and 28-70 % of
    the outline came out unmarked (or a crease), the jump put on the empty side."""
    import math

    mesh = _chamfered_plate()
    assert mesh.is_watertight
    scene = rs.load_scene([mesh])
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 160, "camera.height": 120})
    e, a = math.radians(elevation), math.radians(azimuth)
    eye = 380.0 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    scan = rs.scan(scene, sensor, pose=look_at(eye, (0, 0, 6), up=(0, 0, 1)), seed=0)
    truth = np.asarray(rs.ground_truth_edges(scan, scene))
    hit = scan.part >= 0
    outline = hit & ndimage.binary_dilation(~hit, structure=ndimage.generate_binary_structure(2, 1))
    outline[[0, -1], :] = outline[:, [0, -1]] = False
    assert outline.sum() > 200
    assert (truth[outline] == EdgeLabel.JUMP).mean() >= 0.98
