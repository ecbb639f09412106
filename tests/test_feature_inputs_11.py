"""Feature finders' inputs a user can get wrong (an independent probe, eleventh session):
edge maps with impossible offsets, relations of what is not a feature list, mesh circles of
a file name, line parameters that find nothing on a perfect line."""
from __future__ import annotations

import json

import numpy as np
import pytest

import rangesim as rs
from rangesim.core import RangesimError


def _ring_map(offset=None):
    H, W = 120, 160
    y, x = np.mgrid[0:H, 0:W]
    m = (np.abs(np.hypot(x - 80, y - 60) - 20) < 0.5) | (x == 0) | (y == H - 1)  # a rim, and two borders
    return rs.edges.EdgeMap(m, np.zeros((H, W), np.uint8), np.zeros((H, W), np.float32), offset=offset)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1.5, -1e5])
def test_offsets_not_finite_or_beyond_a_pixel_are_refused(bad):
    # the finders' compiled kernels index accumulators and grids by the moved points: a NaN or
    # a far offset wrote outside them (a segfault, or heap corruption); refused when the map is
    # made, and again when a finder reads a map changed since
    em = _ring_map()
    off = np.zeros(em.mask.shape + (2,), np.float32)
    r, c = np.argwhere(em.mask)[5]
    off[r, c] = (0.0, bad)
    with pytest.raises(RangesimError, match="EdgeMap.offset"):
        _ring_map(off)
    em.offset = off
    for finder in (rs.features.circles, rs.features.arcs, rs.features.lines, rs.features.ellipses):
        with pytest.raises(RangesimError, match="EdgeMap.offset"):
            finder(em)
    off[...] = 0.0
    off[~em.mask] = np.nan  # read at edge pixels only
    assert _ring_map(off).offset is not None


@pytest.mark.parametrize("shift", [(-1.0, 0.0), (0.0, -1.0), (1.0, 1.0)])
def test_offsets_of_a_whole_pixel_at_the_image_border_are_safe(shift):
    # the largest offset allowed, on pixels of the image's first column and last row: the
    # rim is still found where it lies, moved by the offset
    off = np.zeros((120, 160, 2), np.float32)
    off[...] = shift
    em = _ring_map(off)
    c = rs.features.circles(em)
    assert any(np.hypot(*(np.asarray(k.center) - (80 + shift[0], 60 + shift[1]))) < 0.2 for k in c)
    for h in ("tilings", "chains", "outlines"):
        e = rs.features.ellipses(em, hypotheses=h)
        assert any(np.hypot(*(np.asarray(k.center) - (80 + shift[0], 60 + shift[1]))) < 0.2 for k in e), h
    rs.features.arcs(em)
    rs.features.lines(em)


def test_relations_refuse_what_is_not_a_list_of_features(tmp_path):
    seg = rs.features.Segment((0.0, 0.0), (10.0, 0.0), 10.0, None, 11, 0.0)
    circle = rs.features.Circle((5.0, 5.0), 3.0, 0, 1.0, 0.0)
    rows = rs.features.relations([seg], [circle])
    assert rows and rows[0]["relation"] == "circle_segment_distance"
    with pytest.raises(RangesimError, match="segments must be a list of features"):
        rs.features.relations(seg)
    with pytest.raises(RangesimError, match="circles must be a list"):
        rs.features.relations([seg], circle)
    with pytest.raises(RangesimError, match=r"segments\[0\] is a tuple"):
        rs.features.relations([((0, 0), (1, 1))])
    with pytest.raises(RangesimError, match="is a directory"):
        rs.features.relations_to_json(rows, tmp_path)
    assert list(tmp_path.iterdir()) == []  # nothing half-written beside it
    with pytest.raises(RangesimError, match="row 0 must be a dict with the keys"):
        rs.features.relations_to_csv([{**rows[0], "extra": 1}])
    # NumPy scalars are written as numbers
    text = rs.features.relations_to_json([{**rows[0], "value": np.float32(2.5)}], tmp_path / "r.json")
    assert json.loads(text)[0]["value"] == 2.5 and json.loads((tmp_path / "r.json").read_text()) == json.loads(text)


def test_mesh_circles_refuse_a_file_name_and_bad_thresholds():
    import trimesh
    mesh = trimesh.creation.cylinder(radius=5.0, height=10.0, sections=64)
    assert len(rs.features.mesh_circles(mesh)) == 2  # the two end rims
    with pytest.raises(RangesimError, match="must be a trimesh.Trimesh"):
        rs.features.mesh_circles("part.stl")
    for bad in (-1.0, 0.0, 180.0, float("nan")):
        with pytest.raises(RangesimError, match="crease_deg"):
            rs.features.mesh_circles(mesh, crease_deg=bad)


def test_lines_never_cut_between_neighbouring_pixels_and_refuse_a_band_under_half_a_pixel():
    m = np.zeros((40, 160), bool)
    m[20, 10:150] = True  # a perfect 140 px row
    for gap in (0.0, 0.5, 1.0):
        seg = rs.features.lines(m, max_gap=gap)
        assert len(seg) == 1 and abs(seg[0].length - 139) < 1.0, gap
    m[20, 80] = False  # a missing pixel: a gap of 2 px between the points beside it
    assert len(rs.features.lines(m, max_gap=1.0)) == 2
    assert len(rs.features.lines(m, max_gap=2.0)) == 1
    with pytest.raises(RangesimError, match="band_px"):
        rs.features.lines(m, band_px=0.0)
