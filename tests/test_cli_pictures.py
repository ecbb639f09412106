"""The pictures the README promises (issue 16 item 7): compare without a mesh, readable point previews,
previews of scans larger than a screen."""
from __future__ import annotations

import json

import numpy as np

import rangesim as rs
from rangesim.cli.main import main
from rangesim.viz import preview
from rangesim.viz.points import spread_subset


def _png_size(path) -> tuple[int, int]:
    from PIL import Image

    with Image.open(path) as im:
        assert im.format == "PNG"
        return im.size


def test_compare_without_mesh_writes_the_edge_picture(tmp_path, capsys):
    scan_path = tmp_path / "plate.exr"
    rs.datasets.plate_scan().save(scan_path)
    out = tmp_path / "cmp"
    assert main(["compare", str(scan_path), "--out", str(out)]) == 0
    assert "compare.png" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mesh"] is None and set(metrics["edges"]) == set(rs.edges.DETECTORS)
    w, h = _png_size(out / "compare.png")
    assert w > 600 and h > 400  # a panel per detector and the scan


def test_point_preview_spreads_the_normals_over_a_dense_cloud():
    rng = np.random.default_rng(0)
    dense = rng.normal(0, 0.05, (5000, 3))  # a thread-like clump
    sparse = np.c_[np.mgrid[0:20, 0:20].reshape(2, -1).T * 5.0 + 10, np.zeros(400)]
    pick = spread_subset(np.r_[dense, sparse], 4.0, 4000)
    assert (pick < 5000).sum() <= 8  # the clump gets a handful, not 4000 x 5000 / 5400 of them
    assert (pick >= 5000).sum() == 400  # every sparse point keeps its normal


def test_preview_of_a_large_scan_is_drawn_from_every_kth_pixel(tmp_path, monkeypatch):
    scan = rs.datasets.plate_scan()
    monkeypatch.setattr(preview, "MAX_PREVIEW_PX", 40)
    thin = preview._thinned(scan)
    k = -(-max(scan.shape) // 40)
    assert thin.shape == scan.depth[::k, ::k].shape and max(thin.shape) <= 40
    np.testing.assert_array_equal(thin.status, scan.status[::k, ::k])
    path = preview.save_preview(scan, tmp_path / "p.png")
    assert "128" in preview.default_title(scan)  # the title still gives the full size
    assert _png_size(path)[0] > 100


def test_the_structured_light_twin_panel_shows_its_figures():
    # the Kinect twin's comparison left its fourth panel empty: its figures were only in metrics.json
    from matplotlib.figure import Figure

    from rangesim.viz.compare import _structured_light_table

    ax = Figure().subplots()
    _structured_light_table(ax, {
        "z2_coefficient_mm_per_m2": {"recorded": 4.21, "twin": 3.47}, "z_spread": {"recorded": 1.3, "twin": 1.06},
        "depth_level_gaps_in_steps": {"recorded": {"median": 0.9}, "twin": {"median": 1.0}},
        "iou": 0.93, "iou_no_physics": 0.942, "edges": {"gradient": {"f1": 0.27, "edges": 10}}})
    text = "\n".join(t.get_text() for t in ax.texts)
    for line in ("z^2 noise k (mm/m^2)         4.21     3.47", "depth-level gap (steps)      0.90     1.00",
                 "valid-mask IoU 0.930 (no physics 0.942)", "edge F1 gradient      0.270"):
        assert line in text, (line, text)


def test_region_truth_is_drawn_without_a_type():
    # segment-label boundaries were drawn and counted as "jump edge" (table contacts included)
    from rangesim.core.constants import EdgeLabel
    from rangesim.evaluate.runs import EdgeTruth

    labels = np.zeros((6, 6), np.uint8)
    labels[2, 1:5] = EdgeLabel.JUMP
    regions, geometry = EdgeTruth(labels, "regions").edge_map(), EdgeTruth(labels, "geometry").edge_map()
    assert regions.mask.sum() == geometry.mask.sum() == 4
    assert not regions.labels.any() and (geometry.labels[2, 1:5] == EdgeLabel.JUMP).all()


def test_a_structured_light_scan_s_shadow_is_the_projector_s():
    # the preview's legend and the scan summary said "laser shadow" for a sensor without a laser
    from rangesim.core.constants import Status, status_name
    from rangesim.viz.preview import _status_label

    assert status_name(Status.SHADOW) == "laser shadow"
    assert status_name(Status.SHADOW, "structured_light") == _status_label(Status.SHADOW, "structured_light") \
        == "projector shadow"
    assert status_name(Status.DROPOUT, "structured_light") == "dropout"
