"""The stripe noise model (rangesim.sensor.stripe_noise) against its laws, in the scanner and the twin."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.sensor import stripe_noise as sn
from tests.conftest import make_sensor, plane, top_down_pose


# -- the laws on their own -------------------------------------------------------------------
@pytest.mark.parametrize("corr", [0.7, 1.5, 3.0])
def test_correlated_field_has_unit_variance_and_gaussian_correlation(corr):
    f = sn.correlated_field(np.random.default_rng(3), (300, 300), (corr, corr))
    assert f.std() == pytest.approx(1.0, abs=0.08)
    for lag in (1, 2):
        rho = np.corrcoef(f[:, :-lag].ravel(), f[:, lag:].ravel())[0, 1]
        assert rho == pytest.approx(math.exp(-lag**2 / (4 * corr**2)), abs=0.04)


def test_correlated_field_longer_than_the_grid_keeps_its_law():
    # a kernel longer than the grid along the rows (8 sigma + 1 > 64) is filtered in Fourier
    # space: the same unit variance and Gaussian correlation along the columns, over 60 draws
    fields = [sn.correlated_field(np.random.default_rng(k), (64, 400), (9.0, 1.5)) for k in range(60)]
    assert np.mean([np.mean(f**2) for f in fields]) == pytest.approx(1.0, abs=0.05)
    for lag in (1, 3):
        rho = np.mean([np.mean(f[:, :-lag] * f[:, lag:]) for f in fields])
        assert rho == pytest.approx(math.exp(-lag**2 / (4 * 1.5**2)), abs=0.04)
        rho_rows = np.mean([np.mean(f[:-lag] * f[lag:]) for f in fields])
        assert rho_rows == pytest.approx(math.exp(-lag**2 / (4 * 9.0**2)), abs=0.04)


def test_correlated_field_of_a_correlation_beyond_the_grid_is_one_value_per_line():
    # a twin's fitted grid of a perspective scan gave 1.3 million cells of correlation on 64
    # rows: the spatial filter ran for minutes; the field is then constant down each column
    f = sn.correlated_field(np.random.default_rng(0), (64, 64), (1.3e6, 0.25))
    assert np.ptp(f, axis=0).max() < 1e-9 and np.ptp(f[0]) > 1.0
    values = [sn.correlated_field(np.random.default_rng(k), (8, 8), (np.inf, np.inf)) for k in range(400)]
    assert all(np.ptp(v) < 1e-12 for v in values)
    assert np.std([v[0, 0] for v in values]) == pytest.approx(1.0, abs=0.1)


def test_detection_probability_is_the_gamma_speckle_law():
    s = np.array([2.0, 0.5, 0.1, 0.02])
    # fully developed speckle: exponential intensity, P(S X >= m) = exp(-m / S)
    np.testing.assert_allclose(sn.detection_probability(s, 0.05, 1.0), np.exp(-0.05 / s), rtol=1e-9)
    # lower contrast: a steeper curve through the same threshold, 1 above and 0 below in the limit
    p = sn.detection_probability(s, 0.05, 0.25)
    assert p[0] > 0.999 and p[-1] < 0.01 and np.all(np.diff(p) < 0)
    draws = sn.draw_detected(np.random.default_rng(0), (200, 200), np.full(40000, 0.3), (1.5, 1.5))
    assert draws.mean() == pytest.approx(0.3, abs=0.03)


def test_truncated_stripe_centroid_shift():
    s = 1.0 / sn.FWHM_TO_SIGMA  # sigma_s = 1 mm on a facing surface
    cut = sn.partial_stripe_shift_mm(np.array([0.0, 1.0, 5.0]), np.ones(3), s)
    phi = lambda t: math.exp(-t * t / 2) / math.sqrt(2 * math.pi)  # noqa: E731
    Phi = lambda t: 0.5 * (1 + math.erf(t / math.sqrt(2)))  # noqa: E731
    np.testing.assert_allclose(cut, [phi(t) / Phi(t) for t in (0.0, 1.0, 5.0)], rtol=1e-6)
    # an inclined surface widens the footprint by 1 / cos i, and the shift with it
    wide = sn.partial_stripe_shift_mm(np.array([0.0]), np.array([0.5]), s)
    assert wide[0] == pytest.approx(2 * cut[0], rel=1e-6)


def test_signal_term_grows_as_cos_to_the_minus_three_halves():
    noise = sn.StripeNoise(signal_px=0.1, stripe_width_mm=1.0, psf_px=0.0)
    cos = np.array([1.0, 0.5, 0.25])
    w = sn.stripe_width_px(cos, 2.0, 1.0, 0.0) / 2.0
    sig = sn.peak_sigma_px(noise, width_ratio=w, amplitude=cos, speckle_px=np.zeros(3), edge_px=np.zeros(3))
    np.testing.assert_allclose(sig["total"], 0.1 * cos**-1.5, rtol=1e-9)
    assert np.all(sig["white"] == 0)  # the signal-limited term is speckle-correlated


# -- in the geometric scanner ------------------------------------------------------------------
def _tilted_plane(angle_deg):
    p = plane()
    p.apply_transform(trimesh.transformations.rotation_matrix(math.radians(angle_deg), [0, 1, 0]))
    return p


def test_depth_noise_grows_with_incidence_as_the_law_says():
    # rotating sweep, plane tilted about the camera's y axis: the laser incidence grows with the tilt
    changes = {"noise.signal_px": 0.3, "laser.stripe_width": 0.5, "camera.psf_px": 0.0}
    sensor = make_sensor(**changes)
    stds, predicted = [], []
    for angle in (0.0, -50.0):  # -50: the plane turns away from the laser (incidence about 70 deg)
        scan = rs.scan([_tilted_plane(angle)], sensor, pose=top_down_pose(400.0), seed=2)
        c = scan.valid.copy()
        c[:, :60] = False
        c[:, 100:] = False
        stds.append(np.std((scan.depth - scan.xyz_true[..., 2])[c]))
        predicted.append(np.median(scan.sigma[c]))
    assert stds[1] / stds[0] > 1.5  # noise grows with incidence ...
    assert stds[1] / stds[0] == pytest.approx(predicted[1] / predicted[0], rel=0.15)  # ... as predicted


@pytest.mark.parametrize("terms", [
    {"noise.sigma_px": 0.2},
    # small errors: the linearised prediction holds while the error stays well inside the surface's curvature
    {"noise.signal_px": 0.03, "noise.speckle_contrast": 0.5, "noise.correlation_mm": 0.6, "laser.stripe_width": 0.5,
     "noise.quantization_px": 0.0625, "noise.edge_gain": 0.5},
])
def test_z_score_has_unit_std_in_every_incidence_bin(terms):
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=80.0)
    sensor = make_sensor(**{"camera.width": 240, "camera.height": 200, **terms})
    scan = rs.scan([sphere], sensor, pose=top_down_pose(480.0), seed=5)
    assert scan.sigma is not None and scan.sigma.dtype == np.float32
    assert np.isfinite(scan.sigma[scan.valid]).all() and np.isnan(scan.sigma[~scan.valid]).all()
    z = (scan.depth - scan.xyz_true[..., 2]) / scan.sigma
    cos_e = -np.einsum("ijk,ijk->ij", scan.normal, scan.xyz_true) / np.linalg.norm(scan.xyz_true, axis=2)
    incidence = np.degrees(np.arccos(np.clip(cos_e, 0, 1)))
    checked = 0
    for lo, hi in ((0, 30), (30, 60), (60, 75), (75, 90)):
        sel = scan.valid & (incidence >= lo) & (incidence < hi)
        if sel.sum() >= 300:
            assert np.std(z[sel]) == pytest.approx(1.0, abs=0.1), (lo, hi)
            checked += 1
    assert checked >= 3


def test_speckle_correlation_length_carries_into_the_depth_error():
    """``correlation_mm`` is mm on a facing surface at the reference distance, one size on the
    sensor (subjective speckle grains): the depth error's neighbour correlation is
    exp(-1 / (4 l^2)) with l = correlation_mm f / z_ref pixels, at any range."""
    corr_mm = 3.0  # 1.2 px: a kernel the pixel grid resolves
    sensor = make_sensor(**{"noise.speckle_contrast": 1.0, "noise.correlation_mm": corr_mm})
    corr_px = corr_mm * sensor.K[0, 0] / sensor.reference_distance
    for z in (250.0, 400.0, 800.0):
        scan = rs.scan([plane()], sensor, pose=top_down_pose(z), seed=4)
        e = scan.depth - z
        rho = np.corrcoef(e[:, :-1].ravel(), e[:, 1:].ravel())[0, 1]
        assert rho == pytest.approx(math.exp(-1 / (4 * corr_px**2)), abs=0.05), z


def test_dropouts_follow_the_speckle_detection_law():
    sensor = make_sensor(**{"noise.min_signal": 0.1, "noise.signal_contrast": 1.0})
    scan = rs.scan([plane()], sensor, pose=top_down_pose(600.0), seed=1)
    s = scan.intensity[scan.part == 0]
    expected = np.mean(1 - np.exp(-0.1 / s))
    assert 0.05 < expected < 0.6
    assert scan.count(Status.DROPOUT) / s.size == pytest.approx(expected, abs=0.02)
    again = rs.scan([plane()], sensor, pose=top_down_pose(600.0), seed=1)
    np.testing.assert_array_equal(scan.status, again.status)  # deterministic per seed


@pytest.mark.parametrize("suffix", [".exr", ".npz"])
def test_sigma_round_trips_and_info_shows_it(tmp_path, suffix, capsys):
    from rangesim.cli.main import main

    scan = rs.scan([plane()], make_sensor(**{"noise.sigma_px": 0.2}), pose=top_down_pose(400.0), seed=0)
    path = scan.save(tmp_path / f"s{suffix}")
    back = rs.load_scan(path)
    np.testing.assert_array_equal(back.sigma, scan.sigma)
    assert main(["info", str(path)]) == 0
    assert "predicted depth std (sigma)" in capsys.readouterr().out


def test_detectors_take_the_predicted_noise_where_the_data_underestimates_it():
    from dataclasses import replace

    from rangesim.edges import estimate_depth_noise
    from rangesim.edges._scan_access import pixel_geometry

    sensor = make_sensor(**{"noise.speckle_contrast": 1.0, "noise.correlation_mm": 6.0})
    scan = rs.scan([plane()], sensor, pose=top_down_pose(400.0), seed=4)
    fp = float(np.median(pixel_geometry(scan).footprint[scan.valid]))
    true = float(np.std(scan.depth[scan.valid] - 400.0)) / fp
    assert estimate_depth_noise(scan) == pytest.approx(true, rel=0.1)
    # without the prediction the second differences of a correlated error see only a fraction of it
    assert estimate_depth_noise(replace(scan, sigma=None)) < 0.5 * true


@pytest.mark.parametrize("sampling", [(1.0, 1.0), (0.3, 0.5)])
def test_border_distance_is_along_the_row_at_any_asked_cells(sampling):
    """The distance to the nearest unmeasurable cell of the same row (the border half a cell
    beyond it), as a loop over each row finds it; the rows' scan at a few asked cells gives the
    same."""
    rng = np.random.default_rng(4)
    m = np.ones((60, 80), bool)
    m[rng.random(m.shape) < 0.01] = False  # scattered holes
    m[20:35, 10:30] = False  # a shadow
    m[:, :3] = False
    m[50, :] = True  # a row with no border at all
    full = sn.border_distance(m, sampling=sampling)
    loop = np.full(m.shape, np.inf)
    for i in range(m.shape[0]):
        bad = np.flatnonzero(~m[i])
        for j in range(m.shape[1]):
            loop[i, j] = 0.0 if not m[i, j] else (max(np.abs(bad - j).min() * sampling[1] - 0.5 * sampling[1], 0.0)
                                                  if bad.size else np.inf)
    np.testing.assert_allclose(full, loop.ravel(), atol=1e-12)
    cells = rng.choice(np.flatnonzero(m.ravel()), 300, replace=False)
    np.testing.assert_allclose(sn.border_distance_at(m, cells, sampling), full[cells], atol=1e-12)
    ask = np.zeros(m.size, bool)
    ask[cells] = True
    part = sn.border_distance(m, sampling=sampling, where=ask)
    np.testing.assert_allclose(part[cells], full[cells], atol=1e-12)
    assert np.isinf(part[~ask & m.ravel()]).all() and (part[~m.ravel()] == 0).all()


def test_truncated_stripe_error_only_where_an_outline_crosses_the_row():
    """A square plate facing the camera, only the partial-stripe term on (a 2 mm stripe): its
    left and right outlines cut the stripe's width profile (which lies along the row) and move
    the peaks there by about a millimetre; its top and bottom outlines run along the row, cut
    nothing, and get no more than the inside does (they once got as much as the sides: the
    distance was to any border)."""
    sensor = make_sensor(**{"noise.edge_gain": 1.0, "laser.stripe_width": 2.0, "noise.min_signal": 0.0})
    scan = rs.scan([plane(80.0)], sensor, pose=top_down_pose(350.0), seed=0)
    rows, cols = np.flatnonzero(scan.valid.any(1)), np.flatnonzero(scan.valid.any(0))
    r0, r1, c0, c1 = rows[0], rows[-1], cols[0], cols[-1]
    err = scan.depth - scan.xyz_true[..., 2]
    inner, along = slice(r0 + 3, r1 - 2), slice(c0 + 3, c1 - 2)
    inside = float(scan.sigma[inner, along].max())  # the sides' tails, three footprints in
    assert inside < 0.02
    for c in (c0, c1):  # the sides: every outline pixel moved, with the predicted spread
        assert scan.sigma[inner, c].min() > 0.5 and np.sqrt(np.mean(err[inner, c] ** 2)) > 0.5
    for r in (r0, r1):  # top and bottom: what the inside gets
        assert scan.sigma[r, along].max() <= inside + 1e-6 and np.sqrt(np.mean(err[r, along] ** 2)) < 0.02


def _outline_spread(width_mm: float, gain: float, seeds: int = 8):
    """Depth errors (seeds, 2 x rows), predicted std and cosine of the laser's incidence (2 x
    rows,) on the left and right outline columns of an 80 mm plate facing the camera, only the
    partial-stripe term on."""
    sensor = make_sensor(**{"noise.edge_gain": gain, "laser.stripe_width": width_mm, "noise.min_signal": 0.0})
    errs = []
    for seed in range(seeds):
        scan = rs.scan([plane(80.0)], sensor, pose=top_down_pose(350.0), seed=seed)
        rows, cols = np.flatnonzero(scan.valid.any(1)), np.flatnonzero(scan.valid.any(0))
        inner = slice(rows[0] + 3, rows[-1] - 2)
        sides = [cols[0], cols[-1]]
        errs.append((scan.depth - scan.xyz_true[..., 2])[inner][:, sides].T.ravel())
    points = scan.xyz_true[inner][:, sides].transpose(1, 0, 2).reshape(-1, 3).astype(np.float64)
    to_laser = sensor.laser_origin - points
    cos_i = to_laser[:, 2] * -1 / np.linalg.norm(to_laser, axis=1)  # the plate's normal faces the camera: -z
    return np.array(errs), scan.sigma[inner][:, sides].T.ravel(), np.abs(cos_i)


def test_truncated_stripe_term_is_a_spread_of_its_stated_size():
    """The partial-stripe term is a random error of std g m sigma_s phi(t) / Phi(t) (pixels;
    sigma_s = s / (2.355 cos i), t = delta / sigma_s, delta = half a footprint z / f at the
    outline column) on top of the fixed shift the mixed-pixel model gives there (``scan.sigma``
    is the RMS error about the truth: both in quadrature). So: without it (g = 0) the outline
    errors are that shift, the same for every seed; with it, their spread about the shift
    follows sqrt(sigma^2 - shift^2); and that spread scales between two stripe widths as
    sigma_s phi(t) / Phi(t) does (m and dz/du cancel in the ratio, pixel by pixel). The outline
    test above passes at g = 0 too (the fixed shift alone)."""
    from scipy.special import ndtr

    def law(width, cos_i):
        sigma_s = width / (2.0 * math.sqrt(2.0 * math.log(2.0)) * cos_i)
        t = 0.5 * (350.0 / make_sensor().focal_px) / sigma_s
        return sigma_s * np.exp(-0.5 * t * t) / math.sqrt(2 * math.pi) / ndtr(t)

    spreads = {}
    for width, seeds in ((2.0, 8), (3.0, 1)):
        shift, _, _ = _outline_spread(width, 0.0, seeds=2)
        assert np.abs(shift[1] - shift[0]).max() < 1e-4 and np.abs(shift).mean() > 0.1  # shifted, not spread
        err, sigma, cos_i = _outline_spread(width, 1.0, seeds=seeds)
        spreads[width] = np.sqrt(sigma.astype(np.float64) ** 2 - shift[0].astype(np.float64) ** 2)
        if seeds > 1:
            z = (err - shift[0]) / spreads[width]
            assert 0.85 < z.std() < 1.15, z.std()  # 8 seeds x ~140 outline pixels
    assert 0.8 < cos_i.min() and cos_i.max() < 0.99  # the laser is 150 mm aside: both sides differ
    np.testing.assert_allclose(spreads[3.0] / spreads[2.0], law(3.0, cos_i) / law(2.0, cos_i), rtol=0.01)
