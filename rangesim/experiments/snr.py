"""Signal-to-noise ratio of the edges in a synthetic scan, per edge type.

Definitions (the README's figure draws them):

* **depth noise** ``sigma_z`` (mm): measured, not modelled. The error of the measured depth
  against the noise-free surface behind the same pixel, ``e = depth - xyz_true.z`` over the
  valid pixels, and its robust standard deviation ``1.4826 * median(|e - median(e)|)`` (a
  Gaussian's sigma from the median absolute deviation). Everything the scanner adds counts
  (stripe-peak jitter, speckle, quantisation); the few percent of mixed pixels at depth
  edges barely move the median. ``sigma_fp`` is the same statistic of ``e / (z / f)``: the
  noise in pixel footprints (``z / f`` mm, the lateral size of a pixel on the surface).
* **jump edge**: ``SNR = dz / sigma_z``, ``dz`` the step height at the edge pixel: the
  largest noise-free depth difference ``|z_true(q) - z_true(p)|`` to a neighbour ``q`` in
  the 8-neighbourhood that hits a surface (a jump to a pixel that hits nothing has no
  height and is left out).
* **crease** (convex or concave): ``SNR = |dg| / sigma_dg``. ``g = -(n_x, n_y) / (n . r)``
  is the surface's depth slope per millimetre of pixel footprint (``dz/du * f / z``, from
  the true normal ``n`` and the pixel's ray ``r = K^-1 (j + .5, i + .5, 1)``), and ``dg``
  its change across the crease: the largest ``|g(q) - g(p)|`` to an 8-neighbour ``q`` on
  the same object. The slope is estimated by a least-squares line through ``k`` pixels on
  each side of the crease (``k`` = ``window``, default 3), whose slope noise is
  ``sigma_slope = sigma_fp * sqrt(12 / (k (k^2 - 1)))`` (k samples one footprint apart),
  and the change of slope is the difference of two such independent estimates:
  ``sigma_dg = sqrt(2) * sigma_slope``.
* the scan's ``snr_jump`` and ``snr_crease`` are the medians over its true edge pixels of
  that type; the headline ``snr`` is the median over all of its true edge pixels (each
  with its own type's SNR): half the edge pixels a detector should find are at least that
  far above the noise.

A noise-free scan has ``sigma = 0`` and every SNR infinite; a scan without edges of a type
has NaN for it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError

#: default number of pixels on each side of a crease in the slope estimate
DEFAULT_WINDOW = 3
#: Gaussian sigma from the median absolute deviation
MAD_TO_SIGMA = 1.4826
#: fewest valid pixels that give a noise estimate (else NaN)
MIN_NOISE_PIXELS = 50


@dataclass(frozen=True)
class EdgeSNR:
    """SNR of one scan's edges (see the module docstring).

    Attributes
    ----------
    sigma_z : float
        Depth noise, mm (robust std of ``depth - xyz_true.z`` on valid pixels).
    sigma_fp : float
        Depth noise in pixel footprints (``z / f`` mm).
    snr_jump, snr_crease, snr : float
        Medians over the true jump, crease and all edge pixels; ``inf`` when the scan is
        noise-free, NaN without such edges.
    n_jump, n_crease : int
        Edge pixels that have an SNR (a step height or a slope change).
    per_pixel : (H, W) float32
        SNR of each true edge pixel, NaN elsewhere.
    window : int
        ``k`` of the slope estimate.
    """

    sigma_z: float
    sigma_fp: float
    snr_jump: float
    snr_crease: float
    snr: float
    n_jump: int
    n_crease: int
    per_pixel: np.ndarray
    window: int = DEFAULT_WINDOW

    def as_row(self) -> dict[str, float | int]:
        """The scalar fields, for a results table."""
        return {"sigma_z_mm": self.sigma_z, "sigma_fp": self.sigma_fp, "snr": self.snr,
                "snr_jump": self.snr_jump, "snr_crease": self.snr_crease,
                "n_jump_px": self.n_jump, "n_crease_px": self.n_crease}


def slope_noise_factor(window: int) -> float:
    """``sqrt(12 / (k (k^2 - 1)))``: std of a least-squares slope through ``k`` samples one
    unit apart, per unit of sample noise."""
    k = int(window)
    if k < 2:
        raise RangesimError(f"the slope window needs at least 2 pixels, got {window}")
    return math.sqrt(12.0 / (k * (k * k - 1)))


def _robust_sigma(e: np.ndarray) -> float:
    e = e[np.isfinite(e)]
    if e.size < MIN_NOISE_PIXELS:
        return float("nan")
    return float(MAD_TO_SIGMA * np.median(np.abs(e - np.median(e))))


def depth_noise(scan) -> tuple[float, float]:
    """Measured depth noise of a synthetic scan.

    Parameters
    ----------
    scan : RangeScan
        Needs ``xyz_true`` and ``meta["K"]``.

    Returns
    -------
    sigma_z : float
        Robust std of ``depth - xyz_true[..., 2]`` over valid pixels, mm.
    sigma_fp : float
        The same of ``(depth - z_true) / (z_true / f)``, pixel footprints, ``f`` =
        sqrt(fx fy).

    Raises
    ------
    ValueError
        Without ``xyz_true`` (a recorded scan has no truth to measure against).
    """
    if scan.xyz_true is None:
        raise RangesimError("depth noise needs a synthetic scan (xyz_true)")
    z_true = scan.xyz_true[..., 2].astype(np.float64)
    ok = scan.valid & np.isfinite(scan.depth) & np.isfinite(z_true) & (z_true > 0)
    e = scan.depth[ok].astype(np.float64) - z_true[ok]
    f = _focal(scan)
    return _robust_sigma(e), _robust_sigma(e * f / z_true[ok])


def _focal(scan) -> float:
    K = np.asarray(scan.meta["K"], dtype=np.float64)
    return float(math.sqrt(abs(K[0, 0] * K[1, 1])))


def _neighbour_max(value: np.ndarray, ok: np.ndarray, same: np.ndarray | None, fn) -> np.ndarray:
    """max over the 8 neighbours q of fn(value[q], value[p]) where ok[q] (and same[q] == same[p])."""
    h, w = ok.shape
    best = np.full((h, w), -np.inf)
    pad = 1
    vp = np.pad(value, [(pad, pad), (pad, pad)] + [(0, 0)] * (value.ndim - 2), mode="edge")
    okp = np.pad(ok, pad, constant_values=False)
    sp = None if same is None else np.pad(same, pad, constant_values=-2)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr == 0 and dc == 0:
                continue
            q = vp[pad + dr:pad + dr + h, pad + dc:pad + dc + w]
            okq = okp[pad + dr:pad + dr + h, pad + dc:pad + dc + w]
            if sp is not None:
                okq = okq & (sp[pad + dr:pad + dr + h, pad + dc:pad + dc + w] == same)
            with np.errstate(invalid="ignore"):
                d = fn(q, value)
            best = np.where(okq & np.isfinite(d) & (d > best), d, best)
    return best


def depth_slopes(scan) -> np.ndarray:
    """(H, W, 2) true depth slope per millimetre of pixel footprint along image x and y:
    ``-(n_x, n_y) / (n . r)``, ``r = K^-1 (j + .5, i + .5, 1)``; NaN where nothing is hit."""
    h, w = scan.shape
    K = np.asarray(scan.meta["K"], dtype=np.float64)
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rx = (jj - K[0, 2]) / K[0, 0]  # pinhole without skew, as every rangesim sensor
    ry = (ii - K[1, 2]) / K[1, 1]
    n = scan.normal.astype(np.float64)
    ndotr = n[..., 0] * rx + n[..., 1] * ry + n[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        g = -n[..., :2] / ndotr[..., None]
    return g


def edge_snr(scan, labels: np.ndarray, window: int = DEFAULT_WINDOW,
             noise: tuple[float, float] | None = None) -> EdgeSNR:
    """SNR of every true edge pixel of a synthetic scan, and per-type medians.

    Parameters
    ----------
    scan : RangeScan
        A synthetic scan (``xyz_true``, ``normal``, ``part``, ``meta["K"]``).
    labels : (H, W) uint8
        True :class:`~rangesim.core.constants.EdgeLabel` per pixel (e.g.
        ``rangesim.evaluate.runs.scan_truth(scan, scene).labels``).
    window : int
        ``k``, pixels on each side of a crease in the slope estimate (>= 2).
    noise : (sigma_z, sigma_fp), optional
        Depth noise in mm and in footprints; default :func:`depth_noise` of the scan.

    Returns
    -------
    EdgeSNR
    """
    labels = np.asarray(labels)
    if labels.shape != scan.shape:
        raise RangesimError(f"labels {labels.shape} and scan {scan.shape} differ in shape")
    if not isinstance(window, (int, np.integer)) or isinstance(window, bool) or 2 * int(window) + 1 > min(scan.shape):
        # k pixels on each side of the crease and the crease itself must fit the image
        raise RangesimError(f"snr_window must be a whole number of pixels with 2 k + 1 <= {min(scan.shape)} (the "
                            f"image's {scan.shape[1]} x {scan.shape[0]} px), got {window!r}")
    sigma_z, sigma_fp = depth_noise(scan) if noise is None else noise
    factor = slope_noise_factor(window)
    hit = (scan.part >= 0) & np.all(np.isfinite(scan.xyz_true), axis=-1)
    z = np.where(hit, scan.xyz_true[..., 2].astype(np.float64), np.nan)
    jump = (labels == EdgeLabel.JUMP) & hit
    crease = ((labels == EdgeLabel.CONVEX) | (labels == EdgeLabel.CONCAVE)) & hit

    step = _neighbour_max(z, hit, None, lambda q, p: np.abs(q - p))
    g = depth_slopes(scan)
    change = _neighbour_max(g, hit, scan.part, lambda q, p: np.hypot(q[..., 0] - p[..., 0], q[..., 1] - p[..., 1]))

    def ratio(signal: np.ndarray, sigma: float) -> np.ndarray:
        if not math.isfinite(sigma):  # too few valid pixels to measure the noise
            return np.full(signal.shape, np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(sigma > 0, signal / sigma, np.where(signal > 0, np.inf, np.nan))

    per_pixel = np.full(scan.shape, np.nan)
    jump_ok = jump & np.isfinite(step)
    crease_ok = crease & np.isfinite(change)
    per_pixel[jump_ok] = ratio(step[jump_ok], sigma_z)
    per_pixel[crease_ok] = ratio(change[crease_ok], math.sqrt(2.0) * factor * sigma_fp)

    def median(mask: np.ndarray) -> float:
        v = per_pixel[mask]
        v = v[~np.isnan(v)]
        return float(np.median(v)) if v.size else float("nan")

    return EdgeSNR(
        sigma_z=float(sigma_z), sigma_fp=float(sigma_fp),
        snr_jump=median(jump_ok), snr_crease=median(crease_ok), snr=median(jump_ok | crease_ok),
        n_jump=int(jump_ok.sum()), n_crease=int(crease_ok.sum()),
        per_pixel=per_pixel.astype(np.float32), window=int(window),
    )
