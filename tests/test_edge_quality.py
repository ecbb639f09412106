"""Edge-detector quality on the Green Piece against exact ground truth (issue 4's "Done means").

Scans: ``scenes/green_piece.toml`` with the ``white_scanner`` preset (512 x 480 px), seed 0.
Noise-free: ``noise.sigma_px = noise.speckle_contrast = noise.quantization_px = 0`` (the
stripe width stays: mixed pixels at jumps are physics, not noise). Preset noise: the
preset as is (depth noise 0.24 pixel footprints, measured by
``rangesim.edges.estimate_depth_noise``). Scores: ``edge_scores`` on jump + crease
edges together, tolerance 2 px, default detector settings (noise-adaptive: see
``rangesim.edges._noise``). Truth is kept on measured pixels only (``scan_truth``).

Documented F1 (measured; the floors asserted below are these minus a small margin):

=============  ==========  ======================  ============  ======================
detector       noise-free  noise-free, stripe 0    preset noise  flagged at preset noise
=============  ==========  ======================  ============  ======================
gradient       0.900       0.917                   0.850         1.2 % of valid pixels
normal         0.903       0.927                   0.815         1.1 %
line_fit       0.855       0.885                   0.839         1.3 %
curvature      0.879       0.907                   0.809         1.1 %
pcl_organized  0.747       0.733                   0.685         1.8 %
=============  ==========  ======================  ============  ======================

(Since 2026-12-03 line_fit keeps no crease one pixel beyond a jump's far side, the step's
foot rounded by the stripe's width, ``rangesim.edges._line_fit.LINE_FIT_CLEARANCE``: noise-free
0.846 -> 0.855, with noise 0.842 -> 0.839.)

(Since 2026-12-02 the holes' rims over their own laser shadow are edges: a shadow gap that no
caster explains is not the surface continued, ``rangesim.edges._self_shadow``; before it
gradient / normal / line_fit / curvature measured 0.893 / 0.897 / 0.840 / 0.871 noise-free
and 0.839 / 0.792 / 0.633 / 0.798 with the preset noise.)

Truth: mesh creases rasterised 8-connected (1 px on diagonals), kept only where a ray
from the camera reaches the edge itself and the scan samples both faces next to it. The
threads' flanks are staircases of sub-footprint steps (a ~110 degree convex + concave pair
around a grazing riser 0.1 mm high, layer by layer); the earlier truth drew them as 2 px
concave bands, which halved concave recall. Most of the remaining loss is convex
responses on the thread crests next to the jump (precision) and, with stripe width, mixed
pixels along the jumps; the gradient and normal detectors drop creases within 2 px of a
jump and thin NMS staircases to 1 px diagonals (before: gradient 0.738 / 0.871 / 0.838,
normal 0.711 / 0.910 / 0.797). Before the noise-adaptive defaults, gradient / normal / line_fit /
pcl_organized flagged 30-39 % of the valid pixels at preset noise (F1 ~0.1).

The figures fell by 0.02-0.06 (from gradient 0.913 / 0.928 / 0.869, normal 0.923 / 0.937 /
0.830, curvature 0.642 / 0.662 / 0.637) when mixed pixels started to follow the stripe's
physics instead of a 0.5 %-of-range gate (issue 14 item 6): the scratches and the threads'
small steps now mix too (3236 -> 3943 pixels off by over 0.05 mm noise-free), so the scan
is harder there; with stripe width 0 (no mixing) the figures are close to the earlier ones.

line_fit and curvature rose (from 0.773 / 0.855 / 0.603 and 0.585 / 0.635 / 0.579) when
line_fit's crease bands were thinned to 1 px (pieces under 5 px dropped) and curvature's
default rule became the ridges of the larger principal curvature (the paper's Fig. 12
rule, both curvatures large, marks corners only: ``rule="both"``). Both were tuned on the
machined parts of ``benchmarks/bench_detectors.py`` (seeds 0-7), not on these scans. The
preset-noise column fell by 0.006-0.013 when the thresholds started to follow the scan's
predicted noise per pixel (``RangeScan.sigma``), which gained 0.1-0.2 on the machined parts'
cyberware_3030 and inria_laser scans (line_fit's, with a per-pixel tolerance, rose to 0.633).

line_fit's preset-noise figure rose from 0.651 to 0.841 when its lines on noisy scans were
drawn ``s`` pixels out (median stride 3 here; ``rangesim.edges._line_rings``), chosen on the
machined parts' tuning seeds 0-19; these scans were not looked at before it was settled.
The preset-noise column moved on 2026-12-03 (third session) with changes chosen on the
machined parts' tuning seeds, not on these scans: gradient 0.847 -> 0.850 (smoothing that never
crosses a depth step), normal 0.801 -> 0.815 (block-plane normals against their predicted
noise), pcl_organized 0.654 -> 0.685 (its normals' step from the noise), line_fit 0.841 -> 0.842.
Ninth session (2026-12-04): normal 0.815 -> 0.813 with noise, lone crease specks dropped on
noisy scans (chosen on the machined parts' tuning seeds; noise-free columns unchanged).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rangesim as rs
from rangesim.edges import DETECTORS, estimate_depth_noise
from rangesim.edges._noise import NOISE_FLOOR
from rangesim.evaluate._edge_scores import edge_scores
from rangesim.evaluate.runs import scan_truth

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "green_piece.toml"
QUIET = {"noise.sigma_px": 0.0, "noise.speckle_contrast": 0.0, "noise.quantization_px": 0.0}

#: F1 floors (documented values above minus ~0.03)
CLEAN_FLOOR = {"gradient": 0.88, "normal": 0.88, "line_fit": 0.82, "curvature": 0.86,
               "pcl_organized": 0.72}
NOISY_FLOOR = {"gradient": 0.83, "normal": 0.78, "curvature": 0.79, "line_fit": 0.81}
#: the flat machined target (shared data), noise-free: measured gradient 0.72, line_fit 0.87,
#: normal 0.70, curvature 0.73, pcl_organized 0.86 (line_fit 0.77 before it cleared the steps'
#: feet, the false creases one pixel beyond each jump's far side; 0.79-0.82 before its crease
#: pieces under 5 px were dropped: the chamfers show in short pieces; curvature 0.68 with
#: the corner rule). Its 0.5 mm chamfers run beside the plate's
#: jump edges, less than a pixel footprint (0.9 mm) inside them: the truth marks a convex
#: crease one pixel from the jump, which gradient and normal clear as part of the jump.
#: pcl_organized measured 0.733 since truncated stripes at shadow borders are dimmed (and may
#: drop out): its NaN-boundary rule then marks the rim one pixel further in.
FLAT_FLOOR = {"gradient": 0.70, "line_fit": 0.84, "normal": 0.68, "curvature": 0.70,
              "pcl_organized": 0.71}
#: most of the valid pixels a detector may flag at preset noise (no flooding)
MAX_FRACTION = 0.05


def _scan(changes, scene_file=SCENE):
    sensor = rs.load_sensor("white_scanner")
    if changes:
        sensor = sensor.with_params(changes)
    scene = rs.load_scene(str(scene_file))
    scan = rs.scan(scene, sensor)
    return scan, scan_truth(scan, str(scene_file))


@pytest.fixture(scope="module")
def clean():
    return _scan(QUIET)


@pytest.fixture(scope="module")
def noisy():
    return _scan({})


def _f1(scan, truth, method):
    em = DETECTORS[method](scan)
    s = edge_scores(em.mask, truth.mask, 2.0)
    return s["f1"], em.mask.sum() / scan.valid.sum()


def test_noise_estimate(clean, noisy):
    assert estimate_depth_noise(clean[0]) < 0.01 < NOISE_FLOOR
    assert 0.2 < estimate_depth_noise(noisy[0]) < 0.3     # the preset's 0.27 (rms incl. tails)


def test_noise_free_f1_floors(clean):
    scan, truth = clean
    for method, floor in CLEAN_FLOOR.items():
        f1, _ = _f1(scan, truth, method)
        assert f1 >= floor, (method, f1)


def test_preset_noise_no_flooding(noisy):
    scan, truth = noisy
    for method in DETECTORS:
        f1, fraction = _f1(scan, truth, method)
        assert fraction < MAX_FRACTION, (method, fraction)
        if method in NOISY_FLOOR:
            assert f1 >= NOISY_FLOOR[method], (method, f1)


def test_flat_machined_target_f1_floors(data_dir, monkeypatch):
    monkeypatch.setenv("RANGESIM_DATA", str(data_dir))
    scan, truth = _scan(QUIET, SCENE.parent / "flat_target.toml")
    for method, floor in FLAT_FLOOR.items():
        f1, _ = _f1(scan, truth, method)
        assert f1 >= floor, (method, f1)


def test_gradient_takes_peak_quantisation_for_noise():
    # a laser scan with only its 1/16 px peak quantisation (0.04 footprints, under NOISE_FLOOR)
    # had its quantisation steps marked as creases at the fixed 15 degrees (precision 0.38
    # against 0.86 noise-free on this plate at 256 px); then its threshold alone was raised to
    # 29-34 degrees, which lost every 20-29 degree crease (below): such noise now gets the
    # noisy path's smoothing and per-pixel threshold, as the full preset noise does
    import rangesim as rs

    quiet = {"noise.sigma_px": 0, "noise.speckle_contrast": 0}
    scene = rs.datasets.plate_scene()
    scores = {}
    for q in (0.0, 0.0625):
        scan = rs.datasets.plate_scan({**quiet, "noise.quantization_px": q}, width=256, height=240)
        edges = rs.edges.gradient(scan)
        scores[q] = rs.evaluate.score_edges(edges, scan, scene)
        assert (edges.params["sigma"] > 0) == (q > 0)  # smoothed only where there is noise
    assert scores[0.0625]["precision"] > scores[0.0]["precision"] - 0.03
    assert scores[0.0625]["recall"] > scores[0.0]["recall"] - 0.02


def test_gradient_keeps_a_gentle_crease_under_quantisation_alone(tmp_path):
    """A 25 degree roof seen from above by white_scanner with only its peak quantisation (the
    README's quiet recipe): recall 0.03 when the quantisation raised the threshold to 29
    degrees unsmoothed, 0.68 with the full preset noise; found as noise-free."""
    import trimesh

    import rangesim as rs

    half, h = 150.0, 150.0 * np.tan(np.radians(12.5))  # faces 12.5 degrees each side: a 25 degree bend
    v = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0],
                  [0, -half, h], [0, half, h]], float)
    f = [[0, 1, 4], [1, 2, 5], [1, 5, 4], [2, 3, 5], [3, 0, 4], [3, 4, 5], [0, 3, 1], [1, 3, 2]]
    trimesh.Trimesh(v, f, process=True).export(tmp_path / "roof.stl")
    (tmp_path / "roof.toml").write_text('units = "mm"\n[[object]]\nmesh = "roof.stl"\n'
                                        '[view]\nposition = [0, 0, 350]\nlook_at = [0, 0, 0]\nup = [0, 1, 0]\n')
    scene = rs.load_scene(tmp_path / "roof.toml")
    for q in (0.0, 0.0625):
        sensor = rs.load_sensor("white_scanner").with_params(
            {"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": q,
             "camera.width": 128, "camera.height": 120})
        scan = rs.scan(scene, sensor, seed=0)
        s = rs.evaluate.score_edges(rs.edges.gradient(scan), scan, scene)
        assert s["recall"] > 0.85 and s["precision"] > 0.9, (q, s["recall"], s["precision"])


def test_normal_drops_lone_crease_specks_only_under_noise(clean, noisy):
    """Crease fragments of 1-2 px touching no other edge are noise excursions on a noisy scan
    (dropped) but small features on a noise-free one (the Green Piece's scratches and dents:
    38 such pixels, 26 of them within 2 px of a true edge, kept)."""
    from scipy import ndimage

    def lone(scan, truth):
        em = DETECTORS["normal"](scan)
        crease = em.mask & ((em.labels == 2) | (em.labels == 3))
        parts, _ = ndimage.label(em.mask, structure=np.ones((3, 3), bool))
        lone = crease & (np.bincount(parts.ravel())[parts] <= 2)
        return lone.sum(), (lone & (ndimage.distance_transform_edt(~truth.mask) <= 2)).sum()

    n_clean, on_truth = lone(*clean)
    assert n_clean >= 20 and on_truth >= 0.6 * n_clean
    assert lone(*noisy)[0] == 0
