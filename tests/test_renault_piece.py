"""The Renault Piece: five sub-parts, B-spline tops, a tangent blend between neck and plate."""
from __future__ import annotations

from pathlib import Path

import manifold3d
import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cad import BSplineSurface, renault_piece
from rangesim.cad._renault_piece import DEFAULTS, _head_surface, _neck_surface
from rangesim.core.constants import Status
from tests.conftest import make_sensor, top_down_pose

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def part():
    return renault_piece()


def test_closed_valid_mesh_with_two_mounting_holes(part):
    mesh = part.mesh
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    solid = manifold3d.Manifold(manifold3d.Mesh(mesh.vertices.astype(np.float32), mesh.faces.astype(np.uint32)))
    assert solid.status() == manifold3d.Error.NoError and solid.genus() == 2


def test_five_sub_parts_in_the_tree_and_on_the_mesh(part):
    names = {"neck", "right_head", "back_bump", "left_head", "base_plate"}
    assert names <= {leaf.name for leaf in part.tree.leaves()}
    assert names <= {part.labels[k] for k in np.unique(part.face_labels)}
    assert part.tree.operation == "union"
    for node in part.tree.walk():
        assert node.properties["volume"] > 0
    # the heads sit at +-head_x: their triangles' centroids are on their own side
    labels = np.array(part.labels)[part.face_labels]
    centres = part.mesh.triangles_center
    assert (centres[labels == "right_head", 0] > 0).all() and (centres[labels == "left_head", 0] < 0).all()


def test_freeform_tops_are_bspline_patches_and_the_neck_blends_tangentially():
    p = DEFAULTS
    neck = _neck_surface(p, p["plate_thickness"])
    assert isinstance(neck, BSplineSurface) and neck.degree_u == neck.degree_v == 3
    (u0, u1), (v0, v1) = neck.domain
    s = np.linspace(u0, u1, 25)
    for u, v in [(s, np.full_like(s, v0)), (s, np.full_like(s, v1)), (np.full_like(s, u0), s), (np.full_like(s, u1), s)]:
        # on its border the neck is at the plate's level and tangent to it: a rounded edge
        np.testing.assert_allclose(neck.evaluate(u, v)[..., 2], p["plate_thickness"], atol=1e-9)
        np.testing.assert_allclose(neck.normal(u, v), np.tile([0, 0, 1.0], (len(s), 1)), atol=1e-9)
    head = _head_surface(p, 1)
    corner = head.evaluate(head.domain[0][0], head.domain[1][0])
    assert corner[2] > p["plate_thickness"] + 10  # the heads end in walls: sharp edges


def test_blend_is_smooth_and_head_rims_are_sharp_on_the_mesh(part):
    mesh = part.mesh
    labels = np.array(part.labels)[part.face_labels]
    pairs = mesh.face_adjacency
    angle = np.degrees(mesh.face_adjacency_angles)
    kinds = {tuple(sorted(pair)) for pair in labels[pairs]}
    neck_plate = np.array([set(labels[pr]) == {"neck", "base_plate"} for pr in pairs])
    head_plate = np.array([set(labels[pr]) == {"right_head", "base_plate"} for pr in pairs])
    assert ("base_plate", "neck") in kinds and neck_plate.any() and head_plate.any()
    assert angle[neck_plate].max() < 20.0  # blended: only the tessellation's facets bend there
    assert np.median(angle[head_plate]) > 80.0  # a wall standing on the plate


def test_features_lie_on_the_surface(part):
    closest = trimesh.proximity.ProximityQuery(part.mesh)
    for curve in part.features.curves:
        _, distance, _ = closest.on_surface(curve.points)
        assert distance.max() < 0.5, curve.name  # within the tessellation's sag
        assert 45 < np.median(curve.dihedral_deg) < 135
    points = np.array([s.start for s in part.features.segments] + [s.end for s in part.features.segments])
    _, distance, _ = closest.on_surface(points)
    assert distance.max() < 0.5
    for circle in part.features.circles:
        _, distance, _ = closest.on_surface(circle.points(24))
        assert distance.max() < 0.05, circle.name


def test_scan_of_the_scene_is_clean():
    scene = rs.load_scene(REPO / "scenes" / "renault_piece.toml")
    sensor = make_sensor(**{"camera.width": 160, "camera.height": 120, "camera.fov_deg": 35})
    scan = rs.scan(scene, sensor, pose=top_down_pose(350.0))
    assert scan.count(Status.MISS) == 0
    seen = set(np.array(scene.subpart_names)[scene.subpart_image(scan.part, scan.face)[scan.valid]])
    assert {f"renault_piece/{n}" for n in ("neck", "right_head", "back_bump", "left_head", "base_plate")} <= seen
    with pytest.raises(rs.RangesimError, match="unknown renault_piece parameter"):
        renault_piece(neck_hieght=3)


@pytest.mark.parametrize(("params", "words"), [
    ({"neck_width": 0}, "neck_width must be a number > 0"),  # was numpy's LinAlgError
    ({"hole_radius": 500}, r"the hole \(hole_x, hole_radius\) at \(66, 0\) reaching 500 mm does not lie on the 150 x 80 mm plate"),
    ({"samples_per_mm": 0}, "samples_per_mm must be a number > 0"),  # was accepted
    ({"corner_radius": 50}, r"corner_radius 50 mm must be less than half the plate \(40 mm\)"),
    ({"head_size": 3}, r"head_size must be \(x, y\)"),
])
def test_bad_sizes_are_refused_with_their_name(params, words):
    with pytest.raises(rs.RangesimError, match=words):
        rs.cad.renault_piece(**params)
