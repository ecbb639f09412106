"""Six sensor effects checked against closed-form expectations (audit 13).

Each test states its law, its units and where the numbers come from; every expectation is
computed here from the scene's geometry, not read back from the scanner's own arithmetic.

1. structured light: the disparity noise sigma_d (px) of the block matcher on near-fronto planes
   at three distances is constant and equals ``matching_sigma_px``'s closed form;
2. structured light: the IR image's mean and variance (electrons): shot, speckle and read noise;
3. laser stripe: the optics' blur ``camera.psf_px`` in the imaged stripe width and the noise;
4. laser stripe: a truncated stripe's dimming Phi(t) drops exactly the outline column;
5. laser stripe: camera occlusion behind a box, x_e h / (D - h);
6. laser stripe: the Dorsch speckle limit widened by sqrt(w / w0).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.constants import Status
from rangesim.sensor import stripe_noise as sn
from rangesim.sensor.matching_noise import matching_sigma_px
from rangesim.sensor.structured_light import ir_image, matching_setup
from tests.conftest import box, make_sensor, plane, top_down_pose

#: FWHM / std of a Gaussian, 2 sqrt(2 ln 2)
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
#: the default albedo of a scene object (rs.load_scene)
ALBEDO = 0.6


def _Phi(t):
    """Standard normal CDF (NumPy arrays)."""
    from scipy.special import ndtr

    return ndtr(t)


# 1. structured-light disparity noise ----------------------------------------------------------
@pytest.mark.parametrize("steps", [8, 1])
def test_structured_light_disparity_noise_is_constant_over_range_and_equals_the_matching_law(steps):
    """The block matcher's disparity error (px) does not depend on the distance and equals
    the model's law (``rangesim.sensor.matching_noise``):

        sigma_d = sqrt(s0^2 - (1/8)^2 / 12 + q^2 / 12 + (a s)^2 + (c s^2)^2)   px,
        q = 1 / subpixel_steps px, s = window * g px, g the disparity gradient (px / px),

    with the ``kinect_v1`` constants (s0 = 0.078 px, a = 0.043, c = 0.022 / px, window 9).
    The measured error is e_d = f b / z_measured - f b / z_true (px); unlike
    e_z ~ z^2 e_d / (f b) it is not a linearisation, so this is not circular.

    Well-posedness: on an exactly fronto-parallel plane every pixel has the same true
    disparity, so its rounding to the 1/q grid and any sub-pixel (pixel-locking)
    bias are one constant offset, not a spread. The plane is therefore tilted about the
    camera's y axis so that its disparity (affine in the pixel on a plane, gradient
    g = b tan(t) / z0) sweeps exactly 2 px across the W-px image, g = 2 / W: the true
    disparity's phase then runs uniformly over every rounding quantum (16 quanta at 1/8 px,
    2 at whole pixels) and twice over the pixel-locking period, while the slant term
    a s = 0.043 * 9 * 2 / 256 = 0.003 px adds 0.1 % in quadrature. Distances 900, 2000, 3500 mm
    span the preset's 500-4000 mm working range (disparities 24, 11, 6 px at 256 px).
    ``steps = 1`` rounds to whole pixels: the law's q^2 / 12 = 1/12 px^2 term then dominates
    (0.297 px against 0.078 px), which tests the quantisation term on its own.
    """
    W, H = 256, 192
    sensor = rs.load_sensor("kinect_v1").with_params({
        "camera.width": W, "camera.height": H, "structured_light.subpixel_steps": steps})
    sl = sensor.params["structured_light"]
    b = sensor.params["laser"]["baseline"]
    fb = sensor.focal_px * abs(b)
    g = 2.0 / W
    s = sl["window"] * g
    s0, a, c = sl["match_sigma_px"], sl["slant_linear"], sl["slant_quadratic"]
    expected = math.sqrt(s0**2 - (1 / 8) ** 2 / 12 + (1 / steps) ** 2 / 12 + (a * s) ** 2 + (c * s * s) ** 2)
    # the model's own function is that closed form
    assert float(matching_sigma_px(g, sl["window"], s0, a, c, steps)) == pytest.approx(expected, rel=1e-12)
    measured = {}
    for z in (900.0, 2000.0, 3500.0):
        tilted = plane(8 * z)
        tilted.apply_transform(trimesh.transformations.rotation_matrix(math.atan(g * z / abs(b)), [0, 1, 0]))
        scan = rs.scan([tilted], sensor, pose=top_down_pose(z), seed=0)
        ok = scan.valid & np.isfinite(scan.xyz_true[..., 2])
        assert ok.sum() > 0.5 * W * H
        e_d = fb / scan.depth[ok].astype(np.float64) - fb / scan.xyz_true[..., 2][ok].astype(np.float64)
        gross = np.abs(e_d) > 2.0  # chance matches are not the noise law's business; there are none
        assert gross.mean() < 0.005
        measured[z] = float(np.std(e_d[~gross]))
    for z, sigma_d in measured.items():
        assert sigma_d == pytest.approx(expected, rel=0.10), (z, sigma_d, expected)
    assert max(measured.values()) / min(measured.values()) < 1.10, measured


# 2. the structured-light IR image -----------------------------------------------------------------
def _ir_sensor():
    # ambient high enough (120 e- on albedo 0.6) that no dark pixel is clipped at 0 electrons, and
    # a full well no pixel reaches: the law below is the unclipped one; independent dots, whose
    # gaps leave pixels dark enough to test the law's dark end on (2 px spaced dots leave few)
    return rs.load_sensor("kinect_v1").with_params({
        "camera.width": 256, "camera.height": 192, "structured_light.ambient": 0.1, "camera.full_well_e": 1e6,
        "structured_light.dot_min_spacing_px": 0.0})


def test_ir_image_moments_are_shot_speckle_and_read_noise():
    """``structured_light.ir_image`` on uniform inputs: pattern term P and ambient term A
    (relative irradiance, dimensionless), exposure E (e- per unit), speckle contrast C
    (unit-mean Gamma on the pattern term), Poisson shot noise, read noise R (e- rms):

        mean = E (P + A)   e-,
        var  = E (P + A) + (C E P)^2 + R^2   e-^2

    (a Poisson variable of random mean L has variance E[L] + Var[L]; Var[E P X] = (C E P)^2).
    200,000 samples per level: the mean within 4 standard errors, the variance within 3 %."""
    sensor = _ir_sensor()
    E = sensor.params["structured_light"]["exposure_e"]
    C = sensor.params["noise"]["speckle_contrast"]
    R = sensor.params["camera"]["read_noise_e"]
    assert (E, C, R) == (2000.0, 0.3, 8.0)
    n, ambient = 200_000, 0.05
    for P in (0.0, 0.2, 1.0):
        e = ir_image(np.random.default_rng(11), np.full(n, P), np.full(n, ambient), sensor)
        mean = E * (P + ambient)
        var = E * (P + ambient) + (C * E * P) ** 2 + R**2
        assert abs(e.mean() - mean) < 4 * math.sqrt(var / n), (P, e.mean(), mean)
        assert e.var() == pytest.approx(var, rel=0.03), (P, e.var(), var)


def test_ir_image_of_a_tilted_plane_follows_the_irradiance_law_pixel_by_pixel():
    """A plane tilted 30 deg about the camera's y axis, 1200 mm away (z_ref = 2250 mm): each
    pixel's IR value (``scan.intensity`` x E, electrons) against the stated model,

        mean_p = E (albedo cos i (z_ref / d_L)^2 pattern(x_p, y_p) + albedo ambient)   e-,
        var_p  = mean_p + (C E albedo cos i (z_ref / d_L)^2 pattern)^2 + R^2   e-^2,

    i the incidence of the projector's ray from L = (b, 0, 0), d_L the distance to it (mm),
    pattern the device's dot pattern sampled where the surface point projects into the
    projector, x_p = f (X - b) / Z + c_x, y_p = f Y / Z + c_y (px). Over the whole image the
    standardised residuals (e - mean_p) / sqrt(var_p) have mean 0 and std 1; so do they on
    the dots (speckle-dominated) and between them (shot and read noise only)."""
    sensor = _ir_sensor()
    p = sensor.params
    sl = p["structured_light"]
    E, C, R = sl["exposure_e"], p["noise"]["speckle_contrast"], p["camera"]["read_noise_e"]
    b, K = p["laser"]["baseline"], sensor.K
    f, z_ref, z = K[0, 0], sensor.reference_distance, 1200.0
    tilted = plane(8 * z)
    tilted.apply_transform(trimesh.transformations.rotation_matrix(math.radians(30), [0, 1, 0]))
    scan = rs.scan([tilted], sensor, pose=top_down_pose(z), seed=2)
    P = scan.xyz_true.reshape(-1, 3).astype(np.float64)
    normal = scan.normal.reshape(-1, 3).astype(np.float64)
    assert np.isfinite(P).all() and (scan.status != Status.SHADOW).all()
    to_projector = np.array([b, 0.0, 0.0]) - P
    d_L = np.linalg.norm(to_projector, axis=1)
    cos_i = np.einsum("ij,ij->i", normal, to_projector) / d_L
    x_p = f * (P[:, 0] - b) / P[:, 2] + K[0, 2]
    y_p = f * P[:, 1] / P[:, 2] + K[1, 2]
    pattern_term = ALBEDO * cos_i * (z_ref / d_L) ** 2 * matching_setup(sensor).pattern.sample(x_p, y_p)
    assert cos_i.min() < 0.6 and (z_ref / d_L).max() ** 2 > 4.0  # the law varies across the image
    mean = E * (pattern_term + ALBEDO * sl["ambient"])
    var = mean + (C * E * pattern_term) ** 2 + R**2
    electrons = scan.intensity.reshape(-1).astype(np.float64) * E
    resid = (electrons - mean) / np.sqrt(var)
    assert abs(resid.mean()) < 0.02 and resid.std() == pytest.approx(1.0, abs=0.02)
    dots = pattern_term > 0.1 * pattern_term.max()
    dark = pattern_term < 1e-3 * ALBEDO * sl["ambient"]
    assert dots.sum() > 1000 and dark.sum() > 1000
    assert electrons[dots].mean() / mean[dots].mean() == pytest.approx(1.0, abs=0.02)
    assert resid[dots].std() == pytest.approx(1.0, abs=0.07)
    assert resid[dark].std() == pytest.approx(1.0, abs=0.05)


# helpers for the laser-stripe scans of a plane facing the camera ------------------------------------
def _plane_law(scan, sensor):
    """Per-pixel geometry of a plane facing the camera (normal (0, 0, -1), camera frame), flat:
    d_C, d_L (mm), cos i, sin theta (angle between the camera ray and the laser ray)."""
    b = sensor.params["laser"]["baseline"]
    P = scan.xyz_true.reshape(-1, 3).astype(np.float64)
    to_laser = np.array([b, 0.0, 0.0]) - P
    d_L, d_C = np.linalg.norm(to_laser, axis=1), np.linalg.norm(P, axis=1)
    cos_i = P[:, 2] / d_L
    sin_theta = np.linalg.norm(np.cross(P / d_C[:, None], to_laser / d_L[:, None]), axis=1)
    return P, d_C, d_L, cos_i, sin_theta


def _width_ratio(sensor, P):
    """w / w0 from the stated law on a plane facing the camera (normal (0, 0, -1)) under the
    rotating sheet (sensor params: stripe FWHM s mm, blur psf px, f px): the imaged stripe is
    s / a px, a the mm of the sheet's thickness one pixel along the row crosses. On the plane
    a pixel step moves the point by z / f mm along x (not d_C / f: the rays crowd towards the
    image's edges), and the sheet through P and L = (b, 0, 0) holding the y axis has the unit
    normal (-z, 0, x - b) / sqrt(z^2 + (x - b)^2), so a = z^2 / (f sqrt(z^2 + (x - b)^2))."""
    f, z_ref = sensor.K[0, 0], sensor.reference_distance
    b = sensor.params["laser"]["baseline"]
    s, psf = sensor.params["laser"]["stripe_width"], sensor.params["camera"]["psf_px"]
    x, z = P[:, 0], P[:, 2]
    a = z**2 / (f * np.sqrt(z**2 + (x - b) ** 2))
    w = np.sqrt(psf**2 + (s / a) ** 2)
    w0 = math.sqrt(psf**2 + (f * s / z_ref) ** 2)
    return w / w0


def _zscores(scan, sigma_z):
    err = scan.depth.reshape(-1).astype(np.float64) - scan.xyz_true[..., 2].reshape(-1)
    v = scan.valid.reshape(-1)
    assert v.all()
    return err[v] / sigma_z[v]


# 3. lens blur psf_px ----------------------------------------------------------------------------
def test_stripe_width_px_adds_blur_and_footprint_in_quadrature():
    """w = sqrt(psf^2 + (m s / cos i)^2) px (FWHM): with no sheet thickness the imaged
    stripe is the blur alone (w = psf whatever the incidence and magnification); with both,
    a 3-4-5 triangle: psf = 3 px, m s / cos i = 0.8 px/mm * 2.5 mm / 0.5 = 4 px -> w = 5 px."""
    cos = np.array([1.0, 0.5, 0.1])
    np.testing.assert_allclose(sn.stripe_width_px(cos, np.array([0.3, 1.0, 4.0]), 0.0, 2.0), [2.0, 2.0, 2.0],
                               rtol=1e-12)
    assert float(sn.stripe_width_px(np.array([0.5]), 0.8, 2.5, 3.0)[0]) == pytest.approx(5.0, rel=1e-12)
    assert float(sn.stripe_width_px(np.array([0.5]), 0.8, 2.5, 0.0)[0]) == pytest.approx(4.0, rel=1e-12)


@pytest.mark.parametrize("z", [250.0, 900.0])
def test_blur_sets_the_signal_limited_noise_on_a_plane(z):
    """Signal-limited peak error (px) on a plane facing the camera at z mm (white noise,
    ``correlation_mm`` 0, every other term off):

        sigma_u = signal_px sqrt(w / w0) / A,  A = albedo cos i (z_ref / d_L)^2,
        w  = sqrt(psf^2 + (s / a)^2),  w0 = sqrt(psf^2 + (f s / z_ref)^2)   px,

(a = z^2 / (f sqrt(z^2 + (x - b)^2)), :func:`_width_ratio`)

    and, for the rotating sheet (the plane through L = (b, 0, 0) holding P and the y axis),
    a peak moved by e px moves the point along the ray to z = b / ((u + e) / f - k): on a
    fronto-parallel plane dz/du = z^2 / (f b) at every pixel, so sigma_z = z^2 sigma_u / (f b) mm.
    s = 2.5 mm, f s / z_ref = 1 px; psf = 2 px. At 250 mm the footprint widens the stripe
    (w / w0 = 1.45; 2.56 without the blur, 1.15 with psf 4), at 900 mm narrows it (0.94; 0.62
    without the blur): the measured depth error over this sigma_z has std 1 within 3 %,
    and ``scan.sigma`` is that law."""
    sensor = make_sensor(**{"noise.signal_px": 0.05, "laser.stripe_width": 2.5, "camera.psf_px": 2.0})
    f, b, z_ref = sensor.K[0, 0], sensor.params["laser"]["baseline"], sensor.reference_distance
    assert f * 2.5 / z_ref == pytest.approx(1.0, rel=0.01)
    scan = rs.scan([plane()], sensor, pose=top_down_pose(z), seed=1)
    P, d_C, d_L, cos_i, _ = _plane_law(scan, sensor)
    sigma_u = 0.05 * np.sqrt(_width_ratio(sensor, P)) / (ALBEDO * cos_i * (z_ref / d_L) ** 2)
    sigma_z = P[:, 2] ** 2 * sigma_u / (f * b)
    zs = _zscores(scan, sigma_z)
    assert zs.std() == pytest.approx(1.0, abs=0.03) and abs(zs.mean()) < 0.05
    np.testing.assert_allclose(scan.sigma.reshape(-1), sigma_z, rtol=1e-3)


@pytest.mark.parametrize("tilt_deg", [-35.0, 35.0])
def test_an_oblique_view_foreshortens_the_imaged_stripe(tilt_deg):
    """The imaged stripe is as wide as the sheet's thickness s spans along the row:
    w = s / a px (psf 0), a the mm of the sheet's thickness that one pixel along the row
    crosses, a = |n_s . dP/du|, measured here from the scan's true points (the central
    difference of the neighbouring pixels' points) and the rotating sheet's normal n_s
    through P and L = (b, 0, 0). On a plane tilted by t about the camera's y axis, at the
    image centre, this is the footprint s / cos i seen foreshortened by the viewing angle
    e = t: w = (f / z) s cos e / cos i (within 1 %; without the cosine of the view the width
    is 1 / cos 35 deg = 1.22x too large). The signal-limited term follows it,
    sigma_u = signal_px sqrt(w / w0) / A, and the depth std is sigma_u dz/du with
    dz/du = z |n_s,x| / (f |n_s . r|), r the pixel's ray with unit z (the peak moved along
    the row triangulated against the same sheet)."""
    s_mm, z = 2.5, 400.0
    sensor = make_sensor(**{"noise.signal_px": 0.05, "laser.stripe_width": s_mm, "camera.psf_px": 0.0})
    f, b, z_ref = sensor.K[0, 0], sensor.params["laser"]["baseline"], sensor.reference_distance
    t = math.radians(tilt_deg)
    tilted = plane(size=600.0).apply_transform(trimesh.transformations.rotation_matrix(-t, [0, 1, 0]))
    scan = rs.scan([tilted], sensor, pose=top_down_pose(z), seed=1)
    H, W = scan.depth.shape
    i, j = H // 2, W // 2
    P = scan.xyz_true.astype(np.float64)
    p = P[i, j]
    n = np.array([-math.sin(t), 0.0, -math.cos(t)])  # the plane's normal towards the camera, camera frame
    measured = np.cross(P[i + 1, j] - p, P[i, j + 1] - p)
    np.testing.assert_allclose(measured / np.linalg.norm(measured), n, atol=1e-4)
    n_s = np.array([-p[2], 0.0, p[0] - b]) / math.hypot(p[2], p[0] - b)
    a = abs(n_s @ (P[i, j + 1] - P[i, j - 1]) / 2)
    to_laser = np.array([b, 0.0, 0.0]) - p
    d_L = np.linalg.norm(to_laser)
    cos_i = abs(n @ to_laser) / d_L
    w = s_mm / a
    view = -n @ p / np.linalg.norm(p)
    assert w == pytest.approx(f / p[2] * s_mm * view / cos_i, rel=0.01)
    assert view == pytest.approx(math.cos(t), rel=0.01)
    w0 = f * s_mm / z_ref
    sigma_u = 0.05 * math.sqrt(w / w0) / (ALBEDO * cos_i * (z_ref / d_L) ** 2)
    r = p / p[2]
    dz_du = p[2] * abs(n_s[0]) / (f * abs(n_s @ r))
    assert float(scan.sigma[i, j]) == pytest.approx(sigma_u * dz_du, rel=2e-3)


def test_blur_alone_leaves_the_noise_at_its_facing_value():
    """With no sheet thickness (s = 0) the imaged stripe is the blur, w = w0 = psf at every
    pixel, so sigma_u = signal_px / A (px) whatever the blur: psf 2 and psf 4 give the same
    scan, and its error follows z^2 sigma_u / (f b) (std of the z-scores 1 within 3 %)."""
    scans = {}
    for psf in (2.0, 4.0):
        sensor = make_sensor(**{"noise.signal_px": 0.05, "laser.stripe_width": 0.0, "camera.psf_px": psf})
        scans[psf] = rs.scan([plane()], sensor, pose=top_down_pose(300.0), seed=1)
    np.testing.assert_array_equal(scans[2.0].depth, scans[4.0].depth)
    f, b, z_ref = sensor.K[0, 0], sensor.params["laser"]["baseline"], sensor.reference_distance
    P, _, d_L, cos_i, _ = _plane_law(scans[2.0], sensor)
    sigma_z = P[:, 2] ** 2 * 0.05 / (ALBEDO * cos_i * (z_ref / d_L) ** 2) / (f * b)
    assert _zscores(scans[2.0], sigma_z).std() == pytest.approx(1.0, abs=0.03)


# 4. truncated-stripe dimming at scan level ---------------------------------------------------------
def test_truncated_stripe_dimming_drops_exactly_the_outline_column():
    """A 30 x 60 mm plate facing the camera at 350 mm with nothing behind it. The stripe
    (FWHM s, std on the surface sigma_s = s / (2.355 cos i) mm) is cut by the plate's left and
    right outlines, which cross the rows; the model puts the border half a cell beyond the
    last plate pixel, so the k-th pixel from the outline (k = 0 the outline pixel) lies
    delta_k = (k + 1/2) d_C / f mm from it, t_k = delta_k / sigma_s, and keeps the share
    Phi(t_k) of its light: the detected return is S Phi(t_k) with
    S = albedo cos i cos e (z_ref / d_L)^2 (z_ref / d_C)^2. s is chosen so that t_0 = 1/2 on
    the axis (Phi = 0.69, t_1 = 3/2: Phi = 0.93; S varies 11 % over the plate), and
    ``min_signal`` halfway between max S Phi(t_0) and min S Phi(t_1) over the plate: exactly
    the left and right outline pixels of every row drop out (status 3), nothing else; the
    top and bottom outlines run along the rows and cut nothing."""
    z, b = 350.0, 150.0
    sensor = make_sensor()
    f, z_ref = sensor.K[0, 0], sensor.reference_distance
    cos_axis = z / math.hypot(z, b)
    s = FWHM_PER_SIGMA * cos_axis * (z / f)  # sigma_s = one footprint z / f: t_0 = 1/2 on the axis
    plate = plane(1.0)
    plate.apply_scale([30.0, 60.0, 1.0])

    def scan_with(min_signal, width=s):
        sensor = make_sensor(**{"laser.stripe_width": width, "noise.min_signal": min_signal})
        return rs.scan([plate], sensor, pose=top_down_pose(z), seed=0)

    whole = scan_with(0.0)
    hit = whole.status != Status.MISS
    assert whole.valid[hit].all() and 30 < hit.any(1).sum() and hit.sum(1).max() > 15
    P = whole.xyz_true.astype(np.float64)
    to_laser = np.array([b, 0.0, 0.0]) - P
    d_L, d_C = np.linalg.norm(to_laser, axis=2), np.linalg.norm(P, axis=2)
    cos_i, cos_e = P[..., 2] / d_L, P[..., 2] / d_C
    S = ALBEDO * cos_i * cos_e * (z_ref / d_L) ** 2 * (z_ref / d_C) ** 2
    k = np.full(hit.shape, -1)
    for i in np.flatnonzero(hit.any(1)):
        cols = np.flatnonzero(hit[i])
        assert np.all(np.diff(cols) == 1)
        k[i, cols] = np.minimum(cols - cols[0], cols[-1] - cols)
    t = (k + 0.5) * (d_C / f) / (s / (FWHM_PER_SIGMA * cos_i))
    dimmed = S * _Phi(t)
    top0, bottom1 = dimmed[k == 0].max(), dimmed[k == 1].min()
    assert top0 < bottom1  # a threshold between the two columns exists
    min_signal = 0.5 * (top0 + bottom1)
    scan = scan_with(min_signal)
    dropout = scan.status == Status.DROPOUT
    np.testing.assert_array_equal(dropout, hit & (k == 0))
    np.testing.assert_array_equal(dropout[hit], dimmed[hit] < min_signal)
    assert scan.valid[hit & (k >= 1)].all()


def test_an_occluding_edge_over_a_measured_floor_cuts_the_stripe_as_an_outline_does():
    """The same plate 150 mm above a floor. Its right outline now borders the lit floor, not
    empty space (its left one borders the laser shadow it casts on the floor, as before): the
    stripe's light past the outline falls on the floor delta / a ~ 150 sin(alpha) / 1.46 ~ 40 px
    away along the row, outside the peak detector's +-16 px window, so the plate's stripe is cut
    there exactly as over nothing. Until an independent review found it, only unmeasurable
    cells were borders: over a floor the outline column was neither dimmed nor given the edge
    term. Now the plate's pixels drop out (min_signal between the outline column's and the next
    one's dimmed returns, as in the test above) and carry the predicted std (edge_gain 1:
    sigma_edge = m sigma_s phi(t) / Phi(t)) exactly as without the floor. A step whose light
    stays inside the window cuts nothing (the mixed pixels' centroid takes it): a 0.2 mm ledge
    gets no edge term."""
    z, b = 350.0, 150.0
    sensor = make_sensor()
    f = sensor.K[0, 0]
    s = FWHM_PER_SIGMA * z / math.hypot(z, b) * (z / f)
    plate = plane(1.0)
    plate.apply_scale([30.0, 60.0, 1.0])
    floor = plane(2000.0, z=-150.0)
    probe = rs.scan([plate], make_sensor(**{"laser.stripe_width": s}), pose=top_down_pose(z), seed=0)
    S = probe.intensity[probe.status == Status.VALID]  # the undimmed return (t_0 ~ 1/2, t_1 ~ 3/2)
    threshold = 0.5 * (S.max() * _Phi(0.5) + S.min() * _Phi(1.5))
    scans = {}
    for name, meshes in (("alone", [plate]), ("floor", [plate, floor])):
        for min_signal in (0.0, threshold):
            quiet = make_sensor(**{"laser.stripe_width": s, "noise.min_signal": min_signal, "noise.edge_gain": 1.0})
            scans[name, min_signal] = rs.scan(meshes, quiet, pose=top_down_pose(z), seed=0)
    # the right half: at the left outline the sheet that grazes the plate's corner lands on the
    # floor at the end of the plate's laser shadow, ~12 px away, inside the 16 px window, and
    # that light mixes in (a phantom point, rangesim.sensor.mixed_pixels: not this test's law)
    on_plate = (np.abs(scans["alone", 0.0].xyz_true[..., 2] - z) < 1e-3) & (scans["alone", 0.0].xyz_true[..., 0] > 0)
    assert on_plate.sum() > 200
    for min_signal in (0.0, threshold):
        a, b_ = scans["alone", min_signal], scans["floor", min_signal]
        np.testing.assert_array_equal(a.status[on_plate], b_.status[on_plate])
        both = on_plate & a.valid
        np.testing.assert_allclose(b_.sigma[both], a.sigma[both], rtol=1e-5)
    dropped = scans["floor", threshold].status[on_plate] == Status.DROPOUT
    assert 30 < dropped.sum() < on_plate.sum() / 3  # the outline column, not the plate
    # the right outline borders lit, measured floor
    h = a.shape[0] // 2
    right = np.flatnonzero(on_plate[h])[-1]
    assert scans["floor", 0.0].valid[h, right + 1:right + 4].all()
    # a 0.2 mm ledge: the same sigma with and without the edge term
    ledge = [plate.copy().apply_translation([0, 0, 0.2]), plane(2000.0)]
    sig = {g: rs.scan(ledge, make_sensor(**{"laser.stripe_width": s, "noise.edge_gain": g}),
                      pose=top_down_pose(z), seed=0).sigma for g in (0.0, 1.0)}
    np.testing.assert_array_equal(sig[0.0], sig[1.0])


# 5. camera occlusion ------------------------------------------------------------------------------------
@pytest.mark.parametrize("D, h, x1, x2", [(400.0, 100.0, 20.0, 80.0), (600.0, 150.0, 30.0, 100.0)])
def test_camera_occlusion_behind_a_box_is_x_e_h_over_D_minus_h(D, h, x1, x2):
    """A box x1 < x < x2, |y| < 40, height h (mm) on a floor, the camera D mm above the floor
    looking straight down, the laser at x = b = 150 mm > x2. Similar triangles through the
    camera centre: the ray over the box's top edge at (x_e = x2, D - h) meets the floor at
    x_e D / (D - h), so the camera cannot see the floor strip

        x_e < x < x_e D / (D - h),  width x_e h / (D - h)  mm

    (26.7 and 33.3 mm here). The first floor pixel seen beyond the box lies within one pixel
    footprint (D / f mm) of that strip's far end; the pixels whose rays would meet the floor
    in the strip see the lit box top instead (part 1, status 0: camera occlusion has no status
    of its own), while the laser shadow on the other side, (b - x1) h / (D - h) wide, has status 2."""
    sensor = make_sensor(**{"camera.width": 256, "camera.height": 192})
    f, b, cx = sensor.K[0, 0], sensor.params["laser"]["baseline"], sensor.K[0, 2]
    scan = rs.scan([plane(), box([x1, -40, 0], [x2, 40, h])], sensor, pose=top_down_pose(D), seed=0)
    rows = np.abs(scan.xyz_true[..., 1]) < 30
    x = scan.xyz_true[..., 0]
    footprint = D / f
    hidden = x2 * h / (D - h)
    floor_beyond = (scan.part == 0) & rows & (x > x2)
    seen_from = float(x[floor_beyond].min())
    assert 0.0 <= (seen_from - x2) - hidden < footprint, (seen_from - x2, hidden, footprint)
    # the rays that would meet the floor inside the hidden strip end on the box top, lit and valid
    floor_x = D * (np.arange(scan.shape[1]) + 0.5 - cx) / f
    strip = rows & ((floor_x > x2) & (floor_x < x2 + hidden))[None, :]
    assert strip.sum() > 10 * rows.any(1).sum()
    assert (scan.part[strip] == 1).all() and (scan.status[strip] == Status.VALID).all()
    assert np.allclose(scan.xyz_true[..., 2][strip], D - h, atol=1e-3)
    # the laser shadow is the other status: on the floor left of the box
    shadow = (scan.status == Status.SHADOW) & (scan.part == 0) & rows
    assert abs((x1 - x[shadow].min()) - (b - x1) * h / (D - h)) < 1.5 * footprint
    assert not (shadow & strip).any()


# 6. the Dorsch speckle limit and its sqrt(w / w0) widening ------------------------------------------
def test_dorsch_sigma_and_its_width_widening_in_the_model():
    """sigma = C lambda / (2 pi sin u_obs sin theta) mm, sin u_obs = (D/2) / sqrt((D/2)^2 + d^2)
    (Dorsch et al. 1994). At d = 400 mm, D = 6 mm, lambda = 670 nm, C = 1, sin theta = 0.35:
    sin u = 3 / 400.011 = 0.0075, sigma = 6.7e-4 / (2 pi 0.0075 0.35) = 0.0406 mm; it scales
    as C and lambda and (nearly) as d / D. A stripe w / w0 times the facing one holds that many
    more grains, whose centroid random walk widens the term: peak_sigma_px gives speckle_px
    sqrt(w / w0) (px) as the correlated term."""
    d = np.array([400.0, 800.0, 400.0])
    sin_t = np.array([0.35, 0.35, 0.7])
    sin_u = 3.0 / np.sqrt(9.0 + d**2)
    expected = 670e-6 / (2 * math.pi * sin_u * sin_t)
    np.testing.assert_allclose(sn.dorsch_sigma_mm(d, sin_t, 1.0, 670.0, 6.0), expected, rtol=1e-12)
    assert expected[0] == pytest.approx(0.0406, abs=5e-5)
    np.testing.assert_allclose(sn.dorsch_sigma_mm(d, sin_t, 0.5, 830.0, 6.0), expected * 0.5 * 830 / 670, rtol=1e-12)
    ratio = np.array([0.25, 1.0, 2.56, 9.0])
    speckle = np.array([0.1, 0.2, 0.3, 0.4])
    out = sn.peak_sigma_px(sn.StripeNoise(speckle_contrast=1.0), width_ratio=ratio, amplitude=np.ones(4),
                           speckle_px=speckle, edge_px=np.zeros(4))
    np.testing.assert_allclose(out["correlated"], speckle * np.sqrt(ratio), rtol=1e-12)
    np.testing.assert_allclose(out["total"], speckle * np.sqrt(ratio), rtol=1e-12)


@pytest.mark.parametrize("z", [250.0, 900.0])
def test_speckle_noise_of_a_wide_stripe_is_dorsch_times_sqrt_w_over_w0(z):
    """A plane facing the camera at z mm, only speckle on (C = 1, lambda 670 nm, aperture
    6 mm, white: ``correlation_mm`` 0), a 2.5 mm sheet and no blur (psf 0), so that
    w / w0 = z_ref / (f a) exactly (a as in :func:`_width_ratio`):

        sigma_z = C lambda / (2 pi sin u_obs sin theta) * cos(alpha) * sqrt(z_ref / (f a))   mm

    per pixel (d_C, d_L, sin theta = |r_C x r_L| from the geometry). Dorsch's limit is a
    displacement along the laser ray, and the scanner's error runs along that ray, so its
    depth (z) part is cos(alpha) of it, alpha the ray's angle from the optical axis
    (cos alpha = z / d_L). At 250 mm the width factor is about sqrt(2.56) = 1.60, at 900 mm
    sqrt(0.62) = 0.79: the measured error over this law has std 1 within 3 %, and
    ``scan.sigma`` is the law; and the 3D error along the laser ray is Dorsch's limit itself."""
    sensor = make_sensor(**{"noise.speckle_contrast": 1.0, "laser.stripe_width": 2.5, "camera.psf_px": 0.0})
    z_ref, f, b = sensor.reference_distance, sensor.K[0, 0], sensor.params["laser"]["baseline"]
    scan = rs.scan([plane()], sensor, pose=top_down_pose(z), seed=1)
    P, d_C, d_L, cos_i, sin_theta = _plane_law(scan, sensor)
    a = P[:, 2] ** 2 / (f * np.sqrt(P[:, 2] ** 2 + (P[:, 0] - b) ** 2))
    ratio = z_ref / (f * a)
    np.testing.assert_allclose(ratio, _width_ratio(sensor, P), rtol=1e-12)
    sin_u = 3.0 / np.sqrt(9.0 + d_C**2)
    dorsch = 1.0 * 670e-6 / (2 * math.pi * sin_u * sin_theta) * np.sqrt(ratio)
    sigma_z = dorsch * P[:, 2] / d_L
    # along the laser ray: the error vector's length over Dorsch's limit
    err3 = np.linalg.norm(scan.xyz.reshape(-1, 3).astype(np.float64) - P, axis=1)
    assert np.sqrt(np.mean((err3 / dorsch) ** 2)) == pytest.approx(1.0, abs=0.03)
    zs = _zscores(scan, sigma_z)
    assert zs.std() == pytest.approx(1.0, abs=0.03) and abs(zs.mean()) < 0.05
    np.testing.assert_allclose(scan.sigma.reshape(-1), sigma_z, rtol=1e-3)
