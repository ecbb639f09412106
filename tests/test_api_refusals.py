"""Plausible mistakes with the Python API get a one-line RangesimError naming the input (not an
AttributeError from deep inside, a MemoryError or a hang), and scans compare by value. Small
synthetic inputs: the plate scan (128 x 120) and hand-made images."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core import RangeScan, RangesimError
from rangesim.edges import EdgeMap
from rangesim.features._lines import segment_pairs


@pytest.fixture(scope="module")
def plate():
    scan = rs.datasets.plate_scan()
    return scan, rs.datasets.plate_scene(), rs.edges.gradient(scan)


def _refused(call, *words):
    with pytest.raises(RangesimError) as err:
        call()
    text = str(err.value)
    assert "\n" not in text, text
    for word in words:
        assert word in text, text
    return text


def _plane(h: int = 20, w: int = 30, meta: dict | None = None) -> RangeScan:
    """A fronto-parallel plane at 300 mm through a 100 px pinhole."""
    f, z = 100.0, np.full((h, w), 300.0)
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    xyz = np.stack([(jj - w / 2) / f * z, (ii - h / 2) / f * z, z], -1)
    K = [[f, 0, w / 2], [0, f, h / 2], [0, 0, 1]]
    return RangeScan(depth=z, xyz=xyz, valid=np.ones((h, w), bool), normal=np.zeros((h, w, 3)),
                     intensity=np.ones((h, w)), part=np.zeros((h, w)), face=np.zeros((h, w)),
                     status=np.zeros((h, w)), meta={"K": K, **(meta or {})})


# -- RangeScan ----------------------------------------------------------------------------------------------
def test_scans_compare_by_value(plate):
    scan = plate[0]
    again = rs.datasets.plate_scan()
    assert scan is not again and scan == again and not scan != again   # one seed, one scan (NaN equal to NaN)
    assert np.isnan(scan.depth).any()
    assert scan != rs.datasets.plate_scan(seed=1)                      # the noise differs
    moved = dataclasses.replace(scan, depth=np.where(scan.valid, scan.depth + 1e-3, np.nan))
    assert scan != moved
    other_meta = dataclasses.replace(scan, meta={**scan.meta, "K": np.asarray(scan.meta["K"])})
    assert scan == other_meta                                          # a list and its array alike
    assert scan != dataclasses.replace(scan, meta={**scan.meta, "seed": -1})
    assert scan != dataclasses.replace(scan, sigma=None) and (scan == "scan") is False
    with pytest.raises(TypeError):
        hash(scan)                                                     # mutable: no hash, as before


@pytest.mark.parametrize("pose, words", [
    (np.zeros((4, 4)), ("pose", "singular")),
    (np.full((4, 4), np.nan), ("pose", "NaN")),
    (np.diag([1.0, 1.0, 0.0, 1.0]), ("pose", "singular")),
])
def test_scans_refuse_poses_that_are_no_camera_pose(pose, words):
    _refused(lambda: dataclasses.replace(_plane(), pose=pose), *words)
    assert _plane().pose.shape == (4, 4)                               # the identity passes


@pytest.mark.parametrize("K", [[[1, 0], [0, 1]], "x", [[0, 0, 15], [0, 0, 10], [0, 0, 1]],
                               [[np.nan, 0, 15], [0, 100, 10], [0, 0, 1]], [[-100, 0, 15], [0, 100, 10], [0, 0, 1]]])
def test_scans_refuse_intrinsics_that_are_no_pinhole(K):
    _refused(lambda: _plane(meta={"K": K}), "meta['K']", "3x3")
    scan = _plane()
    scan.meta["K"] = K                                                 # reassigned after construction
    _refused(lambda: scan.K, "meta['K']")


def test_scans_refuse_a_negative_sigma():
    scan = _plane()
    sigma = np.full(scan.shape, 0.1, np.float32)
    sigma[3, 4] = -1.0
    _refused(lambda: dataclasses.replace(scan, sigma=sigma), "sigma", ">= 0", "-1.0")
    sigma[3, 4] = np.nan                                               # not predicted there: accepted
    assert dataclasses.replace(scan, sigma=sigma).sigma is not None


# -- detectors ------------------------------------------------------------------------------------------------
def test_size_parameters_are_bounded(plate):
    scan = plate[0]
    _refused(lambda: rs.edges.gradient(scan, stride=10 ** 9), "stride", "255")
    _refused(lambda: rs.edges.line_fit(scan, max_stride=10 ** 9), "max_stride", "255")
    _refused(lambda: rs.edges.line_fit(scan, k=10 ** 6), "k", "64")
    _refused(lambda: rs.edges.line_fit(np.random.default_rng(0).normal(size=(50, 3)), k=65), "k")
    _refused(lambda: rs.load_sensor("kinect_v1").with_params({"structured_light.window": 99999}),
             "structured_light.window", "255")
    huge = _plane(meta={"sensor": {"mode": "structured_light", "structured_light": {"window": 99999}}})
    for detector in rs.edges.DETECTORS.values():
        _refused(lambda d=detector: d(huge), "window", "255")


def test_image_detectors_refuse_an_unorganized_point_list():
    points = _plane(1, 60, meta={"organized": False})                 # a point cloud read as 1 x N
    for detector in rs.edges.DETECTORS.values():
        _refused(lambda d=detector: d(points), "unorganized", "line_fit")
    assert rs.edges.line_fit(points.points()).shape == (60,)
    assert rs.edges.gradient(_plane(1, 60)).mask.shape == (1, 60)      # a one-row image stays an image


def test_a_sigma_that_predicts_nothing_is_no_prediction(plate):
    scan = plate[0]
    blank = dataclasses.replace(scan, sigma=np.full(scan.shape, np.nan, np.float32))
    none = dataclasses.replace(scan, sigma=None)
    for name, detector in rs.edges.DETECTORS.items():
        np.testing.assert_array_equal(detector(blank).mask, detector(none).mask, err_msg=name)


# -- features and evaluation ----------------------------------------------------------------------------------
def test_radii_under_a_pixel_and_booleans_name_radii(plate):
    em = plate[2]
    for radii in ((0.1, 0.5), (0, 0)):
        text = _refused(lambda r=radii: rs.features.arcs(em, radii=r), "radii")
        assert "cell_px" not in text.split(":")[0]
    for finder in (rs.features.circles, rs.features.arcs):
        _refused(lambda f=finder: f(em, radii=(True, 30)), "radii")


def test_arguments_of_the_wrong_kind_are_named(plate):
    scan, scene, em = plate
    circles = rs.features.circles(em, radii=(3, 30))
    assert circles
    _refused(lambda: rs.evaluate.feature_scores({"circles": circles}, {"circles": circles}),
             "truth['circles']", "ground_truth_features")
    _refused(lambda: rs.evaluate.score_edges(em, scan.depth, scene), "score_edges", "RangeScan", "ndarray")
    _refused(lambda: rs.evaluate.ground_truth_edges(scan.depth, scene), "RangeScan")
    _refused(lambda: rs.evaluate.visible_truth(scan, scene, crease=20), "visible_truth", "crease", "crease_deg")
    _refused(lambda: segment_pairs(circles), "segment_pairs", "start and end")
    _refused(lambda: rs.features.predict_ellipses(scan, None), "circles3d")
    _refused(lambda: rs.datasets.plate_scan(changes="x"), "changes")
    _refused(lambda: rs.curvature.curvature_mesh(None), "trimesh")
    _refused(lambda: rs.curvature.curvature_edges([0.5], [0.5], "0.1"), "threshold")
    _refused(lambda: rs.curvature.hk_sign_map([0.0], [0.0], eps_K=-1), "eps_K")
    _refused(lambda: rs.evaluate.region_boundaries(np.zeros((3, 3)), background="x"), "background")
    _refused(lambda: EdgeMap(mask=np.ones((3, 3), bool), labels=np.full((3, 3), 7), strength=np.zeros((3, 3))),
             "labels", "0-4")


def test_a_detector_map_scores_as_truth(plate):
    scan, _, em = plate
    assert (em.labels == 4).any()                                      # rims: scored as jumps
    s = rs.evaluate.score_edges(em, scan, truth=em.labels)
    assert s["f1"] == 1.0 and s["per_label"]["jump"]["f1"] == 1.0


def test_ring_neighbourhoods_stop_once_they_cover_the_mesh():
    # 162 vertices, every one within ~10 rings of every other: 10^7 rings are those ~10 (one sparse
    # product per ring took 8 s per 10^4 rings: this call would not end)
    mesh = trimesh.creation.icosphere(2)
    many = rs.curvature.curvature_mesh(mesh, rings=10 ** 7)
    few = rs.curvature.curvature_mesh(mesh, rings=30)
    for key in ("H", "K"):
        np.testing.assert_array_equal(many[key], few[key])


def test_an_independent_reviews_cases(plate):
    """The review of this file's fixes: each of these went wrong in their first version."""
    scan, _, em = plate
    from rangesim.features._circles import circle_hypotheses

    _refused(lambda: circle_hypotheses(em, radii=(3, 30), cell_px=None), "cell_px")   # was a TypeError
    assert len(rs.features.circles(em, radii=(r for r in (3, 30)))) == len(rs.features.circles(em, radii=(3, 30)))
    _refused(lambda: EdgeMap(mask=np.ones((3, 3), bool), labels=np.full((3, 3), -1), strength=np.zeros((3, 3))),
             "got -1")                                                  # (not the 255 of a uint8 cast)
    with_nan = dataclasses.replace(scan, meta={**scan.meta, "x": np.float32("nan"), "o": np.array(None, object)})
    assert with_nan == dataclasses.replace(with_nan)
    assert rs.evaluate.region_boundaries(np.arange(9).reshape(3, 3), background=None).all()


def test_a_reader_that_sets_a_bad_pose_after_building_the_scan_is_refused_at_load(tmp_path, monkeypatch):
    """load_scan runs the constructor's checks again on what a reader returns (a pose set after
    construction, as a .conf sets it, or a registered reader of another package)."""
    import copy

    import rangesim.io as rio

    def reader(path, **kwargs):
        scan = copy.copy(rs.datasets.plate_scan())
        scan.pose = np.full((4, 4), np.nan)                           # after construction: unchecked
        return scan

    monkeypatch.setitem(rio._READERS, ".weird", reader)
    path = tmp_path / "x.weird"
    path.write_text("x")
    _refused(lambda: rs.load_scan(path), "x.weird", "pose holds NaN")
    monkeypatch.setitem(rio._READERS, ".fine", lambda path, **kw: rs.datasets.plate_scan())
    (tmp_path / "y.fine").write_text("y")
    assert rs.load_scan(tmp_path / "y.fine") == rs.datasets.plate_scan()
