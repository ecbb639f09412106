"""The Green Piece: a closed, valid, labelled mesh with an exact part tree and features."""
from __future__ import annotations

import math
from pathlib import Path

import manifold3d
import numpy as np
import pytest

import rangesim as rs
from rangesim.cad import green_piece
from rangesim.cad._green_piece import DEFAULTS, THREAD_DEPTH_PER_PITCH
from rangesim.core.constants import Status
from tests.conftest import make_sensor, top_down_pose

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def part():
    return green_piece()


def polygon_area(radius, n):
    return 0.5 * n * radius**2 * math.sin(2 * math.pi / n)


def test_closed_valid_mesh_with_one_tunnel_per_through_hole(part):
    mesh = part.mesh
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    solid = manifold3d.Manifold(manifold3d.Mesh(mesh.vertices.astype(np.float32), mesh.faces.astype(np.uint32)))
    assert solid.status() == manifold3d.Error.NoError
    # 4 plain holes + 7 threads go through the plate: genus 11
    assert solid.genus() == len(DEFAULTS["holes"]) + len(DEFAULTS["threads"])


def test_volume_matches_the_design(part):
    p = DEFAULTS
    L, W, T, n = p["length"], p["width"], p["thickness"], p["segments"]
    volume = L * W * T
    volume -= sum(polygon_area(r, n) * T for _, _, r in p["holes"])
    _, _, R, d = p["dent"]
    volume -= math.pi * d**2 * (3 * R - d) / 3
    volume -= sum(length * width * depth for *_, length, width, depth in p["scratches"])
    # a twisted extrusion keeps its section's area: threads remove (section area) x T
    volume -= sum(polygon_area(r - THREAD_DEPTH_PER_PITCH * pitch / 2, n) * T for *_, r, pitch in p["threads"])
    assert part.mesh.volume == pytest.approx(volume, rel=2e-3)  # the dent is a faceted sphere


def test_part_tree_steps_and_volume_properties(part):
    tree = part.tree
    assert tree.operation == "difference" and tree.name == "green_piece"
    assert [n.name for n in tree.walk() if n.operation != "solid"] == [
        "green_piece", "with_scratches", "with_dent", "plate_and_holes"]
    functions = {leaf.function for leaf in tree.leaves()}
    assert functions == {"plate", "hole", "dent", "scratch", "thread"}
    plate = tree.find("plate").properties
    L, W, T = DEFAULTS["length"], DEFAULTS["width"], DEFAULTS["thickness"]
    assert plate["volume"] == pytest.approx(L * W * T, rel=1e-9)
    np.testing.assert_allclose(plate["centroid"], [0, 0, T / 2], atol=1e-9)
    m = L * W * T
    np.testing.assert_allclose(np.diag(plate["inertia"]),
                               [m * (W**2 + T**2) / 12, m * (L**2 + T**2) / 12, m * (L**2 + W**2) / 12], rtol=1e-9)
    assert tree.properties["volume"] == pytest.approx(part.mesh.volume, rel=1e-9)
    d = part.to_dict()
    assert d["tree"]["children"][0]["name"] == "with_scratches" and len(d["labels"]) == 16


def test_every_triangle_knows_its_sub_part(part):
    mesh = part.mesh
    labels = np.array(part.labels)[part.face_labels]
    assert set(labels) == set(part.labels)
    for k, (x, y, r) in enumerate(DEFAULTS["holes"], start=1):
        corners = mesh.triangles[labels == f"hole_{k}"].reshape(-1, 3)
        np.testing.assert_allclose(np.hypot(corners[:, 0] - x, corners[:, 1] - y), r, rtol=1e-9)
    for k, (x, y, r, pitch) in enumerate(DEFAULTS["threads"], start=1):
        corners = mesh.triangles[labels == f"thread_{k}"].reshape(-1, 3)
        radial = np.hypot(corners[:, 0] - x, corners[:, 1] - y)
        depth = THREAD_DEPTH_PER_PITCH * pitch
        assert radial.min() > r - depth - 1e-6 and radial.max() < r + 1e-6
        assert radial.max() - radial.min() > 0.9 * depth  # the wall really is a helical ridge
    plate = mesh.triangles[labels == "plate"].reshape(-1, 3)
    L, W, T = DEFAULTS["length"], DEFAULTS["width"], DEFAULTS["thickness"]
    on_box = (np.isclose(np.abs(plate[:, 0]), L / 2) | np.isclose(np.abs(plate[:, 1]), W / 2)
              | np.isclose(plate[:, 2], 0) | np.isclose(plate[:, 2], T))
    assert on_box.all()


def test_analytic_features_lie_on_the_mesh(part):
    vertices = part.mesh.vertices
    for circle in part.features.circles:
        # every rim is a polygon of the mesh in the rim's plane: points of the circle are
        # within one facet's length of the vertices there
        ring = circle.points(16)
        on_plane = np.abs(vertices[:, 2] - circle.center[2]) < 1e-6
        near = np.linalg.norm(vertices[on_plane, None, :2] - ring[None, :, :2], axis=2).min(axis=0)
        facet = 2 * math.pi * circle.radius / (48 if circle.name != "dent_rim" else 40)
        assert near.max() < facet, circle.name
    for circle in part.features.circles:
        if circle.name.startswith(("hole", "thread")):  # polygon vertices lie exactly on the circle
            on_plane = np.abs(vertices[:, 2] - circle.center[2]) < 1e-6
            r = np.linalg.norm(vertices[on_plane, :2] - circle.center[:2], axis=1)
            assert np.sum(np.abs(r - circle.radius) < 1e-9) >= 48, circle.name
    kinds = {(s.convex, s.part.split("_")[0]) for s in part.features.segments}
    assert (True, "plate") in kinds and (False, "scratch") in kinds and (True, "scratch") in kinds
    for seg in part.features.segments:
        for end in (seg.start, seg.end):
            assert np.linalg.norm(vertices - end, axis=1).min() < 1e-6, seg.name


def test_parameters_change_the_part_and_bad_ones_are_refused():
    thin = green_piece(thickness=8.0, threads=[(0.0, 0.0, 5.0, 1.5)], holes=[], scratches=[])
    assert thin.mesh.bounds[1, 2] == pytest.approx(8.0)
    assert sum(leaf.function == "thread" for leaf in thin.tree.leaves()) == 1
    with pytest.raises(rs.RangesimError, match="unknown green_piece parameter"):
        green_piece(thikness=3)


@pytest.mark.parametrize(("params", "words"), [
    # the analytic features once listed rims of holes 42 mm off a 1 mm plate
    ({"length": 1.0}, r"holes\[0\] at \(-42, -30\) reaching 3.2 mm does not lie on the 1 x 76.2 mm plate"),
    ({"width": 5.0}, "does not lie on the 101.6 x 5 mm plate"),
    ({"threads": [(48.0, 0.0, 6.0, 1.75)]}, r"threads\[0\] at \(48, 0\)"),
    ({"dent": (-26.0, 16.0, 30.0, 13.0)}, "dent depth 13 mm must be less than"),
    ({"scratches": [(40.0, 0.0, 0.0, 25.0, 0.6, 0.4)]}, r"scratches\[0\] at \(65, 0\)"),
    ({"holes": -1}, r"holes must be a list of \(x, y, radius\), got -1"),
    ({"holes": [1, 2]}, r"holes must be a list of \(x, y, radius\) \(finite numbers\)"),
    ({"dent": True}, r"dent must be \(x, y, sphere radius, depth\)"),
    ({"threads": [(0.0, 0.0, 6.0, 0.0)]}, "pitch must be a number > 0"),
    ({"length": -3.0}, "length must be a number > 0"),
])
def test_features_off_the_plate_and_wrong_types_are_refused(params, words):
    with pytest.raises(rs.RangesimError, match=words):
        green_piece(**params)


def test_scene_file_scans_the_green_piece_cleanly():
    scene = rs.load_scene(REPO / "scenes" / "green_piece.toml")
    piece = scene.objects[0]
    assert piece.features is not None and piece.face_labels is not None and piece.watertight
    sensor = make_sensor(**{"camera.width": 200, "camera.height": 160, "camera.fov_deg": 30})
    scan = rs.scan(scene, sensor, pose=top_down_pose(300.0))
    # the table is under the part: every ray meets a surface, holes included
    assert scan.count(Status.MISS) == 0
    sub = np.array(scene.subpart_names)[scene.subpart_image(scan.part, scan.face)[scan.valid]]
    seen = set(sub)
    assert {"green_piece/plate", "green_piece/dent", "table"} <= seen
    assert any(name.startswith("green_piece/thread_") for name in seen)
    assert any(name.startswith("green_piece/hole_") for name in seen)


def test_model_command_writes_mesh_and_tree(tmp_path):
    import json

    import trimesh

    from rangesim.cli.main import main

    out, tree = tmp_path / "gp.ply", tmp_path / "gp.json"
    assert main(["model", "green_piece", "--out", str(out), "--tree", str(tree), "--param", "thickness=9"]) == 0
    mesh = trimesh.load(out)
    assert mesh.is_watertight and mesh.bounds[1, 2] == pytest.approx(9.0)
    data = json.loads(tree.read_text())
    assert data["tree"]["name"] == "green_piece" and data["features"]["circles"]
    assert main(["model", "no_such_part", "--out", str(tmp_path / "x.stl")]) == 2
    assert main(["model", "green_piece", "--out", str(tmp_path / "x.txt")]) == 2
    assert not (tmp_path / "x.stl").exists() and not (tmp_path / "x.txt").exists()
