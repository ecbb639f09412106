"""Stripe-peak localisation error on the sensor, in pixels along the image row.

Three terms, all moving the detected peak along the row (across the stripe):

* Gaussian localisation noise of std ``noise.sigma_px`` (pixels): detector noise and
  the sub-pixel peak estimator.
* Speckle (optional, ``noise.speckle_contrast`` C > 0): the speckle limit of laser
  triangulation (Dorsch, Haeusler & Herrmann, Applied Optics 33(7), 1994),
  delta_z = C lambda / (2 pi sin(u_obs) sin(theta)), with u_obs the observation aperture
  half-angle (sin u_obs = (D/2) / distance, D = ``camera.aperture_mm``) and theta the
  triangulation angle between the camera ray and the laser ray. Converted to pixels
  through |dz/du| and added in quadrature.
* Quantisation of the peak position to steps of ``noise.quantization_px`` pixels. The true
  peak falls at a random phase of the quantisation grid, so the error is uniform in
  [-q/2, q/2] (std q / sqrt(12)) when the other terms vanish.
"""
from __future__ import annotations

import numpy as np


def speckle_sigma_mm(points, sources, contrast, wavelength_nm, aperture_mm):
    """Speckle-limited depth uncertainty (mm) per point (Dorsch et al. 1994).

    Parameters
    ----------
    points, sources : (N, 3) float arrays
        Surface points and laser source positions, camera frame, mm.
    contrast : float
        Speckle contrast C (1 for fully developed speckle, 0 disables).
    wavelength_nm, aperture_mm : float
        Laser wavelength and lens entrance-pupil diameter.
    """
    if contrast == 0:
        return np.zeros(len(points))
    d_camera = np.linalg.norm(points, axis=1)
    half = 0.5 * aperture_mm
    sin_u = half / np.hypot(half, d_camera)
    view = -points / d_camera[:, None]
    light = sources - points
    light /= np.linalg.norm(light, axis=1)[:, None]
    sin_theta = np.linalg.norm(np.cross(view, light), axis=1)
    wavelength_mm = wavelength_nm * 1e-6
    with np.errstate(divide="ignore"):
        return contrast * wavelength_mm / (2 * np.pi * sin_u * sin_theta)


def peak_error_px(sigma_px, quantization_px, gaussian, phase):
    """Peak localisation error (pixels) from pre-drawn random numbers.

    Parameters
    ----------
    sigma_px : (N,) float array or float
        Std of the Gaussian part, pixels.
    quantization_px : float
        Quantisation step q, pixels (0: none).
    gaussian, phase : (N,) float arrays
        Standard normal draws and uniform [0, 1) draws (the quantiser phase).
    """
    error = sigma_px * gaussian
    if quantization_px > 0:
        offset = phase * quantization_px  # where the true peak sits on the quantiser grid
        error = quantization_px * np.round((offset + error) / quantization_px) - offset
    return error
