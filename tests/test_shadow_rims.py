"""Rims of holes whose inside the laser cannot reach, and shadows that are no edges.

A laser-shadow gap bordered by one surface on both sides is either that surface, shadowed by
a caster between it and the laser, or no part of it (a hole that shadows its own inside).
The edge detectors tell the two apart by looking for the caster in the depth image
(:mod:`rangesim.edges._self_shadow`). Scenes of their own kind, not used to choose the rule:

* the caster test on analytic depth images (a plane, a plane with a wall beside the path);
* a 24 mm thick plate with three through-holes on a table, seen head-on from 300 mm: the
  laser (150 mm to the camera's side) reaches little of the holes' insides, so most of
  each top rim borders shadow; gradient, normal and line_fit must mark the rims, with and
  without the preset noise;
* a post standing on a table: its laser shadow on the table is bordered by the table on
  both sides, and its outline there must stay no edge.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.core.geometry import look_at
from rangesim.edges import RIM, gradient, line_fit, normal
from rangesim.edges._self_shadow import uncast
from tests.conftest import circle_px, holed_plate, pixel_centres, pixels_inside, world_heights

NOISE_OFF = {"noise.sigma_px": 0.0, "noise.speckle_contrast": 0.0, "noise.quantization_px": 0.0}
SENSOR = {"mode": "geometric", "laser": {"baseline": 150.0, "sweep": "rotating"}, "range": {"near": 200, "far": 400}}
F = 400.0
K = np.array([[F, 0, 64.0], [0, F, 48.0], [0, 0, 1]])
#: (x, y, radius) of the thick plate's holes, mm; plate 90 x 50 x 24 mm centred at 0
HOLES = ((-25.0, 0.0, 5.0), (0.0, 0.0, 6.5), (25.0, 0.0, 8.0))
THICK = 24.0


def test_a_plane_point_sees_the_laser_and_a_wall_in_front_blocks_it():
    z = np.full((96, 128), 300.0, np.float32)
    thr = np.full(z.shape, 1.0, np.float32)
    rows, cols, depth = np.array([48]), np.array([40]), np.array([300.0])
    # nothing in front of the path: the point would be lit
    assert uncast(z, thr, K, SENSOR, rows, cols, depth).all()
    # a wall 50 mm nearer, 20 px towards the laser (+x in the image): the path runs behind it
    walled = z.copy()
    walled[:, 60:64] = 250.0
    assert not uncast(walled, thr, K, SENSOR, rows, cols, depth).any()
    # the same wall beside the path (rows above it) does not block it
    beside = z.copy()
    beside[:30, 60:64] = 250.0
    assert uncast(beside, thr, K, SENSOR, rows, cols, depth).all()
    # unmeasured pixels never block; a point behind the plane (in a hole) is blocked by it
    gap = walled.copy()
    gap[:, 60:64] = np.nan
    assert uncast(gap, thr, K, SENSOR, rows, cols, depth).all()
    assert not uncast(z, thr, K, SENSOR, rows, cols, np.array([330.0])).any()


@pytest.fixture(scope="module")
def thick_plate_scene():
    plate = holed_plate(90, 50, THICK, HOLES)
    table = trimesh.creation.box((400, 400, 2)).apply_translation((0, 0, -1))
    return rs.load_scene([plate, table])


def _scan(scene, changes, seed=1):
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 256, "camera.height": 192, **changes})
    return rs.scan(scene, sensor, pose=look_at((0.0, 0.0, 300.0 + THICK), (0.0, 0.0, 0.0), up=(0, 1, 0)), seed=seed)


@pytest.mark.parametrize("noisy", [False, True], ids=["noise-free", "preset-noise"])
@pytest.mark.parametrize("detector", [gradient, normal, line_fit])
def test_rims_over_their_own_shadow_are_found(detector, noisy, thick_plate_scene):
    scan = _scan(thick_plate_scene, {} if noisy else NOISE_OFF)
    em = detector(scan)
    tree = cKDTree(pixel_centres(em.mask))
    for x, y, r in HOLES:
        uv = circle_px(scan, x, y, r, THICK)
        ij = pixels_inside(uv)
        shadowed = scan.status[ij[:, 0], ij[:, 1]] == Status.SHADOW
        assert shadowed.mean() >= 0.5  # the scene is what it claims: most of the rim over shadow
        d, _ = tree.query(uv[shadowed])
        assert np.mean(d <= 1.5) >= 0.9, (detector.__name__, r, np.mean(d <= 1.5))


def test_the_rule_needs_the_scan_to_say_where_the_shadow_is(thick_plate_scene):
    scan = _scan(thick_plate_scene, NOISE_OFF)
    marked = gradient(scan).label_mask(RIM)
    assert marked.sum() > 100
    # a recorded scan says only that a return is missing (its reader marks every gap MISS
    # and sets meta["source"]): no shadow to reason about, the rule is off
    recorded_like = dataclasses.replace(scan, meta=dict(scan.meta, source="recorded"))
    assert gradient(recorded_like).label_mask(RIM).sum() < 0.2 * marked.sum()


@pytest.fixture(scope="module")
def post_scan():
    post = trimesh.creation.box((12, 12, 40)).apply_translation((0, 0, 20))
    table = trimesh.creation.box((300, 300, 2)).apply_translation((0, 0, -1))
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 256, "camera.height": 192, **NOISE_OFF})
    return rs.scan(rs.load_scene([post, table]), sensor, pose=look_at((0.0, 0.0, 330.0), (0.0, 0.0, 0.0), up=(0, 1, 0)),
                   seed=2)


@pytest.mark.parametrize("detector", [gradient, normal, line_fit])
def test_a_shadow_cast_on_the_table_is_no_edge(detector, post_scan):
    scan = post_scan
    shadow = scan.status == Status.SHADOW
    assert shadow.sum() > 300  # the post casts a long shadow on the table
    em = detector(scan)
    # table pixels bordering the shadow, away from the post's own outline
    h, w = scan.shape
    pad = np.pad(shadow, 1)
    beside = np.zeros((h, w), bool)
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        beside |= pad[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
    world_z = world_heights(scan)
    on_table = scan.valid & (np.abs(world_z) < 0.5)
    post = scan.valid & (world_z > 1.0)
    ii, jj = np.nonzero(post)
    far = cKDTree(np.stack([ii, jj], 1)).query(np.stack(np.nonzero(beside & on_table), 1))[0] > 3
    outline = np.zeros((h, w), bool)
    outline[tuple(np.stack(np.nonzero(beside & on_table), 1)[far].T)] = True
    assert outline.sum() > 50
    assert not (em.mask & outline).any(), (em.mask & outline).sum()


@pytest.mark.parametrize("offset", [(-40.0, 0.0), (0.0, 25.0), (35.0, -20.0)])
def test_a_boss_shadow_through_its_unlit_wall_is_no_rim(offset):
    # a short boss on a table: its shadow on the table begins at its unlit wall, which the
    # camera sees but the scanner does not measure, so the march sees no caster; the boss
    # top found across the gap, clearly nearer, is taken for it (CASTER_STEPS)
    boss = trimesh.creation.cylinder(8.0, 6.0).apply_translation((*offset, 3.0))
    table = trimesh.creation.box((300, 300, 2)).apply_translation((0, 0, -1))
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 256, "camera.height": 192, **NOISE_OFF})
    scan = rs.scan(rs.load_scene([boss, table]), sensor, pose=look_at((0.0, 0.0, 330.0), (0.0, 0.0, 0.0), up=(0, 1, 0)),
                   seed=4)
    assert (scan.status == Status.SHADOW).sum() > 30
    world_z = world_heights(scan)
    on_table = scan.valid & (np.abs(world_z) < 0.5)
    for detector in (gradient, normal, line_fit):
        assert not (detector(scan).label_mask(RIM) & on_table).any(), detector.__name__


def test_specks_of_shadow_in_a_face_are_no_rims(thick_plate_scene):
    # single shadowed pixels in the plate's top (as between thread crests): their caster lies
    # within a pixel, below what the depth image resolves; they must mark nothing
    scan = _scan(thick_plate_scene, NOISE_OFF)
    plain = gradient(scan)
    depth, xyz, valid, status = scan.depth.copy(), scan.xyz.copy(), scan.valid.copy(), scan.status.copy()
    rows, cols = np.meshgrid(np.arange(60, 80, 4), np.arange(40, 220, 6), indexing="ij")
    rows, cols = rows.ravel(), cols.ravel()
    keep = valid[rows, cols]
    rows, cols = rows[keep], cols[keep]
    depth[rows, cols], xyz[rows, cols], valid[rows, cols], status[rows, cols] = np.nan, np.nan, False, int(Status.SHADOW)
    specked = gradient(dataclasses.replace(scan, depth=depth, xyz=xyz, valid=valid, status=status))
    near = np.zeros(scan.shape, bool)
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            near[rows + dr, cols + dc] = True
    assert len(rows) > 20
    assert not (specked.label_mask(RIM) & near & ~plain.label_mask(RIM)).any()
