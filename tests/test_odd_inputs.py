"""Odd but plausible inputs to the public API and the CLI: degenerate scans give correct, empty-ish
results; malformed arguments and files give a RangesimError naming the input (the CLI: one line,
exit code 2, no file left behind). Small synthetic inputs only; no Mitsuba scan but one tiny one."""
from __future__ import annotations

import os

import numpy as np
import pytest

import rangesim as rs
from rangesim.cli.main import main
from rangesim.core import RangeScan, RangesimError


def _scan(depth, f: float = 100.0, meta: bool = True) -> RangeScan:
    """A pinhole scan of a depth image (NaN, inf, zero and negative depths are invalid pixels)."""
    depth = np.asarray(depth, np.float64)
    h, w = depth.shape
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    valid = np.isfinite(depth) & (depth > 0)
    xyz = np.stack([(jj - w / 2) / f * depth, (ii - h / 2) / f * depth, depth], -1)
    xyz[~valid] = np.nan
    return RangeScan(depth=np.where(valid, depth, np.nan), xyz=xyz, valid=valid, normal=np.zeros((h, w, 3)),
                     intensity=np.ones((h, w)), part=np.zeros((h, w)), face=np.zeros((h, w)),
                     status=np.where(valid, 0, 1), meta={"K": [[f, 0, w / 2], [0, f, h / 2], [0, 0, 1]]} if meta else {})


# -- edge detectors on degenerate scans: correct results, never an exception ------------------------------------
DEGENERATE = {
    "all_nan": np.full((30, 40), np.nan),
    "no_positive_depth": np.full((30, 40), -5.0),
    "constant_plane": np.full((30, 40), 300.0),
    "1x40_plane": np.full((1, 40), 300.0),
    "40x1_plane": np.full((40, 1), 300.0),
    "3x3_plane": np.full((3, 3), 300.0),
    "2x2_plane": np.full((2, 2), 300.0),
    "1x1": np.full((1, 1), 300.0),
}


@pytest.mark.filterwarnings("ignore:pcl_organized")  # no valid pixel: no distance to decide PCL's rule on
@pytest.mark.parametrize("detector", sorted(rs.edges.DETECTORS))
@pytest.mark.parametrize("case", sorted(DEGENERATE))
def test_no_edges_on_empty_or_flat_scans(detector, case):
    edges = rs.edges.DETECTORS[detector](_scan(DEGENERATE[case]))
    assert edges.mask.shape == DEGENERATE[case].shape
    assert not edges.mask.any()


@pytest.mark.parametrize("detector", sorted(rs.edges.DETECTORS))
def test_a_few_valid_pixels_are_at_most_rims(detector):
    depth = np.full((30, 40), np.nan)
    depth[5, 5:8] = 300.0
    edges = rs.edges.DETECTORS[detector](_scan(depth))
    assert not (edges.mask & np.isnan(depth)).any()          # no edge where nothing was measured


@pytest.mark.filterwarnings("ignore:pcl_organized")  # without K: the constant-spacing rule, said in a warning
@pytest.mark.parametrize("detector", sorted(rs.edges.DETECTORS))
def test_a_plane_without_intrinsics_has_no_edges(detector):
    assert not rs.edges.DETECTORS[detector](_scan(np.full((30, 40), 300.0), meta=False)).mask.any()


# -- features: malformed edge maps and parameter ranges --------------------------------------------------------
@pytest.fixture(scope="module")
def plate():
    scan = rs.datasets.plate_scan({"noise.sigma_px": 0, "noise.speckle_contrast": 0})
    return scan, rs.edges.gradient(scan)


@pytest.mark.parametrize("finder", ["circles", "arcs", "circle_hypotheses", "lines", "ellipses"])
@pytest.mark.parametrize("mask", [np.zeros((30, 40), bool), np.ones((1, 1), bool), np.zeros((0, 0), bool)],
                         ids=["empty", "1x1", "0x0"])
def test_finders_on_empty_and_tiny_masks(finder, mask):
    assert getattr(rs.features, finder)(mask) == []


@pytest.mark.parametrize("finder", ["circles", "arcs", "circle_hypotheses", "lines", "ellipses"])
@pytest.mark.parametrize("mask", [np.ones(10, bool), np.ones((4, 4, 4), bool), None], ids=["1d", "3d", "None"])
def test_finders_refuse_what_is_no_edge_image(finder, mask):
    with pytest.raises(RangesimError, match=r"^edge_map: must be an EdgeMap or an \(H, W\) bool mask"):
        getattr(rs.features, finder)(mask)


@pytest.mark.parametrize("finder", ["circles", "arcs", "circle_hypotheses", "lines"])
def test_keep_of_another_shape(finder, plate):
    with pytest.raises(RangesimError, match=r"^keep: has shape \(3, 3\), the edge map \(120, 128\)"):
        getattr(rs.features, finder)(plate[1], keep=np.ones((3, 3), bool))


@pytest.mark.parametrize("finder", ["circles", "arcs", "circle_hypotheses"])
@pytest.mark.parametrize("radii", [(30, 5), (-5, 10), (5, np.inf), (np.nan, 10), (5,), 5, (1, 2, 3), ("a", 3)])
def test_bad_radius_ranges(finder, radii, plate):
    """Reversed, negative, infinite or malformed radius ranges were empty results or crashes
    (OverflowError on inf, IndexError on one number)."""
    with pytest.raises(RangesimError, match=r"^radii: must be two"):
        getattr(rs.features, finder)(plate[1], radii=radii)


def test_bad_axes_range(plate):
    with pytest.raises(RangesimError, match=r"^axes_range: must be two finite numbers 0 <= min <= max"):
        rs.features.ellipses(plate[1], plate[0], axes_range=(200, 4))


def test_lines_with_min_length_zero(plate):
    """min_length=0 made the Hough threshold 0 and every empty accumulator cell a 'peak', sorted first
    (negated unsigned counts): no segment at all instead of at least the plate's outline."""
    scan, edges = plate
    assert len(rs.features.lines(edges, min_length=0)) >= len(rs.features.lines(edges)) >= 4
    for name in ("min_length", "max_gap", "band_px"):
        with pytest.raises(RangesimError, match=f"^{name} must be a finite number >= 0"):
            rs.features.lines(edges, **{name: -1})


@pytest.mark.parametrize("finder", ["lines", "ellipses"])
def test_scan_of_another_size(finder, plate):
    with pytest.raises(RangesimError, match=r"^scan: is 20x20, the edge map 120x128"):
        getattr(rs.features, finder)(plate[1], _scan(np.full((20, 20), 300.0)))


def test_model_ellipses_need_intrinsics(plate):
    """A recorded scan without K and a scene: a ValueError deep in the projection before."""
    scan, edges = plate
    bare = _scan(np.full(scan.shape, 300.0), meta=False)
    with pytest.raises(RangesimError, match=r"^scan: has no camera intrinsics"):
        rs.features.ellipses(edges, bare, rs.datasets.plate_scene())


# -- scene files with values of the wrong type ------------------------------------------------------------------
BOX = '[[object]]\nprimitive = "box"\nsize = [10, 20, 30]\n'


@pytest.mark.parametrize(("text", "words"), [
    ("object = 5\n", "'object' must be [[object]] tables"),
    ("object = [1, 2]\n", "'object' must be [[object]] tables"),
    (BOX + 'rotate_deg = [0, "x", 0]\n', "[[object]] 0.rotate_deg must be numbers"),
    (BOX + "translate = {x = 1}\n", "[[object]] 0.translate must be numbers"),
    (BOX + 'scale = "big"\n', "[[object]] 0.scale must be numbers"),
    (BOX + 'albedo = "x"\n', "[[object]] 0.albedo must be numbers"),
    (BOX + "albedo = [0.5]\n", "[[object]] 0.albedo must be one number"),
    ('units = ["mm"]\n' + BOX, "unknown units ['mm']"),
    ('[[object]]\nmodel = ["green_piece"]\n', "unknown model ['green_piece']"),
    (BOX + 'view = 5\n', "unknown key(s) view"),
    ('view = 5\n' + BOX, "'view' must be a [view] table"),
    (BOX + '[view]\nposition = "up"\n', "view.position must be numbers"),
])
def test_scene_values_of_the_wrong_type(tmp_path, text, words):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(RangesimError) as info:
        rs.load_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and message.count(str(path)) == 1, message
    assert words in message


def test_toml_with_a_byte_order_mark_and_a_directory(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + BOX.encode())
    assert len(rs.load_scene(path).objects) == 1
    with pytest.raises(RangesimError, match="is a directory"):
        rs.load_sensor(tmp_path)


# -- files ------------------------------------------------------------------------------------------------------
def test_empty_scan_is_not_written_as_pcd(tmp_path):
    """A 0 x W scan made a PCD with HEIGHT 0 that no reader (ours included) takes back."""
    empty = _scan(np.zeros((0, 8)))
    with pytest.raises(RangesimError, match="cannot write an empty 0x8 scan as PCD"):
        empty.save(tmp_path / "empty.pcd")
    assert list(tmp_path.iterdir()) == []


# -- the command line -------------------------------------------------------------------------------------------
SENSOR = ('name = "tiny"\n[camera]\nwidth = 32\nheight = 24\nfov_deg = 40.0\n[laser]\nbaseline = 150.0\n'
          "[range]\nnear = 100.0\nfar = 1000.0\n")
SCENE = ('[[object]]\nprimitive = "box"\nsize = [50, 40, 20]\ntranslate = [0, 0, 10]\n'
         '[view]\nposition = [0, -180, 300]\nlook_at = [0, 0, 10]\n')


def test_scan_writes_the_documented_pcd(tmp_path, capsys):
    """README: `rangesim scan ... --out OUT.{exr,npz,ply,pcd}`; .pcd was refused by the CLI though
    RangeScan.save writes it."""
    (tmp_path / "s.toml").write_text(SENSOR)
    (tmp_path / "scene.toml").write_text(SCENE)
    out = tmp_path / "scan.pcd"
    assert main(["scan", str(tmp_path / "scene.toml"), "--sensor", str(tmp_path / "s.toml"), "--out", str(out)]) == 0
    back = rs.load_scan(out)
    assert back.shape == (24, 32) and back.valid.sum() > 0


def test_cli_scene_of_the_wrong_type(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(SENSOR)
    (tmp_path / "scene.toml").write_text(BOX + 'rotate_deg = [0, "x", 0]\n')
    out = tmp_path / "out" / "scan.exr"
    code = main(["scan", str(tmp_path / "scene.toml"), "--sensor", str(tmp_path / "s.toml"), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.splitlines()) == 1 and "scene.toml" in err and "rotate_deg" in err, err
    assert not out.parent.exists() or not any(out.parent.iterdir())


@pytest.mark.parametrize(("args", "words"), [
    (["scan", "x.toml", "--seed", "1e3", "--out", "x.exr"], "scan: argument --seed: invalid int value: '1e3'"),
    (["detect", "x.exr", "--method", "nope", "--out", "d"], "detect: argument --method: invalid choice: 'nope'"),
    (["scan"], "scan: the following arguments are required: SCENE_OR_MESH, --out"),
    (["nope"], "argument COMMAND: invalid choice: 'nope'"),
])
def test_usage_errors_are_one_line(args, words, capsys):
    """argparse printed its usage block over several lines before the error."""
    assert main(args) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("rangesim: error: ") and words in err, err
    assert "(see rangesim" in err


def test_detectors_refuse_what_is_not_a_scan_and_empty_or_odd_scans():
    for bad in (None, np.zeros((3, 3))):
        with pytest.raises(RangesimError, match="take a RangeScan"):
            rs.edges.gradient(bad)
    for detector in rs.edges.DETECTORS.values():
        with pytest.raises(RangesimError, match=r"non-empty \(H, W\) image, got shape \(0, 40\)"):
            detector(_scan(np.zeros((0, 40))))
    scan = _scan(np.full((30, 40), 300.0))
    scan.meta["K"] = "abc"
    with pytest.raises(RangesimError, match=r"meta\['K'\] must be a 3 x 3"):
        rs.edges.normal(scan)


def test_line_fit_skips_valid_pixels_without_a_finite_point():
    scan = rs.datasets.plate_scan({"noise.sigma_px": 0, "noise.speckle_contrast": 0})
    reference = rs.edges.line_fit(scan).mask
    creases = np.argwhere(reference & (rs.edges.line_fit(scan).labels != 1))
    r, c = creases[len(creases) // 2]  # an edge pixel of the reference
    scan.xyz[r, c] = np.nan  # depth stays finite and valid stays True: the point is unusable
    edges = rs.edges.line_fit(scan).mask
    assert not edges[r, c] and (edges != reference).sum() < 40


def test_detector_parameters_are_checked_before_any_work():
    scan = _scan(np.full((30, 40), 300.0))
    for k in (0, float("nan"), None):
        with pytest.raises(ValueError, match=r"k must be an integer in \[2, 64\], got"):
            rs.edges.line_fit(scan, k=k)
    with pytest.raises(ValueError, match="curvature_threshold must be two numbers"):
        rs.edges.pcl_organized(scan, curvature_threshold=(1,))
    plate = rs.datasets.plate_scan()
    one = rs.edges.pcl_organized(plate, edge_types="occluding")  # one type named alone
    assert one.params["edge_types"] == ["occluding"]
    assert one.mask.sum() == rs.edges.pcl_organized(plate, edge_types=("occluding",)).mask.sum() > 0
    with pytest.raises(RangesimError, match="with_params takes a mapping"):
        rs.load_sensor("kinect_v1").with_params(None)


def test_loaders_take_path_like_objects(tmp_path):
    rs.datasets.plate_scan().save(tmp_path / "plate.npz")
    (entry,) = [e for e in os.scandir(tmp_path) if e.name == "plate.npz"]
    assert rs.load_scan(entry).shape == rs.datasets.plate_scan().shape


def test_loaders_refuse_what_is_not_a_file_name():
    with pytest.raises(RangesimError, match="load_scan takes a file name, got NoneType"):
        rs.load_scan(None)
    with pytest.raises(RangesimError, match="load_scene takes a Scene, meshes or a file name, got int"):
        rs.load_scene(5)


def test_pcl_organized_on_a_scan_with_nothing_measured_gives_no_edges_and_no_warning():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        em = rs.edges.pcl_organized(_scan(np.full((30, 40), np.nan)))
    assert not em.mask.any()


def test_cli_features_takes_one_radius_as_the_api_does(tmp_path):
    scan_path = tmp_path / "plate.npz"
    rs.datasets.plate_scan().save(scan_path)
    assert main(["features", str(scan_path), "--rmin", "20", "--rmax", "20", "--out", str(tmp_path / "f")]) == 0
    assert (tmp_path / "f").is_dir()


# -- parameters of the curvature and pcl functions: RangesimError naming them, never garbage ---------
@pytest.mark.parametrize(("call", "words"), [
    (lambda s, m: rs.curvature.curvature_scan(s, max_dist=-1), "max_dist must be a finite distance > 0"),  # all NaN
    (lambda s, m: rs.curvature.curvature_scan(s, window=4), "window must be an odd whole number from 3 to 255"),
    (lambda s, m: rs.curvature.curvature_scan(s, min_points=2), "min_points must be"),
    (lambda s, m: rs.curvature.curvature_mesh(m, radius=-1), "radius must be a finite distance > 0"),  # all NaN
    (lambda s, m: rs.curvature.curvature_mesh(m, rings=0), "rings must be"),
    (lambda s, m: rs.curvature.hk_sign_map(np.zeros(3), np.zeros(4)), "shapes differ"),
    (lambda s, m: rs.curvature.surface_type_name(99), "no surface type 99"),  # was KeyError: 99
    (lambda s, m: rs.edges.pcl_organized(s, distance_mm="3"), "distance_mm must be a number"),  # was 3 mm
    (lambda s, m: rs.edges.pcl_organized(s, distance_mm=True), "distance_mm must be a number"),  # was 1 mm
    (lambda s, m: rs.features.ellipses(np.zeros((8, 8), bool), hypotheses="bogus"), "hypotheses must be"),
])
def test_analysis_parameters_are_refused_with_a_rangesim_error(call, words):
    import trimesh

    with pytest.raises(RangesimError, match=words):
        call(rs.datasets.plate_scan(width=32, height=30), trimesh.creation.icosphere(subdivisions=1))
