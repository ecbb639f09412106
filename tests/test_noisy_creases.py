"""Creases on noisy scans: the gradient detector's smoothing chosen from the measured noise.

At the INRIA preset's noise (0.8 pixel footprints) the noise rule ``clip(4 noise, 1, 3)``
smoothed by 3 px, which kept 26 % of a crease's bend on the operators' ridge: a 45-degree
crease read as ~12 degrees, under the 15-degree floor, and was never found.
:func:`rangesim.edges._gradient.crease_sigma` picks the smoothing whose noise-raised
threshold lets the gentlest creases through.
"""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.edges._gradient import crease_sigma, smoothing_gain
from tests.conftest import pinhole_scan


def _bent_strip(noise_fp: float, seed: int, size: int = 96, f: float = 300.0, z0: float = 400.0) -> RangeScan:
    """A frontal plane at ``z0`` mm (footprint ``z0 / f`` = 1.33 mm) that turns 45 degrees
    away from the camera at column 30 (convex crease), frontal again from column 50 (concave
    crease), and steps 20 footprints down at column 70; Gaussian depth noise of ``noise_fp``
    footprints, the noise model's ``sigma`` (mm) attached as a laser-stripe scan carries it."""
    fp = z0 / f
    col = np.arange(size, dtype=float)
    z = z0 + fp * np.clip(col, 30, 50) - 30 * fp          # slope 1 footprint / px: 45 degrees
    z = np.where(col >= 70, z + 20 * fp, z)
    sigma_mm = noise_fp * fp
    depth = np.repeat(z[None, :], size, 0) + sigma_mm * np.random.default_rng(seed).standard_normal((size, size))
    return pinhole_scan(depth, f, sigma_mm)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gradient_finds_45_degree_creases_at_0_8_footprints_noise(seed):
    """Both 45-degree creases in most rows (3 px smoothing found none of them), and no
    crease elsewhere on the planes."""
    em = rs.edges.gradient(_bent_strip(0.8, seed))
    assert 1.0 <= em.params["sigma"] < 3.0
    rows = slice(8, -8)
    convex = em.mask & (em.labels == EdgeLabel.CONVEX)
    concave = em.mask & (em.labels == EdgeLabel.CONCAVE)
    assert convex[rows, 29:32].any(axis=1).mean() >= 0.6
    assert concave[rows, 49:52].any(axis=1).mean() >= 0.6
    crease = convex | concave
    elsewhere = crease[rows].sum() - crease[rows, 29:32].sum() - crease[rows, 49:52].sum()
    assert elsewhere <= 3


def test_smoothing_stays_where_the_noise_rule_is_best():
    """At the White Scanner preset's noise (0.25 footprints) the rule's 1 px stays; a noise-free
    scan is not smoothed at all; an explicit threshold keeps the rule's sigma."""
    assert rs.edges.gradient(_bent_strip(0.25, 0)).params["sigma"] == pytest.approx(1.0)
    assert rs.edges.gradient(_bent_strip(0.0, 0)).params["sigma"] == 0.0
    noisy = _bent_strip(0.8, 0)
    assert rs.edges.gradient(noisy, threshold=15.0).params["sigma"] == pytest.approx(3.0, abs=0.25)


def test_smoothing_gain_is_the_ridge_share_of_a_roof():
    """No smoothing sees the whole bend; the share falls as the roof is rounded wider."""
    gains = [smoothing_gain(s) for s in (0.0, 1.0, 1.5, 2.0, 3.0)]
    assert gains[0] == 1.0
    assert all(a > b for a, b in zip(gains, gains[1:]))
    assert 0.2 < gains[-1] < 0.3


def test_crease_sigma_within_the_rule_range():
    """The chosen sigma lies between 1 px and the noise rule's; deterministic."""
    from rangesim.edges._discontinuities import discontinuities
    from rangesim.edges._scan_access import scan_depth

    scan = _bent_strip(0.8, 0)
    z, valid = scan_depth(scan)
    disc, geo = discontinuities(scan, z, 3.73, 50)
    a = crease_sigma(z, disc.pairs, disc.touching, geo.footprint, valid, 0.8)
    b = crease_sigma(z, disc.pairs, disc.touching, geo.footprint, valid, 0.8)
    assert a == b and 1.0 <= a <= 3.0


def test_search_tiles_whole_image_up_to_512_squared_else_a_quarter():
    """Scans up to 512 x 512 search on every pixel (the benchmark's 256 x 256 among them);
    larger ones on 128-px tiles every 256 px, a quarter of the pixels."""
    from rangesim.edges._gradient import _search_tiles

    assert _search_tiles((256, 256)) == [(slice(0, 256), slice(0, 256))]
    tiles = _search_tiles((1024, 1024))
    covered = np.zeros((1024, 1024), bool)
    for t in tiles:
        covered[t] = True
    assert len(tiles) == 16 and covered.mean() == 0.25


@pytest.mark.parametrize("shape", [(700, 600), (1024, 1024)])
def test_search_mosaic_measures_each_tile_as_alone(shape):
    """The tiles packed into one image with blank gaps give each tile's noise bends to the
    bit, at the 5-tap and at the Gaussian smoothings, with holes and jumps in the tiles."""
    from rangesim.edges._discontinuities import find_discontinuities
    from rangesim.edges._gradient import _noise_bends, _search_mosaic, _search_tiles

    rng = np.random.default_rng(7)
    h, w = shape
    z = (400 + 0.05 * np.arange(w)[None, :] + rng.normal(0, 0.4, shape)).astype(np.float32)
    z[:, w // 3:] += 30                                  # a step through several tiles
    z[rng.random(shape) < 0.02] = np.nan                 # scattered dropouts
    z[100:180, 200:290] = np.nan                         # a hole across a tile's edge
    disc = find_discontinuities(z, np.float32(3.0), 0)
    inv_fp = np.full(shape, 1 / 1.3, np.float32)
    valid = np.isfinite(z)
    tiles = _search_tiles(shape)
    packed = _search_mosaic(tiles, (z, np.nan), (disc.pairs, False), (disc.touching, False), (inv_fp, np.nan),
                            (valid, False))
    for sigma in (1.0, 1.25, 2.0, 3.0):
        alone = np.concatenate([_noise_bends(z[t], disc.pairs[(slice(None), *t)], disc.touching[t], inv_fp[t],
                                             valid[t], sigma) for t in tiles])
        together = _noise_bends(*packed, sigma)
        assert alone.size > 1000
        np.testing.assert_array_equal(np.sort(alone), np.sort(together))


def test_sampled_operators_are_the_dense_ones_at_the_samples():
    """The noise search's operators on every 4th row and column are the dense responses there,
    to the bit, with holes, broken pairs and skipped pixels."""
    from rangesim.edges._discontinuities import find_discontinuities
    from rangesim.edges._gradient import sampled_second_differences, second_differences

    rng = np.random.default_rng(3)
    for h, w in ((3, 5), (17, 30), (64, 61)):
        z = (400 + rng.normal(0, 1, (h, w)).cumsum(1)).astype(np.float32)
        z[rng.random((h, w)) < 0.1] = np.nan
        disc = find_discontinuities(z, np.float32(2.0), 0)
        skip = rng.random((h, w)) < 0.1
        for pairs, sk in ((disc.pairs, skip), (None, None)):
            for dense, sampled in zip(second_differences(z, pairs, skip=sk),
                                      sampled_second_differences(z, pairs, sk, 4)):
                np.testing.assert_array_equal(dense[::4, ::4], sampled)


def test_curvature_fits_wider_blocks_on_noisier_scans():
    """The default quadric block grows from 5 to 7 px at a depth noise of 0.5 footprints (the
    curvature noise falls as the block's half-width squared, the threshold as its first
    power), on scans that carry their noise model; a recording's measured noise keeps 5."""
    import dataclasses

    from rangesim.edges._curvature import DEFAULT_WINDOW, NOISY_BLOCK_NOISE, NOISY_BLOCK_WINDOW

    assert (DEFAULT_WINDOW, NOISY_BLOCK_WINDOW, NOISY_BLOCK_NOISE) == (5, 7, 0.5)
    noisy, quiet = _bent_strip(0.8, 0), _bent_strip(0.25, 0)
    assert rs.edges.curvature(noisy).params["window"] == 7
    assert rs.edges.curvature(quiet).params["window"] == 5
    assert rs.edges.curvature(dataclasses.replace(noisy, sigma=None)).params["window"] == 5
    assert rs.edges.curvature(noisy, window=5).params["window"] == 5
