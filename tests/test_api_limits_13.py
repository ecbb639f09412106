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
