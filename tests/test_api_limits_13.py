"""Public functions that crashed, ran out of memory or returned nonsense on odd but plausible
arguments (an independent probe of the Python API): each now gives a correct result or a
one-line RangesimError naming the problem."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cad.features import Circle3D
from rangesim.core.geometry import project_circle


@pytest.fixture(scope="module")
def plate():
    return rs.datasets.plate_scan(), rs.datasets.plate_scene()


# -- windows and kernels whose memory grew with their size, not the image's --------------------------
def test_curvature_window_is_bounded():
    small = rs.datasets.plate_scan(width=32, height=30)
    with pytest.raises(rs.RangesimError, match="window must be an odd whole number from 3 to 255"):
        rs.curvature.curvature_scan(small, window=999)  # asked for 21 GiB
    with pytest.raises(rs.RangesimError, match="from 3 to 255"):
        rs.edges.curvature(small, window=257)


def test_curvature_batches_do_not_change_the_fits(monkeypatch):
    """The quadric fits go in batches of pixels x window^2 points; any batch size gives the same fits."""
    from rangesim.curvature import grid

    scan = rs.datasets.plate_scan(width=48, height=40)
    whole = grid.curvature_scan(scan, window=7)
    monkeypatch.setattr(grid, "_CHUNK_VALUES", 7 * 7 * 13)  # 13 pixels per batch
    pieces = grid.curvature_scan(scan, window=7)
    assert np.isfinite(whole["K"]).sum() > 500
    for key in whole:
        np.testing.assert_array_equal(whole[key], pieces[key], err_msg=key)


def test_gradient_sigma_is_bounded():
    small = rs.datasets.plate_scan(width=32, height=30)
    with pytest.raises(rs.RangesimError, match=r"sigma must be a finite number in \[0, 42.5\]"):
        rs.edges.gradient(small, sigma=1e6)  # 18 s on 32 x 30; 1e9 raised MemoryError
    assert rs.edges.gradient(small, sigma=42.5).mask.shape == small.shape


# -- ground truth from a scene that did not make the scan --------------------------------------------
def test_ground_truth_refuses_a_scene_with_other_triangles(plate):
    scan, _ = plate
    other = rs.load_scene([trimesh.creation.box((60, 40, 10)), trimesh.creation.box((300, 300, 2))])
    with pytest.raises(rs.RangesimError, match="scan hits triangle .* whose mesh in this scene has"):
        rs.ground_truth_edges(scan, other)  # IndexError before
    with pytest.raises(rs.RangesimError, match="scan hits triangle"):
        rs.evaluate.score_edges(rs.edges.gradient(scan), scan, other)


@pytest.mark.parametrize("shift_mm", [0.1, 2.0])
def test_ground_truth_refuses_the_scene_moved(plate, shift_mm):
    """The same meshes moved: every face index exists, but the scan's true hits no longer lie on
    the planes of the triangles they name (the unmoved scene: all of them, to ~1e-4 mm)."""
    scan, scene = plate
    moved = rs.load_scene([o.mesh.copy().apply_translation((0.0, 0.0, shift_mm)) for o in scene.objects])
    with pytest.raises(rs.RangesimError, match="not the one this scan was made from"):
        rs.ground_truth_edges(scan, moved)
    assert rs.ground_truth_edges(scan, scene).any()


def test_region_boundaries_and_jump_edges_check_shapes():
    with pytest.raises(rs.RangesimError, match=r"labels must be an \(H, W\) array"):
        rs.evaluate.region_boundaries(np.zeros(5, int))
    with pytest.raises(rs.RangesimError, match="valid has shape"):
        rs.evaluate.region_boundaries(np.zeros((3, 3), int), valid=np.ones((2, 2), bool))
    xyz, hit = np.zeros((4, 4, 3)), np.ones((4, 4), bool)
    with pytest.raises(rs.RangesimError, match="rays"):
        rs.evaluate.jump_edges(xyz, hit, rays=np.zeros((2, 2, 3)))
    with pytest.raises(rs.RangesimError, match="max_angle_deg"):
        rs.evaluate.jump_edges(xyz, hit, max_angle_deg=float("nan"))  # every pixel 'no jump' before


def test_region_boundaries_take_nan_as_no_segment():
    # NaN != NaN made every pixel of an all-NaN float label image a boundary (an API probe)
    assert not rs.evaluate.region_boundaries(np.full((5, 5), np.nan)).any()
    labels = np.ones((4, 6))
    labels[:, 3:] = 2.0
    labels[0, 0] = np.nan
    expected = np.zeros((4, 6), bool)
    expected[:, 2:4] = True
    np.testing.assert_array_equal(rs.evaluate.region_boundaries(labels), expected)
    with pytest.raises(rs.RangesimError, match="numeric segment ids"):
        rs.evaluate.region_boundaries(np.full((3, 3), "a"))


def test_score_edges_flag_is_a_bool(plate):
    scan, scene = plate
    with pytest.raises(rs.RangesimError, match="ignore_data_boundary must be True or False"):
        rs.evaluate.score_edges(rs.edges.gradient(scan), scan, scene, ignore_data_boundary="no")


# -- circles behind the camera ----------------------------------------------------------------------
def test_project_circle_facing_the_camera_is_the_pinhole_circle():
    """A circle of radius r facing the camera on its axis at depth d images as a circle of radius
    f r / d about the principal point (pixel-centre coordinates: cx - 0.5)."""
    from rangesim.core.conics import ellipse_from_conic

    f, cx, cy = 500.0, 64.0, 48.0
    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    (x0, y0), (a, b), _ = ellipse_from_conic(project_circle(np.array([0, 0, 300.0]), np.array([0, 0, 1.0]), 6.0, K))
    assert (x0, y0) == pytest.approx((cx - 0.5, cy - 0.5), abs=1e-9)
    assert (a, b) == pytest.approx((f * 6.0 / 300.0,) * 2, rel=1e-9)


@pytest.mark.parametrize(("z", "normal", "expected"), [
    (-300.0, (0, 0, 1.0), None),      # wholly behind: the conic of its mirror image in front before
    (3.0, (0.6, 0, 0.8), None),       # tilted, radius 6 reaching 0.6 r = 3.6 mm along z: 0.6 mm behind
    (4.0, (0.6, 0, 0.8), "ellipse"),  # ... to 0.4 mm in front of the camera plane
    (3.0, (0, 0, 1.0), "ellipse"),    # facing the camera 3 mm away: all of it in front
])
def test_project_circle_only_images_circles_in_front(z, normal, expected):
    K = np.array([[500.0, 0, 64], [0, 500.0, 48], [0, 0, 1]])
    conic = project_circle(np.array([0.0, 0.0, z]), np.array(normal), 6.0, K)
    assert (conic is None) == (expected is None)
    if expected:
        from rangesim.core.conics import ellipse_from_conic

        assert ellipse_from_conic(conic) is not None


def test_predict_ellipses_checks_its_circles(plate):
    scan, _ = plate
    cam, forward = scan.pose[:3, 3], scan.pose[:3, 2]
    assert rs.features.predict_ellipses(scan, [Circle3D("behind", cam - 100 * forward, forward, 8.0)]) == []
    assert len(rs.features.predict_ellipses(scan, [Circle3D("ahead", cam + 100 * forward, forward, 8.0)])) == 1
    with pytest.raises(rs.RangesimError, match=r"circles3d\[0\] must be a Circle3D"):
        rs.features.predict_ellipses(scan, [(1, 2, 3)])
    with pytest.raises(rs.RangesimError, match="positive radius"):
        rs.features.predict_ellipses(scan, [Circle3D("c", cam + 100 * forward, forward, -8.0)])


# -- the noise estimate's arrays ---------------------------------------------------------------------
def test_estimate_depth_noise_checks_its_arrays():
    scan = rs.datasets.plate_scan(width=32, height=30)
    for kwargs, words in ((dict(z=scan.depth, fp=np.ones((3, 3))), "one shape"),
                          (dict(z=scan.depth, fp=np.ones(5)), "one shape"),
                          (dict(scan=scan, quantum=-1), "quantum must be None or an")):
        with pytest.raises(rs.RangesimError, match=words):
            rs.edges.estimate_depth_noise(**kwargs)


# -- scenes built in Python ----------------------------------------------------------------------
def test_scene_objects_are_checked_when_built():
    from rangesim.scene.scene import Scene, SceneObject

    box = trimesh.creation.box((10, 10, 10))
    with pytest.raises(rs.RangesimError, match="albedo must be a finite reflectance in"):
        SceneObject("b", box, albedo=float("nan"))  # scanned to 0 valid pixels before
    with pytest.raises(rs.RangesimError, match="mesh must be a trimesh.Trimesh"):
        SceneObject("b", None)
    with pytest.raises(rs.RangesimError, match=r"face_labels must be \(12,\) integers"):
        SceneObject("b", box, face_labels=np.zeros(5, int), labels=["x"])
    with pytest.raises(rs.RangesimError, match="face_labels must index its 1 labels"):
        SceneObject("b", box, face_labels=np.full(12, 5), labels=["x"])
    with pytest.raises(rs.RangesimError, match="at least one object"):
        Scene([])
    bad = box.copy()
    bad.vertices[0] = np.nan
    with pytest.raises(rs.RangesimError, match="NaN or infinite vertex"):
        Scene([SceneObject("b", bad)])  # "view position and look_at coincide" at scan time before
    assert Scene([SceneObject("b", box, albedo=1)]).objects[0].albedo == 1.0


# -- PCD's LZF streams -------------------------------------------------------------------------------
def test_lzf_refuses_sizes_no_stream_can_hold():
    """A back reference's 3 bytes give at most 264 bytes: 88 per compressed byte."""
    from rangesim.recorded.lzf import LZFError, lzf_decompress, lzf_store

    packed = lzf_store(b"abc")
    assert lzf_decompress(packed, 3) == b"abc"
    for size in (10**12, -1, 88 * len(packed) + 1):  # 10**12 raised MemoryError before
        with pytest.raises(LZFError, match="at most 88 per compressed byte"):
            lzf_decompress(packed, size)
    run = bytes([0]) + b"a" + bytes([0xE0, 255, 0])  # 'a', then 264 copies of the byte 1 back
    assert lzf_decompress(run, 265) == b"a" * 265 and len(run) * 88 >= 265


# -- twins ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "value", "words"), [
    ("theta_deg", float("nan"), "theta_deg must be a finite number in (-90, 90)"),
    ("min_cos", 2.0, "min_cos must be a finite number in [0, 1]"),
    ("sigma_mm", -1.0, "sigma_mm must be a finite number >= 0"),
    ("camera_views", 10**6, "camera_views must be 1 or 2"),
    ("camera_views", 0, "camera_views must be"),
])
def test_twin_parameters_are_checked(name, value, words):
    """Each of these made a twin with no valid pixel, silently."""
    from rangesim.twin.stage import check_twin_param

    with pytest.raises(rs.RangesimError, match=words.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        check_twin_param(name, value)
    assert check_twin_param("theta_deg", -29.0) == -29.0 and check_twin_param("camera_views", 2) == 2


def test_twin_stage_and_calibration_options_are_checked(tmp_path):
    from rangesim.twin.calibration import calibrate
    from rangesim.twin.comparison import check_detector_names
    from rangesim.twin.stage import TwinStage, load_mesh_mm

    box = trimesh.creation.box((10, 10, 10))
    for scale in (float("nan"), 0, -1):
        with pytest.raises(rs.RangesimError, match="mesh_scale must be a finite scale > 0"):
            load_mesh_mm(box, scale)
    assert np.allclose(load_mesh_mm(box, 2.0).extents, 20.0)
    scan = rs.datasets.plate_scan(width=32, height=30)
    with pytest.raises(rs.RangesimError, match="side must be 1, -1 or None"):
        TwinStage(scan, box, None, side=0)  # ZeroDivisionError before
    with pytest.raises(rs.RangesimError, match="unknown detector.*'nope'"):
        check_detector_names(["nope"])  # KeyError after the whole twin before
    assert check_detector_names(None)[0] == "gradient" and check_detector_names("normal") == ["normal"]
    with pytest.raises(rs.RangesimError, match="theta_deg must be a finite number"):
        calibrate(scan, box, None, theta_grid=[1e6], refine=False)  # returned theta 1e6 before
    with pytest.raises(rs.RangesimError, match="cannot fit nope: choose from"):
        calibrate(scan, box, None, params="nope")  # "cannot fit n, o, p, e" before


# -- sweeps built in Python ------------------------------------------------------------------------
def test_run_sweep_checks_a_spec_built_in_python(tmp_path):
    import dataclasses
    from pathlib import Path

    from rangesim.experiments import run_sweep
    from rangesim.experiments.sweep_file import check_spec, load_sweep

    target = Path(__file__).resolve().parents[1] / "scenes" / "flat_target.toml"
    (tmp_path / "s.toml").write_text(f'scenes = ["{target}"]\nsensors = ["white_scanner"]\n[set]\n'
                                      '"camera.width" = 16\n"camera.height" = 12\n')
    spec = load_sweep(tmp_path / "s.toml")
    for change, words in ((dict(views=-1), "views must be an integer >= 0"),
                          (dict(views=2.5), "views must be an integer"),
                          (dict(seed=-1), "seed must be an integer >= 0"),
                          (dict(pose={"cap_deg": -5}), r"\[pose\]"),
                          (dict(pose={"zz": 1}), r"\[pose\]")):
        with pytest.raises(rs.RangesimError, match=words):
            run_sweep(dataclasses.replace(spec, **change), tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out").exists()
    with pytest.raises(rs.RangesimError, match="sweep .toml file or a SweepSpec, got dict"):
        run_sweep({"name": "t"}, tmp_path / "out")
    assert check_spec(spec) == spec


def test_a_sensor_changed_twice_is_modified_once():
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 32}).with_params({"camera.height": 24})
    with pytest.raises(rs.RangesimError) as info:
        sensor.with_params({"camera.width": -1})
    assert str(info.value).count("(modified)") == 1 and "white_scanner.toml (modified): camera.width" in str(info.value)


def test_ellipses_check_seed_and_explained(plate):
    scan, _ = plate
    edges = rs.edges.gradient(scan)
    with pytest.raises(rs.RangesimError, match="seed must be an integer"):
        rs.features.ellipses(edges, seed=float("nan"))
    with pytest.raises(rs.RangesimError, match=r"explained\[0\] must be a found line, circle or arc"):
        rs.features.ellipses(edges, explained=(1, 2))  # explained nothing, silently, before
    assert len(rs.features.ellipses(edges, seed=3)) == len(rs.features.ellipses(edges))


def test_legitimate_inputs_the_new_checks_keep(plate):
    """What an independent review of the checks above found refused and should not be."""
    from rangesim.scene.scene import Scene, SceneObject
    from rangesim.twin.stage import load_mesh_mm

    scan, _ = plate
    edges = rs.edges.gradient(scan)
    assert len(rs.features.ellipses(edges, seed=None)) == len(rs.features.ellipses(edges))  # seed is unused
    box = trimesh.creation.box((10, 10, 10))
    SceneObject("b", box, face_labels=np.arange(12))  # labels without names are not read
    assert len(Scene(SceneObject(f"b{k}", box) for k in range(2)).objects) == 2  # a generator
    assert np.allclose(load_mesh_mm(box, "1000").extents, 10000.0)  # a scale as text


def test_a_spec_with_numpy_numbers_is_taken_as_python_numbers(tmp_path):
    import dataclasses
    from pathlib import Path

    from rangesim.experiments.sweep_file import check_spec, load_sweep

    target = Path(__file__).resolve().parents[1] / "scenes" / "flat_target.toml"
    (tmp_path / "s.toml").write_text(f'scenes = ["{target}"]\nsensors = ["white_scanner"]\n')
    spec = check_spec(dataclasses.replace(load_sweep(tmp_path / "s.toml"), views=np.int64(2), seed=np.int64(7),
                                          tolerance_px=np.float32(2)))
    assert (spec.views, spec.seed, spec.tolerance_px) == (2, 7, 2.0)
    assert type(spec.views) is int and type(spec.seed) is int and type(spec.tolerance_px) is float
