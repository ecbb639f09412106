"""The edge detectors and ``link`` refuse malformed scans and parameters with a RangesimError
naming the culprit (never an IndexError, a broadcasting error, a crash in a compiled kernel, or
a silently wrong edge map)."""
from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError

DETECTORS = sorted(rs.edges.DETECTORS)


@pytest.fixture(scope="module")
def plate():
    return rs.datasets.plate_scan({"noise.sigma_px": 0, "noise.speckle_contrast": 0})


def _assign(scan, fields):
    """A copy with fields reassigned after construction (RangeScan checks shapes only in __init__)."""
    out = dataclasses.replace(scan)
    for k, v in fields.items():
        setattr(out, k, v)
    return out


# -- 1. per-pixel fields of the wrong shape or dtype ----------------------------------------------------------
def test_two_component_points_do_not_crash_the_normal_kernel():
    """Used to abort the process (malloc(): corrupted top size) in the compiled WENO blend."""
    code = ("import rangesim as rs\n"
            "p = rs.datasets.plate_scan({'noise.sigma_px': 0, 'noise.speckle_contrast': 0})\n"
            "p.xyz = p.xyz[..., :2]\n"
            "try:\n    rs.edges.normal(p)\nexcept rs.RangesimError as e:\n    print('refused:', e)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-500:]
    assert "refused: scan.xyz" in run.stdout and "(120, 128, 2)" in run.stdout


@pytest.mark.parametrize("detector", DETECTORS)
@pytest.mark.parametrize("field", ["xyz2", "xyzT", "valid", "sigma", "status", "xyz_text"])
def test_misshapen_fields_are_refused_by_name(plate, detector, field):
    h, w = plate.shape
    bad = {
        "xyz2": ("xyz", plate.xyz[..., :2]),
        "xyzT": ("xyz", np.ascontiguousarray(plate.xyz.transpose(1, 0, 2))),
        "valid": ("valid", plate.valid[:-1]),
        "sigma": ("sigma", plate.sigma[:, :-1]),
        "status": ("status", plate.status[:-1]),
        "xyz_text": ("xyz", plate.xyz.astype(str)),
    }[field]
    with pytest.raises(RangesimError, match=f"scan.{bad[0]}"):
        rs.edges.DETECTORS[detector](_assign(plate, {bad[0]: bad[1]}))


def test_the_weno_kernel_refuses_points_of_another_shape():
    from rangesim.edges._differences import eno_tangent
    with pytest.raises(ValueError, match=r"\(3, H, W\)"):
        eno_tangent(np.zeros((2, 5, 6), np.float32), 0, None)


# -- 2. parameters ----------------------------------------------------------------------------------------------
BAD_PARAMS = [
    ("gradient", {"threshold": -5}), ("gradient", {"threshold": np.nan}), ("gradient", {"threshold": "5"}),
    ("gradient", {"jump_threshold": -1}), ("gradient", {"jump_threshold": 0}), ("gradient", {"sigma": -1}),
    ("gradient", {"max_search": -1}), ("gradient", {"jump_clearance": -3}), ("gradient", {"stride": 0}),
    ("gradient", {"nms": "no"}),
    ("pcl_organized", {"depth_discontinuity": -1}), ("pcl_organized", {"depth_discontinuity": 0}),
    ("pcl_organized", {"max_search": 2.5}), ("pcl_organized", {"normal_window": 4}),
    ("pcl_organized", {"distance_mm": "x"}), ("pcl_organized", {"distance_mm": np.inf}),
    ("curvature", {"threshold": -1}), ("curvature", {"window": 4}), ("curvature", {"rule": "x"}),
    ("line_fit", {"angle_tol_deg": -1}), ("line_fit", {"min_crease_px": -1}), ("line_fit", {"max_stride": 0}),
    ("line_fit", {"line_sep_deg": 0}), ("line_fit", {"workers": 0}), ("line_fit", {"k": 2.5}),
    ("normal", {"threshold_deg": -1}), ("normal", {"threshold_deg": np.inf}), ("normal", {"jump_threshold": np.nan}),
    ("normal", {"window": 4}), ("normal", {"blocks": "yes"}),
]


@pytest.mark.parametrize("detector, params", BAD_PARAMS, ids=[f"{d}-{next(iter(p))}={next(iter(p.values()))!r}"
                                                              for d, p in BAD_PARAMS])
def test_bad_parameters_are_refused_by_name(plate, detector, params):
    (name, value), = params.items()
    with pytest.raises(RangesimError, match=f"{name} must be") as err:
        rs.edges.DETECTORS[detector](plate, **params)
    assert repr(value)[:10] in str(err.value)


def test_documented_special_values_are_kept(plate):
    # 0: off / none / only direct neighbours, as the docstrings say; 1 keeps every crease piece
    rs.edges.gradient(plate, sigma=0, max_search=0, jump_clearance=0, stride=1)
    rs.edges.line_fit(plate, min_crease_px=1, max_stride=1, jump_clearance=0, workers=-1, k=8.0)
    rs.edges.normal(plate, window=3, threshold_deg=20, max_search=0)
    rs.edges.curvature(plate, window=5, threshold=0.05)
    rs.edges.pcl_organized(plate, curvature_threshold=(0, 0), depth_discontinuity=0.02)


def test_point_list_parameters_are_checked():
    pts = np.random.default_rng(0).normal(size=(50, 3))
    with pytest.raises(RangesimError, match="angle_tol_deg"):
        rs.edges.line_fit_points(pts, angle_tol_deg=np.full(50, -1.0))
    with pytest.raises(RangesimError, match="line_sep_deg"):
        rs.edges.line_fit(pts, line_sep_deg=np.nan)


# -- 3. depth behind a pinhole camera, infinite depth ------------------------------------------------------------
@pytest.mark.parametrize("detector", DETECTORS)
def test_valid_pixels_behind_the_camera_are_refused(plate, detector):
    flipped = _assign(plate, {"depth": -plate.depth, "xyz": plate.xyz * np.array([1, 1, -1], np.float32)})
    with pytest.raises(RangesimError, match=f"{int(plate.valid.sum())} pixels marked valid have a depth <= 0"):
        rs.edges.DETECTORS[detector](flipped)


@pytest.mark.parametrize("detector", DETECTORS)
def test_infinite_depth_on_valid_pixels_is_refused(plate, detector):
    depth = plate.depth.copy()
    depth[plate.valid.nonzero()[0][:7], plate.valid.nonzero()[1][:7]] = np.inf
    with pytest.raises(RangesimError, match="7 pixels marked valid have an infinite depth"):
        rs.edges.DETECTORS[detector](_assign(plate, {"depth": depth}))


@pytest.mark.filterwarnings("ignore:pcl_organized")
def test_a_centred_range_axis_without_a_camera_model_is_still_accepted(plate):
    """A grid in a scanner frame (no meta['K']: the Cyberware's) may have depths on both sides of 0."""
    xyz = plate.xyz.copy()
    xyz[..., 2] -= np.float32(np.nanmedian(plate.depth))
    moved = _assign(plate, {"xyz": xyz, "depth": xyz[..., 2].copy(),
                            "meta": {k: v for k, v in plate.meta.items() if k != "K"}})
    assert np.nanmin(moved.depth) < 0 < np.nanmax(moved.depth)
    for detector in DETECTORS:
        rs.edges.DETECTORS[detector](moved)


# -- 4. link ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["1d", "3d", "none", "text"])
def test_link_refuses_what_is_not_an_edge_image(plate, case):
    mask = rs.edges.gradient(plate).mask
    edge_map = {"1d": mask[0], "3d": mask[None], "none": None, "text": mask.astype(str)}[case]
    with pytest.raises(RangesimError, match="edge_map: must be an EdgeMap or an \\(H, W\\)"):
        rs.edges.link(edge_map)


@pytest.mark.parametrize("params", [{"min_length": "x"}, {"min_length": np.nan}, {"min_length": -1},
                                    {"max_gap": -1}, {"max_gap": np.nan}, {"thin": "no"}])
def test_link_refuses_bad_parameters(plate, params):
    (name, _), = params.items()
    with pytest.raises(RangesimError, match=f"{name} must be"):
        rs.edges.link(rs.edges.gradient(plate), **params)


def test_link_reads_nan_as_no_edge():
    a = np.zeros((9, 9))
    a[4, 1:8] = 1.0
    b = a.copy()
    b[0, 0:5] = np.nan          # a run long enough to be a chain, were NaN an edge
    for min_length in (1, 3):
        assert ([c.points.tolist() for c in rs.edges.link(a, min_length=min_length)]
                == [c.points.tolist() for c in rs.edges.link(b, min_length=min_length)])
