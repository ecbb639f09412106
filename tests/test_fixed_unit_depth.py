"""Depth rounded to a fixed unit (uint16 millimetres as a Kinect v2, a RealSense or an Azure
Kinect writes them; float16 storage) is quantised depth: :func:`depth_quantum` finds the
unit, and the detectors see its steps for what they are, a rounding error of std
``q / sqrt(12)`` mm per pixel, not creases.

The case that failed: a simulated scan rounded afterwards keeps the noise model's ``sigma``
of the depth before the rounding (0.035 mm on the noise-free plate), which the detectors
took for the noise, so that steps of one quantum read as creases everywhere (noise-free
plate, 1 mm: line_fit 254 -> 3000 edge pixels, curvature 249 -> 4959; 0.25 mm: gradient
410 -> 3758). The noise estimate now adds the rounding's variance to ``sigma``
(:func:`rangesim.edges._noise.quantised_sigma`).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.quantisation import depth_quantum
from rangesim.edges._noise import estimate_depth_noise, stride_gain
from rangesim.edges._scan_access import pixel_geometry, scan_depth

QUIET = {"noise.sigma_px": 0, "noise.speckle_contrast": 0}
#: F1 against the truth at most this much below the unrounded scan's (measured: at most
#: 0.03 below, line_fit on the noisy plate at 1 mm 0.892 against 0.910)
F1_MARGIN = 0.05
#: edge pixels at most this many times the unrounded scan's (measured: at most 1.15,
#: line_fit on the noisy plate at 1 mm, 291 against 253)
COUNT_RATIO = 1.3


def _rounded(scan, unit):
    """``scan`` with its depth rounded to ``unit`` mm ("f16": stored as float16), the points
    moved along their rays; ``sigma`` (the model's, for the depth before rounding) kept."""
    if unit == "f16":
        zq = scan.depth.astype(np.float16).astype(scan.depth.dtype)
    else:
        zq = (np.round(scan.depth / unit) * unit).astype(scan.depth.dtype)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = zq / scan.depth
    return dataclasses.replace(scan, depth=zq, xyz=scan.xyz * ratio[..., None])


@pytest.fixture(scope="module")
def plates():
    """name -> (scan, truth) for the plate noise-free and with the preset's noise."""
    scene = rs.datasets.plate_scene()
    out = {}
    for name, params in (("quiet", QUIET), ("noisy", None)):
        scan = rs.datasets.plate_scan(params)
        out[name] = (scan, rs.evaluate.visible_truth(scan, scene))
    return out


@pytest.mark.parametrize("unit", [0.25, 1.0])
def test_depth_quantum_is_the_unit(plates, unit):
    scan, _ = plates["quiet"]
    q = depth_quantum(_rounded(scan, unit).depth)
    assert q is not None
    assert np.nanmedian(q) == pytest.approx(unit, rel=0.1)
    assert depth_quantum(scan.depth) is None
    assert depth_quantum(plates["noisy"][0].depth) is None


def test_float16_depth_quantum_doubles_with_each_octave():
    """float16 spacing: 0.25 mm over 256-512 mm, 0.5 mm over 512-1024 mm."""
    y, x = np.mgrid[0:300, 0:400]
    z = (400 + 0.8 * x + 0.1 * y + 0.05 * np.sin(0.3 * x)).astype(np.float32)
    assert depth_quantum(z) is None
    q = depth_quantum(z.astype(np.float16).astype(np.float32))
    assert q is not None
    assert np.allclose(q[:, :100], 0.25) and np.allclose(q[:, 150:], 0.5)


@pytest.mark.parametrize("name,unit", [("quiet", 0.25), ("quiet", 1.0), ("quiet", "f16"), ("noisy", 1.0)])
def test_rounded_scan_noise_takes_the_rounding(plates, name, unit):
    """sqrt(sigma^2 + q^2 / 12) over the footprint: the rounding's variance on top of the
    model's (Sheppard); with the preset's noise the data's own second differences agree
    within 5 % (noise-free they see less of it: the rounding's sawtooth along a slanted face
    is correlated over each terrace)."""
    scan, _ = plates[name]
    rounded = _rounded(scan, unit)
    q = 0.25 if unit == "f16" else unit
    z, _ = scan_depth(rounded)
    fp = pixel_geometry(rounded, z).footprint
    model = np.nanmedian(np.sqrt(scan.sigma ** 2 + q * q / 12.0) / fp)
    got = estimate_depth_noise(rounded)
    assert got == pytest.approx(model, rel=0.05)
    if name == "noisy":
        measured = estimate_depth_noise(dataclasses.replace(rounded, sigma=None))
        assert measured == pytest.approx(got, rel=0.05)


@pytest.mark.parametrize("name,unit", [("quiet", 0.25), ("quiet", 1.0), ("noisy", 1.0)])
@pytest.mark.parametrize("method", sorted(rs.edges.DETECTORS))
def test_detectors_on_rounded_depth_as_on_the_scan(plates, name, unit, method):
    scan, truth = plates[name]
    detector = rs.edges.DETECTORS[method]
    ref, em = detector(scan), detector(_rounded(scan, unit))
    f1_ref = rs.evaluate.score_edges(ref, scan, truth=truth)["f1"]
    f1 = rs.evaluate.score_edges(em, _rounded(scan, unit), truth=truth)["f1"]
    assert f1 >= f1_ref - F1_MARGIN, (method, f1, f1_ref)
    assert em.mask.sum() <= COUNT_RATIO * ref.mask.sum(), (method, int(em.mask.sum()), int(ref.mask.sum()))


def test_recorded_rounded_depth_without_sigma(plates):
    """A recording carries no sigma: the noise is measured on the rounded depth itself."""
    scan, truth = plates["quiet"]
    rounded = dataclasses.replace(_rounded(scan, 1.0), sigma=None)
    for method, detector in rs.edges.DETECTORS.items():
        ref = rs.evaluate.score_edges(detector(scan), scan, truth=truth)["f1"]
        assert rs.evaluate.score_edges(detector(rounded), rounded, truth=truth)["f1"] >= ref - F1_MARGIN, method


@pytest.mark.parametrize("unit", [0.25, 1.0])
def test_stride_gain_falls_on_rounded_depth(plates, unit):
    """Most lag-1 second differences of rounded depth are exactly 0 (terraces): the gain is
    measured within 4 quanta, and falls with the lag as on the scan (it was 1 at every lag)."""
    scan, _ = plates["quiet"]
    rounded = _rounded(scan, unit)
    z, _ = scan_depth(rounded)
    gain = stride_gain(z, pixel_geometry(rounded, z).footprint, 8)
    assert gain[1] == 1.0
    assert gain[2] < 0.8 and gain[4] < 0.4 and gain[8] < 0.3


def test_scan_sigma_takes_the_rounding_and_leaves_unrounded_scans_alone():
    # scan_sigma is what the block-plane normals (normal's noisy path) weight their fits by
    from rangesim.edges._noise import scan_sigma

    plate = rs.datasets.plate_scan(QUIET)
    assert scan_sigma(plate) is plate.sigma
    rounded = _rounded(plate, 1.0)
    s = scan_sigma(rounded)[rounded.valid]
    expected = np.sqrt(plate.sigma[rounded.valid].astype(np.float64) ** 2 + 1.0 / 12)
    assert np.allclose(s, expected, rtol=0.02)
