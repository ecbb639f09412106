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
from rangesim.volumes.shapes import bent_tube, deformed_ellipsoid


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
