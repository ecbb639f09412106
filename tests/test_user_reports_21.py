"""A new user's black-box run over settings and data nobody tuned on (2026-12-05, second
session of the day): each test fails without its fix."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.cli.main import main


@pytest.fixture(scope="module")
def plate():
    return rs.datasets.plate_scan(width=64, height=60), rs.datasets.plate_scene()


# -- the scene a scan was made from, for every call that draws from the scene --------------------------
def test_feature_truth_and_model_guided_ellipses_refuse_another_scene(plate):
    """ground_truth_edges refused another scene; ground_truth_features and the model-guided
    ellipses drew that scene's features onto the scan (plausible recall and precision against
    the wrong part)."""
    scan, scene = plate
    other = rs.load_scene([trimesh.creation.box((60, 40, 10)), trimesh.creation.box((300, 300, 2))])
    with pytest.raises(rs.RangesimError, match="give the scene the scan was made from"):
        rs.evaluate.ground_truth_features(scan, other)
    edges = rs.edges.gradient(scan)
    with pytest.raises(rs.RangesimError, match="give the scene the scan was made from"):
        rs.features.ellipses(edges, scan, other)
    # its own scene as before: the hole's rim, predicted from the mesh's crease loop, is found
    assert set(rs.evaluate.ground_truth_features(scan, scene)) == {"circles", "segments"}
    assert len(rs.features.ellipses(edges, scan, scene)) >= 1


def test_another_scene_is_named_by_object_count(plate):
    scan, _ = plate
    two = rs.datasets.plate_scene()
    assert int(scan.part.max()) == 1 and len(two.objects) == 2
    one = rs.load_scene([two.objects[0].mesh])
    with pytest.raises(rs.RangesimError, match=r"object index 1 \(at least 2 objects\) but the scene has 1 object:"):
        rs.ground_truth_edges(scan, one)


# -- an empty scan's reason ----------------------------------------------------------------------------
def test_empty_scan_blames_coarse_pixels_not_units():
    """A 60 mm box under two pixels because each pixel spans 11 degrees: the message asked
    whether the scene was written in metres."""
    from rangesim.sensor._scan import EmptyScanWarning

    sensor = rs.load_sensor({"name": "coarse", "camera": {"width": 16, "height": 12, "fov_deg": 179.0},
                             "laser": {"baseline": 150.0}, "range": {"near": 100.0, "far": 1000.0}})
    box = trimesh.creation.box(extents=(60.0, 60.0, 60.0))
    with pytest.warns(EmptyScanWarning, match=r"only 104 mm across.*each pixel spans 11 degrees") as caught:
        rs.scan([box], sensor)
    assert not any("--units" in str(w.message) for w in caught)


# -- keys a mode does not read ------------------------------------------------------------------------
def test_laser_step_set_on_a_geometric_sensor_warns():
    """The geometric mode never reads laser.step (the rendered mode's frame spacing): a
    --set or a sweep over it gave bit-identical scans without a word. The presets carry it
    quietly, for a switch to the rendered mode."""
    from rangesim.sensor.config import UnusedSensorKeyWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ws = rs.load_sensor("white_scanner")          # its own step = 0.25: quiet
        assert ws.params["laser"]["step"] == 0.25
    with pytest.warns(UnusedSensorKeyWarning, match="geometric mode does not use laser.step"):
        ws.with_params({"laser.step": 1000.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ws.with_params({"noise.sigma_px": 0.2})     # a key it reads: quiet


# -- messages -------------------------------------------------------------------------------------------
def test_xyz_of_one_text_line_says_so(tmp_path, capsys):
    path = tmp_path / "words.xyz"
    path.write_text("a b c\n")
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert "line 1 'a b c', holds no number" in err and "Traceback" not in err


def test_machined_part_lists_seed_among_its_parameters():
    with pytest.raises(rs.RangesimError, match="known: seed, segments, length"):
        rs.cad.machined_part(0, bogus=1)


def test_detect_takes_tolerance_zero_as_the_library_does(tmp_path):
    """rs.evaluate.edge_scores documents a tolerance in [0, 64]; the CLI refused 0."""
    scan = rs.datasets.plate_scan(width=48, height=40)
    path = tmp_path / "plate.exr"
    scan.save(path)
    assert main(["detect", str(path), "--method", "gradient", "--tolerance", "0", "--out", str(tmp_path / "d")]) == 0
    assert (tmp_path / "d").is_dir()
    exact = rs.evaluate.score_edges(rs.edges.gradient(scan), scan, rs.datasets.plate_scene(), tolerance_px=0)
    assert np.isfinite(exact["f1"])


@pytest.mark.parametrize(("size_fp", "words"), [
    (1.05, r"only 0\.\d+ mm across.*--units m"),               # under two pixels, every hit measured
    (6.0, r"every hit was measured, but the scene covers only \d+ of the 76,800 pixels"),
])
def test_an_almost_empty_scan_of_measured_hits_says_why(size_fp, words):
    """A part of a few pixels whose hits are all measured fell through to the status branch,
    which said '0 of the 4 hits lie outside the working range'."""
    from rangesim.core.geometry import look_at
    from rangesim.sensor._scan import EmptyScanWarning

    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 320, "camera.height": 240})
    side = size_fp * 350.0 / sensor.focal_px
    with pytest.warns(EmptyScanWarning, match=words) as caught:
        scan = rs.scan([trimesh.creation.box(extents=(side, side, side))], sensor,
                       pose=look_at((0, 0, 350), (0, 0, 0), up=(0, 1, 0)))
    assert scan.valid.sum() >= 1
    assert not any("0 of the" in str(w.message) for w in caught)


def test_a_scene_behind_the_camera_is_said_to_be_behind_it():
    """A pose looking away from the part said the scene lay 2,000 mm away, beyond the working
    range; looking at it from as far, that is the reason."""
    from rangesim.sensor._scan import EmptyScanWarning

    sensor = rs.load_sensor("white_scanner").with_params({"camera.width": 32, "camera.height": 24})
    box = trimesh.creation.box(extents=(60.0, 60.0, 20.0))
    away = np.diag([1.0, -1.0, -1.0, 1.0])
    away[2, 3] = -2000.0                       # at z = -2000 mm, looking along -z: away from the box
    with pytest.warns(EmptyScanWarning, match="the scene lies behind the camera"):
        rs.scan([box], sensor, pose=away)
    towards = away.copy()
    towards[2, 3] = 2000.0                     # at z = +2000 mm, looking along -z: at the box
    with pytest.warns(EmptyScanWarning, match="beyond the end of white_scanner's working range"):
        rs.scan([box], sensor, pose=towards)
