"""Volumes and sweeps: the CSG-like model of a part tree and generalized cylinders."""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli import volume_commands
from rangesim.core.errors import RangesimError
from rangesim.volumes import decompose, generalized_cylinders, sections_intersect
from rangesim.volumes.csg import boolean_expression, volumetric_model
from rangesim.volumes.shapes import bent_tube, deformed_ellipsoid, swept_tube


def _check_sections(gc):
    assert len(gc.sections) >= 3
    for a in range(len(gc.sections)):
        for b in range(a + 1, len(gc.sections)):
            assert not sections_intersect(gc.sections[a], gc.sections[b]), (a, b)


def test_deformed_ellipsoid_axis_within_2_percent():
    mesh, centre_line = deformed_ellipsoid()
    gcs = generalized_cylinders(mesh, resolution=4.0)
    assert len(gcs) == 1
    gc = gcs[0]
    curve = centre_line(np.linspace(-60, 60, 20001))
    dist = np.linalg.norm(gc.axis[:, None] - curve[None], axis=2).min(axis=1)
    assert dist.max() < 0.02 * 120.0
    _check_sections(gc)
    sweep = gc.sweep
    assert np.all(sweep["area"] > 0) and np.all(np.diff(sweep["s"]) > 0)


def test_bent_tube_axis_and_sections():
    mesh, centre, radius = bent_tube(radius=8.0, bend_radius=60.0, angle_deg=100.0)
    gc = generalized_cylinders(mesh, resolution=5.0)[0]
    rel = gc.axis - centre
    dist = np.hypot(np.hypot(rel[:, 0], rel[:, 1]) - radius, rel[:, 2])
    assert dist.max() < 0.02 * radius * np.radians(100.0)
    _check_sections(gc)
    # interior sections are circles of the tube's radius
    r = np.array([s.radii for s in gc.sections[1:-1]])
    assert np.allclose(r, 8.0, rtol=0.03)


def _against_centre_line(gc, centre_line, radius, t_range, n_around):
    """Per section: angle (deg) between its normal and the true tangent at the nearest centre
    line point, its area over the true n-gon's, and its centroid's distance to the line (mm)."""
    t = np.linspace(*t_range, 200001)
    p = centre_line(t)
    tangent = np.gradient(p, t, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    out = []
    for s in gc.sections:
        k = int(np.argmin(np.linalg.norm(p - s.centroid, axis=1)))
        r = radius(t[k]) if callable(radius) else radius
        ngon = 0.5 * n_around * r ** 2 * np.sin(2 * np.pi / n_around)
        out.append((np.degrees(np.arccos(min(1.0, abs(s.normal @ tangent[k])))), s.area / ngon,
                    np.linalg.norm(p[k] - s.centroid)))
    return np.array(out)


def test_bent_tube_end_sections_perpendicular_at_their_centroids():
    # issue 14 item 7: the first cuts near the extremes are 45 deg off a quarter arc's ends,
    # and step 5 must turn them (and the split's cuts beside them) perpendicular too
    mesh, _, bend = bent_tube(radius=9.0, bend_radius=80.0, angle_deg=90.0)
    gc = generalized_cylinders(mesh, resolution=5.0)[0]
    m = _against_centre_line(gc, lambda t: np.column_stack([bend * np.cos(t), bend * np.sin(t), 0 * t]), 9.0,
                             (0.0, np.pi / 2), 32)
    assert m[:, 0].max() < 2.0  # deg, ends included
    assert np.abs(m[:, 1] - 1).max() < 0.01
    assert m[:, 2].max() < 0.1  # mm
    _check_sections(gc)


def test_tapered_helix_end_sections_perpendicular():
    # a shape of another kind (space curve, tapered), not used for tuning
    def helix(t):
        return np.column_stack([40 * np.cos(t), 40 * np.sin(t), 15 * t])

    def taper(t):
        return 8.0 - 1.5 * t

    mesh = swept_tube(helix, taper, (0.0, 2.0), n_around=64, n_along=120)
    gc = generalized_cylinders(mesh, resolution=5.0)[0]
    m = _against_centre_line(gc, helix, taper, (0.0, 2.0), 64)
    assert m[:, 0].max() < 2.0
    assert np.abs(m[:, 1] - 1).max() < 0.01
    assert m[:, 2].max() < 0.1
    assert np.ptp(gc.sweep["area"]) > 0.5 * gc.sweep["area"].max()  # the taper is seen
    _check_sections(gc)


def test_cylinder():
    cyl = trimesh.creation.cylinder(radius=10.0, height=80.0, sections=48)
    gc = generalized_cylinders(cyl, resolution=10.0)[0]
    assert np.abs(gc.axis[:, :2]).max() < 0.02 * 80
    assert np.ptp(gc.axis[:, 2]) > 0.8 * 80
    _check_sections(gc)
    d = gc.to_dict()
    json.dumps(d)
    assert len(d["axis"]) == len(d["sections"])


def test_recursion_levels_and_resolution():
    mesh, _ = deformed_ellipsoid(subdivisions=3)
    n = [len(generalized_cylinders(mesh, 1.0, max_recursions=r)[0].sections) for r in (1, 3, 5)]
    assert n == [3, 9, 33]
    coarse = generalized_cylinders(mesh, 200.0)[0]
    assert len(coarse.sections) == 2


def test_renault_decomposition_and_junctions():
    part = rs.cad.renault_piece()
    labels = decompose(part.mesh)
    # the crease regions separate the heads from the plate: each head's faces mostly in one region
    for name in ("right_head", "left_head"):
        k = part.labels.index(name)
        regions = labels[part.face_labels == k]
        plate = labels[part.face_labels == part.labels.index("base_plate")]
        main_region = np.bincount(regions).argmax()
        assert np.mean(regions == main_region) > 0.8
        assert np.mean(plate == main_region) < 0.1
    gcs = generalized_cylinders(part.mesh, 10.0, parts=part)
    names = [g.name for g in gcs]
    assert {"neck", "right_head", "left_head", "back_bump", "base_plate"} == set(names)
    for g in gcs:
        assert len(g.axis) >= 2
    neck = gcs[names.index("neck")]
    assert {j.b if j.a == "neck" else j.a for j in neck.junctions} >= {"base_plate"}
    json.dumps([g.to_dict(with_points=False) for g in gcs])


def test_volumetric_model_and_cli(tmp_path):
    part = rs.cad.green_piece()
    expr = boolean_expression(part.tree)
    assert expr.startswith("green_piece = ((((plate - hole_1")
    model = volumetric_model(part.tree)
    assert model["children"][1]["role"] == "removes material"
    assert model["properties"]["area"] > 0 and len(model["properties"]["principal_axes"]) == 3
    out, pic = tmp_path / "tree.json", tmp_path / "tree.png"
    parser = argparse.ArgumentParser()
    volume_commands.register(parser.add_subparsers())
    args = parser.parse_args(["volumes", "renault_piece", "--out", str(out), "--picture", str(pic)])
    assert args.func(args) == 0
    data = json.loads(out.read_text())
    assert data["expression"].startswith("renault_piece = (neck + right_head")
    assert pic.stat().st_size > 1000
    bad = parser.parse_args(["volumes", "renault_piece", "--out", str(tmp_path / "x.txt")])
    with pytest.raises(RangesimError):
        bad.func(bad)


def test_part_tree_picture_colours_cutters_by_role():
    """Blue is material and red the cutters, as the picture's legend says: a step or a slot
    (functions other than hole, thread, dent, scratch) was drawn blue though a difference
    takes it away."""
    from rangesim.viz.volumes import cutter_ids

    tree = rs.cad.machined_part(6).tree  # a step, a slot, through holes, cylinders on the plate
    cut = cutter_ids(tree)
    by_name = {n.name: id(n) in cut for n in tree.walk()}
    assert by_name["step"] and by_name["slot"] and by_name["through_hole_1"]
    assert not by_name["machined_part"] and not by_name["body"] and not by_name["plate"]
    assert not by_name["cylinder_1"] and not by_name["lying_cylinder_1"]
