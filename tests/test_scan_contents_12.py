"""Scan files whose contents are broken in ways the readers let through (an independent probe):
refused at load, in one line naming the file and the problem; ``rangesim info`` exits 2."""
from __future__ import annotations

import json

import numpy as np
import pytest

import rangesim as rs
from rangesim.cli.main import main


def _edited(tmp_path, edit):
    """The plate scan saved as .npz with its arrays changed by ``edit(arrays, meta)``."""
    good = tmp_path / "good.npz"
    rs.datasets.plate_scan().save(good)
    with np.load(good) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays["meta"]))
    edit(arrays, meta)
    arrays["meta"] = np.str_(json.dumps(meta))
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    return path


def _nan_xyz(a, m):
    xyz = a["xyz"].copy()
    xyz[np.nonzero(a["valid"])[0][0], np.nonzero(a["valid"])[1][0]] = np.nan
    a["xyz"] = xyz


CASES = {
    "sensor not a table": (lambda a, m: m.update(sensor="nope"), "meta.sensor must be a table"),
    "units in parsecs": (lambda a, m: m.update(units="parsec"), "meta.units is 'parsec'"),
    "NaN pose": (lambda a, m: a.update(pose=np.full((4, 4), np.nan)), "pose holds NaN"),
    "zero pose": (lambda a, m: a.update(pose=np.zeros((4, 4))), "singular rotation block"),
    "zero focal length": (lambda a, m: m.update(K=[[0, 0, 1], [0, 0, 1], [0, 0, 1]]), "positive focal"),
    "K of the wrong shape": (lambda a, m: m.update(K=[1, 2, 3]), "3x3"),
    "NaN point at a valid pixel": (_nan_xyz, "1 valid pixels have NaN"),
    "complex depth": (lambda a, m: a.update(depth=a["depth"].astype(np.complex64)), "depth must hold real numbers"),
    "valid of 0.5": (lambda a, m: a.update(valid=np.full(a["valid"].shape, 0.5)), "valid must hold booleans"),
    "status as floats": (lambda a, m: a.update(status=a["status"] + 0.5), "status must hold integers"),
    "format version -1": (lambda a, m: a.update(rangesim_format_version=np.int64(-1)), "versions start at 1"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_broken_contents_are_refused_at_load(tmp_path, capsys, case):
    edit, words = CASES[case]
    path = _edited(tmp_path, edit)
    with pytest.raises(rs.RangesimError) as info:
        rs.load_scan(path)
    assert str(info.value).startswith(f"{path}: ") and words in str(info.value), str(info.value)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "internal error" not in err[0]


def test_the_unedited_file_loads(tmp_path):
    path = _edited(tmp_path, lambda a, m: None)
    scan = rs.load_scan(path)
    assert scan.valid.any() and np.isfinite(scan.pose).all()


@pytest.mark.parametrize(("lines", "words"), [
    ("bmesh s.ply 0 0 0 0 0 0 1\nbmesh s.ply 0.1 0 0 0 0 0 1\n", "line 3: a second bmesh line for s.ply"),
    ("bmesh s.ply 1e308 0 0 0 0 0 1\n", "line 2: the translation is out of range"),
])
def test_conf_files_that_place_a_scan_two_ways_or_nowhere_are_refused(tmp_path, lines, words):
    from rangesim.recorded.conf import read_conf

    conf = tmp_path / "s.conf"
    conf.write_text("camera 0 0 0 0 0 0 1\n" + lines)
    with pytest.raises(rs.RangesimError, match=words):
        read_conf(conf)
    conf.write_text("bmesh s.ply 0 0 0 0 0 0 1\nbmesh s.ply 0 0 0 0 0 0 1\n")  # the same line twice: fine
    assert np.allclose(read_conf(conf)["s.ply"], np.eye(4))
