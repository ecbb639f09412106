"""Bad input to the scores and the feature finders: a clear RangesimError naming the argument,
never a hang, a raw numpy error or a result built on garbage (a new user's probe, sixth
session of 2026-12-03)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import MAX_TOLERANCE_PX
from rangesim.core.errors import RangesimError
from rangesim.evaluate import edge_scores, feature_scores


@pytest.fixture(scope="module")
def plate():
    scan, scene = rs.datasets.plate_scan(), rs.datasets.plate_scene()
    return scan, scene, rs.edges.gradient(scan), rs.evaluate.visible_truth(scan, scene)


@pytest.mark.parametrize("tolerance", [np.inf, np.nan, -1.0, "2", None, 1e6])
def test_edge_scores_refuses_tolerances_that_are_no_distance(plate, tolerance):
    # 1e6 px once ran for minutes (the candidate offsets grow with the tolerance's square)
    _, _, edges, truth = plate
    with pytest.raises(RangesimError, match="tolerance_px"):
        edge_scores(edges.mask, truth, tolerance_px=tolerance)


def test_edge_scores_takes_tolerances_up_to_its_bound():
    pred = np.zeros((6, 6), bool)
    gt = np.zeros((6, 6), bool)
    pred[0, 0] = gt[5, 5] = True
    assert edge_scores(pred, gt, tolerance_px=10)["matched"] == 1   # 7.1 px apart
    assert edge_scores(pred, gt, tolerance_px=MAX_TOLERANCE_PX)["matched"] == 1
    with pytest.raises(RangesimError, match="tolerance_px"):
        edge_scores(pred, gt, tolerance_px=MAX_TOLERANCE_PX + 1)


def test_cli_and_sweep_files_check_the_tolerance_before_any_work(tmp_path, capsys):
    from rangesim.cli.main import main
    from rangesim.experiments.sweep_file import load_sweep

    scan = rs.datasets.plate_scan()
    scan.save(tmp_path / "plate.exr")
    assert main(["detect", str(tmp_path / "plate.exr"), "--tolerance", "100", "--out", str(tmp_path / "d")]) != 0
    assert "--tolerance must be at most 64" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
    sweep = tmp_path / "s.toml"
    scene = Path(rs.__file__).resolve().parents[1] / "scenes" / "green_piece.toml"
    sweep.write_text(f'name = "t"\nscenes = ["{scene.as_posix()}"]\ntolerance_px = 80.0\n')
    with pytest.raises(RangesimError, match="tolerance_px must be at most 64"):
        load_sweep(sweep)


@pytest.mark.parametrize("bad", [np.zeros(5), np.zeros((3, 3, 3)), None, "edges", np.array([["a"]])])
def test_edge_scores_refuses_what_is_no_image(bad):
    with pytest.raises(RangesimError, match="pred_mask"):
        edge_scores(bad, np.zeros((3, 3)))


def test_nan_in_a_float_map_is_no_edge(plate):
    _, _, edges, truth = plate
    as_float = np.where(edges.mask, 1.0, np.nan)
    assert edge_scores(as_float, truth)["n_pred"] == int(edges.mask.sum())
    assert len(rs.features.lines(as_float)) == len(rs.features.lines(edges.mask)) > 0


def test_score_edges_truth_as_float_map_and_wrong_shapes(plate):
    scan, _, edges, truth = plate
    as_float = np.where(truth > 0, truth.astype(float), np.nan)  # NaN in a float map is no edge
    assert rs.evaluate.score_edges(edges, scan, truth=as_float) == rs.evaluate.score_edges(edges, scan, truth=truth)
    assert rs.evaluate.score_edges(edges, scan, truth=np.full(truth.shape, np.nan))["n_gt"] == 0
    with pytest.raises(RangesimError, match=r"truth \(3, 3\) and scan"):
        rs.evaluate.score_edges(edges, scan, truth=np.zeros((3, 3), np.uint8))
    with pytest.raises(RangesimError, match=r"edge map \(3, 3\) and scan"):  # was numpy's broadcast error
        rs.evaluate.score_edges(np.ones((3, 3), bool), scan, truth=np.zeros((3, 3), np.uint8))
    for bad in (np.full(truth.shape, 7), np.full(truth.shape, 0.5), np.full(truth.shape, -1)):
        with pytest.raises(RangesimError, match="truth labels must be whole numbers 0-4"):
            rs.evaluate.score_edges(edges, scan, truth=bad)


def test_edge_scores_refuses_labels_of_another_shape(plate):
    _, _, edges, truth = plate
    with pytest.raises(RangesimError, match="pred_labels"):
        edge_scores(edges.mask, truth, pred_labels=np.zeros((3, 3), np.uint8))


@pytest.mark.parametrize("crease_deg", [0, -5, np.nan, 200, "20"])
def test_truth_refuses_crease_angles_that_are_no_angle(plate, crease_deg):
    scan, scene, edges, _ = plate
    with pytest.raises(RangesimError, match="crease_deg"):
        rs.evaluate.score_edges(edges, scan, scene, crease_deg=crease_deg)
    with pytest.raises(RangesimError, match="crease_deg"):
        rs.evaluate.visible_truth(scan, scene, crease_deg=crease_deg)


@pytest.mark.parametrize("found, match", [
    ("circles", "found must be"),
    ({"blobs": []}, "unknown feature kinds"),
    ({"circles": [1, 2, 3]}, "is not a feature"),
    ({"segments": ["a"]}, "is not a feature"),
    ({"circles": 5}, "must be a list"),
])
def test_feature_scores_refuses_found_that_is_no_features(found, match):
    with pytest.raises(RangesimError, match=match):
        feature_scores(found, {"circles": [], "segments": []})


@pytest.mark.parametrize("kwargs, match", [
    ({"center_tol_px": -1}, "center_tol_px"), ({"size_tol": np.nan}, "size_tol"),
    ({"segment_tol_px": np.inf}, "segment_tol_px"), ({"min_visible": 2}, "min_visible"),
])
def test_feature_scores_refuses_bad_tolerances(kwargs, match):
    with pytest.raises(RangesimError, match=match):
        feature_scores({}, {"circles": []}, **kwargs)


def test_feature_scores_refuses_truth_and_scan_of_the_wrong_kind():
    with pytest.raises(RangesimError, match="truth"):
        feature_scores({}, None)
    with pytest.raises(RangesimError, match="scan"):
        feature_scores({}, {}, "scan.exr")


def test_circles_and_arcs_stay_in_the_radii_asked_for(plate):
    # the refinement moved hypotheses out of narrow ranges: (8, 8.3) gave a circle of 8.6 px,
    # (2, 3) an arc of 4.1 px
    _, _, edges, _ = plate
    for lo, hi in [(8, 8.3), (2, 3), (5, 9), (9.5, 10), (3, 40)]:
        for f in [*rs.features.circles(edges, radii=(lo, hi)), *rs.features.arcs(edges, radii=(lo, hi))]:
            assert lo <= f.radius <= hi
    assert rs.features.circles(edges, radii=(3, 40))      # the plate's hole is still found


@pytest.mark.parametrize("finder, kwargs, name", [
    (rs.features.lines, {"min_length": "5"}, "min_length"),
    (rs.features.lines, {"angle_tol_deg": 0}, "angle_tol_deg"),
    (rs.features.lines, {"max_lines": 0}, "max_lines"),
    (rs.features.lines, {"threshold": -1}, "threshold"),
    (rs.features.circles, {"min_support": 2}, "min_support"),
    (rs.features.circles, {"threshold": -1}, "threshold"),
    (rs.features.circles, {"angle_tol_deg": "4"}, "angle_tol_deg"),
    (rs.features.arcs, {"max_coverage": np.nan}, "max_coverage"),
    (rs.features.arcs, {"max_residual": 0}, "max_residual"),
])
def test_feature_finders_refuse_bad_parameters(plate, finder, kwargs, name):
    _, _, edges, _ = plate
    with pytest.raises(RangesimError, match=name):
        finder(edges, **kwargs)


@pytest.mark.parametrize(("which", "labels"), [("pred_labels", -1), ("gt_labels", 300), ("pred_labels", 1.5),
                                               ("gt_labels", np.nan)])
def test_edge_scores_refuses_labels_that_are_no_edge_type(which, labels):
    # a -1 or a 300 fell in no type and vanished from every per-label count (an API probe)
    a = np.zeros((32, 40), bool)
    a[10] = True
    b = np.zeros((32, 40), bool)
    b[11] = True
    given = {which: np.where(a if which == "pred_labels" else b, labels, 0)}
    with pytest.raises(RangesimError, match=f"{which} must hold whole numbers 0-4"):
        edge_scores(a, b, **given)
    rim = edge_scores(a, b, pred_labels=a * 4.0, gt_labels=b.astype(np.uint8))  # a rim scores as a jump
    assert rim["per_label"]["jump"]["f1"] == 1.0


@pytest.mark.parametrize(("name", "value"), [("spacing_px", 0), ("spacing_px", 1e-9), ("spacing_px", -1.0),
                                             ("spacing_px", np.nan), ("depth_tol_px", np.nan),
                                             ("depth_tol_px", -1.0)])
def test_ground_truth_features_refuses_spacings_and_tolerances_out_of_range(plate, name, value):
    # spacing 1e-9 px asked for 111 GiB, 0 raised OverflowError; NaN / negative tolerances passed
    scan, scene, _, _ = plate
    with pytest.raises(RangesimError, match=name):
        rs.evaluate.ground_truth_features(scan, scene, **{name: value})


@pytest.mark.parametrize("given", [{"z": np.ones((8, 8))}, {"fp": np.ones((8, 8))}, {}])
def test_estimate_depth_noise_without_a_scan_needs_z_and_fp(given):
    with pytest.raises(RangesimError, match="needs a scan, or both z and fp"):
        rs.edges.estimate_depth_noise(**given)
