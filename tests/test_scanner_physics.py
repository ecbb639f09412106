"""The geometric scanner checked against analytic expectations, one physical effect per test."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.core.geometry import look_at
from tests.conftest import box, make_sensor, plane, top_down_pose


def fronto_plane_scan(distance, **sensor_changes):
    """A plane facing the camera at ``distance`` mm, seen straight down."""
    sensor = make_sensor(**sensor_changes)
    return rs.scan([plane()], sensor, pose=top_down_pose(distance), seed=1), sensor


# 1. pinhole rays, one ray_intersect ---------------------------------------------------
def test_noise_free_plane_is_exact():
    scan, sensor = fronto_plane_scan(400.0)
    assert scan.valid.all()
    assert np.max(np.abs(scan.depth - 400.0)) < 1e-4 * 400.0
    h, w = scan.shape
    K = sensor.K
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    expected_x = (jj + 0.5 - K[0, 2]) / K[0, 0] * 400.0
    expected_y = (ii + 0.5 - K[1, 2]) / K[1, 1] * 400.0
    assert np.max(np.abs(scan.xyz[..., 0] - expected_x)) < 1e-4 * 400.0
    assert np.max(np.abs(scan.xyz[..., 1] - expected_y)) < 1e-4 * 400.0
    np.testing.assert_allclose(scan.normal.reshape(-1, 3), [[0, 0, -1]] * (h * w), atol=1e-6)
    assert (scan.part == 0).all() and np.isin(scan.face, [0, 1]).all()


def test_tilted_plane_depth_matches_ray_plane_intersection():
    tilted = plane()
    tilted.apply_transform(trimesh.transformations.rotation_matrix(math.radians(25), [0, 1, 0]))
    sensor = make_sensor()
    scan = rs.scan([tilted], sensor, pose=top_down_pose(500.0))
    # plane through world origin with normal R e_z; in the camera frame (x, -y, 500 - z)
    n_world = tilted.face_normals[0]
    n_cam = np.array([n_world[0], -n_world[1], -n_world[2]])
    p0_cam = np.array([0.0, 0.0, 500.0])
    h, w = scan.shape
    K = sensor.K
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    rays = np.stack([(jj + 0.5 - K[0, 2]) / K[0, 0], (ii + 0.5 - K[1, 2]) / K[1, 1], np.ones_like(jj, float)], -1)
    expected = (n_cam @ p0_cam) / (rays @ n_cam)
    assert scan.valid.mean() > 0.99
    rel = np.abs(scan.depth - expected)[scan.valid] / expected[scan.valid]
    assert rel.max() < 1e-4


# 2. laser shadows ------------------------------------------------------------------------
@pytest.mark.parametrize("sweep", ["rotating", "translating"])
def test_box_shadow_width_is_h_tan_incidence(sweep):
    distance, height, x_edge, baseline = 400.0, 30.0, 20.0, 150.0
    sensor = make_sensor(**{
        "camera.width": 320, "camera.height": 240, "laser.sweep": sweep, "laser.tilt_deg": 15.0,
        "laser.baseline": baseline,
    })
    scene = [plane(), box([x_edge, -40, 0], [x_edge + 40, 40, height])]
    scan = rs.scan(scene, sensor, pose=top_down_pose(distance))
    if sweep == "rotating":  # light from the laser origin, over the box's top edge
        tan_incidence = (baseline - x_edge) / (distance - height)
    else:  # every sheet keeps the same tilt
        tan_incidence = math.tan(math.radians(15.0))
    on_plane = (scan.status == Status.SHADOW) & (scan.part == 0)
    # the box spans |y| < 40: look at rows through its middle
    rows = np.abs(scan.xyz_true[..., 1]) < 30
    shadow_x = scan.xyz_true[..., 0][on_plane & rows]
    width = x_edge - shadow_x.min()
    footprint = distance / sensor.K[0, 0]
    assert abs(width - height * tan_incidence) < 1.5 * footprint
    # nothing lit lies inside the predicted shadow, and the plane is lit beyond it
    lit_plane = (scan.status == Status.VALID) & (scan.part == 0) & rows
    lit_x = scan.xyz_true[..., 0][lit_plane]
    inside = (lit_x > x_edge - height * tan_incidence + footprint) & (lit_x < x_edge)
    assert not inside.any()
    # the box side facing away from the laser is self-shadowed
    side = (scan.part == 1) & (np.abs(scan.xyz_true[..., 0] - x_edge) < 1e-3)
    assert side.any() and (scan.status[side] == Status.SHADOW).all()


# 3. return signal -------------------------------------------------------------------------
def test_return_signal_follows_lambert_and_inverse_square():
    distance, baseline = 400.0, 150.0
    scan, sensor = fronto_plane_scan(distance)
    albedo = 0.6  # scene default
    z_ref = sensor.reference_distance
    p = scan.xyz_true.reshape(-1, 3).astype(float)
    to_laser = np.array([baseline, 0, 0]) - p
    d_l = np.linalg.norm(to_laser, axis=1)
    d_c = np.linalg.norm(p, axis=1)
    cos_i = p[:, 2] / d_l  # normal (0, 0, -1), to_laser_z = -z
    cos_e = p[:, 2] / d_c
    expected = albedo * cos_i * cos_e * (z_ref / d_l) ** 2 * (z_ref / d_c) ** 2
    np.testing.assert_allclose(scan.intensity.ravel(), expected, rtol=1e-4)
    # doubling the distance cuts the on-axis return by about 16 (r^-2 both ways)
    far_scan, _ = fronto_plane_scan(2 * distance)
    c = (scan.shape[0] // 2, scan.shape[1] // 2)
    ratio = scan.intensity[c] / far_scan.intensity[c]
    expected_ratio = 16 * (baseline**2 + (2 * distance) ** 2) / (baseline**2 + distance**2) / 4 * (
        (distance / math.hypot(baseline, distance)) / (2 * distance / math.hypot(baseline, 2 * distance))
    )
    assert ratio == pytest.approx(expected_ratio, rel=5e-3)  # the centre pixel is 0.5 px off the axis


def test_dropout_exactly_where_signal_is_below_min_signal():
    # a sphere: the return falls towards its rim (grazing incidence) and drops out there
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=60.0)
    sensor = make_sensor(**{"noise.min_signal": 0.25})
    scan = rs.scan([sphere], sensor, pose=top_down_pose(450.0))
    hit = scan.status != Status.MISS
    dropout = scan.status == Status.DROPOUT
    assert dropout.any() and scan.valid.any()
    # dropouts sit at grazing angles, valid points at the centre
    cos_e = -np.einsum("ijk,ijk->ij", scan.normal, scan.xyz_true) / np.linalg.norm(scan.xyz_true, axis=2)
    assert np.nanmedian(cos_e[dropout]) < np.nanmedian(cos_e[scan.valid])
    # the rule itself: valid <=> lit and signal >= min_signal
    lit = hit & (scan.status != Status.SHADOW)
    assert (scan.intensity[lit & dropout] < 0.25).all()
    assert (scan.intensity[scan.valid] >= 0.25).all()


def test_working_range_marks_status_4():
    near_scan, _ = fronto_plane_scan(400.0, **{"range.near": 500.0, "range.far": 900.0})
    assert (near_scan.status == Status.OUT_OF_RANGE).all() and not near_scan.valid.any()
    far_scan, _ = fronto_plane_scan(400.0, **{"range.near": 100.0, "range.far": 350.0})
    assert (far_scan.status == Status.OUT_OF_RANGE).all()
    assert np.isnan(far_scan.depth).all() and np.isfinite(far_scan.xyz_true).all()



def test_measured_depths_past_the_working_range_are_not_valid():
    """The camera reads the stripe only within its window (the working range): a peak error that
    carries the measured depth past ``near`` falls off the sensor. A plane at 400 mm with
    ``near`` half a depth std below it loses the share of pixels whose error is below -0.5 std
    (about Phi(-0.5) = 0.31 for the near-Gaussian peak error); no valid depth lies past near."""
    sigma_z = depth_error_std(400.0, **{"noise.sigma_px": 0.5})[0]
    near = 400.0 - 0.5 * sigma_z
    scan, _ = fronto_plane_scan(400.0, **{"noise.sigma_px": 0.5, "range.near": near})
    assert np.isfinite(scan.xyz_true).all() and (scan.xyz_true[..., 2] >= near).all()
    assert (scan.depth[scan.valid] >= near).all()
    out = scan.status == Status.OUT_OF_RANGE
    assert np.isnan(scan.depth[out]).all()
    share = out.mean() / (out | scan.valid).mean()
    assert abs(share - 0.5 * math.erfc(0.5 / math.sqrt(2))) < 0.06, share

# 4. range noise through triangulation --------------------------------------------------------
def depth_error_std(distance, **changes):
    scan, sensor = fronto_plane_scan(distance, **changes)
    return float(np.std(scan.depth[scan.valid] - distance)), sensor


def test_rotating_sweep_depth_noise_grows_as_z_squared():
    sigma_px = 0.5
    s1, sensor = depth_error_std(300.0, **{"noise.sigma_px": sigma_px})
    s2, _ = depth_error_std(600.0, **{"noise.sigma_px": sigma_px})
    assert s2 / s1 == pytest.approx(4.0, rel=0.08)
    f, b = sensor.K[0, 0], sensor.params["laser"]["baseline"]
    assert s1 == pytest.approx(300.0**2 * sigma_px / (f * b), rel=0.05)


def test_translating_sweep_depth_noise_on_axis_grows_as_z():
    # fixed sheet tilt: the sheet crossing the axis at z sits z tan(tilt) off the camera,
    # so sigma_z = z^2 sigma_u / (f z tan t) = z sigma_u / (f tan t) on the axis
    changes = {"noise.sigma_px": 0.5, "laser.sweep": "translating", "laser.tilt_deg": 20.0}
    centre = slice(70, 90)  # columns around the optical axis (a ~ 0)
    errs = []
    for z in (300.0, 600.0):
        scan, sensor = fronto_plane_scan(z, **changes)
        errs.append(np.std((scan.depth - z)[:, centre]))
    assert errs[1] / errs[0] == pytest.approx(2.0, rel=0.1)
    f = sensor.K[0, 0]
    assert errs[0] == pytest.approx(300.0 * 0.5 / (f * math.tan(math.radians(20.0))), rel=0.1)


def test_quantisation_error_is_uniform_within_half_a_step():
    q = 0.5
    scan, sensor = fronto_plane_scan(400.0, **{"noise.quantization_px": q})
    f, b = sensor.K[0, 0], sensor.params["laser"]["baseline"]
    dzdu = 400.0**2 / (f * b)
    err = (scan.depth - 400.0)[scan.valid]
    assert np.abs(err).max() <= dzdu * q / 2 * 1.01
    assert np.std(err) == pytest.approx(dzdu * q / math.sqrt(12), rel=0.05)


def test_speckle_limited_depth_noise_matches_dorsch():
    contrast, wavelength_nm, aperture, z, b = 1.0, 670.0, 6.0, 400.0, 150.0
    scan, _ = fronto_plane_scan(z, **{"noise.speckle_contrast": contrast})
    centre = scan.depth[50:70, 70:90] - z
    sin_u = (aperture / 2) / math.hypot(aperture / 2, z)
    sin_theta = b / math.hypot(b, z)  # on the axis: camera ray along z, laser from (b, 0, 0)
    expected = contrast * wavelength_nm * 1e-6 / (2 * math.pi * sin_u * sin_theta)
    assert np.std(centre) == pytest.approx(expected, rel=0.12)


def test_noisy_points_stay_in_the_laser_sheet():
    scan, sensor = fronto_plane_scan(400.0, **{"noise.sigma_px": 0.5})
    b = sensor.params["laser"]["baseline"]
    p = scan.xyz_true[scan.valid].astype(float)
    x = scan.xyz[scan.valid].astype(float)
    normal = np.stack([-p[:, 2], np.zeros(len(p)), p[:, 0] - b], axis=1)  # sheet through L, P and y
    assert np.abs(np.einsum("ij,ij->i", x - p, normal) / np.linalg.norm(normal, axis=1)).max() < 1e-3
    assert np.abs(x - p).max() > 0.05  # the noise is really there


# 5. mixed pixels --------------------------------------------------------------------------------
def step_scan(stripe_width):
    sensor = make_sensor(**{"camera.width": 240, "camera.height": 120, "laser.stripe_width": stripe_width})
    scene = [plane(), box([-20, -40, 0], [40, 40, 25])]
    return rs.scan(scene, sensor, pose=top_down_pose(400.0))


def test_stripe_width_makes_phantom_points_at_depth_edges():
    sharp = step_scan(0.0)
    err = np.linalg.norm(sharp.xyz - sharp.xyz_true, axis=2)[sharp.valid]
    assert err.max() < 1e-3
    wide = step_scan(3.0)
    err = np.linalg.norm(wide.xyz - wide.xyz_true, axis=2)
    phantom = wide.valid & (err > 0.5)
    assert phantom.sum() >= 10
    # phantoms float between the box top (z = 375) and the plane (z = 400)
    z = wide.depth[phantom]
    assert ((z > 375.0 + 0.5) & (z < 400.0 - 0.5)).mean() > 0.8
    # and only near the box's outline, not on flat surfaces
    x_true = wide.xyz_true[..., 0][phantom]
    assert (np.minimum(np.abs(x_true + 20.0), np.abs(x_true - 40.0)) < 15).all()
    x = wide.xyz_true[..., 0]
    flat = wide.valid & ((x > 70) | (x < -60)) & (np.abs(wide.xyz_true[..., 1]) < 20)
    assert err[flat].max() < 1e-3


# 6. determinism ------------------------------------------------------------------------------------
def test_same_seed_same_scan_other_seed_changes_only_noise():
    sensor = make_sensor(**{"noise.sigma_px": 0.3, "noise.speckle_contrast": 0.5, "noise.min_signal": 0.05})
    scene = rs.load_scene([plane(), box([-20, -40, 0], [40, 40, 25])])
    a = rs.scan(scene, sensor, pose=top_down_pose(400.0), seed=7)
    b = rs.scan(scene, sensor, pose=top_down_pose(400.0), seed=7)
    c = rs.scan(scene, sensor, pose=top_down_pose(400.0), seed=8)
    for name in ("depth", "xyz", "normal", "intensity", "part", "face", "status", "valid", "xyz_true"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for name in ("normal", "intensity", "part", "face", "status", "valid", "xyz_true"):
        np.testing.assert_array_equal(getattr(a, name), getattr(c, name))
    assert not np.allclose(a.depth[a.valid], c.depth[c.valid])


# labels and the shared-edge guard ------------------------------------------------------------------
def test_part_and_face_labels_point_at_the_hit_triangle():
    scene = rs.load_scene([plane(), box([-20, -40, 0], [40, 40, 25])])
    scan = rs.scan(scene, make_sensor(), pose=look_at((60, -250, 300), (0, 0, 0)))
    hit = scan.status != Status.MISS
    assert set(np.unique(scan.part[hit])) == {0, 1}
    assert (scan.part[~hit] == -1).all() and (scan.face[~hit] == -1).all()
    world = scan.xyz_true[hit].astype(float) @ scan.pose[:3, :3].T + scan.pose[:3, 3]
    for part in (0, 1):
        mesh = scene.objects[part].mesh
        sel = scan.part[hit] == part
        faces = scan.face[hit][sel]
        normals = mesh.face_normals[faces]
        on_plane = np.einsum("ij,ij->i", world[sel] - mesh.triangles[faces, 0], normals)
        assert np.abs(on_plane).max() < 1e-3


def test_closed_solid_has_no_leaks_through_shared_edges():
    # a dense scan of a closed solid: no miss inside its silhouette, no hit on the far wall
    solid = trimesh.creation.icosphere(subdivisions=4, radius=80.0)
    sensor = make_sensor(**{"camera.width": 256, "camera.height": 256})
    scan = rs.scan([solid], sensor, pose=top_down_pose(400.0))
    h, w = scan.shape
    K = sensor.K
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    rays = np.stack([(jj + 0.5 - K[0, 2]) / K[0, 0], (ii + 0.5 - K[1, 2]) / K[1, 1], np.ones((h, w))], -1)
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    centre = np.array([0, 0, 400.0])
    # distance of each ray from the sphere centre; the inscribed radius of the icosphere > 0.99 r
    miss_distance = np.linalg.norm(np.cross(rays, centre), axis=2)
    inside = miss_distance < 0.98 * 80.0
    assert (scan.status[inside] != Status.MISS).all()
    front = np.einsum("ijk,ijk->ij", scan.xyz_true - centre, rays) < 0
    assert front[scan.status != Status.MISS].all()


def test_no_leak_through_a_box_standing_on_the_floor():
    # top-down, square image: the anti-diagonal pixels look exactly along the box top's and
    # bottom's shared diagonal edges; a leaking ray would land on the floor under the box
    sensor = make_sensor(**{"camera.width": 128, "camera.height": 128})
    scan = rs.scan([plane(), box([-50, -50, 0], [50, 50, 30])], sensor, pose=top_down_pose(400.0))
    x, y = scan.xyz_true[..., 0], scan.xyz_true[..., 1]
    under_top = (np.abs(x) < 45) & (np.abs(y) < 45)
    assert under_top.sum() > 1000 and (scan.part[under_top] == 1).all()


def test_a_new_pose_reuses_the_compiled_kernels():
    # poses enter the kernels as opaque variables: sweeps and datasets of many views compile
    # once. Two warm-up views compile the data-dependent branches too (the shared-edge
    # re-cast runs only where a view has suspect pixels); fresh views then compile nothing.
    import drjit as dr

    scene = rs.load_scene([plane(z=0.0), box((-20, -20, 0), (20, 20, 30))])
    sensor = make_sensor()

    def view(k):
        pose = top_down_pose(400.0 + 9.0 * k)
        pose[:3, 3] += [3.0 * k, -2.0 * k, 0.0]
        return pose

    flag = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    try:
        for k in range(2):
            rs.scan(scene, sensor, pose=view(k), seed=k)
        # hashes as well as hits: a variant an earlier run left in the on-disk cache is a hit
        seen = {str(k.get("hash")) for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT}
        for k in range(2, 4):
            rs.scan(scene, sensor, pose=view(k), seed=k)
        kernels = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, flag)
    assert kernels and all(k["cache_hit"] for k in kernels)
    new = [(k.get("size"), k.get("operation_count")) for k in kernels if str(k.get("hash")) not in seen]
    assert not new, new


# Embree's coherent traversal: a speed setting per CPU, never a different scan --------------
@pytest.fixture
def coherent_setting(monkeypatch):
    from rangesim.core import backend

    def use(value):
        monkeypatch.setenv("RANGESIM_COHERENT_RAYS", value)
        backend.coherent_rays.cache_clear()
        return backend.coherent_rays()

    yield use
    monkeypatch.delenv("RANGESIM_COHERENT_RAYS", raising=False)
    backend.coherent_rays.cache_clear()


def test_coherent_and_incoherent_casts_give_the_same_scan(coherent_setting):
    sensor = make_sensor(**{"camera.width": 160, "camera.height": 120, "laser.tilt_deg": 15.0})
    scene = [plane(), box([20, -40, 0], [60, 40, 30])]  # laser shadows and camera occlusion
    scans = []
    for value, expected in (("1", True), ("0", False)):
        assert coherent_setting(value) is expected
        scans.append(rs.scan(scene, sensor, pose=top_down_pose(400.0), seed=3))
    a, b = scans
    assert np.array_equal(a.status, b.status) and np.array_equal(a.face, b.face)
    assert np.nanmax(np.abs(a.depth - b.depth)) < 1e-3  # mm: the hit points' last bits at most


def test_coherent_setting_refuses_other_values(coherent_setting):
    from rangesim.core.errors import RangesimError

    with pytest.raises(RangesimError, match="RANGESIM_COHERENT_RAYS must be 1 or 0"):
        coherent_setting("fast")
