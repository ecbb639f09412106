"""Part builders whose listed features the mesh did not have, or that failed deep inside on odd
parameters (a probe of rangesim.cad): each is now refused with a one-line message naming the
parameter (and, for overlapping features, both features), and what is built lists only
features that lie on its mesh."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cad import _layout
from rangesim.cad.bspline import MAX_TESSELLATION_VERTICES
from rangesim.cad.machined import _check_design, feature_type, machined_design, machined_part
from rangesim.core.errors import RangesimError

N = 64  # facets of a circle


def assert_features_on_mesh(part, segments=N, circle_tol=None):
    """Every listed rim and crease lies on the mesh's surface (a few points of each)."""
    query = trimesh.proximity.ProximityQuery(part.mesh)
    top = part.params.get("thickness", 0.0)
    for c in part.features.circles:
        points = c.points(24)
        if feature_type(c.name) == "lying_cylinder_end":
            points = points[points[:, 2] > top + 1e-6]  # the arc above the plate
        _, distance, _ = query.on_surface(points)
        # the mesh's circles are inscribed n-gons
        tol = c.radius * (1 - math.cos(math.pi / segments)) + 1e-3 if circle_tol is None else circle_tol
        assert distance.max() <= tol, (c.name, distance.max())
    for s in part.features.segments:
        _, distance, _ = query.on_surface(s.start + np.linspace(0, 1, 7)[:, None] * (s.end - s.start))
        assert distance.max() <= 1e-3, (s.name, distance.max())


def refused(builder, words, *args, **kwargs):
    with pytest.raises(RangesimError) as info:
        builder(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message, message
    return message


# -- 1: the plate's outline ----------------------------------------------------------------------
@pytest.mark.parametrize(("kw", "words"), [
    # a 100 mm chamfer was clamped in the mesh (top at z = 10.2) but not in the features (z = -89.8)
    ({"outline": "chamfer", "outline_size": 100, "step": None}, ["outline_size 100 mm", "too large for a chamfer"]),
    ({"outline": "fillet", "outline_size": 1e6}, ["outline_size 1e+06 mm", "too large for a fillet", "36.456"]),
    ({"outline": "weird"}, ["outline must be one of", "'weird'"]),
    ({"outline": None}, ["outline must be one of", "None"]),
    ({"outline_size": -2}, ["outline_size", ">= 0", "-2"]),
    ({"outline": "fillet", "outline_size": float("nan")}, ["outline_size", "finite", "nan"]),   # was manifold3d's
    ({"outline": "chamfer", "outline_size": 2.0, "step": (30.0, 5.0)}, ["step", "chamfered plate"]),
    ({"outline": "fillet", "outline_size": 8.0, "step": (6.0, 5.0)}, ["step", "width 6 mm", "fillet's 8 mm"]),
])
def test_outline_sizes_and_kinds_are_checked(kw, words):
    refused(machined_part, ["machined_part:", *words], 0, **kw)


@pytest.mark.parametrize("kw", [
    {"outline": "chamfer", "outline_size": 4.9, "step": None, "holes": [(20.0, 0.0, 3.0, None)]},  # 0.49 T - 0.098
    {"outline": "fillet", "outline_size": 30.0, "holes": [(-10.0, 0.0, 3.0, None)], "lying": []},
    {"outline": "fillet", "outline_size": 8.0, "step": (20.0, 4.0), "holes": [(30.0, 0.0, 3.0, 4.0)]},
])
def test_a_chamfer_or_fillet_within_the_limits_lists_its_edges_on_the_mesh(kw):
    part = machined_part(0, **kw)
    assert part.mesh.is_watertight
    assert_features_on_mesh(part)


# -- 2: features that overlap, or stand where the top is not ---------------------------------------
@pytest.mark.parametrize(("kw", "words"), [
    ({"holes": [(0.0, 0.0, 5.0, None), (0.0, 0.0, 2.0, None)]}, ["hole 1 and hole 2 overlap"]),
    ({"holes": [(0.0, 0.0, 3.0, None), (6.2, 0.0, 3.0, None)]}, ["hole 1 and hole 2 lie 0.2 mm apart", "0.5 mm"]),
    ({"holes": [(40.0, 0.0, 3.0, None)], "step": (30.0, 5.0)}, ["hole 1 at (40, 0)", "runs into the step",
                                                                  "x = 30.9 mm"]),
    ({"bosses": [(40.0, 0.0, 3.0, 4.0)], "step": (30.0, 5.0)}, ["boss 1 at (40, 0)", "runs into the step"]),
    ({"slot": (0.0, 0.0, 10.0, 5.0, 3.0, "x"), "holes": [(0.0, 0.0, 2.0, None)]}, ["slot and hole 1 overlap"]),
    ({"holes": [(0.0, 0.0, 2.0, None)], "bosses": [(3.0, 0.0, 2.0, 4.0)]}, ["hole 1 and boss 1 overlap"]),
    ({"outline": "chamfer", "outline_size": 3.0, "step": None, "holes": [(58.0, 0.0, 1.0, None)]},
     ["hole 1 at (58, 0)", "plate's flat top", "3 mm chamfer"]),
    ({"outline": "fillet", "outline_size": 20.0, "step": None, "holes": [(58.0, 34.0, 1.0, None)]},
     ["hole 1", "20 mm fillet"]),
    ({"holes": [(0.0, 0.0)]}, ["hole 1 must be (x, y, radius[, depth or None])"]),                             # was an unpacking error
    ({"holes": 5}, ["holes must be a list"]),
    ({"holes": [(0.0, 0.0, 3.0, "deep")]}, ["hole 1 depth 'deep'"]),
    ({"thickness": 0.8, "step": None, "holes": [], "bosses": [(0.0, 0.0, 3.0, 4.0)]}, ["thickness 0.8 mm", "must exceed 1 mm"]),
    ({"lying": [(-20.0, 0.0, 25.0, 30.0, "x")], "step": None, "holes": []}, ["lying cylinder 1", "radius 25 mm"]),
])
def test_overlapping_or_misplaced_overrides_are_refused_naming_them(kw, words):
    refused(machined_part, ["machined_part:", *words], 0, **kw)


def test_features_that_keep_clear_are_built_with_every_rim_on_the_mesh():
    part = machined_part(0, holes=[(-50.0, 0.0, 3.0, None), (-43.0, 0.0, 3.0, 4.0), (22.0, 0.0, 4.0, None)],
                         bosses=[(-20.0, 20.0, 4.0, 5.0)], slot=(0.0, -20.0, 20.0, 6.0, 3.0, "x"), lying=[],
                         step=(30.0, 5.0))                   # the step begins at x = 30.9: the last hole 4.9 mm short
    names = {c.name for c in part.features.circles}
    assert {"through_hole_1_top", "blind_hole_2_floor", "through_hole_3_bottom", "boss_1_foot"} <= names
    assert_features_on_mesh(part)


def test_random_designs_pass_the_override_checks_unchanged():
    """The seeded layouts keep 3 mm between features and from the outline and the step, so the
    checks a user's override gets accept every one of them (the benchmark's parts stay as they are)."""
    for seed in [*range(100), *range(1000, 1100)]:
        d = machined_design(seed)
        _check_design(d, d["length"], d["width"], d["thickness"])
    # an override that leaves the layout as drawn builds the very same part
    d = machined_design(7)
    same, drawn = machined_part(7, holes=d["holes"]), machined_part(7)
    assert np.array_equal(same.mesh.vertices, drawn.mesh.vertices) and np.array_equal(same.mesh.faces, drawn.mesh.faces)
    assert [c.name for c in same.features.circles] == [c.name for c in drawn.features.circles]


@pytest.mark.parametrize(("kw", "words"), [
    ({"holes": [(0.0, 0.0, 20.0)]}, ["holes[0] and threads[0] overlap"]),                # thread_1 swallowed
    ({"holes": [(0.0, 0.0, 3.0), (1.0, 0.0, 3.0)], "threads": []}, ["holes[0] and holes[1] overlap"]),
    ({"dent": (0.0, 0.0, 30.0, 3.0)}, ["threads[0] and dent overlap"]),
    ({"scratches": [(15.0, 14.0, 10.0, 25.0, 0.6, 0.4), (20.0, 10.0, 90.0, 10.0, 0.5, 0.3)]},
     ["scratches[0] and scratches[1] overlap"]),
    ({"segments": 0}, ["segments must be an integer in [3, 4096], got 0"]),
    ({"segments": -5}, ["segments", "-5"]),
    ({"segments": 2}, ["segments", "got 2"]),
    ({"segments": 2.5}, ["segments", "2.5"]),
    ({"segments": float("nan")}, ["segments", "nan"]),
    ({"divisions_per_turn": 0}, ["divisions_per_turn must be an integer in [1, 1024], got 0"]),
    ({"divisions_per_turn": -1}, ["divisions_per_turn", "-1"]),
    ({"divisions_per_turn": 0.5}, ["divisions_per_turn", "0.5"]),
])
def test_green_piece_overlaps_and_tessellation_counts_are_refused(kw, words):
    refused(rs.cad.green_piece, ["green_piece:", *words], **kw)


def test_green_piece_features_that_keep_clear_are_on_the_mesh():
    part = rs.cad.green_piece(holes=[(-42.0, -30.0, 3.2), (-42.0, 30.0, 3.2), (42.0, 30.0, 3.2), (40.0, -8.0, 4.0)],
                              segments=24, divisions_per_turn=4)
    assert part.params["segments"] == 24 and part.params["divisions_per_turn"] == 4
    assert "hole_4_rim_top" in {c.name for c in part.features.circles}
    assert_features_on_mesh(part, segments=24)


@pytest.mark.parametrize(("kw", "words"), [
    ({"hole_x": 0}, ["hole_1 (hole_x, hole_radius) and hole_2 (hole_x, hole_radius) overlap"]),
    ({"hole_x": 64}, ["hole_1", "left head", "0 mm apart"]),
    ({"neck_length": 130}, ["hole_1 (hole_x, hole_radius) and the neck (neck_length, neck_width) overlap"]),
    ({"neck_length": 1000}, ["the neck (neck_length, neck_width) reaches past the plate (150 x 80 mm"]),
    ({"neck_width": 100}, ["the neck (neck_length, neck_width) reaches past the plate"]),
    ({"neck_width": 50}, ["the neck (neck_length, neck_width) and the back bump (bump_y, bump_size) overlap"]),
    ({"bump_y": 31, "neck_width": 46}, ["the corner edge at (30, -22) of the right head", "the neck"]),
    ({"neck_height": 40}, ["the neck (neck_height 40 mm) rises to 43.6 mm", "right head", "36.4 mm"]),
    ({"head_x": 10}, ["the right head (head_x, head_size) and the left head (head_x, head_size) overlap"]),
    ({"head_x": 60}, ["the heads (head_x, head_size) reach past the plate"]),
    ({"hole_x": float("nan")}, ["hole_x must be a finite number", "nan"]),
    ({"segments": 0}, ["segments must be an integer in [3, 4096], got 0"]),
    ({"segments": 2.5}, ["segments", "2.5"]),
    ({"segments": float("nan")}, ["segments", "nan"]),
])
def test_renault_piece_layouts_whose_features_the_mesh_lacks_are_refused(kw, words):
    refused(rs.cad.renault_piece, ["renault_piece:", *words], **kw)


def test_renault_piece_a_shorter_narrower_neck_is_built_with_its_features_on_the_mesh():
    part = rs.cad.renault_piece(neck_length=60.0, neck_width=30.0, hole_x=-66.0)
    assert_features_on_mesh(part, circle_tol=0.05)


# -- 3: not finite numbers -------------------------------------------------------------------------
@pytest.mark.parametrize(("kw", "words"), [
    ({"length": float("nan")}, ["length must be a finite positive number", "nan"]),     # was LinAlgError
    ({"width": math.inf}, ["width", "inf"]),
    ({"thickness": 1e9}, ["thickness", "100000"]),
    ({"thickness": -1.0}, ["thickness", "positive"]),
    ({"segments": float("nan")}, ["segments must be an integer in [3, 4096], got nan"]),
    ({"segments": 2}, ["segments", "got 2"]),
])
def test_machined_part_sizes_must_be_finite_and_positive(kw, words):
    refused(machined_part, ["machined_part:", *words], 0, **kw)


# -- 5, 6: tessellation, sampling, Coons patches ---------------------------------------------------
def test_a_tessellation_beyond_the_cap_is_refused_before_any_allocation():
    plane = rs.cad.BSplineSurface.plane()
    refused(rs.cad.tessellate_surface, ["100,000 x 100,000", f"{MAX_TESSELLATION_VERTICES:,}"], plane, 100000, 100000)
    refused(rs.cad.tessellate_surface, ["n_u >= 2", "nan"], plane, float("nan"), 3)
    refused(rs.cad.tessellate_surface, ["n_v >= 2", "2.5"], plane, 3, 2.5)
    refused(rs.cad.tessellate_surface, ["n_u >= 2", "got 1"], plane, 1, 3)
    assert len(rs.cad.tessellate_surface(plane, 3.0, 4).vertices) == 12


@pytest.mark.parametrize("mesh", ["x", None, 3])
def test_surface_points_of_something_not_a_mesh_names_its_type(mesh):
    refused(rs.cad.surface_points, ["needs a triangle mesh", type(mesh).__name__], mesh, 1.0)


def test_surface_points_refuses_faces_past_the_vertices():
    mesh = trimesh.Trimesh(np.zeros((3, 3)), [[0, 1, 5]], process=False)
    refused(rs.cad.surface_points, ["faces indexing them", "0..5"], mesh, 1.0)


@pytest.mark.parametrize("tol", [float("nan"), -1, "x"])
def test_coons_tolerance_must_be_a_number_at_least_zero(tol):
    t = np.linspace(0, 1, 11)[:, None]

    def line(a, b):
        return np.asarray(a, float) + t * (np.asarray(b, float) - np.asarray(a, float))

    curves = (line([0, 0, 0], [100, 0, 0]), line([0, 100, 0], [100, 100, 0]),
              line([0, 0, 0], [0, 100, 0]), line([100, 0, 0], [100, 100, 0]))
    message = refused(rs.cad.coons_patch, ["coons_patch: tol must be a finite number >= 0"], *curves, tol=tol)
    assert "corners" not in message
    assert rs.cad.coons_patch(*curves, tol=0).evaluate(0.5, 0.5).tolist() == [50.0, 50.0, 0.0]


def test_footprint_gaps():
    assert _layout.gap(_layout.circle(0, 0, 1), _layout.circle(3, 0, 1)) == 1.0
    assert _layout.gap(_layout.box(0, 0, 1, 1), _layout.circle(3, 0.5, 1)) == 1.0
    assert _layout.gap(_layout.box(0, 0, 1, 1), _layout.circle(0.5, 0.5, 0.1)) < 0     # inside
    assert _layout.gap(_layout.box(0, 0, 1, 1), _layout.box(2, 3, 4, 4)) == pytest.approx(math.hypot(1, 2))
    assert _layout.gap(_layout.box(0, 0, 2, 2), _layout.box(1, 1, 3, 3)) < 0
    diamond = _layout.polygon([(0, -1), (1, 0), (0, 1), (-1, 0)])
    assert _layout.gap(diamond, _layout.box(1, 1, 2, 2)) == pytest.approx(math.sqrt(0.5))
    # inside a 10 x 6 rectangle whose corners are rounded with radius 2
    assert _layout.clearance_in_rounded_rect(_layout.circle(0, 0, 1), 5, 3, 2) == pytest.approx(2.0)
    # a disc on the core's corner (3, 1) has 2 - r to spare
    assert _layout.clearance_in_rounded_rect(_layout.circle(3, 1, 0.5), 5, 3, 2) == pytest.approx(1.5)
    assert _layout.clearance_in_rounded_rect(_layout.box(4, 2, 4.9, 2.9), 5, 3, 2) < 0  # in the rounded-off corner


def test_a_three_value_hole_is_a_through_hole():
    """TOML (the CLI's --param) has no None for a through hole's depth: (x, y, radius) is one."""
    three = rs.cad.machined_part(0, holes=[(-40.0, 0.0, 3.0)])
    four = rs.cad.machined_part(0, holes=[(-40.0, 0.0, 3.0, None)])
    assert {c.name for c in three.features.circles} == {c.name for c in four.features.circles}
    assert {"through_hole_1_top", "through_hole_1_bottom"} <= {c.name for c in three.features.circles}
    np.testing.assert_array_equal(three.mesh.vertices, four.mesh.vertices)
