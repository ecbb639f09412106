"""Creases to a fraction of a pixel: the gradient detector's crease pixels carry an offset
along the crease's normal that puts them on an analytic roof's crease line."""
from __future__ import annotations

import numpy as np
import pytest
from test_subpixel_contours import depth_scan

import rangesim as rs
from rangesim.core.constants import EdgeLabel


def roof_crease_distances(angle_deg: float, c: float, noise: float = 0.0, seed: int = 0,
                          convex: bool = True, detector: str = "gradient", **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances (px, along the crease normal) from a detector's (default gradient's) crease
    pixels to the crease line of a roof (slope 0.6 mm per mm either side, 400 mm away,
    1 mm footprint), before and after their offsets; the line lies ``c`` px past the
    image centre, so that the pixel grid meets it at a known phase."""
    size = 96
    a = np.radians(angle_deg)
    n = np.array([np.cos(a), np.sin(a)])
    ii, jj = np.mgrid[0:size, 0:size]
    signed = jj * n[0] + ii * n[1] - ((size / 2) * (n[0] + n[1]) + c)
    z = 400.0 + (0.6 if convex else -0.6) * np.abs(signed)
    z = z + noise * np.random.default_rng(seed).standard_normal(z.shape)
    e = rs.edges.DETECTORS[detector](depth_scan(z), **kwargs)
    creases = e.mask & np.isin(e.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
    ei, ej = np.nonzero(creases)
    inner = (ei > 8) & (ei < size - 9) & (ej > 8) & (ej < size - 9)
    ei, ej = ei[inner], ej[inner]
    assert ei.size >= 70                  # the whole line is found (78 px inside the margin)
    before = -signed[ei, ej]              # from the pixel centre to the line, along n
    return before, before - e.offset[ei, ej] @ n


@pytest.mark.parametrize("angle_deg", [0.0, 90.0])
@pytest.mark.parametrize("c", [0.2, 0.35, -0.3])
@pytest.mark.parametrize("convex", [True, False])
def test_noise_free_crease_pixels_move_onto_an_axis_crease(angle_deg, c, convex):
    # along an axis every pixel sees the line at the same phase: their centres are all c
    # off it (the nearest row or column), moved by their offsets they are on it
    before, after = roof_crease_distances(angle_deg, c, convex=convex)
    assert np.mean(before) == pytest.approx(c, abs=1e-6)
    assert abs(np.mean(after)) <= 0.02
    assert np.max(np.abs(after)) <= 0.02


@pytest.mark.parametrize("angle_deg", [3.0, 30.0, 62.0])
def test_noise_free_crease_pixels_on_an_oblique_crease(angle_deg):
    # off the axes the phase runs through every value (mean ~0 either way): the mean
    # distance stays ~0, the mean |distance| (~1/4 px at the centres) falls near 0
    before, after = roof_crease_distances(angle_deg, 0.3)
    assert abs(np.mean(after)) <= 0.02
    assert np.mean(np.abs(before)) > 0.2
    assert np.mean(np.abs(after)) <= 0.03


@pytest.mark.parametrize("angle_deg,sigma", [(0.0, 1.0), (90.0, 2.0), (30.0, 1.0)])
@pytest.mark.parametrize("seed", [0, 1])
def test_noisy_crease_pixels_move_onto_the_crease(angle_deg, sigma, seed):
    # 0.05 mm noise, smoothed (the ridge's parabola): within 0.1 px on average, from 0.35
    # (the smoothing fixed: this is about the offsets, not the noise-chosen scale)
    before, after = roof_crease_distances(angle_deg, 0.35, noise=0.05, seed=seed, sigma=sigma, threshold=15.0)
    assert abs(np.mean(after)) <= 0.1
    assert np.mean(np.abs(after)) <= 0.1
    if angle_deg in (0.0, 90.0):
        assert np.mean(before) == pytest.approx(0.35, abs=1e-6)


def test_ridge_offsets_parabola_triangle_and_missing_neighbours():
    from rangesim.edges._thinning import ridge_offsets

    s = np.zeros((5, 5), np.float32)
    s[2, 1:4] = [1.0, 3.0, 2.0]           # a ridge across x (direction 0) at row 2
    where = np.zeros((5, 5), bool)
    where[2, 2] = True
    d = np.zeros((5, 5), np.float32)
    # parabola: (1 - 2) / (2 (1 - 6 + 2)) = 1/6 px towards +x; triangle: (2 - 1) / 6
    np.testing.assert_allclose(ridge_offsets(s, d, where)[2, 2], [1 / 6, 0], atol=1e-6)
    np.testing.assert_allclose(ridge_offsets(s, d, where, peak="triangle")[2, 2], [1 / 6, 0], atol=1e-6)
    # the same ridge across y (direction pi / 2) moves along y
    np.testing.assert_allclose(ridge_offsets(s.T.copy(), d + np.pi / 2, where)[2, 2], [0, 1 / 6], atol=1e-6)
    # clipped to half a pixel; 0 without a neighbour and away from ``where``
    s[2, 1:4] = [0.0, 1.0, 1.0]
    np.testing.assert_allclose(ridge_offsets(s, d, where)[2, 2], [0.5, 0], atol=1e-6)
    s[2, 1] = np.nan
    assert np.all(ridge_offsets(s, d, where) == 0)
    with pytest.raises(ValueError):
        ridge_offsets(s, d, where, peak="gauss")


@pytest.mark.parametrize("angle_deg,c", [(0.0, 0.2), (0.0, 0.35), (90.0, -0.3), (30.0, 0.3), (62.0, 0.3)])
def test_normal_crease_pixels_move_towards_the_crease(angle_deg, c):
    """normal keeps the pixel its summed bend ranks highest, which on an axis crease is often
    the one across it (0.65-0.75 px off the line on average); the offsets from the ranks bring
    its crease pixels at least a quarter nearer the line (along an axis, over half), never
    further on average."""
    before, after = roof_crease_distances(angle_deg, c, detector="normal")
    gain = np.mean(np.abs(after)) / np.mean(np.abs(before))
    assert gain <= (0.5 if angle_deg in (0.0, 90.0) else 0.8)
    assert abs(np.mean(after)) <= abs(np.mean(before)) + 0.01
