"""The rendered scanner: path-traced frames, spacetime peaks, image noise, and what it shows
that the geometric scanner cannot (interreflections, glossy metal)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.sensor import rendered
from rangesim.sensor.frames import expose, pixel_speckle_contrast, splat_frames
from rangesim.sensor.peaks import find_peaks
from tests.conftest import make_sensor, plane

#: camera at the world origin looking along +z (world = camera frame)
FACING = np.eye(4)


@pytest.fixture(scope="module", autouse=True)
def _needs_llvm_for_bsdfs():
    try:
        rendered.check_backend()
    except RangesimError as exc:  # .ci/run installs Debian's libllvm19
        pytest.skip(str(exc))


def render_sensor(**changes):
    """A small noise-free rendered sensor: 2 mm stripe, 0.5 mm steps, z_ref = 350 mm."""
    base = {"mode": "rendered", "camera.width": 64, "camera.height": 16, "camera.fov_deg": 22.0,
            "laser.stripe_width": 2.0, "laser.step": 0.5, "range.near": 250.0, "range.far": 450.0,
            "render.image_noise": False, "render.spp": 4}
    return make_sensor(**{**base, **changes})


def facing_plane(z=350.0, albedo=0.8):
    scene = rs.load_scene([plane(size=400.0, z=0.0).apply_translation([0, 0, z])])
    scene.objects[0].albedo = albedo
    return scene


# -- the pieces, against exact expectations ---------------------------------------------------
def test_gaussian_peak_fit_is_exact_on_gaussian_profiles():
    frames = np.arange(40)
    centre, sigma = np.array([10.3, 20.77, 5.5, 31.02]), np.array([1.2, 0.8, 2.0, 0.6])
    stack = 900 * np.exp(-0.5 * ((frames[None] - centre[:, None]) / sigma[:, None]) ** 2)
    peaks = find_peaks(stack, "gaussian")
    np.testing.assert_allclose(peaks.position, centre, atol=1e-9)
    np.testing.assert_allclose(peaks.sigma, sigma, atol=1e-9)
    parabola = 100 - (frames[None] - centre[:, None]) ** 2
    np.testing.assert_allclose(find_peaks(parabola, "parabolic").position, centre, atol=1e-9)


def test_peak_at_the_sweep_ends_or_flat_is_not_a_peak():
    stack = np.zeros((3, 10))
    stack[0, 0] = 5  # brightest frame is the first one
    stack[1, 9] = 5  # ... the last one
    peaks = find_peaks(stack)  # row 2: all zero, not log-concave
    assert np.all(np.isnan(peaks.position))


def test_saturated_run_is_located_at_its_middle():
    frames = np.arange(30)
    stack = np.minimum(5000 * np.exp(-0.5 * ((frames - 12.0) / 2.0) ** 2), 3000)[None]
    peaks = find_peaks(stack, "gaussian", full_well_e=3000)
    assert peaks.saturated[0]
    assert peaks.position[0] == pytest.approx(12.0)


def test_splat_spreads_a_vertex_over_the_sheet_profile():
    sigma_mm, ds, lam = 0.85, 0.5, 2.0  # profile std in frames: 0.85 / (2 * 0.5) = 0.85
    stack = splat_frames(np.array([0]), np.array([0.7]), np.array([3.0 + 10.3 * ds]), np.array([lam]),
                         1, 3.0, ds, 25, sigma_mm)[0]
    frames = np.arange(25)
    expected = 0.7 * np.exp(-0.5 * ((frames - 10.3) / (sigma_mm / (lam * ds))) ** 2)
    expected[np.abs(frames - 10.3) > 4.5 * 0.85] = 0.0
    np.testing.assert_allclose(stack, expected, atol=1e-12)


def test_shot_and_read_noise_follow_their_laws():
    rng = np.random.default_rng(1)
    mean_e, read = 1000.0, 12.0
    stack = np.full((200, 500), mean_e / 4000.0)
    electrons = expose(stack, 4000.0, 1e6, read, 0.0, rng)
    assert electrons.mean() == pytest.approx(mean_e, rel=0.005)
    assert electrons.var() == pytest.approx(mean_e + read**2, rel=0.03)  # Poisson: variance = mean
    dark = expose(np.zeros((100, 100)), 4000.0, 1e6, read, 0.0, rng)
    assert dark.std() == pytest.approx(read, rel=0.03) and abs(dark.mean()) < 0.5
    clipped = expose(np.full((10, 10), 2.0), 4000.0, 5000.0, 0.0, 0.0, rng)
    assert clipped.max() == 5000.0  # the well holds no more
    assert np.array_equal(expose(stack, 4000.0, 1e6, read, 0.0, None), np.full(stack.shape, 1000.0, np.float32))


def test_speckle_multiplies_by_a_unit_mean_gamma():
    rng = np.random.default_rng(2)
    m, c = 1e4, 0.3
    electrons = expose(np.full((400, 500), 1.0), m, 1e9, 0.0, np.full(400, c), rng)
    assert electrons.mean() == pytest.approx(m, rel=0.005)
    assert electrons.var() == pytest.approx(m + (c * m) ** 2, rel=0.03)  # shot + speckle variance


def test_pixel_speckle_contrast_averages_grains_over_the_footprint():
    d, contrast, lam_nm, aperture, f = 350.0, 0.5, 632.8, 6.0, 1317.0
    grain = lam_nm * 1e-6 / (2 * (aperture / 2) / math.hypot(aperture / 2, d))
    expected = contrast * grain / (d / f)  # footprint 0.27 mm >> grain 0.037 mm
    got = pixel_speckle_contrast(np.array([d, np.nan]), contrast, lam_nm, aperture, f)
    assert got[0] == pytest.approx(expected) and got[1] == 0.0
    assert pixel_speckle_contrast(np.array([d]), contrast, lam_nm, aperture, 1e5)[0] == contrast  # tiny pixels


# -- whole scans ------------------------------------------------------------------------------
@pytest.mark.parametrize("sweep", ["rotating", "translating"])
def test_plane_rendered_and_geometric_agree(sweep):
    scene = facing_plane()
    sensor = render_sensor(**{"laser.sweep": sweep})
    exact = rs.scan(scene, sensor, pose=FACING)
    geometric = rs.scan(scene, sensor.with_params({"mode": "geometric"}), pose=FACING)
    assert exact.valid.all() and geometric.valid.all()
    assert np.abs(exact.depth - geometric.depth).max() < 0.01  # mm, noise-free
    noisy = rs.scan(scene, sensor.with_params({"render.image_noise": True}), pose=FACING, seed=3)
    error = (noisy.depth - noisy.xyz_true[..., 2])[noisy.valid]
    assert noisy.valid.mean() > 0.99
    assert abs(error.mean()) < 0.02 and 0.002 < error.std() < 0.2  # unbiased, noise of the photon count


def test_a_single_column_renders_like_the_geometric_scan():
    # one column has no neighbour to measure the stripe's footprint by (numpy.gradient refused it)
    # (the field of view is the width's: 1.4 deg over one column keeps 64 x 16's focal length)
    scene, sensor = facing_plane(), render_sensor(**{"camera.width": 1, "camera.fov_deg": 22.0 / 64})
    exact = rs.scan(scene, sensor, pose=FACING)
    geometric = rs.scan(scene, sensor.with_params({"mode": "geometric"}), pose=FACING)
    assert exact.shape == (16, 1) and exact.valid.all()
    assert np.abs(exact.depth - geometric.depth).max() < 0.01  # mm


def test_plane_peak_intensity_is_the_irradiance_law():
    # a 4 mm stripe much wider than the 0.5 mm pixel footprint and the 0.5 mm sweep step:
    # the peak frame reads the full irradiance (footprint and step cost < 1 %)
    scene = facing_plane(albedo=0.8)
    sensor = render_sensor(**{"laser.stripe_width": 4.0, "camera.width": 256, "camera.height": 4})
    result = rs.scan(scene, sensor, pose=FACING)
    points = result.xyz_true.reshape(-1, 3)
    to_laser = sensor.laser_origin - points
    d2 = (to_laser**2).sum(axis=1)
    expected = 0.8 * (-to_laser[:, 2] / np.sqrt(d2)) * sensor.reference_distance**2 / d2  # albedo cos_i (z_ref/d)^2
    ratio = result.intensity.ravel() / expected
    assert np.all(np.abs(ratio - 1) < 0.015)


def _corner(albedo, length=80.0, half_height=60.0, z0=350.0):
    """Two walls meeting at 90 degrees along the camera's y axis, opening towards the camera."""
    c = math.cos(math.pi / 4)
    quad = [[0, 1, 2], [0, 2, 3]]
    wall_a = trimesh.Trimesh([[0, -half_height, z0], [length * c, -half_height, z0 - length * c],
                              [length * c, half_height, z0 - length * c], [0, half_height, z0]], quad, process=False)
    wall_b = trimesh.Trimesh([[0, -half_height, z0], [0, half_height, z0],
                              [-length * c, half_height, z0 - length * c],
                              [-length * c, -half_height, z0 - length * c]], quad, process=False)
    scene = rs.load_scene([wall_a, wall_b])
    for obj in scene.objects:
        obj.albedo = albedo
    return scene


def _corner_bias(result):
    """Largest column-mean depth error (mm) within 6 mm of the corner line."""
    error = np.where(result.valid, result.depth - result.xyz_true[..., 2], np.nan)
    near = np.abs(np.nanmedian(result.xyz_true[..., 0], axis=0)) < 6.0
    return np.nanmax(np.abs(np.nanmean(error[:, near], axis=0)))


def test_concave_corner_shows_interreflection_bias_that_falls_with_albedo():
    sensor = render_sensor(**{"camera.width": 96, "render.spp": 16})
    bright = _corner_bias(rs.scan(_corner(0.9), sensor, pose=FACING))
    direct_only = _corner_bias(rs.scan(_corner(0.9), sensor.with_params({"render.max_depth": 2}), pose=FACING))
    dark = _corner_bias(rs.scan(_corner(0.3), sensor, pose=FACING))
    geometric = _corner_bias(rs.scan(_corner(0.9), sensor.with_params({"mode": "geometric"}), pose=FACING))
    assert bright > 0.3  # mm: light from the other wall drags the peak
    assert direct_only < 0.02 and geometric < 0.01  # no interreflection, no bias
    assert 0.15 * bright < dark < 0.6 * bright  # indirect light scales with the albedo


def test_polished_metal_sphere_drops_out_and_throws_outliers():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=30.0).apply_translation([0, 0, 350])
    floor = trimesh.creation.box((300, 300, 2)).apply_translation([0, 0, 382])
    sensor = render_sensor(**{"camera.width": 48, "camera.height": 48, "camera.fov_deg": 16.0,
                              "noise.min_signal": 0.02, "render.spp": 8})

    def run(material, mode):
        scene = rs.load_scene([sphere, floor])
        scene.objects[0].material = material
        result = rs.scan(scene, sensor.with_params({"mode": mode}), pose=FACING)
        # the sphere's inside, away from the phantom points both modes make at its silhouette
        on = ndimage.binary_erosion(result.part == 0, iterations=2)
        error = np.abs(result.depth - result.xyz_true[..., 2])
        dropped = np.isin(result.status[on], (Status.DROPOUT, Status.OUT_OF_RANGE)).mean()
        gross = result.valid & on & (error > 5.0)  # mm: not noise, not a mixed pixel
        return dropped, int(gross.sum()), int((result.valid & on).sum())

    metal = run({"type": "roughconductor", "alpha": 0.05}, "rendered")
    matte = run({}, "rendered")
    geometric = run({}, "geometric")
    assert metal[0] > 0.5 and matte[0] < 0.05 and geometric[0] < 0.1  # the mirror sends the stripe away
    assert metal[1] >= max(5, 0.3 * metal[2])  # ...and the floor's stripe into the camera
    assert matte[1] == 0 and geometric[1] == 0


def test_reflectance_edge_biases_only_the_pixels_that_straddle_it():
    # spacetime analysis (Curless & Levoy 1995): a pixel's temporal profile holds only its own
    # footprint, so a bright/dark edge pulls the peak only where a footprint straddles it
    def half(x0, x1, z=350.0):
        return trimesh.Trimesh([[x0, -100, z], [x1, -100, z], [x1, 100, z], [x0, 100, z]], [[0, 1, 2], [0, 2, 3]],
                               process=False)

    scene = rs.load_scene([half(-200, 0.3), half(0.3, 200)])  # the edge 0.3 mm into column 32
    scene.objects[0].albedo, scene.objects[1].albedo = 0.9, 0.05
    result = rs.scan(scene, render_sensor(**{"render.spp": 16}), pose=FACING)
    column_bias = np.nanmean(np.where(result.valid, result.depth - result.xyz_true[..., 2], np.nan), axis=0)
    assert column_bias[32] < -0.5  # the bright sliver drags the peak towards it (and the laser)
    assert np.all(np.abs(np.delete(column_bias, 32)) < 0.02)
    geometric = rs.scan(scene, render_sensor(mode="geometric"), pose=FACING)
    assert np.nanmax(np.abs(geometric.depth - geometric.xyz_true[..., 2])) < 0.01


def test_tiles_reuse_compiled_kernels(monkeypatch):
    monkeypatch.setattr(rendered, "STACK_CELLS", 64 * 4 * 300)  # 4 rows per tile: 4 tiles
    result = rs.scan(facing_plane(), render_sensor(), pose=FACING)
    kernels = result.meta["kernels"]
    assert result.meta["tiles"] == 4 and kernels["later_tiles"] > 0
    assert kernels["later_cache_hits"] == kernels["later_tiles"]  # no recompilation after the first tile
    whole = rs.scan(facing_plane(), render_sensor(), pose=FACING)  # noise-free: tiling changes nothing
    np.testing.assert_allclose(result.depth, whole.depth, atol=1e-4)


def test_seeds_and_frames():
    sensor = render_sensor(**{"render.image_noise": True})
    scene = facing_plane()
    a, stack = rs.scan(scene, sensor, pose=FACING, seed=5, keep_frames=True)
    b = rs.scan(scene, sensor, pose=FACING, seed=5)
    c = rs.scan(scene, sensor, pose=FACING, seed=6)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)
    assert not np.array_equal(a.depth, c.depth, equal_nan=True)
    assert stack.frames.shape == (a.meta["frames"], 16, 64)
    # the brightest frame of each pixel lies at its sub-frame peak, and gives back its sheet
    top = stack.frames.argmax(axis=0)
    s_top = stack.s0 + top * stack.ds
    s_true = np.arctan2(a.xyz_true[..., 0] - 150.0, a.xyz_true[..., 2])
    assert np.all(np.abs(s_top - s_true) <= stack.ds)


def test_rendered_configuration_errors():
    scene = facing_plane()
    with pytest.raises(RangesimError, match="stripe_width > 0"):
        rs.scan(scene, render_sensor(**{"laser.stripe_width": 0.0}), pose=FACING)
    with pytest.raises(RangesimError, match="render.frames >= "):
        rs.scan(scene, render_sensor(**{"render.frames": 10}), pose=FACING)
    with pytest.raises(RangesimError, match="only the rendered mode has frames"):
        rs.scan(scene, render_sensor(mode="geometric"), pose=FACING, keep_frames=True)
    with pytest.raises(RangesimError, match="render.max_depth"):
        render_sensor(**{"render.max_depth": 1})
    with pytest.raises(RangesimError, match="mode 'laser' is not available"):
        render_sensor(mode="laser")


def test_old_llvm_is_refused_with_a_clear_message(monkeypatch):
    import drjit as dr

    if not rs.core.backend.mitsuba().variant().startswith("llvm"):
        pytest.skip("CPU backend only")
    monkeypatch.setattr(dr.detail, "llvm_version", lambda: (14, 0, 6))
    with pytest.raises(RangesimError, match="libllvm19"):
        rendered.check_backend()


def test_scene_materials_are_checked(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('[[object]]\nprimitive = "sphere"\nradius = 10\nmaterial = { type = "velvet" }\n')
    with pytest.raises(RangesimError, match="velvet"):
        rs.load_scene(path)
    path.write_text('[[object]]\nprimitive = "sphere"\nradius = 10\n'
                    'material = { type = "roughconductor", alpha = 0.05, shine = 1 }\n')
    with pytest.raises(RangesimError, match="shine"):
        rs.load_scene(path)
    path.write_text('[[object]]\nprimitive = "sphere"\nradius = 10\n'
                    'material = { type = "roughplastic", alpha = 0.1 }\nalbedo = 0.4\n')
    obj = rs.load_scene(path).objects[0]
    assert obj.material == {"type": "roughplastic", "alpha": 0.1}
    assert rs.load_scene(path).mitsuba_scene() is not None  # Mitsuba accepts it


def test_intensity_image_is_registered_with_the_range_image():
    block = trimesh.creation.box((60, 40, 30)).apply_translation([10, -5, 335])
    scene = rs.load_scene([block, plane(size=400.0, z=0.0).apply_translation([0, 0, 350])])
    sensor = render_sensor(**{"camera.width": 80, "camera.height": 60, "mode": "geometric"})
    image = rs.intensity_image(scene, sensor, pose=FACING, spp=16)
    result = rs.scan(scene, sensor, pose=FACING)
    assert image.shape == result.shape
    # the block's front face (its outline inset by a pixel) is bright and uniform; the wall
    # around it is darkened near the block by occlusion of the room light
    front = ndimage.binary_erosion(result.part == 0, iterations=1)
    assert image[front].mean() == pytest.approx(0.6 * 1.0, rel=0.1)  # albedo 0.6, half-space of sky: 1
    edge = (result.part == 0) ^ ndimage.binary_dilation(result.part == 0)  # the ring just outside the block
    assert image[edge].mean() < image[front].mean()


def test_cli_rendered_scan_with_frames_and_intensity(tmp_path):
    from rangesim.cli.main import main

    sensor_path = tmp_path / "s.toml"
    sensor_path.write_text(
        'mode = "rendered"\n[camera]\nwidth = 48\nheight = 12\nfov_deg = 22\n'
        '[laser]\nbaseline = 150\nstripe_width = 2.0\nstep = 0.5\n[range]\nnear = 250\nfar = 450\n'
        '[render]\nspp = 2\n')
    mesh = tmp_path / "plane.stl"
    plane(size=400.0, z=0.0).apply_translation([0, 0, -350]).export(mesh)
    out = tmp_path / "scan.npz"
    pose = tmp_path / "pose.json"
    pose.write_text("[[1,0,0,0],[0,-1,0,0],[0,0,-1,0],[0,0,0,1]]")  # looking down -z at the plane
    code = main(["scan", str(mesh), "--sensor", str(sensor_path), "--pose", str(pose), "--out", str(out),
                 "--keep-frames", "--intensity-image", str(tmp_path / "white.png")])
    assert code == 0
    loaded = rs.load_scan(out)
    assert loaded.meta["mode"] == "rendered" and loaded.valid.mean() > 0.95
    frames = np.load(tmp_path / "scan.frames.npz")
    assert frames["frames"].shape == (loaded.meta["frames"], 12, 48)
    assert (tmp_path / "white.png").stat().st_size > 0
    assert main(["scan", str(mesh), "--out", str(tmp_path / "g.npz"), "--keep-frames"]) == 2
    assert not (tmp_path / "g.npz").exists()


def test_diff_compares_the_two_modes(tmp_path):
    from rangesim.cli.main import main
    from rangesim.viz.scan_difference import depth_difference

    scene = facing_plane()
    geometric = rs.scan(scene, render_sensor(mode="geometric"), pose=FACING)
    shifted = rs.scan(scene, render_sensor(mode="geometric"), pose=FACING)
    shifted.depth = shifted.depth + 0.25
    shifted.valid[0, :5] = False
    difference, stats = depth_difference(geometric, shifted)
    assert np.allclose(difference[shifted.valid], 0.25) and np.isnan(difference[0, :5]).all()
    assert stats["only_a"] == 5 and stats["median_abs_mm"] == pytest.approx(0.25)
    rs.save_scan(geometric, tmp_path / "a.npz")
    rs.save_scan(rs.scan(scene, render_sensor(), pose=FACING), tmp_path / "b.npz")
    assert main(["diff", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "d.png")]) == 0
    assert (tmp_path / "d.png").stat().st_size > 0
    assert main(["diff", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "d.jpg")]) == 2
