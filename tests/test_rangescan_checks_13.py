"""RangeScan refuses values its dtypes cannot hold exactly (a plain cast wrapped or rounded
them silently), a meta that is not a dict, and a depth that is not 2-D; the writers re-run
the same checks on a scan whose fields were reassigned after construction."""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan, checked_scan


@pytest.fixture(scope="module")
def scan() -> RangeScan:
    return rs.datasets.plate_scan(width=32, height=30)


def _fields(scan: RangeScan, **changes: Any) -> dict[str, Any]:
    """The scan's constructor arguments, with ``changes`` applied."""
    return {**{f.name: getattr(scan, f.name) for f in dataclasses.fields(scan)}, **changes}


def _one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text, text
    return text


HW = (30, 32)
REFUSED = {
    "status of 300": ({"status": np.full(HW, 300)}, "RangeScan.status holds 300, outside the uint8 range 0..255"),
    "negative status": ({"status": np.full(HW, -1)}, "RangeScan.status holds -1, outside the uint8 range"),
    "NaN valid": ({"valid": np.full(HW, np.nan)}, "RangeScan.valid must hold booleans (or 0 / 1, or integers"),
    "valid of 0.5": ({"valid": np.full(HW, 0.5)}, "non-zero is True), found 0.5"),
    "part of 2**40": ({"part": np.full(HW, 2**40)}, "RangeScan.part holds 1099511627776, outside the int32 range"),
    "face of 0.5": ({"face": np.full(HW, 0.5)}, "RangeScan.face must hold integers, found 0.5"),
    "NaN part": ({"part": np.full(HW, np.nan)}, "RangeScan.part must hold integers, found nan"),
    "complex depth": ({"depth": np.zeros(HW, complex)}, "RangeScan.depth must hold real numbers, got dtype complex128"),
    "string intensity": ({"intensity": np.full(HW, "x")}, "RangeScan.intensity must hold real numbers"),
    "depth past float32": ({"depth": np.full(HW, 1e300)}, "RangeScan.depth holds 1e+300, beyond the float32 range"),
    "1-D depth": ({"depth": np.zeros(5)}, "RangeScan.depth must be a 2-D (H, W) array, got shape (5,)"),
    "None depth": ({"depth": None}, "RangeScan.depth must be a 2-D (H, W) array, got None"),
    "None xyz": ({"xyz": None}, "RangeScan.xyz is required, got None"),
    "3x3 pose": ({"pose": np.eye(3)}, "RangeScan.pose must be a 4x4 matrix, got shape (3, 3)"),
    "list meta": ({"meta": []}, "RangeScan.meta must be a dict, got list"),
    "string meta": ({"meta": "x"}, "RangeScan.meta must be a dict, got str"),
    "sensor not a table": ({"meta": {"sensor": "x"}}, "RangeScan.meta.sensor must be a table (dict), got str 'x'"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_values_the_dtypes_cannot_hold_are_refused(scan, case):
    changes, words = REFUSED[case]
    with pytest.raises(RangesimError) as info:
        RangeScan(**_fields(scan, **changes))
    assert words in _one_line(info), str(info.value)


def test_values_that_convert_exactly_are_accepted(scan):
    made = RangeScan(**_fields(
        scan,
        valid=scan.valid.astype(np.int64),  # 0 / 1
        status=scan.status.astype(np.int64),  # within 0..255
        part=scan.part.astype(np.float64),  # integral floats, -1 included
        face=scan.face.astype(np.int64),
        depth=scan.depth.astype(np.float64),
        intensity=scan.intensity.tolist(),
    ))
    for name in ("valid", "status", "part", "face", "depth", "intensity"):
        assert getattr(made, name).dtype == getattr(scan, name).dtype, name
        assert np.array_equal(getattr(made, name), getattr(scan, name), equal_nan=True), name
    # an OpenCV-style 0 / 255 uint8 mask: non-zero is valid
    mask255 = scan.valid.astype(np.uint8) * 255
    np.testing.assert_array_equal(RangeScan(**_fields(scan, valid=mask255)).valid, scan.valid)
    # float 0 / 1 in valid (as an EXR channel holds it) and bool labels still convert
    assert RangeScan(**_fields(scan, valid=scan.valid.astype(np.float32))).valid.dtype == np.bool_
    assert RangeScan(**_fields(scan, part=scan.valid)).part.max() == 1


def test_none_meta_is_an_empty_one(scan):
    made = RangeScan(**_fields(scan, meta=None))
    assert made.meta == {}
    assert "sensor='?'" in repr(made)
    rs.edges.gradient(made)  # crashed on meta.get before


def test_repr_survives_fields_reassigned_after_construction(scan):
    c = dataclasses.replace(scan)
    c.meta = {"sensor": "x"}
    assert repr(c) == f"RangeScan(30x32, valid={int(scan.valid.sum())}, sensor='?')"
    c.meta, c.depth = None, scan.depth.tolist()
    assert repr(c).startswith("RangeScan(30x32, ")


@pytest.mark.parametrize("suffix", [".exr", ".npz", ".ply"])
def test_writers_recheck_a_scan_changed_after_construction(scan, tmp_path, suffix):
    c = dataclasses.replace(scan)
    c.valid = np.ones((2, 2), bool)
    path = tmp_path / f"x{suffix}"
    with pytest.raises(RangesimError) as info:
        c.save(path)
    assert _one_line(info) == (f"{path}: cannot write the scan: RangeScan.valid has shape (2, 2), "
                               "expected (30, 32)")
    # rs.save_scan reaches the writer with a temporary name; the message names the final one
    c.status = np.full(HW, 300)
    c.valid = scan.valid
    with pytest.raises(RangesimError) as info:
        rs.save_scan(c, path)
    assert _one_line(info).startswith(f"{path}: cannot write the scan: RangeScan.status holds 300")
    assert list(tmp_path.iterdir()) == []  # no partial file, no temporary left behind


@pytest.mark.parametrize("suffix", [".exr", ".npz", ".ply"])
def test_writers_refuse_what_is_not_a_scan(tmp_path, suffix):
    with pytest.raises(TypeError, match=r"^can only write a RangeScan, got dict$"):
        rs.save_scan({"depth": 1}, tmp_path / f"y{suffix}")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".exr", ".npz"])
def test_reassigned_fields_that_convert_are_written_as_the_constructor_converts_them(scan, tmp_path, suffix):
    # every format stores what RangeScan(...) would have held: float64 depth rounded to
    # float32 in both (the EXR writer used to refuse it, the npz one to round it)
    c = dataclasses.replace(scan)
    c.depth = (scan.depth.astype(np.float64) + 1e-9).tolist()
    c.status = scan.status.astype(np.int64)
    back = rs.load_scan(c.save(tmp_path / f"z{suffix}"))
    expected = RangeScan(**_fields(c))
    assert np.array_equal(back.depth, expected.depth, equal_nan=True)
    assert back.depth.dtype == np.float32 and back.status.dtype == np.uint8
    assert np.array_equal(back.status, scan.status)
    assert isinstance(c.depth, list)  # saving does not convert the caller's scan in place


def test_checked_scan_leaves_conforming_arrays_uncopied(scan):
    again = checked_scan(scan)
    assert again is not scan and all(
        getattr(again, f.name) is getattr(scan, f.name) for f in dataclasses.fields(scan) if f.name != "pose"
    )


def test_a_saved_scan_round_trips_unchanged(scan, tmp_path: Path):
    back = rs.load_scan(scan.save(tmp_path / "plate.npz"))
    for f in dataclasses.fields(scan):
        a, b = getattr(scan, f.name), getattr(back, f.name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f.name
