"""Hough features on the noise-free Green Piece: circles head-on, ellipses on the tilted view,
plate edges as segments; relations, scores and the CLI."""
from __future__ import annotations

import argparse
import csv
import json

import numpy as np
import pytest

import rangesim as rs
import rangesim.edges  # noqa: F401
import rangesim.evaluate  # noqa: F401
import rangesim.features as F
from rangesim.core.geometry import look_at
from rangesim.evaluate._feature_scores import feature_scores

QUIET = {"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": 0}
#: and no stripe width: mixed pixels where the 0.5 mm stripe straddles a rim move its edge
#: pixels by up to ~0.5 px (tilted thread rims 0.98-1.04 px off with it, <= 0.6 px without),
#: a sensor effect, not the finder's error the tilted-view test measures
EXACT = {**QUIET, "laser.stripe_width": 0.0}
HOLES = ("hole_1_rim_top", "hole_2_rim_top", "hole_3_rim_top", "hole_4_rim_top")


@pytest.fixture(scope="module")
def green():
    scene = rs.load_scene("scenes/green_piece.toml")
    out = {}
    for view, pose in (("tilt", None), ("top", look_at((0, 0, 300), (0, 0, 0), up=(0, 1, 0)))):
        sensor = rs.load_sensor("white_scanner").with_params(EXACT if view == "tilt" else QUIET)
        scan = rs.scan(scene, sensor, seed=0, pose=pose)
        out[view] = (scan, rs.edges.gradient(scan, jump_clearance=0), rs.evaluate.ground_truth_features(scan, scene))
    return scene, out


def _nearest(found, center):
    d = [np.hypot(*(np.asarray(f.center) - center)) for f in found]
    return (min(d), found[int(np.argmin(d))]) if d else (np.inf, None)


def test_holes_as_circles_head_on(green):
    _, views = green
    scan, edges, truth = views["top"]
    found = F.circles(edges, radii=(5, 70))
    for g in truth["circles"]:
        if g.name in HOLES:
            d, c = _nearest(found, g.center)
            assert d <= 1.0, (g.name, d)
            assert abs(c.radius - g.axes[0]) <= 1.5 and c.support >= 0.5


def test_rims_as_ellipses_on_tilted_view(green):
    scene, views = green
    scan, edges, truth = views["tilt"]
    found = F.ellipses(edges, scan, scene)
    visible = [g for g in truth["circles"] if g.visible >= 0.5]
    assert len(visible) >= 12
    for g in visible:  # holes, threads and the dent rim
        d, e = _nearest(found, g.center)
        assert d <= 1.0, (g.name, d)
        assert np.all(np.abs(np.asarray(e.axes) - g.axes) <= 1.5), (g.name, e.axes, g.axes)
    scores = feature_scores({"ellipses": found}, truth, scan)
    assert scores["round"]["recall"] == 1.0
    assert scores["round"]["center_error_px"]["max"] <= 1.0


def test_ellipses_without_model_on_a_crop(green):
    _, views = green
    scan, edges, truth = views["tilt"]
    g = next(c for c in truth["circles"] if c.name == "dent_rim")
    x0, y0 = (np.asarray(g.center) - 60).astype(int)
    crop = edges.mask[y0:y0 + 121, x0:x0 + 121]
    found = F.ellipses(crop, remove_explained=False)
    d, _ = _nearest(found, np.asarray(g.center) - (x0, y0))
    assert d <= 1.0


def test_plate_edges_as_segments(green):
    _, views = green
    for view in ("tilt", "top"):
        scan, edges, truth = views[view]
        segs = F.lines(edges, scan)
        long_edges = [t for t in truth["segments"] if t.name.startswith("plate_edge") and t.visible >= 0.9
                      and np.hypot(*(t.xyxy[2:] - t.xyxy[:2])) > 100]
        assert long_edges
        for t in long_edges:
            a, b = t.xyxy[:2], t.xyxy[2:]
            u = (b - a) / np.linalg.norm(b - a)
            n = np.array([-u[1], u[0]])
            best = 0.0
            for s in segs:
                p = np.array([s.start, s.end])
                if np.all(np.abs((p - a) @ n) <= 2.0):
                    best = max(best, abs(np.diff((p - a) @ u)[0]) / np.linalg.norm(b - a))
            assert best >= 0.8, (view, t.name, best)
        assert all(s.length_mm is not None and s.length_mm > 0 for s in segs)


def test_relations_table_and_pairs(green, tmp_path):
    _, views = green
    scan, edges, _ = views["top"]
    segs = F.lines(edges, scan)[:4]
    circ = F.circles(edges, radii=(5, 70))[:3]
    dist, ang = F.segment_pairs(segs)
    assert dist.shape == (4, 4) and np.allclose(dist, dist.T) and np.all(ang <= 90)
    rows = F.relations(segs, circ, [])
    kinds = {r["relation"] for r in rows}
    assert {"circle_segment_distance", "circle_circle_distance", "segment_segment_angle"} <= kinds
    F.relations_to_csv(rows, tmp_path / "r.csv")
    assert len(list(csv.DictReader(open(tmp_path / "r.csv")))) == len(rows)
    assert json.loads(F.relations_to_json(rows)) == rows


def test_cli_writes_outputs(green, tmp_path):
    from rangesim.cli.feature_commands import register

    _, views = green
    views["tilt"][0].save(tmp_path / "s.npz")
    p = argparse.ArgumentParser()
    register(p.add_subparsers())
    args = p.parse_args(["features", str(tmp_path / "s.npz"), "--out", str(tmp_path / "o"),
                         "--scene", "scenes/green_piece.toml"])
    assert args.func(args) == 0
    for name in ("features.json", "relations.csv", "features.png"):
        assert (tmp_path / "o" / name).is_file()
    report = json.loads((tmp_path / "o" / "features.json").read_text())
    assert report["scores"]["round"]["recall"] == 1.0
    # no round feature found: the precision of nothing found was a bare NaN (not JSON)
    small = rs.scan(rs.load_scene("scenes/green_piece.toml"),
                    rs.load_sensor("white_scanner").with_params({"camera.width": 64, "camera.height": 48}))
    small.save(tmp_path / "small.npz")
    args = p.parse_args(["features", str(tmp_path / "small.npz"), "--out", str(tmp_path / "none"),
                         "--scene", "scenes/green_piece.toml", "--rmin", "40", "--rmax", "41"])
    assert args.func(args) == 0
    strict = json.loads((tmp_path / "none" / "features.json").read_text(),
                        parse_constant=lambda c: pytest.fail(f"{c} in features.json"))
    assert strict["scores"]["round"]["precision"] is None


def test_flat_target_labelled_rims(data_dir, monkeypatch):
    """The flat machined target's labelled circles (features YAML, read without PyYAML) as
    ground truth: its visible hole rims are found as ellipses with centre error <= 1 px."""
    from rangesim.core.geometry import object_transform
    from rangesim.recorded.features_yml import read_features_yml

    folder = data_dir / "machined-targets"
    if not (folder / "FlatTargetv3_features.yml").is_file():
        pytest.skip("flat target data not found")
    monkeypatch.setenv("RANGESIM_DATA", str(data_dir))
    scene = rs.load_scene("scenes/flat_target.toml")
    feats = read_features_yml(folder / "FlatTargetv3_features.yml", folder / "FlatTargetv3_trimesh.obj",
                              object_transform((-75, 75, 10), (180, 0, 0)))
    assert len(feats.circles) >= 8 and len(feats.segments) >= 4
    scene.objects[0].features = feats
    scan = rs.scan(scene, rs.load_sensor("white_scanner").with_params(QUIET), seed=0)
    edges = rs.edges.gradient(scan, jump_clearance=0)
    truth = rs.evaluate.ground_truth_features(scan, scene)
    visible = [g for g in truth["circles"] if g.visible >= 0.5]
    assert visible
    found = F.ellipses(edges, scan, scene)
    scores = feature_scores({"ellipses": found}, truth, scan)["round"]
    print("flat target rims:", len(visible), "visible; recall", scores["recall"], "precision",
          scores["precision"], "centre error", scores["center_error_px"])
    assert scores["recall"] == 1.0
    # 0.96 px at most until the imaged stripe's width took the view's foreshortening
    # (eighteenth session): one rim pixel, at (91, 419), is no longer dimmed out, and the
    # rim at (410.5, 83.0) moves 0.08 px to 1.03 px off; the mean stays at 0.57-0.59 px
    assert scores["center_error_px"]["max"] <= 1.1
    assert scores["center_error_px"]["mean"] <= 0.65


@pytest.mark.parametrize("span_deg", [90, 120, 180])
def test_arcs_span_thin_8_connected_arcs(span_deg):
    """A thin arc's pixels lie up to sqrt(2) px apart along it, so one-pixel angular bins left a
    lone empty bin every few pixels and the longest run stopped at 45-60 degrees (a clean 180
    degree arc ran 61 degrees); a lone empty bin no longer breaks the run."""
    y, x = np.mgrid[0:160, 0:160]
    ring = np.abs(np.hypot(x - 80.3, y - 79.6) - 30) < 0.5
    arc = ring & (np.degrees(np.arctan2(y - 79.6, x - 80.3)) % 360 <= span_deg)
    best = rs.features.arcs(arc, radii=(5, 80))[0]
    assert abs(best.radius - 30) < 1.5 and abs(np.degrees(best.span) - span_deg) < 10


def test_arcs_on_a_canny_edge_map():
    """A half disc through skimage's Canny (1 px wide, 8-connected): its 180 degree arc is found."""
    from skimage.feature import canny

    y, x = np.mgrid[0:160, 0:160]
    edges = canny(((np.hypot(x - 80.3, y - 79.6) < 40) & (y < 79.6)).astype(float), sigma=1.5)
    found = rs.features.arcs(edges, radii=(20, 60))
    assert found and abs(found[0].radius - 40) < 1 and np.degrees(found[0].span) > 170


def test_feature_finders_refuse_bad_parameters_in_one_line():
    """ellipses and circle_hypotheses check what circles, arcs and lines check (they raised
    TypeError / ZeroDivisionError from inside NumPy, or took the value silently)."""
    from rangesim.core.errors import RangesimError

    m = np.zeros((60, 60), bool)
    m[20, 10:40] = True
    bad = [
        lambda: F.ellipses(m, min_points="a"),
        lambda: F.ellipses(m, explained=5),
        lambda: F.ellipses(m, free_support=np.nan),
        lambda: F.ellipses(m, min_support=-1),
        lambda: F.ellipses(m, band_px=-1),
        lambda: F.ellipses(m, remove_explained="no"),
        lambda: F.ellipses(m, scene=rs.datasets.plate_scene()),      # a model needs the scan too
        lambda: F.ellipses(m, rs.datasets.plate_scan(width=60, height=60), "scenes/plate.toml"),
        lambda: F.circle_hypotheses(m, angle_tol_deg=-5),
        lambda: F.circle_hypotheses(m, threshold=np.nan),
        lambda: F.circle_hypotheses(m, max_hypotheses=0),
        lambda: F.circle_hypotheses(m, max_hypotheses=2.5),
        lambda: F.circle_hypotheses(m, radius_step=0),
        lambda: F.circle_hypotheses(m, cell_px=-1),
        lambda: F.circle_hypotheses(m, (5, 80), cell_px=1e9),   # asked for terabytes of radius bins
        lambda: F.circle_hypotheses(m, (5, 80), rel_cell=1e9),
        lambda: F.circles(m, split_tangent="no"),
    ]
    for call in bad:
        with pytest.raises(RangesimError) as info:
            call()
        assert "\n" not in str(info.value)


def test_feature_edge_cases_from_a_users_probe():
    # a run of exactly min_length px is kept (its projected extent rounded to 29.999...)
    m = np.zeros((100, 100), bool)
    m[50, 10:41] = True
    assert len(F.lines(m, min_length=30)) == 1
    # radii beyond the image's diagonal are not searched (a 1e6 px range was refused for memory)
    y, x = np.mgrid[0:100, 0:100]
    ring = np.abs(np.hypot(x - 50, y - 50) - 20) < 0.6
    (c,) = F.circles(ring, radii=(5, 1e6))
    assert abs(c.radius - 20) < 0.1
    # relations as strict JSON: a non-finite value is null
    from rangesim.features._circles import Circle
    from rangesim.features._lines import Segment

    text = F.relations_to_json(F.relations([Segment((0, 0), (10, 0), 10, None, 10, 0)], [Circle((np.nan, 1), 3, 1, 1, 0)]))
    assert "NaN" not in text and json.loads(text)[0]["value"] is None


def test_segment_lengths_are_measured_on_the_surface_the_edge_bounds(tmp_path):
    """A 60 mm box edge seen against the table came out 83 mm long: its fitted end point rounded
    onto a table pixel beyond the occluding edge; the run's own end pixels lie on the box."""
    from rangesim.core.geometry import look_at
    from tests.conftest import make_sensor

    (tmp_path / "s.toml").write_text(
        'units = "mm"\n[[object]]\nname = "box"\nprimitive = "box"\nsize = [60, 60, 30]\ntranslate = [0, 0, 15]\n'
        'rotate_deg = [0, 0, 30]\n[[object]]\nname = "table"\nprimitive = "plane"\nsize = [1200, 1200]\n')
    scan = rs.scan(tmp_path / "s.toml", make_sensor(**{"noise.sigma_px": 0.0}),
                   pose=look_at((0.0, -260.0, 300.0), (0.0, 0.0, 15.0), up=(0, 0, 1)), seed=0)
    found = [s for s in F.lines(rs.edges.gradient(scan), scan=scan, min_length=15) if s.length_mm is not None]
    assert found and max(s.length_mm for s in found) <= 62.0


def test_arcs_must_bow_away_from_a_straight_edge():
    """A straight edge 2-3 px thick (a jump and its crease side by side, as on a plain box's
    outline) let a circle of radius 5-10 px thread it over 60-90 degrees with an RMS under
    0.8 px: `rangesim features` reported 34 arcs along a box's outline. An arc's run must now
    lie LINE_RATIO times farther from its best line than from the arc: none on the thick edge,
    while drawn arcs of radius 7-30 px over 70-120 degrees are still found."""
    from rangesim.features._arcs import LINE_RATIO

    assert LINE_RATIO > 1
    y, x = np.mgrid[0:120, 0:200]
    for thick in (2, 3):
        band = (y >= 60) & (y < 60 + thick) & (x > 10) & (x < 190)
        band |= (y == 60 + thick) & (x % 7 == 0) & (x > 10) & (x < 190)  # a ragged side
        assert F.arcs(band, radii=(5, 40)) == [], thick
    for r, span in ((7, 90), (10, 70), (20, 70), (30, 120)):
        ring = np.abs(np.hypot(x - 100.3, y - 59.6) - r) < 0.5
        arc = ring & (np.degrees(np.arctan2(y - 59.6, x - 100.3)) % 360 <= span)
        found = F.arcs(arc, radii=(5, 40))
        assert found and abs(np.degrees(found[0].span) - span) < 25, (r, span, found)
