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

Random numbers come from a PCG32 stream per pixel (sequence = pixel index) whose state is
drawn from the caller's ``numpy.random.Generator``: a pixel's noise depends only on the seed
and its index, and the same on every backend.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from rangesim.core.backend import mitsuba


def speckle_sigma_mm(points, sources, contrast: float, wavelength_nm: float, aperture_mm: float):
    """Speckle-limited depth uncertainty (mm) per point (Dorsch et al. 1994).

    Parameters
    ----------
    points, sources : mi.Vector3f
        Surface points and laser source positions, camera frame, mm.
    contrast : float
        Speckle contrast C (1 for fully developed speckle, 0 disables).
    wavelength_nm, aperture_mm : float
        Laser wavelength and lens entrance-pupil diameter.
    """
    mi = mitsuba()
    if contrast == 0:
        return dr.zeros(mi.Float, dr.width(points))
    d_camera = dr.norm(points)
    half = 0.5 * aperture_mm
    sin_u = half * dr.rsqrt(half * half + d_camera * d_camera)
    sin_theta = dr.norm(dr.cross(points / d_camera, dr.normalize(sources - points)))
    return contrast * (wavelength_nm * 1e-6) / (2 * math.pi * sin_u * sin_theta)


def pixel_random(rng: np.random.Generator, n_pixels: int):
    """Per-pixel standard normal and uniform [0, 1) draws, (mi.Float, mi.Float)."""
    mi = mitsuba()
    state = int(rng.integers(0, 2**63))
    # opaque: a literal state would compile a new kernel for every seed
    pcg = mi.PCG32(size=n_pixels, initstate=dr.opaque(mi.UInt64, state), initseq=dr.arange(mi.UInt64, n_pixels))
    u1, u2, phase = pcg.next_float32(), pcg.next_float32(), pcg.next_float32()
    gaussian = mi.warp.square_to_std_normal(mi.Point2f(u1, u2)).x
    return gaussian, phase


def peak_error_px(sigma_px, quantization_px: float, gaussian, phase):
    """Peak localisation error (pixels).

    Parameters
    ----------
    sigma_px : mi.Float or float
        Std of the Gaussian part, pixels.
    quantization_px : float
        Quantisation step q, pixels (0: none).
    gaussian, phase : mi.Float
        Standard normal draws and uniform [0, 1) draws (the quantiser phase).
    """
    error = sigma_px * gaussian
    if quantization_px > 0:
        offset = phase * quantization_px  # where the true peak sits on the quantiser grid
        error = quantization_px * dr.round((offset + error) / quantization_px) - offset
    return error
