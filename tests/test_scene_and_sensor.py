"""Scene files, sensor presets and their validation errors."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import look_at
from tests.conftest import make_sensor

REPO = Path(__file__).resolve().parents[1]


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["white_scanner", "cyberware_3030", "inria_laser"])
def test_presets_load_with_documented_keys(name):
    sensor = rs.load_sensor(name)
    assert sensor.name == name
    assert sensor.params["laser"]["sweep"] in ("rotating", "translating")
    K = sensor.K
    assert K[0, 2] == sensor.width / 2 and K[1, 2] == sensor.height / 2
    assert rs.load_sensor(sensor.to_dict()).params == sensor.params


def test_cyberware_preset_matches_the_stanford_grid():
    sensor = rs.load_sensor("cyberware_3030")
    assert (sensor.width, sensor.height) == (512, 400)
    assert sensor.params["laser"]["sweep"] == "translating" and sensor.params["laser"]["step"] == 0.5


@pytest.mark.parametrize(
    "change, message",
    [
        ({"camera.width": 0}, "camera.width must be positive"),
        ({"camera.height": -5}, "camera.height must be positive"),
        ({"laser.baseline": 0.0}, "laser.baseline must be positive"),
        ({"range.near": 500.0, "range.far": 400.0}, "must be less than range.far"),
        ({"range.near": 400.0, "range.far": 400.0}, "must be less than range.far"),
        ({"laser.sweep": "wobbling"}, "laser.sweep must be one of"),
        ({"noise.sigma_px": float("nan")}, "must be finite"),
        ({"laser.basline": 10.0}, "unknown key(s) basline"),
    ],
)
def test_bad_sensor_values_raise_one_line_errors(change, message):
    with pytest.raises(rs.RangesimError) as err:
        make_sensor(**change)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_unknown_preset_lists_the_available_ones():
    with pytest.raises(rs.RangesimError, match="unknown sensor preset.*white_scanner"):
        rs.load_sensor("no_such_scanner")


def test_sensor_toml_file_and_error_names_the_file(tmp_path):
    good = write(tmp_path / "mine.toml", """
[camera]
width = 32
height = 24
fov_deg = 30
[laser]
baseline = 100
[range]
near = 100
far = 500
""")
    assert rs.load_sensor(good).name == "mine"
    bad = write(tmp_path / "bad.toml", "[camera]\nwidth = 32\nheight = 24\nfov_deg = 30\n[laser]\nbaseline = 1\n")
    with pytest.raises(rs.RangesimError, match=r"bad\.toml: missing required key range\.near"):
        rs.load_sensor(bad)
    broken = write(tmp_path / "broken.toml", "[camera\nwidth = ")
    with pytest.raises(rs.RangesimError, match="broken.toml: invalid TOML"):
        rs.load_sensor(broken)


def test_scene_file_units_transforms_and_view(tmp_path):
    trimesh.creation.box(extents=[0.1, 0.1, 0.1]).export(tmp_path / "cube_m.stl")
    scene_file = write(tmp_path / "s.toml", """
units = "cm"
[[object]]
name = "cube"
mesh = "cube_m.stl"
units = "m"
translate = [1, 2, 3]
rotate_deg = [0, 0, 45]
albedo = 0.9
[[object]]
primitive = "sphere"
radius = 2
[view]
position = [0, -30, 40]
look_at = [0, 0, 0]
""")
    scene = rs.load_scene(scene_file)
    cube, sphere = scene.objects
    assert cube.name == "cube" and cube.albedo == 0.9 and cube.watertight
    # 0.1 m cube = 100 mm, rotated 45 degrees about z, centred at (10, 20, 30) mm
    np.testing.assert_allclose(cube.mesh.bounds.mean(axis=0), [10, 20, 30], atol=1e-5)
    np.testing.assert_allclose(np.ptp(cube.mesh.vertices[:, 0]), 100 * np.sqrt(2), rtol=1e-6)  # STL stores float32
    np.testing.assert_allclose(np.linalg.norm(sphere.mesh.vertices, axis=1), 20.0, rtol=1e-9)
    np.testing.assert_allclose(scene.view[:3, 3], [0, -300, 400])
    np.testing.assert_allclose(scene.view[:3, 2], [0, 0.6, -0.8])  # looks at the origin


@pytest.mark.parametrize(
    "content, message",
    [
        ("", "no such mesh file"),
        ("solid empty\nendsolid empty\n", "mesh"),
        ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "NaN or infinite"),
    ],
)
def test_bad_meshes_raise_one_line_errors(tmp_path, content, message):
    name = "part.stl" if content.startswith("solid") else "part.obj"
    path = tmp_path / name
    if content:
        path.write_text(content)
    with pytest.raises(rs.RangesimError) as err:
        rs.load_scene(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_scene_errors_name_the_file(tmp_path):
    missing = write(tmp_path / "m.toml", '[[object]]\nmesh = "nowhere.stl"\n')
    with pytest.raises(rs.RangesimError, match="nowhere.stl: no such mesh file"):
        rs.load_scene(missing)
    typo = write(tmp_path / "t.toml", '[[object]]\nprimitive = "box"\nsize = [1, 1, 1]\nalbedoo = 1\n')
    with pytest.raises(rs.RangesimError, match="t.toml: unknown key.*albedoo"):
        rs.load_scene(typo)
    with pytest.raises(rs.RangesimError, match="no such scene"):
        rs.load_scene(tmp_path / "nothing.xyz")


def test_default_pose_frames_a_scene_without_view():
    mesh = trimesh.creation.icosphere(radius=40.0)
    sensor = make_sensor(**{"range.near": 200.0, "range.far": 600.0})
    scan = rs.scan(mesh, sensor)
    # the whole object is seen, inside the working range, not touching the border
    assert scan.valid.sum() > 0.2 * scan.valid.size
    seen = scan.status != Status.MISS
    assert not seen[0].any() and not seen[-1].any() and not seen[:, 0].any() and not seen[:, -1].any()
    assert (scan.status != Status.OUT_OF_RANGE).all()


def test_scene_mesh_paths_can_name_the_shared_data(data_dir, monkeypatch, tmp_path):
    monkeypatch.setenv("RANGESIM_DATA", str(data_dir))
    scene = rs.load_scene(REPO / "scenes" / "flat_target.toml")
    target = scene.objects[0]
    # 150 x 150 x 10 mm, turned over and centred by the scene file
    np.testing.assert_allclose(target.mesh.bounds, [[-75, -75, 0], [75, 75, 10]], atol=1e-6)
    monkeypatch.setenv("RANGESIM_DATA", str(tmp_path / "nowhere"))
    with pytest.raises(rs.RangesimError, match="no such mesh file"):
        rs.load_scene(REPO / "scenes" / "flat_target.toml")


@pytest.mark.parametrize(("change", "words"), [
    ((3, slice(None), [5.0, 5.0, 5.0, 5.0]), "bottom row 0 0 0 1"),  # once scanned with 280 dropouts
    ((3, 2, 1e-3), "bottom row 0 0 0 1"),
    ((0, 0, 2.0), "orthonormal"),
    ((0, 0, -1.0), "right-handed"),
    ((1, 3, np.nan), "finite 4x4"),
])
def test_scan_refuses_a_pose_that_is_no_rigid_transform(change, words):
    from rangesim.core.geometry import check_pose

    pose = look_at((0, -180, 300), (0, 0, 10))
    check_pose(pose)  # a camera pose from look_at is rigid
    row, col, value = change
    pose[row, col] = value
    with pytest.raises(RangesimError, match=words):
        rs.scan(rs.datasets.plate_scene(), "white_scanner", pose=pose)


def test_a_pose_written_with_a_few_decimals_is_taken_as_the_nearest_rotation():
    """A rotation rounded to 4 decimals (a pose file, a calibration's output; the shared data's
    shapes_pose.json is 7e-4 off orthonormal) was refused at 1e-6; it is now snapped to the
    nearest rotation (polar decomposition), which moves it by the rounding's order, and scans
    as the exact pose does to within the rounding. A block 0.01 off is still refused, naming
    the deviation."""
    from rangesim.core.geometry import POSE_ORTHONORMAL_TOL, check_pose

    exact = look_at((30, -180, 300), (0, 0, 10))
    rounded = np.round(exact, 4)
    off = np.abs(rounded[:3, :3].T @ rounded[:3, :3] - np.eye(3)).max()
    assert 1e-6 < off < POSE_ORTHONORMAL_TOL
    snapped = check_pose(rounded)
    np.testing.assert_allclose(snapped[:3, :3].T @ snapped[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(snapped[:3, :3]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(snapped, exact, atol=2e-4)
    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 64, "camera.height": 48})
    a = rs.scan(rs.datasets.plate_scene(), sensor, pose=exact, seed=0)
    b = rs.scan(rs.datasets.plate_scene(), sensor, pose=rounded, seed=0)
    assert abs(int(a.valid.sum()) - int(b.valid.sum())) <= 2
    both = a.valid & b.valid
    assert np.nanmedian(np.abs(a.depth[both] - b.depth[both])) < 0.1
    skewed = exact.copy()
    skewed[:3, :3] *= 1.01
    with pytest.raises(RangesimError, match=r"differs from the identity by up to 0\.02"):
        check_pose(skewed)


def test_a_default_view_that_crops_the_scene_says_so():
    """Without a pose the camera frames the scene's bounding sphere in 90 % of the narrower
    field, inside the working range: a part too large for that (a 300 mm box for white_scanner,
    whose range ends at 450 mm) was cropped without a word (a new-user review: the bunny in
    metres). The sphere fits iff radius <= distance sin(narrow / 2)."""
    import math
    import warnings

    from rangesim.sensor._scan import default_pose

    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 64, "camera.height": 60})
    big = rs.load_scene(trimesh.creation.box((300, 300, 50)))
    with pytest.warns(UserWarning, match=r"fits the view from \d+ mm away \(its centre\), which puts its far side past the working range \(250-450 mm\)"):
        pose = default_pose(big, sensor)
    distance = np.linalg.norm(pose[:3, 3] - big.bounds.mean(axis=0))
    narrow = 2 * math.atan(math.tan(math.radians(22.0) / 2) * 60 / 64)
    assert big.bounding_radius > distance * math.sin(narrow / 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        default_pose(rs.load_scene(trimesh.creation.box((60, 40, 10))), sensor)


def test_scene_objects_with_one_name_are_refused(tmp_path):
    from rangesim.experiments.scenes import apply_object_overrides
    from rangesim.experiments.sweep_file import load_sweep

    path = tmp_path / "dup.toml"
    path.write_text('[[object]]\nname = "a"\nprimitive = "box"\nsize = [10, 10, 10]\n\n'
                    '[[object]]\nname = "a"\nprimitive = "plane"\nsize = [100, 100]\n')
    with pytest.raises(RangesimError, match="both named 'a'"):
        rs.load_scene(path)
    # a sweep's override of object "a" once changed only the second one
    with pytest.raises(RangesimError, match="both named 'a'"):
        apply_object_overrides(path, {"a": {"albedo": 0.1}})
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('scenes = ["dup.toml"]\n[grid]\n"noise.sigma_px" = [0, 0.2]\n')
    with pytest.raises(RangesimError, match="sweep.toml: scenes: .*both named 'a'"):  # when loaded, before any scan
        load_sweep(sweep)


def test_scene_objects_from_a_users_probe(tmp_path):
    """A model keeps its millimetres in a cm or inch scene (it came out 10x / 25.4x too big),
    model params get the checks --param gets, primitive tessellation keys are checked, and a
    geometry key of another kind is refused (it was ignored)."""
    def write(body):
        path = tmp_path / "s.toml"
        path.write_text(body)
        return path

    mm = rs.load_scene(write('units = "mm"\n[[object]]\nmodel = "green_piece"\n')).objects[0].mesh.extents
    for unit in ("cm", "in"):
        ext = rs.load_scene(write(f'units = "{unit}"\n[[object]]\nmodel = "green_piece"\ntranslate = [1, 0, 0]\n'
                                  )).objects[0].mesh.extents
        np.testing.assert_allclose(ext, mm, rtol=1e-9)
    bad = {
        '[[object]]\nmodel = "green_piece"\nparams = {segments = 0}\n': r"\[\[object\]\] 0\.params: segments must lie in 3\.\.",
        '[[object]]\nmodel = "green_piece"\nparams = {segments = 2.5}\n': r"params: segments must be an integer",
        '[[object]]\nprimitive = "cylinder"\nradius = 1\nheight = 2\nsections = 2\n': r"sections' must be a whole number in 3\.\.",
        '[[object]]\nprimitive = "cylinder"\nradius = 1\nheight = 2\nsections = "many"\n': r"sections' must be a whole",
        '[[object]]\nprimitive = "cylinder"\nradius = [1, 2]\nheight = 2\n': r"\[\[object\]\] 0 \(object0\): primitive 'radius' must be one number",
        '[[object]]\nprimitive = "sphere"\nradius = 1\nsubdivisions = 40\n': r"subdivisions' must be a whole number in 0\.\.8",
        '[[object]]\nprimitive = "sphere"\nradius = 1\nsubdivisions = -1\n': r"subdivisions' must be a whole number",
        '[[object]]\nprimitive = "sphere"\nradius = 1\nsize = [1, 1, 1]\n': r"size does not apply to a sphere",
        '[[object]]\nprimitive = "box"\nsize = [1, 1, 1]\nradius = 3\n': r"radius does not apply to a box",
        '[[object]]\nmodel = "green_piece"\nsize = [1, 1, 1]\n': r"size does not apply to a model",
    }
    for body, message in bad.items():
        with pytest.raises(rs.RangesimError, match=message) as info:
            rs.load_scene(write(body))
        assert "\n" not in str(info.value)
