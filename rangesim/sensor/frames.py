"""The frame stack of the rendered scanner: stripe vertices spread over sweep positions, and
the camera's image noise.

Frame ``f`` has its sheet at sweep coordinate ``s_f = s_0 + f * ds``. A vertex at sweep
coordinate ``s`` lies ``d = lam * (s - s_f)`` mm from that sheet and receives the fraction
``g(d) = exp(-d^2 / (2 sigma_w^2))`` of the sheet's peak irradiance, with ``sigma_w`` the
sheet's Gaussian thickness (``laser.stripe_width`` is its FWHM, ``sigma_w = FWHM / 2.3548``).

Image noise (electrons, per pixel and frame, independent between frames):

* speckle: the signal is multiplied by a Gamma variate of mean 1 and variance C_pix^2
  (shape 1 / C_pix^2: the intensity of 1 / C_pix^2 independent speckle cells summed).
  A pixel integrates M = (footprint / grain)^2 speckle grains of the surface's contrast C
  (``noise.speckle_contrast``), so C_pix = C / sqrt(M) = C * grain / footprint (at most C),
  with grain = lambda / (2 sin u_obs) the speckle size on the surface (sin u_obs = (D/2) /
  distance, D = ``camera.aperture_mm``) and footprint = distance / f the pixel's size there
  (Goodman, "Speckle phenomena in optics", 2007, ch. 5: speckle integrated over an area);
* photon shot noise: Poisson with the mean number of photo-electrons;
* saturation: the well holds at most ``camera.full_well_e`` electrons;
* read noise: Gaussian, ``camera.read_noise_e`` electrons rms.
"""
from __future__ import annotations

import numpy as np

from rangesim.core import constants

#: FWHM of a Gaussian in units of its standard deviation
FWHM_PER_SIGMA = constants.FWHM_PER_SIGMA
#: vertices light the frames within this many sheet sigmas
PROFILE_CUTOFF = 4.5


def splat_frames(pixel: np.ndarray, weight: np.ndarray, s: np.ndarray, lam: np.ndarray, n_pixels: int,
                 s0: float, ds: float, n_frames: int, sigma_mm: float) -> np.ndarray:
    """Sum stripe vertices into a (n_pixels, n_frames) stack of relative intensities.

    Parameters
    ----------
    pixel, weight, s, lam : (M,) arrays
        See :class:`rangesim.sensor.stripe_paths.StripeVertices`.
    n_pixels : int
    s0, ds : float
        Sweep coordinate of frame 0 and the step between frames.
    n_frames : int
    sigma_mm : float
        Standard deviation of the sheet's thickness profile, mm.

    Returns
    -------
    (n_pixels, n_frames) float64
    """
    phi = (s - s0) / ds  # continuous frame index of each vertex
    sigma_f = sigma_mm / (lam * ds)  # profile std in frames
    inside = (phi > -PROFILE_CUTOFF * sigma_f) & (phi < n_frames - 1 + PROFILE_CUTOFF * sigma_f)
    pixel, weight, phi, sigma_f = pixel[inside], weight[inside], phi[inside], sigma_f[inside]
    stack = np.zeros(n_pixels * n_frames)
    if not len(phi):
        return stack.reshape(n_pixels, n_frames)
    half = int(min(np.ceil(PROFILE_CUTOFF * sigma_f.max()) + 1, n_frames))
    base = np.floor(phi).astype(np.int64)
    for k in range(-half + 1, half + 1):
        frame = base + k
        z = (frame - phi) / sigma_f
        ok = (frame >= 0) & (frame < n_frames) & (np.abs(z) <= PROFILE_CUTOFF)
        stack += np.bincount(pixel[ok] * n_frames + frame[ok], weight[ok] * np.exp(-0.5 * z[ok] ** 2),
                             minlength=n_pixels * n_frames)
    return stack.reshape(n_pixels, n_frames)


def expose(stack: np.ndarray, exposure_e: float, full_well_e: float, read_noise_e: float,
           speckle_contrast: float, rng: np.random.Generator | None) -> np.ndarray:
    """Electrons recorded per pixel and frame from relative intensities.

    Parameters
    ----------
    stack : (..., F) array
        Relative intensity (1 = the white reference target at the stripe's peak).
    exposure_e : float
        Mean electrons for relative intensity 1.
    full_well_e, read_noise_e : float
        Saturation level and read noise (rms), electrons.
    speckle_contrast : float or (P,) array
        Speckle contrast per pixel, C_pix (0: none); see :func:`pixel_speckle_contrast`.
    rng : numpy Generator or None
        None records the mean signal (no noise), still clipped at the full well.

    Returns
    -------
    float32 array of the stack's shape, electrons.
    """
    electrons = np.asarray(stack, dtype=np.float64) * exposure_e
    if rng is None:
        return np.minimum(electrons, full_well_e).astype(np.float32)
    lit = electrons > 0  # a frame the stripe does not reach holds no photons: only read noise
    signal = electrons[lit]
    contrast = np.broadcast_to(np.asarray(speckle_contrast, dtype=np.float64)[..., None], electrons.shape)[lit]
    speckled = contrast > 0
    if speckled.any():
        shape = 1.0 / contrast[speckled] ** 2
        signal[speckled] *= rng.gamma(shape, 1.0 / shape)
    electrons[lit] = rng.poisson(signal)
    np.minimum(electrons, full_well_e, out=electrons)
    out = electrons.astype(np.float32)
    if read_noise_e > 0:
        out += rng.standard_normal(out.shape, dtype=np.float32) * np.float32(read_noise_e)
    return out


def pixel_speckle_contrast(distance_mm: np.ndarray, contrast: float, wavelength_nm: float,
                           aperture_mm: float, focal_px: float) -> np.ndarray:
    """Speckle contrast a pixel records: the surface's contrast averaged over its footprint.

    Parameters
    ----------
    distance_mm : (P,) array
        Camera-to-surface distance per pixel, mm (NaN: no surface; returns 0 there).
    contrast : float
        Speckle contrast C of the surface (``noise.speckle_contrast``).
    wavelength_nm, aperture_mm, focal_px : float
        Laser wavelength, lens entrance-pupil diameter D, focal length in pixels.

    Returns
    -------
    (P,) float64: C * min(1, grain / footprint), grain = lambda d / D (small angles),
    footprint = d / f.
    """
    distance = np.nan_to_num(np.asarray(distance_mm, dtype=np.float64), nan=0.0)
    half = 0.5 * aperture_mm
    with np.errstate(divide="ignore", invalid="ignore"):
        sin_u = half / np.hypot(half, distance)
        grain = wavelength_nm * 1e-6 / (2.0 * sin_u)
        footprint = distance / focal_px
        out = contrast * np.minimum(1.0, grain / footprint)
    return np.where(distance > 0, out, 0.0)
