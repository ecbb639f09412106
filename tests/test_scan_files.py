"""A real scan survives its files: EXR and NPZ exactly, PLY as valid points with normals."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import rangesim as rs
from tests.conftest import box, make_sensor, plane, top_down_pose


@pytest.fixture(scope="module")
def noisy_scan():
    sensor = make_sensor(**{"noise.sigma_px": 0.2, "laser.stripe_width": 1.0, "noise.min_signal": 0.05})
    return rs.scan([plane(), box([-20, -40, 0], [40, 40, 25])], sensor, pose=top_down_pose(400.0), seed=3)


@pytest.mark.parametrize("suffix", [".exr", ".npz"])
def test_exact_round_trip(tmp_path, noisy_scan, suffix):
    path = noisy_scan.save(tmp_path / f"scan{suffix}")
    back = rs.load_scan(path)
    for name in ("depth", "xyz", "valid", "normal", "intensity", "part", "face", "status", "xyz_true"):
        a, b = getattr(noisy_scan, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name
    np.testing.assert_array_equal(back.pose, noisy_scan.pose)
    assert back.meta == noisy_scan.meta
    np.testing.assert_array_equal(back.K, noisy_scan.K)


@pytest.mark.parametrize("suffix", [".exr", ".npz", ".ply", ".pcd"])
def test_a_pose_that_is_not_finite_is_refused_by_every_writer(tmp_path, noisy_scan, suffix):
    import copy

    bad = copy.copy(noisy_scan)
    bad.pose = noisy_scan.pose.copy()
    bad.pose[0, 3] = np.nan  # a .ply written with it could not be read back
    with pytest.raises(rs.RangesimError, match=r"scan\S* .*pose holds NaN or infinity"):
        bad.save(tmp_path / f"scan{suffix}")
    assert list(tmp_path.iterdir()) == []  # nothing written, not even a temporary


def test_ply_holds_the_valid_points(tmp_path, noisy_scan):
    cloud = trimesh.load(noisy_scan.save(tmp_path / "scan.ply"))
    assert len(cloud.vertices) == noisy_scan.valid.sum()
    np.testing.assert_allclose(cloud.vertices, noisy_scan.points(), rtol=1e-6)
