"""The normal detector's block planes on noisy scans (issue 14): the predicted noise of a
fitted normal against measured, and creases of known bend under known Gaussian noise."""
from __future__ import annotations

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.rangescan import RangeScan
from rangesim.edges._normal_planes import RAYLEIGH_MEDIAN, block_planes, normal_angle_std
from tests.conftest import pinhole_scan


def _roof(bend_deg: float, noise_fp: float, seed: int, size: int = 96, f: float = 300.0,
          z0: float = 400.0, tilt: float = 0.0, cut: int | None = None, step: float = 0.0,
          gap: int = 0) -> RangeScan:
    """A plane facing the camera that turns ``bend_deg`` away from it at column 48 (a
    convex crease; ``bend_deg = 0``: a plane), optionally tilted about the x axis (``dz / dy = tilt``); Gaussian depth noise of ``noise_fp`` footprints, the noise
    model's ``sigma`` (mm) attached as a laser-stripe scan carries it."""
    jj, ii = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5)
    fp = z0 / f
    # exact planes: z = z0 + m y + s max(x, 0) (the crease at x = 0, between columns 47 and
    # 48), with x = u z / f, y = v z / f on the pixel rays
    u, v = jj - size / 2, ii - size / 2
    s = np.where(u > 0, np.tan(np.radians(bend_deg)), 0.0)
    depth = z0 / (1 - (s * u + tilt * v) / f)
    sigma_mm = noise_fp * fp
    depth = depth + sigma_mm * np.random.default_rng(seed).standard_normal((size, size))
    if cut is not None:
        # columns left of ``cut`` pushed back by ``step`` mm (a depth jump) and the ``gap``
        # columns before it unmeasured (a shadow)
        depth[:, :cut] += step
        depth[:, cut - gap:cut] = np.nan
    return pinhole_scan(depth, f, sigma_mm)


def _fit(scan: RangeScan, b: int):
    h, w = scan.shape
    xyz = np.ascontiguousarray(np.moveaxis(scan.xyz, -1, 0), np.float32)
    s2 = (scan.sigma ** 2).astype(np.float32)
    out = (np.empty((3, h, w), np.float32), np.empty((h, w), np.float32), np.empty((3, h, w), np.float32))
    block_planes(xyz, scan.valid, np.zeros((h, w), bool), s2, b, 0.6, *out)
    return out


@pytest.mark.parametrize("b", [3, 5, 9])
@pytest.mark.parametrize("tilt", [0.0, 1.5])
def test_fitted_normal_noise_follows_the_law(b, tilt):
    """On a noisy plane the fitted normals scatter as predicted: their RMS angle about the
    mean normal is the predicted ``sqrt(v)`` within 10 % (15 % on the slanted face, where the
    measured scatter runs up to 11 % above it at b = 9; the detector scales the prediction by
    the scan's own measured :func:`noise_gain`, at least 1), and head-on (no tilt) both are
    ``sqrt(2) sigma / (spacing sqrt(n) e)``, e = sqrt((b^2 - 1) / 12); a face tilted by
    atan(1.5) = 56 degrees is quieter by cos(t) across and cos^2(t) along its slope (within
    10 %: the prediction is taken at the fitted, noisy slope, 0.12 rad per axis at b = 3)."""
    scan = _roof(0.0, 0.3, seed=b, tilt=tilt)
    normal, var, _ = _fit(scan, b)
    inner = (slice(b, -b), slice(b, -b))                 # every whole block
    n = normal[(slice(None),) + inner].reshape(3, -1)
    mean = n.mean(1)
    mean /= np.linalg.norm(mean)
    measured = np.sqrt(np.mean(np.arccos(np.clip(mean @ n, -1, 1)) ** 2))
    predicted = np.sqrt(np.mean(var[inner]))
    assert measured == pytest.approx(predicted, rel=0.1 if tilt == 0.0 else 0.15)
    head_on = normal_angle_std(0.3, 1.0, b)
    if tilt == 0.0:
        assert predicted == pytest.approx(head_on, rel=0.1)
    else:
        c = np.cos(np.arctan(tilt))
        assert predicted == pytest.approx(head_on * np.sqrt((c ** 2 + c ** 4) / 2), rel=0.1)


def test_pair_angles_are_rayleigh_on_a_plane():
    """The angle between blocks either side of a pixel over ``sqrt(v_A + v_B)`` has the
    Rayleigh median sqrt(ln 2) on a noisy plane (within 5 %)."""
    scan = _roof(0.0, 0.8, seed=3)
    normal, var, _ = _fit(scan, 5)
    a, b = normal[:, 10:-10, 8:-12], normal[:, 10:-10, 12:-8]          # blocks at p -+ 2 px
    ang = np.arccos(np.clip(np.sum(a * b, 0), -1, 1)) / np.sqrt(var[10:-10, 8:-12] + var[10:-10, 12:-8])
    assert np.median(ang) == pytest.approx(RAYLEIGH_MEDIAN, rel=0.05)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_roof_found_within_a_pixel_under_noise(seed):
    """A 45 degree roof under 0.8 footprints of Gaussian noise (inria_laser's level): the
    crease is found along nearly its whole length (away from the image border), convex, 75 %
    of it within 1 px of the true line (between columns 47 and 48) and all within 2.5 px (the
    benchmarks' 2 px tolerance from a pixel's edge), and nowhere else but next to the image
    border (where the data ends; the benchmarks leave such pixels out)."""
    scan = _roof(45.0, 0.8, seed)
    em = rs.edges.normal(scan)
    assert em.params["blocks"]                      # the block path was taken
    crease = em.mask & (em.labels != EdgeLabel.JUMP)
    crease[:, :8] = crease[:, -8:] = False          # the image border, where the data ends
    rows, cols = np.nonzero(crease[12:-12])
    assert rows.size >= 0.9 * (96 - 24)
    off = np.abs(cols + 0.5 - 48)
    assert np.mean(off <= 1.0) >= 0.75 and np.all(off <= 2.5)
    assert np.all(em.labels[12:-12][crease[12:-12]] == EdgeLabel.CONVEX)


def test_no_false_crease_on_a_noisy_plane():
    """A tilted plane under 0.8 footprints of noise: no crease pixel 8 px or more from the
    image border (the false-alarm rate per pair is exp(-16), ~1e-7, at k = 4; 96^2 pixels x 4
    axes), on three draws. (The jump rule's own false alarms are not this detector's.)"""
    for seed in range(3):
        em = rs.edges.normal(_roof(0.0, 0.8, seed, tilt=0.7))
        crease = em.mask & ((em.labels == EdgeLabel.CONVEX) | (em.labels == EdgeLabel.CONCAVE))
        assert not crease[8:-8, 8:-8].any()


def test_noise_free_and_explicit_window_keep_the_stencil_normals():
    """Noise-free scans and an explicit ``window`` take the stencil path (no blocks)."""
    quiet = _roof(45.0, 0.0, 0)
    quiet.sigma = None
    assert "blocks" not in rs.edges.normal(quiet).params
    assert "blocks" not in rs.edges.normal(_roof(45.0, 0.8, 0), window=7).params


@pytest.mark.parametrize("dist", [4, 5])
@pytest.mark.parametrize("gap", [0, 3])
def test_roof_beside_a_jump_found_under_noise(dist, gap):
    """The roof of :func:`test_roof_found_within_a_pixel_under_noise`, 0.5 footprints of noise,
    ``dist`` px right of a 40 mm depth jump (with ``gap`` unmeasured columns before it): a
    block cut by the jump or the gap is fitted on its centre's own side only (the pixels
    joined to it inside the block, not through a pixel beside the jump), so the crease is
    found, within 1 px, along 60 % of its length or more (before, blocks holding a pixel beside the
    jump were not fitted and the crease was missed)."""
    hits = 0
    for seed in range(3):
        scan = _roof(45.0, 0.5, seed, cut=48 - dist, step=40.0, gap=gap)
        em = rs.edges.normal(scan)
        assert em.params["blocks"]
        crease = (em.labels == EdgeLabel.CONVEX) & em.mask
        rows = crease[12:-12, 47:49].any(1)
        hits += np.count_nonzero(rows)
    assert hits >= 0.6 * 3 * (96 - 24)         # before: 8 of 216 rows at 4 px


def test_drop_specks_takes_lone_crease_fragments_only():
    """Fragments of at most 2 crease pixels (8-connected) that touch no other edge pixel go;
    longer lines, fragments touching a jump, and whatever is not droppable stay."""
    from rangesim.edges._thinning import drop_specks

    crease = np.zeros((12, 16), bool)
    jump = np.zeros_like(crease)
    crease[1, 1] = True                      # a lone pixel: goes
    crease[3, 3] = crease[4, 4] = True       # a diagonal pair: goes
    crease[1, 8:11] = True                   # three in a row: stays
    crease[7, 2] = crease[7, 3] = True       # a pair touching a jump pixel: stays
    jump[8, 4] = True
    jump[10, 10] = True                      # a lone jump pixel is not droppable
    kept = drop_specks(crease, crease | jump)
    assert not kept[1, 1] and not kept[3, 3] and not kept[4, 4]
    assert kept[1, 8:11].all() and kept[7, 2] and kept[7, 3]
    assert kept.sum() == 5
    assert np.array_equal(drop_specks(crease, crease | jump, max_px=0), crease)


def test_normal_leaves_no_lone_crease_specks_on_a_noisy_part():
    """inria_laser's noisy scan of a machined part (tuning seed 21): a single-threshold crease
    rule lets 27 lone crease pixels or pairs through (noise excursions; on the parts' check
    seeds dropping them raised F1 by 0.001-0.005); none are left, and the map still scores."""
    import sys
    from pathlib import Path

    from scipy import ndimage

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import bench_detectors as bench

    preset = rs.load_sensor("inria_laser")
    scene, pose, _ = bench.make_case(21, preset)
    scan = rs.scan(scene, preset, pose=pose, seed=21)
    em = rs.edges.normal(scan)
    assert "blocks" in em.params  # the block-plane path of noisy laser scans
    crease = em.mask & ((em.labels == EdgeLabel.CONVEX) | (em.labels == EdgeLabel.CONCAVE))
    parts, _ = ndimage.label(em.mask, structure=np.ones((3, 3), bool))
    sizes = np.bincount(parts.ravel())
    assert crease.sum() > 300 and not (crease & (sizes[parts] <= 2)).any()
    scores = rs.evaluate.score_edges(em, scan, truth=rs.evaluate.visible_truth(scan, scene))
    # 0.856 until the stripe was also cut at occluding edges over a measured background
    # (eighteenth session): 13 more outline pixels drop out (38 against 25), F1 0.848
    assert scores["f1"] > 0.84
