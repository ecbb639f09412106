"""Spacetime peak detection: the sweep position at which each pixel sees the stripe's centre.

A real scanner records, for every pixel, the intensity over the sweep (the temporal
profile) and reports the sheet that passed through the surface point at the profile's peak
(Curless & Levoy, "Better optical triangulation through spacetime analysis", ICCV 1995).
The peak is located to a fraction of a frame by fitting the three samples around the
brightest frame:

gaussian
    a Gaussian (a parabola through the logarithms), exact for a Gaussian profile:
    delta = (ln I- - ln I+) / (2 (ln I- - 2 ln I0 + ln I+)), and its width
    sigma^2 = -1 / (ln I- - 2 ln I0 + ln I+) (frames^2);
parabolic
    a parabola through the intensities: delta = (I- - I+) / (2 (I- - 2 I0 + I+)).

A run of saturated frames is located at its middle instead (the top is clipped).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Peaks:
    """Per-pixel peak of a frame stack.

    Attributes
    ----------
    position : (P,) float64
        Sub-frame position of the peak (frame units); NaN where there is no proper peak
        (brightest frame at the first or last frame, or a profile that is not log-concave).
    height : (P,) float32
        Brightest sample, electrons.
    sigma : (P,) float64
        Gaussian width of the peak, frames (NaN for the parabolic fit or a saturated run).
    saturated : (P,) bool
    """

    position: np.ndarray
    height: np.ndarray
    sigma: np.ndarray
    saturated: np.ndarray


def find_peaks(stack: np.ndarray, fit: str = "gaussian", full_well_e: float | None = None) -> Peaks:
    """Locate the temporal peak of every pixel.

    Parameters
    ----------
    stack : (P, F) array
        Frames per pixel, electrons.
    fit : {"gaussian", "parabolic"}
    full_well_e : float, optional
        Saturation level; frames at or above it form a saturated run.

    Returns
    -------
    Peaks
    """
    stack = np.asarray(stack, dtype=np.float64)
    n_pixels, n_frames = stack.shape
    rows = np.arange(n_pixels)
    top = np.argmax(stack, axis=1)
    height = stack[rows, top]
    inner = (top > 0) & (top < n_frames - 1)
    prev = stack[rows, np.clip(top - 1, 0, n_frames - 1)]
    nxt = stack[rows, np.clip(top + 1, 0, n_frames - 1)]
    sigma = np.full(n_pixels, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        if fit == "gaussian":
            positive = (prev > 0) & (height > 0) & (nxt > 0)
            lp, l0, ln = (np.log(np.where(positive, v, 1.0)) for v in (prev, height, nxt))
            curvature = lp - 2 * l0 + ln
            proper = inner & positive & (curvature < 0)
            delta = np.where(proper, 0.5 * (lp - ln) / curvature, np.nan)
            sigma = np.where(proper, np.sqrt(-1.0 / curvature), np.nan)
        elif fit == "parabolic":
            curvature = prev - 2 * height + nxt
            proper = inner & (curvature < 0)
            delta = np.where(proper, 0.5 * (prev - nxt) / curvature, np.nan)
        else:
            raise ValueError(f"unknown peak fit {fit!r}")
    position = top + delta
    saturated = np.zeros(n_pixels, dtype=bool)
    if full_well_e is not None:
        saturated = height >= full_well_e * (1 - 1e-6)
        if saturated.any():
            at = np.flatnonzero(saturated)
            full = stack[at] >= full_well_e * (1 - 1e-6)
            start, run = top[at], np.zeros(len(at), dtype=np.int64)
            ongoing = np.ones(len(at), dtype=bool)
            for k in range(1, n_frames):  # argmax is the run's first frame; count the rest
                frame = start + k
                ongoing &= frame < n_frames
                ongoing[ongoing] &= full[np.flatnonzero(ongoing), frame[ongoing]]
                run += ongoing
                if not ongoing.any():
                    break
            end = start + run
            position[at] = np.where((start > 0) & (end < n_frames - 1), 0.5 * (start + end), np.nan)
            sigma[at] = np.nan
    return Peaks(position, height.astype(np.float32), sigma, saturated)
