"""Noise-adaptive defaults of the edge detectors: the scan's own depth noise, and thresholds
raised above the noise level of a detector's strength.

Analysis layer: pure NumPy over arrays. Noise-adaptive defaults (every detector, same
estimator): :func:`estimate_depth_noise` measures the depth noise of the scan itself, in
pixel footprints: the median absolute deviation of the second difference
``z(i-1) - 2 z(i) + z(i+1)`` along rows and columns (valid triples only, each divided by
the centre's footprint), times 1.4826 (MAD to sigma of a Gaussian) over sqrt(6) (a second
difference of i.i.d. noise has variance 6 sigma^2).
Planes, smooth surfaces and the few percent of pixels on edges barely move the median, so
a noise-free scan measures ~0 and the White Scanner preset (0.25 footprints) its true
noise within a few percent. Quantised depth (a Kinect's disparity steps) is recognised by
:func:`depth_quantum` and measured as what it is, a rounding error (see
:func:`estimate_depth_noise`); depth rounded to a fixed unit ``q`` (a sensor's uint16
millimetres, float16 storage) is too, and a noise model's predicted ``sigma`` that was made
for the depth before the rounding takes the rounding's variance ``q^2 / 12`` on top
(:func:`quantised_sigma`). Below :data:`NOISE_FLOOR` a scan counts as noise-free and the
detectors use their noise-free defaults unchanged; above it they smooth / widen their
stencils (each documents how) and raise their threshold to
``max(noise-free default, k * median of the strength over valid pixels)``
(:func:`noise_threshold`): edges cover a few percent of the pixels, so the median is the
strength's noise level, and ``k`` (per detector, :data:`NOISE_K_GRADIENT` etc.) puts the
threshold ~4 noise standard deviations above it.
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

from rangesim.core import params as P
from rangesim.core.errors import RangesimError
from rangesim.core.quantisation import depth_quantum, looks_continuous
from rangesim.edges._scan_access import pixel_geometry, scan_depth

__all__ = [
    "depth_quantum", "quantised_sigma", "estimate_depth_noise", "noise_threshold", "local_noise_scale", "noise_in_footprints",
    "predicted_noise", "scan_sigma", "carries_sigma", "raised_threshold", "stride_gain",
    "NOISE_FLOOR", "NOISE_MEASURABLE",
    "NOISE_K_GRADIENT", "NOISE_K_NORMAL", "NOISE_K_NORMAL_LOCAL", "NOISE_K_PCL",
]

#: depth noise (pixel footprints) below which a scan counts as noise-free: the detectors'
#: noise-free defaults hold unchanged (a noise-free scan measures < 0.001)
NOISE_FLOOR = 0.05
#: depth noise (pixel footprints) a scan has at all: a noise-free scan measures < 0.001, a
#: laser scan with only its peak quantisation (1/16 px) about 0.04. Above it the gradient's
#: crease threshold follows the measured noise even under :data:`NOISE_FLOOR` (its fixed 15
#: degrees are only 2.6 sigma of the bend at 0.04 footprints)
NOISE_MEASURABLE = 0.001
#: threshold multiples of the median strength on noisy scans (see the module docstring):
#: the gradient's noise bend ``2 atan(max response)`` (an upper estimate, as if the
#: neighbour across responded as much; 3 medians ~ 4 sigma of the bend estimate), the
#: normal detector's pair angle (Rayleigh-like: median 1.18 scale, 4.5 medians ~ 5.3 scale,
#: ~1e-6 tail per pair) and PCL's Sobel
#: magnitude of the normal field (low hysteresis threshold; high scales with it)
NOISE_K_GRADIENT = 3.0
NOISE_K_NORMAL = 4.5
NOISE_K_PCL = 4.0
#: the normal detector's multiple where the scan's predicted noise raises the threshold per
#: pixel (:func:`local_noise_scale`): the scan-wide 4.5 carries a margin for the noisiest
#: faces that is then not needed (chosen on the machined parts' seeds 0-7: inria_laser's
#: noisy F1 0.72 -> 0.79, white_scanner's 0.93 -> 0.92)
NOISE_K_NORMAL_LOCAL = 3.5

#: default of the ``quantum`` arguments: not given, so :func:`depth_quantum` of the depth is
#: computed (None means continuous depth; the detectors pass ``Discontinuities.quantum``)
UNKNOWN: Any = object()


def quantised_sigma(sigma: np.ndarray, quantum: np.ndarray | None, counted: bool = False) -> np.ndarray:
    """A noise model's predicted depth std ``sigma`` (mm, per pixel) on depth quantised to
    ``quantum`` (mm, per pixel, :func:`depth_quantum`; None: not quantised).

    The model (units mm): a depth rounded to steps of ``q`` carries a rounding error uniform
    over one step, variance ``q^2 / 12``, independent of the sensor's own error of variance
    ``sigma^2`` (Sheppard's correction), so the depth's error has std
    ``sqrt(sigma^2 + q^2 / 12)``; two neighbours differ by up to ``q`` from the rounding alone
    and a second difference has variance ``6 q^2 / 12`` from it where the rounding errors are
    independent (a face that moves by a quantum or more every few pixels). A scan rounded to a
    fixed unit after it was simulated (what a Kinect v2, a RealSense or an Azure Kinect
    writes: uint16 millimetres; float16 storage) keeps the ``sigma`` the model predicted for
    the depth before the rounding, a few hundredths of a millimetre on a laser scan, and its
    detectors would otherwise take the rounding steps for creases (the noise-free plate
    rounded to 1 mm: 0.29 mm of rounding against a predicted 0.035 mm, 3000-5000 edge pixels
    for 250).

    Where the data do not show the rounding the caller leaves ``sigma`` as it is
    (:func:`_rounded_sigma`): rounding is noise only where the surface crosses levels, and a
    noise-free ramp whose columns each hold one exact depth shows evenly spaced levels with
    no rounding at all.

    ``counted``: the model already counts the quantisation (a block matcher's predicted
    sigma includes its disparity steps, which are its quantum: the kinect_v1 preset's is 1.8-3
    times ``q / sqrt(12)`` at every pixel); the depth's error is then only known to be at least
    the rounding's, ``max(sigma, q / sqrt(12))`` (on such a scan ``sigma`` itself, to the
    bit). Where the quantum is NaN (invalid depth) ``sigma`` stays.

    Returns
    -------
    (H, W) float32
        ``sigma`` itself (not a copy) when ``quantum`` is None.
    """
    if quantum is None:
        return sigma
    s = np.asarray(sigma, np.float32)
    rounding = np.asarray(quantum, np.float32) / np.float32(np.sqrt(12.0))
    if counted:
        return np.fmax(s, rounding)
    with np.errstate(invalid="ignore"):
        total = np.sqrt(s * s + rounding * rounding)
    return np.where(np.isfinite(rounding), total, s).astype(np.float32)


#: least share of the rounding's variance ``q^2 / 12`` the data's second differences must show
#: (beyond the model's own noise) for a quantised scan's ``sigma`` to take the rounding
#: (:func:`_rounded_sigma`): at least half its std
ROUNDING_SHOWN = 0.25


def _rounded_sigma(scan: Any, sigma: np.ndarray, z: np.ndarray, fp: np.ndarray,
                   quantum: np.ndarray) -> np.ndarray:
    """:func:`quantised_sigma` of a scan's predicted ``sigma`` on its quantised depth ``z``
    (footprints ``fp``, mm), where the data show the rounding.

    The data show it when their second differences hold at least :data:`ROUNDING_SHOWN` of
    the rounding's variance beyond the model's own noise: ``(m^2 - n^2) / r^2 >= 0.25``, with
    ``m`` the measured noise of the quantised depth (:func:`_measured_noise`: the RMS of
    second differences within 4 quanta, at most 4 median quanta, over sqrt(6)), ``n`` the
    median predicted ``sigma`` and ``r`` the median ``q / sqrt(12)``, all in pixel footprints
    (every 4th row and column). Then
    the whole ``q^2 / 12`` is added: the second differences see less of it than a detector's
    wider stencils do, as a rounding's errors along a slanted face are a sawtooth correlated
    over each terrace (the noise-free plate rounded to 1 mm: m = 0.22, n = 0.04, r = 0.31
    footprints, share 0.51; with the preset's noise m = 0.37, n = 0.21: share 0.95).
    Otherwise the prediction stays: a noise-free synthetic ramp whose columns each hold one
    exact depth shows evenly spaced levels that pass :func:`depth_quantum` but no rounding
    (share ~0.04).
    """
    sub = (slice(None, None, 4), slice(None, None, 4))
    ok = np.isfinite(z[sub])
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.asarray(sigma, np.float32)[sub][ok] / fp[sub][ok]
        r = quantum[sub][ok] / fp[sub][ok] / np.float32(np.sqrt(12.0))
    n, r = n[np.isfinite(n)], r[np.isfinite(r)]
    if n.size < 100 or r.size < 100 or not np.median(r) > 0:
        return sigma
    # the cut at 4 quanta with no quantum above the median one: the running median of the
    # level gaps (depth_quantum) takes a wide last gap for the quantum of the deepest or
    # nearest levels (a step 20 quanta deep at the end of a synthetic ramp), whose steps would
    # otherwise count as rounding
    m = _measured_noise(z, fp, np.fmin(quantum, np.float32(np.nanmedian(quantum))))
    share = (m * m - float(np.median(n)) ** 2) / float(np.median(r)) ** 2
    if share < ROUNDING_SHOWN:
        return sigma
    return quantised_sigma(sigma, quantum, _quantisation_counted(scan))


def _scan_quantum(scan: Any) -> np.ndarray | None:
    """:func:`depth_quantum` of a scan's depth (NaN off ``valid``, as the detectors see it), or
    None when the object carries no depth image (a bare ``sigma``)."""
    depth, valid = getattr(scan, "depth", None), getattr(scan, "valid", None)
    if depth is None or valid is None or np.shape(depth) != np.shape(valid):
        return None
    if looks_continuous(depth, valid):     # (most scans: no copy of the depth)
        return None
    return depth_quantum(scan_depth(scan)[0])


def _quantisation_counted(scan: Any) -> bool:
    """Whether ``scan``'s noise model counts its depth quantisation in ``sigma``: a block
    matcher's (structured light: its disparity steps are the quantum), by the scan's
    ``meta["sensor"]`` (:func:`~rangesim.edges._matching_scale.matching_window`)."""
    from rangesim.edges._matching_scale import matching_window  # (it imports this module's users)

    return matching_window(scan) is not None


def estimate_depth_noise(scan: Any = None, z: np.ndarray | None = None,
                         fp: np.ndarray | None = None, quantum: Any = UNKNOWN) -> float:
    """Depth noise of a scan, in pixel footprints (sigma_z / (z / f)).

    A scan that carries its noise model's prediction (``scan.sigma``, mm, as simulated
    scans do) gives the median of ``sigma / footprint`` over its valid pixels
    (every 4th row and column): the model knows its noise, correlated or not, which the
    data's second differences underestimate when neighbouring errors are correlated. On
    quantised depth the prediction first takes the rounding's variance ``q^2 / 12`` where
    the data's second differences show it (:func:`quantised_sigma`, :func:`_rounded_sigma`:
    a scan rounded after it was simulated; a block matcher's prediction, which counts its
    disparity steps, is only kept at least ``q / sqrt(12)``).
    Otherwise, from the data itself: the robust estimator of the module docstring:
    ``1.4826 * MAD / sqrt(6)`` of the second differences of depth along rows and columns
    over valid triples, each divided by the pixel footprint at its centre (median taken
    about 0: on a noise-free piecewise-smooth surface almost every second difference is
    ~0). Works on recorded scans too (footprint from
    :func:`~rangesim.edges._scan_access.pixel_geometry`).

    Quantised depth (:func:`depth_quantum`) is different: its second differences are whole
    numbers of quanta, mostly 0 and +-1 on a slanted plane, and their median is 0 or one
    quantum depending on which side of 50 % the zeros fall. Rounding is an error uniform
    over one quantum, of standard deviation ``q / sqrt(12)``, and independent roundings
    give second differences of variance ``6 q^2 / 12``: so there the estimate is
    ``sqrt(mean(d^2) / 6)`` over the second differences within 4 quanta (steps beyond are
    edges), the rounding error and any noise on top of it, as the smoothing and thresholds
    of the detectors need it.

    Parameters
    ----------
    scan : RangeScan, optional
        Used for the depth and footprint unless ``z`` and ``fp`` are given.
    z : (H, W) float array, optional
        Depth, NaN where invalid.
    fp : (H, W) float array, optional
        Pixel footprint, mm.

    Returns
    -------
    float
        sigma in footprints (0.0 if fewer than 100 valid triples).

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> quiet = rs.datasets.plate_scan({"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": 0})
    >>> bool(rs.edges.estimate_depth_noise(quiet) < rs.edges.estimate_depth_noise(scan))
    True
    """
    if scan is None and (z is None or fp is None):
        given = " (got only z)" if z is not None else " (got only fp)" if fp is not None else ""
        raise RangesimError("estimate_depth_noise needs a scan, or both z and fp (the depth and its pixel "
                            f"footprints, mm){given}")
    if z is None:
        z, _ = scan_depth(scan)
    if fp is None:
        fp = pixel_geometry(scan, z).footprint
    z = np.asarray(z, np.float32)
    fp = np.asarray(fp, np.float32)
    if z.ndim != 2 or fp.shape != z.shape:
        raise RangesimError(f"z and fp must be (H, W) arrays of one shape, got {z.shape} and {fp.shape}")
    quantum = depth_quantum(z) if quantum is UNKNOWN else quantum
    if quantum is not None and np.shape(quantum) != z.shape:
        raise RangesimError(f"quantum must be None or an (H, W) array like z {z.shape} (mm per pixel), "
                            f"got {quantum!r:.40}")
    predicted = scan.sigma if scan is not None and carries_sigma(scan) else None
    if predicted is not None:
        sub = (slice(None, None, 4), slice(None, None, 4))
        if quantum is not None:     # with the rounding's share of the noise (quantised_sigma)
            predicted = _rounded_sigma(scan, predicted, z, fp, quantum)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.asarray(predicted, np.float32)[sub] / fp[sub]
        ratio = ratio[np.isfinite(ratio) & np.isfinite(z[sub])]
        if ratio.size >= 100:
            return float(np.median(ratio))
    return _measured_noise(z, fp, quantum)


def _measured_noise(z: np.ndarray, fp: np.ndarray, quantum: np.ndarray | None) -> float:
    """The data's own depth noise, footprints (:func:`estimate_depth_noise` without ``sigma``):
    the robust second-difference estimate, or on quantised depth the RMS one within 4 quanta."""
    # every 4th column / row is plenty for a median (and 4x cheaper)
    zc, fc = z[:, ::4], fp[:, ::4]
    zr, fr = z[::4], fp[::4]
    with np.errstate(invalid="ignore", divide="ignore"):
        d0 = (zc[:-2] - 2 * zc[1:-1] + zc[2:]) / fc[1:-1]
        d1 = (zr[:, :-2] - 2 * zr[:, 1:-1] + zr[:, 2:]) / fr[:, 1:-1]
    if quantum is not None:
        qc, qr = quantum[:, ::4][1:-1] / fc[1:-1], quantum[::4][:, 1:-1] / fr[:, 1:-1]
        with np.errstate(invalid="ignore"):
            d0 = np.where(np.abs(d0) <= 4 * qc, d0, np.nan)
            d1 = np.where(np.abs(d1) <= 4 * qr, d1, np.nan)
    d = np.concatenate([d0[np.isfinite(d0)], d1[np.isfinite(d1)]])
    if d.size < 100:
        return 0.0
    if quantum is not None:
        return float(np.sqrt(np.mean(d.astype(np.float64) ** 2) / 6.0))
    return float(1.4826 * np.median(np.abs(d)) / np.sqrt(6.0))


def stride_gain(z: np.ndarray, fp: np.ndarray, max_stride: int, quantum: Any = UNKNOWN) -> np.ndarray:
    """How the bend noise of a line through a pixel falls as its halves grow, measured.

    The second difference of depth at lag ``s``, ``z[i + s] - 2 z[i] + z[i - s]`` over the
    footprint, is the bend of the line from pixel ``i - s`` through ``i`` to ``i + s`` times
    ``s`` (in radians, for a face seen head-on). On a plane its spread is the noise's: for
    independent errors the same at every lag, so the bend noise falls as ``1 / s``; for
    errors correlated over the lag (block matching's windows, a smoothed surface) it falls
    more slowly, and for heavy-tailed ones (patches of wrong matches) its RMS does.

    Returns
    -------
    (max_stride + 1,) float
        ``gain[s]``: the RMS second difference at lag ``s`` over ``s`` times that at lag 1
        (``gain[1] = 1``, ``1 / s`` for independent errors; ``gain[0]`` unused, 1). The RMS
        is over the differences within 4 robust sigmas (1.4826 MAD about 0) of each lag's
        own (beyond are edges), along rows and columns, every 4th line. A lag with fewer
        than 100 differences, or a depth without spread at lag 1, gets gain 1 (no gain).

    Depth rounded to a fixed unit ``q`` mm (:func:`depth_quantum`; uint16 millimetres, float16)
    finer than its slopes leaves most lag-1 second differences exactly 0 (a terrace of equal
    values spans several pixels), so the robust sigma is 0 and would keep nothing. There
    (a quantum, and a median of 0 at lag 1) every lag keeps, as :func:`estimate_depth_noise`
    does, the differences within 4 quanta (the rounding alone moves a second difference by
    at most ``2 q``; steps beyond are edges) over the centre's footprint, and the gain is
    what the rounding's terraces give (their errors are a sawtooth along a slanted face,
    correlated over a terrace, not ``1 / s``). Elsewhere (continuous depth; a block
    matcher's quantised depth, whose noise spreads its lag-1 differences) the rule above,
    to the bit. ``quantum``: :func:`depth_quantum` of ``z`` when the caller has it already.
    """
    z = np.asarray(z, np.float32)
    gain = np.ones(int(max_stride) + 1)
    rms = np.full(int(max_stride) + 1, np.nan)
    zc, fc = z[:, ::4], fp[:, ::4]
    zr, fr = z[::4], fp[::4]
    quantum = depth_quantum(z) if quantum is UNKNOWN else quantum  # (the caller's Discontinuities.quantum)
    by_quanta = False                    # set at lag 1: rounded terraces (see above)
    for lag in range(1, int(max_stride) + 1):
        if 2 * lag >= min(z.shape):
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            d0 = (zc[:-2 * lag] - 2 * zc[lag:-lag] + zc[2 * lag:]) / fc[lag:-lag]
            d1 = (zr[:, :-2 * lag] - 2 * zr[:, lag:-lag] + zr[:, 2 * lag:]) / fr[:, lag:-lag]
        ok0, ok1 = np.isfinite(d0), np.isfinite(d1)
        d = np.abs(np.concatenate([d0[ok0], d1[ok1]]).astype(np.float64))
        if d.size < 100:
            break
        if lag == 1:
            by_quanta = quantum is not None and np.median(d) == 0
        if by_quanta:
            # 4 quanta at the centre pixel, in its footprints
            with np.errstate(invalid="ignore", divide="ignore"):
                q0 = quantum[:, ::4][lag:-lag] / fc[lag:-lag]
                q1 = quantum[::4][:, lag:-lag] / fr[:, lag:-lag]
            d = d[d <= 4 * np.concatenate([q0[ok0], q1[ok1]]).astype(np.float64)]
        else:
            d = d[d <= 4 * 1.4826 * np.median(d)]
        rms[lag] = np.sqrt(np.mean(d * d)) if d.size else np.nan
    if not rms[1] > 0:
        return gain
    ok = np.isfinite(rms) & (np.arange(len(rms)) >= 1)
    gain[ok] = rms[ok] / (np.arange(len(rms))[ok] * rms[1])
    return gain


def stencil_window(window: int | None, name: str, noise: float | None) -> int:
    """The odd stencil size (pixels) of a normal estimate: ``window`` checked, or chosen from the noise.

    Default (None): 3 on noise-free scans (``noise`` below :data:`NOISE_FLOOR` footprints, or
    None), else ``2 ceil(12 noise) + 1`` clipped to 3..9 (7 at the White Scanner preset's 0.25):
    the stencil grows until the noise on the normal's slopes falls under the creases' bend.

    Examples
    --------
    >>> stencil_window(None, "window", 0.25), stencil_window(None, "window", 0.0), stencil_window(5, "window", 0.25)
    (7, 3, 5)
    """
    if window is not None:
        return P.odd_window(window, name)
    if noise is None or noise < NOISE_FLOOR:
        return 3
    return int(np.clip(2 * np.ceil(12 * noise) + 1, 3, 9))


def noise_threshold(strength: np.ndarray, valid: np.ndarray, default: float, k: float,
                    stride: int = 4) -> float:
    """``max(default, k * median(strength))`` over valid pixels with a finite strength.

    The median is taken on every ``stride``-th row and column (1/16 of the pixels by
    default): plenty for a robust noise level, and 16 times cheaper than over a megapixel.
    A caller that computes its strength on that subsample only passes it with ``stride=1``.
    """
    sub = (slice(None, None, stride), slice(None, None, stride))
    st = strength[sub][valid[sub] & np.isfinite(strength[sub])]
    if st.size == 0:
        return float(default)
    return float(max(default, k * float(np.median(st))))


#: side (pixels) of the window over which :func:`predicted_noise` takes the least sigma
NOISE_WINDOW = 5


def carries_sigma(scan: Any) -> bool:
    """Whether the scan carries its noise model's prediction: a ``sigma`` with a finite value at
    some valid pixel. One with none predicts nothing (every detector then measures the noise;
    read as 0 it would set the thresholds to their floors, as if the scan were noise-free)."""
    sigma = getattr(scan, "sigma", None)
    if sigma is None:
        return False
    sigma = np.asarray(sigma)
    valid = getattr(scan, "valid", None)
    return bool(np.isfinite(sigma if valid is None else sigma[np.asarray(valid, dtype=bool)]).any())


def scan_sigma(scan: Any, z: np.ndarray | None = None, quantum: Any = UNKNOWN) -> np.ndarray | None:
    """The noise model's depth std at each pixel, mm (``scan.sigma``), with the rounding's
    variance ``q^2 / 12`` added on quantised depth where the data show it
    (:func:`_rounded_sigma`); None when the scan carries no sigma. ``z`` (the scan's
    :func:`~rangesim.edges._scan_access.scan_depth`) and ``quantum`` (its
    :func:`depth_quantum`, None for continuous depth) when the caller has them already.
    None too where the sigma predicts nothing (:func:`carries_sigma`)."""
    if not carries_sigma(scan):
        return None
    sigma = scan.sigma
    if quantum is UNKNOWN:
        quantum = _scan_quantum(scan)
    if quantum is not None:
        z = scan_depth(scan)[0] if z is None else z
        sigma = _rounded_sigma(scan, sigma, z, pixel_geometry(scan, z).footprint, quantum)
    return sigma


def predicted_noise(scan: Any, window: int | None = None, *, z: np.ndarray | None = None,
                    quantum: Any = UNKNOWN) -> np.ndarray | None:
    """The noise model's depth std of the surface around each pixel, mm, (H, W) float32.

    ``scan.sigma`` (the predicted std per pixel; simulated scans carry it), its
    least value over a ``window`` x ``window`` neighbourhood (default :data:`NOISE_WINDOW`):
    the model also raises sigma at the very pixels of an edge (mixed and truncated stripes),
    and a threshold raised there would hide the edge; a face that is noisy as a whole (seen
    near grazing, far away) stays noisy under the minimum. NaN (invalid) counts as no
    information; 0 where nothing around is valid. None when the scan carries no sigma.
    On quantised depth (:func:`depth_quantum`) each pixel's sigma first takes the rounding's
    variance ``q^2 / 12`` where the data show it (:func:`quantised_sigma`,
    :func:`_rounded_sigma`; a block matcher's, which counts it, is only kept at least
    ``q / sqrt(12)``).
    """
    sigma = scan_sigma(scan, z, quantum)
    if sigma is None:
        return None
    least = _window_min(np.ascontiguousarray(sigma, np.float32), int(window or NOISE_WINDOW) // 2)
    least[~np.isfinite(least)] = 0
    return least


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _window_min(a: np.ndarray, r: int) -> np.ndarray:  # pragma: no cover - compiled
    """Minimum over the (2r + 1)^2 window of each pixel, clipped to the image, non-finite
    values ignored (as ``scipy.ndimage.minimum_filter(a, 2r + 1, mode="nearest")`` with NaN
    and +-inf read as +inf, to the bit, in a tenth of its time: separable, compiled).

    The row minima are kept for the 2r + 1 rows around the output row only (a ring), so
    the output is the one full-size image made: on a shared VM a fresh image costs about
    what this whole pass does."""
    h, w = a.shape
    n = 2 * r + 1
    ring = np.empty((n, w), np.float32)       # row minima of row k at k % n
    src = np.empty(w, np.float32)
    out = np.empty((h, w), np.float32)
    for k in range(min(r, h)):
        _row_min(a[k], r, src, ring[k % n])
    for i in range(h):
        if i + r < h:
            _row_min(a[i + r], r, src, ring[(i + r) % n])
        o = out[i]
        o[:] = ring[i % n]
        for k in range(max(0, i - r), min(h, i + r + 1)):
            if k == i:
                continue
            rk = ring[k % n]
            for j in range(w):
                o[j] = rk[j] if rk[j] < o[j] else o[j]
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _row_min(ar, r, src, rr):  # pragma: no cover - compiled
    """``rr`` = the minimum of ``ar`` (non-finite read as +inf) over ``j - r..j + r`` (clipped),
    in :func:`_window_min`'s order: the pixel, then the pairs of shifts 1..r."""
    w = ar.shape[0]
    inf = np.float32(np.inf)
    for j in range(w):
        src[j] = ar[j] if np.isfinite(ar[j]) else inf  # NaN and +-inf: no information
        rr[j] = src[j]
    for k in range(1, r + 1):  # shifted minima on aligned slices: simple loops that vectorise
        lo, dst = src[0:max(w - k, 0)], rr[k:w]
        for j in range(w - k):
            v = lo[j]
            dst[j] = v if v < dst[j] else dst[j]
        hi, dst2 = src[k:w], rr[0:max(w - k, 0)]
        for j in range(w - k):
            v = hi[j]
            dst2[j] = v if v < dst2[j] else dst2[j]


def local_noise_scale(scan: Any, valid: np.ndarray, footprint: np.ndarray,
                      sigma: np.ndarray | None = None) -> np.ndarray | None:
    """How much noisier each pixel is than the scan's median pixel, in pixel footprints:
    ``max(1, s / median(s))`` with ``s = sigma / footprint``.

    ``sigma`` is :func:`predicted_noise`, the noise model's predicted depth std around the
    pixel (mm; simulated scans carry it), and ``footprint`` the pixel's lateral
    size (``z / f`` mm): the detectors' strengths (bend angles, normal angles, ``|k| R``) are
    relative to the footprint, so their noise goes as ``sigma / footprint``. Noise grows
    steeply with incidence and range, so a face seen near grazing or a far table is several
    times noisier than the median pixel that :func:`noise_threshold` calibrates on; a
    detector multiplies its noise-derived threshold by this scale there (the strength's
    noise is proportional to the depth noise for small angles). Never below 1: a quieter
    pixel keeps the scan's threshold. ``sigma``: :func:`predicted_noise` if the caller has
    it already (:attr:`Discontinuities.noise <rangesim.edges._discontinuities.Discontinuities>`).

    Returns
    -------
    (H, W) float32, or None
        None when the scan carries no usable ``sigma`` (recorded scans, noise-free ones).
    """
    relative = noise_in_footprints(scan, valid, footprint, sigma)
    if relative is None:
        return None
    ok, s = relative
    # the median of every 4th row and column: plenty for a level, 16x cheaper (noise_threshold)
    sub = ok[::4, ::4]
    median = np.float32(np.median(s[::4, ::4][sub] if sub.any() else s[ok]))
    return _over_median(s, ok, median)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _over_median(s, ok, median):  # pragma: no cover - compiled
    """``max(1, s / median)`` where ``ok``, else 1 (float32, one pass)."""
    h, w = s.shape
    out = np.empty((h, w), np.float32)
    one = np.float32(1)
    for i in range(h):
        for j in range(w):
            v = s[i, j]
            out[i, j] = v / median if ok[i, j] and v > median else one
    return out


def raised_noise_threshold(scan: Any, valid: np.ndarray, footprint: np.ndarray, threshold: float,
                           cap: float | None = None, sigma: np.ndarray | None = None) -> float | np.ndarray:
    """``raised_threshold(threshold, local_noise_scale(scan, valid, footprint, sigma), cap)``,
    to the bit, in two compiled passes without the four intermediate images (the scaled
    noise, its mask, the scale and the raised threshold before the cap).

    The first pass counts the usable pixels and gathers the scaled noise on the median's
    grid (every 4th row and column), the second makes the thresholds. Falls back to the
    two functions where that grid holds no usable pixel.
    """
    if sigma is None:
        sigma = predicted_noise(scan)
    if sigma is None:
        return threshold
    sg = np.ascontiguousarray(sigma, np.float32)
    fp = np.ascontiguousarray(np.broadcast_to(np.asarray(footprint, np.float32), sg.shape))
    ok = np.ascontiguousarray(np.broadcast_to(valid, sg.shape))
    n, sample = _usable_on_grid(sg, fp, ok, 4)
    if n < 100:
        return threshold
    if sample.size == 0:
        return raised_threshold(threshold, local_noise_scale(scan, valid, footprint, sigma), cap)
    median = np.float32(np.median(sample))
    return _raised_by_noise(sg, fp, ok, median, np.float32(threshold), np.float32(np.inf if cap is None else cap))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _usable_on_grid(sigma, footprint, valid, step):  # pragma: no cover - compiled
    """How many pixels :func:`_per_footprint` calls usable, and ``sigma / footprint`` at the
    usable ones of every ``step``-th row and column (row-major, as ``s[::4, ::4][ok[::4, ::4]]``)."""
    h, w = sigma.shape
    n = 0
    for i in range(h):
        for j in range(w):
            v = sigma[i, j] / footprint[i, j]
            n += valid[i, j] and np.isfinite(v) and v > 0
    sample = np.empty(((h + step - 1) // step) * ((w + step - 1) // step), np.float32)
    m = 0
    for i in range(0, h, step):
        for j in range(0, w, step):
            v = sigma[i, j] / footprint[i, j]
            if valid[i, j] and np.isfinite(v) and v > 0:
                sample[m] = v
                m += 1
    return n, sample[:m]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _raised_by_noise(sigma, footprint, valid, median, threshold, cap):  # pragma: no cover - compiled
    """``min(threshold * max(1, s / median), cap)`` with ``s = sigma / footprint`` where usable,
    else ``min(threshold, cap)`` (float32: :func:`_per_footprint`, :func:`_over_median` and
    :func:`raised_threshold`'s operations)."""
    h, w = sigma.shape
    out = np.empty((h, w), np.float32)
    one = np.float32(1)
    for i in range(h):
        for j in range(w):
            v = sigma[i, j] / footprint[i, j]
            good = valid[i, j] and np.isfinite(v) and v > 0
            scale = v / median if good and v > median else one
            r = threshold * scale
            out[i, j] = r if r < cap else cap
    return out


def noise_in_footprints(scan: Any, valid: np.ndarray, footprint: np.ndarray,
                        sigma: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`predicted_noise` (or ``sigma``, the same computed already) over the pixel
    footprint, and where it is usable.

    Returns
    -------
    (ok, s) : (H, W) bool, (H, W) float32
        ``s = sigma / footprint``; ``ok`` where it is finite and positive on a valid pixel.
        None when the scan carries no sigma or fewer than 100 pixels have one.
    """
    if sigma is None:
        sigma = predicted_noise(scan)
    if sigma is None:
        return None
    s, ok, n = _per_footprint(np.ascontiguousarray(sigma, np.float32),
                              np.ascontiguousarray(np.broadcast_to(np.asarray(footprint, np.float32), sigma.shape)),
                              np.ascontiguousarray(np.broadcast_to(valid, sigma.shape)))
    if n < 100:
        return None
    return ok, s


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _per_footprint(sigma, footprint, valid):  # pragma: no cover - compiled
    """``sigma / footprint`` (float32), where it is finite and positive on a valid pixel, and
    how many such pixels there are (one pass)."""
    h, w = sigma.shape
    s = np.empty((h, w), np.float32)
    ok = np.empty((h, w), np.bool_)
    n = 0
    for i in range(h):
        for j in range(w):
            v = sigma[i, j] / footprint[i, j]
            s[i, j] = v
            good = valid[i, j] and np.isfinite(v) and v > 0
            ok[i, j] = good
            n += good
    return s, ok, n


def raised_threshold(threshold: float, scale: np.ndarray | None, cap: float | None = None) -> float | np.ndarray:
    """``threshold`` times :func:`local_noise_scale` per pixel (at most ``cap``), or itself
    where there is no scale."""
    if scale is None:
        return threshold
    raised = np.float32(threshold) * scale
    return raised if cap is None else np.minimum(raised, np.float32(cap))
