"""One noise and dropout model for every laser-stripe scan (geometric scanner and twin alike).

The range error of a stripe scanner is the error of the stripe-peak position on the
sensor, e (pixels along the row), triangulated into depth (``dz/du`` mm per pixel, from the
sensor's geometry). This module turns per-pixel physical quantities into the std of e, draws
e, and draws the dropouts. Inputs are flat NumPy arrays over an (H, W) grid, so the same
code serves the geometric scanner (camera pixels) and the twin of a recording (grid cells).

Terms of the peak error (all in pixels, added in quadrature)
------------------------------------------------------------
Imaged stripe width. A sheet of FWHM ``s`` (mm) falling on a surface at laser incidence
``i`` covers ``s / cos i`` across the stripe; imaged with magnification ``m`` (pixels per mm
on the surface along the row: ``f / d cos e`` for a surface seen at viewing angle ``e`` in
the sheet's plane of incidence, whose footprint the camera sees foreshortened) and blurred by
the optics (``camera.psf_px``, Gaussian FWHM), the stripe is

    w = sqrt(psf^2 + (m s / cos i)^2)  pixels,  w0 = the same on a facing surface at z_ref.

(``m s / cos i`` is ``s / a``, ``a`` the mm of the sheet's thickness that one pixel along
the row crosses; the geometric scanner computes ``m = cos i / a`` from each pixel's surface
normal, the twin of a recording, whose grid has no camera model, takes ``f / z_ref``.)

1. ``noise.sigma_px`` -- the sub-pixel estimator's and the detector's floor, white (each
   pixel's own read-out), independent of the stripe.
2. ``noise.signal_px`` -- signal-limited localisation. The Cramer-Rao bound for the position
   of a Gaussian line of width w and peak amplitude A under additive intensity noise is
   sigma = sigma_n sqrt(2 w' / sqrt(pi)) / A (w' its std), so

       sigma_signal = signal_px * sqrt(w / w0) / A,   A = albedo cos i (z_ref / d_L)^2,

   ``A`` the stripe's image brightness (a Lambertian surface's radiance; a pixel's value
   does not depend on the viewing distance or angle). On an inclined surface w grows as
   1 / cos i and A falls as cos i: sigma ~ cos(i)^-1.5. In laser-stripe images the
   intensity noise that limits this bound is the speckle of the surface (it dwarfs shot
   noise at working exposures, Dorsch et al. 1994), and speckle belongs to the surface
   patch, not to the pixel: neighbouring peaks (and, in a sweep, the frames whose stripe
   overlaps the same patch) see the same grains. So this term is **spatially correlated**,
   like term 3.
3. Speckle (``noise.speckle_contrast`` C, ``camera.aperture_mm`` D, ``laser.wavelength_nm``):
   the Dorsch et al. (1994) limit sigma_z = C lambda / (2 pi sin u_obs sin theta) for a
   stripe as narrow as a speckle grain, a displacement along the illumination: a peak shift
   moves the triangulated point along the laser ray, ``dz/du / cos alpha`` mm per pixel
   (alpha the ray's angle from the optical axis), so the callers give it as
   ``sigma_z cos alpha / (dz/du)`` pixels; a wider stripe holds w / w0 more grains, whose
   random intensities move the centroid as a random walk, so sigma_speckle ~ sqrt(w / w0).
   Terms 2-4 share one **correlated field**: white noise filtered with a Gaussian of std
   ``noise.correlation_mm`` (mm on a facing surface at the reference distance: the caller
   converts it to pixels once, ``correlation_mm f / z_ref``, so the grains keep one size on
   the sensor at every range, as subjective speckle's do) and
   scaled back to unit variance.
4. Partial stripes (``noise.edge_gain`` g): where an outline, a shadow border or a depth
   step (an occluding edge over a measured background whose far side's light lands outside
   the peak detector's window; a smaller step's light stays in it, where the mixed pixels'
   centroid takes it) lies inside the stripe's footprint, the imaged stripe is truncated
   (Curless and Levoy 1995). A
   Gaussian profile of std sigma_s = s / (2.355 cos i) on the surface cut at distance delta
   from its centre has its centroid moved by sigma_s phi(t) / Phi(t), t = delta / sigma_s
   (the mean of a truncated normal); the peak estimator keeps a fraction g of it. The
   profile lies along the row (the sweep's direction, the axis the peak is located on), so
   delta is the distance along the row (:func:`border_distance`): a border running along the
   row (where the stripe's line ends) cuts no profile and moves no peak:

       sigma_edge = g m sigma_s phi(t) / Phi(t)   pixels  (correlated like speckle),

   which gives the heavy tails at outlines and shadow borders.
5. ``noise.quantization_px`` q: the peak is reported in steps of q; the true peak sits at a
   random phase of that grid, adding q^2 / 12 of variance.

Dropouts
--------
The detected peak amplitude is the mean return S (:func:`rangesim.sensor.signal.return_signal`)
times the speckle intensity X of the stripe, a unit-mean Gamma variable of contrast
``noise.signal_contrast`` c (c = 1: fully developed speckle, exponential intensity; c = 0: no
fluctuation). A pixel is detected when S X >= ``noise.min_signal``:

    P(valid) = P(X >= S_min / S) = Q(1 / c^2, S_min / (S c^2))   (regularised upper gamma),

so dropouts become likely as S falls (grazing angles, dark surfaces) and appear sparsely,
but not never, on bright facing surfaces. The uniform draws behind the decision come
from a correlated field too (``Phi`` of a Gaussian field), so dropouts form small holes.
Where an outline, shadow border or depth step cuts the stripe's footprint, only the share Phi(t) of its
light is left (:func:`partial_stripe_fraction`), so S is multiplied by it: truncated
stripes at outlines drop out first, the thin rim of missing cells real scans show.

Predicted uncertainty
---------------------
:func:`peak_sigma_px` returns the std of e that the model predicts per pixel, including the
quantisation variance; the callers multiply it by ``dz/du`` to give ``RangeScan.sigma`` (mm).

References
----------
.. [1] R. G. Dorsch, G. Haeusler, J. M. Herrmann, "Laser triangulation: fundamental
   uncertainty in distance measurement", Applied Optics 33(7), 1306-1314 (1994),
   doi:10.1364/AO.33.001306.
.. [2] B. Curless, M. Levoy, "Better optical triangulation through spacetime analysis",
   ICCV 1995, 987-994, doi:10.1109/ICCV.1995.466772.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Callable, Mapping

import drjit as dr
import numpy as np
from scipy import ndimage, special

from rangesim.core.backend import aligned
from rangesim.core.constants import FWHM_PER_SIGMA

__all__ = [
    "StripeNoise", "stripe_width_px", "dorsch_sigma_mm", "partial_stripe_shift_mm",
    "peak_sigma_px", "correlated_field", "draw_peak_error_px", "detection_probability",
    "draw_detected", "NOISE_KEYS", "partial_stripe_fraction", "border_distance", "border_distance_at", "StripeDraw", "simulate",
    "NumPyDraws", "PixelDraws",
]

FWHM_TO_SIGMA = 1.0 / FWHM_PER_SIGMA
#: below this cosine the footprint formulas are clipped (the stripe covers the whole cell)
MIN_COS = 0.02
#: the noise keys of the model and their defaults (all off: a quiet sensor stays exact)
NOISE_KEYS: dict[str, float] = {
    "sigma_px": 0.0, "quantization_px": 0.0, "min_signal": 0.0, "speckle_contrast": 0.0,
    "signal_px": 0.0, "correlation_mm": 0.0, "edge_gain": 0.0, "signal_contrast": 0.0,
}


# The model's arithmetic runs on NumPy arrays (the twin's grid cells, float64) or on Dr.Jit
# arrays (the geometric scanner's pixels, float32, fused into the scan's kernels): the
# formulas are written once against these two namespaces.
def _dr_like(a, ref):
    """A NumPy array as a Dr.Jit array of ``ref``'s type (float32 or bool)."""
    a = np.asarray(a)
    return type(ref)(np.ascontiguousarray(a, dtype=bool if a.dtype == bool else np.float32))


_NP = SimpleNamespace(
    sqrt=np.sqrt, abs=np.abs, clip=np.clip, maximum=np.maximum, where=np.where, isfinite=np.isfinite,
    round=np.round, ndtr=special.ndtr, any=lambda a: bool(np.any(a)), numpy=np.asarray,
    full_like=lambda a, v: np.full(np.shape(a), v), f32=lambda a: np.asarray(a, np.float32),
    like=lambda a, ref: np.asarray(a),
)
_DR = SimpleNamespace(
    sqrt=dr.sqrt, abs=dr.abs, clip=dr.clip, maximum=dr.maximum, where=dr.select, isfinite=dr.isfinite,
    round=dr.round, ndtr=lambda x: 0.5 * (1.0 + dr.erf(x * (1.0 / math.sqrt(2.0)))),
    any=lambda a: bool(dr.any(a)), numpy=np.asarray, full_like=lambda a, v: dr.full(type(a), v, dr.width(a)),
    f32=lambda a: a, like=_dr_like,
)


def _ops(*arrays) -> SimpleNamespace:
    """The namespace for ``arrays``: Dr.Jit's when any of them is a Dr.Jit array."""
    return _DR if any(dr.is_array_v(a) for a in arrays) else _NP


@dataclass(frozen=True)
class StripeNoise:
    """Parameters of the model (see the module docstring), from a sensor's tables.

    Attributes
    ----------
    sigma_px, signal_px, quantization_px : float
        Peak-error terms 1, 2 and 5, pixels.
    speckle_contrast : float
        Speckle contrast C of term 3 (0 disables it).
    correlation_mm : float
        Std of the Gaussian kernel of the correlated terms, mm on a facing surface at the
        reference distance (a fixed ``correlation_mm f / z_ref`` pixels at every range; 0: white).
    edge_gain : float
        Fraction g of a truncated stripe's centroid shift that reaches the peak (term 4).
    min_signal, signal_contrast : float
        Detection threshold on S and the contrast of the speckle intensity X.
    stripe_width_mm, psf_px, wavelength_nm, aperture_mm : float
        Sheet FWHM, optical blur FWHM, laser wavelength and entrance pupil.
    """

    sigma_px: float = 0.0
    signal_px: float = 0.0
    quantization_px: float = 0.0
    speckle_contrast: float = 0.0
    correlation_mm: float = 0.0
    edge_gain: float = 0.0
    min_signal: float = 0.0
    signal_contrast: float = 0.0
    stripe_width_mm: float = 0.0
    psf_px: float = 1.0
    wavelength_nm: float = 670.0
    aperture_mm: float = 5.0

    @classmethod
    def from_params(cls, params: Mapping[str, Mapping[str, Any]]) -> "StripeNoise":
        """From a sensor's ``params`` (tables ``noise``, ``laser``, ``camera``)."""
        n, laser, cam = params["noise"], params["laser"], params["camera"]
        return cls(
            **{k: float(n.get(k, v)) for k, v in NOISE_KEYS.items()},
            stripe_width_mm=float(laser.get("stripe_width", 0.0)), psf_px=float(cam.get("psf_px", 1.0)),
            wavelength_nm=float(laser.get("wavelength_nm", 670.0)), aperture_mm=float(cam.get("aperture_mm", 5.0)),
        )


def stripe_width_px(cos_incidence: np.ndarray, magnification: np.ndarray | float, stripe_width_mm: float,
                    psf_px: float) -> np.ndarray:
    """Imaged stripe width w = sqrt(psf^2 + (m s / cos i)^2), pixels (FWHM).

    Parameters
    ----------
    cos_incidence : (N,) array
        Cosine of the laser's incidence angle on the surface (NumPy, or Dr.Jit: then the
        result is a Dr.Jit array too).
    magnification : (N,) array or float
        Pixels per mm on the surface across the stripe (f / distance on a surface seen
        face-on; times the cosine of the viewing angle on one seen obliquely).
    stripe_width_mm, psf_px : float
        Sheet FWHM (mm) and optical blur FWHM (pixels).

    Examples
    --------
    >>> w = stripe_width_px(np.array([1.0, 0.5]), 2.0, 1.0, 0.0)
    >>> w.tolist()
    [2.0, 4.0]
    """
    xp = _ops(cos_incidence, magnification)
    if xp is _NP:
        cos_incidence, magnification = np.asarray(cos_incidence, np.float64), np.asarray(magnification, np.float64)
    foot = magnification * stripe_width_mm / xp.clip(xp.abs(cos_incidence), MIN_COS, 1.0)
    return xp.sqrt(psf_px**2 + foot * foot)


def dorsch_sigma_mm(distance_mm: np.ndarray | float, sin_triangulation: np.ndarray | float, contrast: float,
                    wavelength_nm: float, aperture_mm: float) -> np.ndarray:
    """Speckle-limited depth uncertainty C lambda / (2 pi sin u_obs sin theta), mm [1]_.

    Takes floats, NumPy arrays or Dr.Jit arrays.

    ``sin u_obs = (D / 2) / sqrt((D / 2)^2 + distance^2)``; theta the angle between the
    camera ray and the laser ray at the point.

    Examples
    --------
    >>> round(float(dorsch_sigma_mm(400.0, 0.35, 1.0, 670.0, 6.0)), 4)
    0.0406
    """
    half = 0.5 * aperture_mm
    # plain arithmetic, so NumPy arrays, floats and Dr.Jit arrays (the geometric scanner) all work
    sin_u = half / (half * half + distance_mm * distance_mm) ** 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        return contrast * (wavelength_nm * 1e-6) / (2 * math.pi * sin_u * sin_triangulation)


def partial_stripe_shift_mm(edge_distance_mm: np.ndarray, cos_incidence: np.ndarray, stripe_width_mm: float
                            ) -> np.ndarray:
    """Centroid shift (mm on the surface) of a stripe truncated at ``edge_distance_mm``.

    A Gaussian footprint of std sigma_s = s / (2.355 cos i) cut at distance delta from its
    centre has its centroid moved by sigma_s phi(t) / Phi(t), t = delta / sigma_s [2]_.
    Negligible (< 1e-3 sigma_s) beyond about 3.3 sigma_s.

    Examples
    --------
    >>> s = partial_stripe_shift_mm(np.array([0.0, 10.0]), np.array([1.0, 1.0]), 2.355)
    >>> np.round(s, 4).tolist()  # cut at the centre: sqrt(2 / pi); far away: nothing
    [0.7979, 0.0]
    """
    c = np.clip(np.abs(np.asarray(cos_incidence, np.float64)), MIN_COS, 1.0)
    sigma_s = stripe_width_mm * FWHM_TO_SIGMA / c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.asarray(edge_distance_mm, np.float64) / sigma_s
        # phi / Phi, written with erfcx so it stays finite for large negative or positive t
        ratio = np.sqrt(2.0 / math.pi) / special.erfcx(-t / math.sqrt(2.0))
        shift = np.where(sigma_s > 0, sigma_s * ratio, 0.0)
    return np.where(np.isfinite(shift), shift, 0.0)


def partial_stripe_fraction(edge_distance_mm: np.ndarray, cos_incidence: np.ndarray, stripe_width_mm: float
                            ) -> np.ndarray:
    """Share of the stripe's light left when its footprint is cut at ``edge_distance_mm``: Phi(delta / sigma_s).

    The truncated stripe is dimmer by this factor, so near outlines and shadow borders the
    detected amplitude falls and the pixel may drop out (1 where the stripe is whole or has
    no width).

    Examples
    --------
    >>> np.round(partial_stripe_fraction(np.array([0.0, 10.0]), np.ones(2), 1.0), 3).tolist()
    [0.5, 1.0]
    """
    xp = _ops(edge_distance_mm, cos_incidence)
    if stripe_width_mm <= 0:
        return xp.full_like(edge_distance_mm, 1.0)
    if xp is _NP:
        cos_incidence, edge_distance_mm = np.asarray(cos_incidence, np.float64), np.asarray(edge_distance_mm, np.float64)
    sigma_s = stripe_width_mm * FWHM_TO_SIGMA / xp.clip(xp.abs(cos_incidence), MIN_COS, 1.0)
    return xp.ndtr(edge_distance_mm / sigma_s)


def peak_sigma_px(noise: StripeNoise, *, width_ratio: np.ndarray, amplitude: np.ndarray,
                  speckle_px: np.ndarray, edge_px: np.ndarray) -> dict[str, np.ndarray]:
    """Std of each term of the peak error, pixels (see the module docstring).

    Parameters
    ----------
    noise : StripeNoise
    width_ratio : (N,) array
        w / w0, the imaged stripe width over the facing stripe's.
    amplitude : (N,) array
        A, the stripe's image brightness relative to a white facing target at z_ref.
    speckle_px : (N,) array
        The Dorsch limit converted to pixels (for a stripe of width w0).
    edge_px : (N,) array
        The truncated stripe's centroid shift, pixels (before ``edge_gain``).

    Returns
    -------
    dict of (N,) arrays
        ``white`` (term 1), ``correlated`` (terms 2-4), ``total`` (all, with the
        quantisation variance q^2 / 12); float64 for NumPy inputs, Dr.Jit floats for Dr.Jit
        inputs.
    """
    xp = _ops(width_ratio, amplitude)
    if xp is _NP:
        amplitude = np.asarray(amplitude, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        root_w = xp.sqrt(xp.maximum(width_ratio, 0.0))
        signal_term = noise.signal_px * root_w / xp.maximum(amplitude, 1e-6)
        speckle_term, edge_term = speckle_px * root_w, noise.edge_gain * edge_px
        correlated = xp.sqrt(signal_term * signal_term + speckle_term * speckle_term + edge_term * edge_term)
    white = xp.full_like(root_w, float(noise.sigma_px))
    correlated = xp.where(xp.isfinite(correlated), correlated, 0.0)
    total = xp.sqrt(white * white + correlated * correlated + noise.quantization_px**2 / 12.0)
    return {"white": white, "correlated": correlated, "total": total}


def correlated_field(rng: np.random.Generator, shape: tuple[int, int], corr_px: tuple[float, float]) -> np.ndarray:
    """A unit-variance Gaussian random field on an (H, W) grid, float64.

    White normal noise filtered by a Gaussian kernel of std ``corr_px`` (rows, columns) in
    cells and divided by the kernel's L2 norm, so every cell keeps variance 1 while
    neighbours correlate as exp(-k^2 / (4 corr^2)) at a lag of k cells. A std of 0 along
    an axis leaves that axis white.

    Examples
    --------
    >>> f = correlated_field(np.random.default_rng(0), (200, 200), (2.0, 2.0))
    >>> bool(abs(f.std() - 1) < 0.1), bool(np.corrcoef(f[:, :-1].ravel(), f[:, 1:].ravel())[0, 1] > 0.85)
    (True, True)
    """
    sr, sc = (float(s) if s > 0 else 0.0 for s in corr_px)  # NaN: white, inf: one value per line
    if sr < 0.05 and sc < 0.05:
        return rng.standard_normal(shape, dtype=np.float32)
    white = rng.standard_normal(shape)
    if 8 * sr + 1 > shape[0] or 8 * sc + 1 > shape[1]:
        return _periodic_field(white, (sr, sc))
    field = ndimage.gaussian_filter(white, (sr, sc), mode="wrap", truncate=4.0)
    # the filter's L2 norm: its response to a unit impulse
    size = (min(shape[0], int(8 * sr) + 3) | 1, min(shape[1], int(8 * sc) + 3) | 1)
    impulse = np.zeros(size)
    impulse[size[0] // 2, size[1] // 2] = 1.0
    norm = float(np.sqrt(np.sum(np.square(ndimage.gaussian_filter(impulse, (sr, sc), mode="constant", truncate=4.0)))))
    return field / norm


def _periodic_field(white: np.ndarray, sigma: tuple[float, float]) -> np.ndarray:
    """:func:`correlated_field` of ``white`` for a kernel longer than the grid along an axis.

    The filter is applied in Fourier space: the periodic Gaussian that ``mode="wrap"`` makes
    of a kernel, untruncated, in one FFT whatever its length (the spatial filter's work grows
    with the kernel: a correlation of a million cells took minutes). A correlation of many grid
    lengths leaves one value along that axis (the std is capped at 64 lengths, where the
    periodic kernel is flat to round-off).
    """
    h, w = white.shape
    sr, sc = min(sigma[0], 64.0 * h), min(sigma[1], 64.0 * w)
    gain_r = np.exp(-2.0 * (np.pi * sr * np.fft.fftfreq(h)) ** 2)
    gain_c = np.exp(-2.0 * (np.pi * sc * np.fft.fftfreq(w)) ** 2)
    field = np.fft.irfft2(np.fft.rfft2(white) * np.outer(gain_r, gain_c[: w // 2 + 1]), s=(h, w))
    # a cell's variance: the mean squared gain over the whole spectrum (separable)
    return field / np.sqrt(np.mean(gain_r ** 2) * np.mean(gain_c ** 2))


class NumPyDraws:
    """Random draws for the model from a ``numpy.random.Generator``, in call order (float32).

    The twin's source: every draw of a grid is one NumPy call.
    """

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def white(self, n: int) -> np.ndarray:
        """(n,) independent standard normals."""
        return self.rng.standard_normal(n, dtype=np.float32)

    def uniform(self, n: int) -> np.ndarray:
        """(n,) independent uniforms in [0, 1)."""
        return self.rng.random(n, dtype=np.float32)

    def field(self, shape: tuple[int, int], corr_px: tuple[float, float]) -> np.ndarray:
        """A flat :func:`correlated_field` over ``shape``."""
        return correlated_field(self.rng, shape, corr_px).reshape(-1)


class PixelDraws:
    """Random draws for the model as Dr.Jit arrays: a PCG32 stream per pixel.

    The geometric scanner's source. Stream ``k`` (sequence = pixel index) starts from one
    state drawn from ``rng``, entered as an opaque value so a new seed compiles nothing;
    a pixel's white draws depend only on the seed and its index. Correlated fields (a
    Gaussian filter over the whole image) are made in NumPy from ``rng`` and moved over.

    Parameters
    ----------
    rng : numpy.random.Generator
    n : int
        Number of pixels drawn for.
    first_index : int
        Image index of the first of them (a band of rows of a larger image: its pixels
        draw what they would draw in the whole image).
    rows : (first, stop), optional
        With ``image_shape`` and ``fields``: the band's rows; correlated fields are then made
        once over the whole image, kept in ``fields`` (shared by the bands, keyed by call
        order) and cut to the band, so a scan in bands equals the scan in one piece.
    image_shape : (H, W), optional
    fields : dict, optional
    """

    def __init__(self, rng: np.random.Generator, n: int, first_index: int = 0,
                 rows: tuple[int, int] | None = None, image_shape: tuple[int, int] | None = None,
                 fields: dict | None = None):
        from rangesim.core.backend import mitsuba

        self.mi = mi = mitsuba()
        self.rng = rng
        self.rows, self.image_shape, self.fields, self._calls = rows, image_shape, fields, 0
        state = int(rng.integers(0, 2**63))
        index = dr.arange(mi.UInt64, n) + dr.opaque(mi.UInt64, int(first_index))
        # seed() rather than the constructor, which offsets both by the band's own arange(n)
        self.pcg = mi.PCG32(size=n)
        self.pcg.seed(dr.opaque(mi.UInt64, state) + index, index)

    def white(self, n: int):
        """Standard normals (Box-Muller of two uniforms), ``mi.Float``."""
        u1, u2 = self.pcg.next_float32(), self.pcg.next_float32()
        return self.mi.warp.square_to_std_normal(self.mi.Point2f(u1, u2)).x

    def uniform(self, n: int):
        """Uniforms in [0, 1), ``mi.Float``."""
        return self.pcg.next_float32()

    def field(self, shape: tuple[int, int], corr_px: tuple[float, float]):
        """A unit-variance field: white PCG normals, or a NumPy :func:`correlated_field`."""
        if max(corr_px) < 0.05:  # the same cut-off as correlated_field's white case
            return self.white(shape[0] * shape[1])
        if self.rows is None:
            return self.mi.Float(aligned(correlated_field(self.rng, shape, corr_px).reshape(-1).astype(np.float32)))
        key = self._calls
        self._calls += 1
        if key not in self.fields:
            self.fields[key] = correlated_field(self.rng, self.image_shape, corr_px).astype(np.float32)
        return self.mi.Float(aligned(self.fields[key][self.rows[0]:self.rows[1]].reshape(-1)))


def _draws(rng) -> "NumPyDraws | PixelDraws":
    return rng if isinstance(rng, (NumPyDraws, PixelDraws)) else NumPyDraws(rng)


def draw_peak_error_px(rng, shape: tuple[int, int], sigmas: Mapping[str, np.ndarray],
                       quantization_px: float, corr_px: tuple[float, float]) -> np.ndarray:
    """Draw the peak error (pixels) of every cell of an (H, W) grid, flat (H * W,).

    ``rng``: a ``numpy.random.Generator`` (or a :class:`NumPyDraws` / :class:`PixelDraws`
    source). ``sigmas`` from :func:`peak_sigma_px` (flat, H * W). The white terms use
    independent normals, the correlated terms one field of :func:`correlated_field`;
    quantisation to steps of q at a uniform random phase comes last.
    """
    draws = _draws(rng)
    n = shape[0] * shape[1]
    xp = _ops(sigmas["white"])
    white = draws.white(n)
    field = xp.f32(draws.field(shape, corr_px))
    phase = draws.uniform(n)
    error = sigmas["white"] * white + sigmas["correlated"] * field
    if quantization_px > 0:
        offset = phase * quantization_px  # where the true peak sits on the quantiser grid
        error = quantization_px * xp.round((offset + error) / quantization_px) - offset
    return error


def detection_probability(signal: np.ndarray, min_signal: float, contrast: float) -> np.ndarray:
    """P(S X >= S_min) with X a unit-mean Gamma of contrast c (see the module docstring).

    Examples
    --------
    >>> p = detection_probability(np.array([1.0, 0.1, 0.01]), 0.05, 1.0)  # exp(-S_min / S)
    >>> np.round(p, 3).tolist()
    [0.951, 0.607, 0.007]
    >>> detection_probability(np.array([0.06, 0.04]), 0.05, 0.0).tolist()  # a hard threshold
    [1.0, 0.0]
    """
    s = np.asarray(signal, np.float64)
    if contrast <= 0 or min_signal <= 0:
        return ((s >= min_signal) & (s > 0)).astype(np.float64)
    k = 1.0 / contrast**2
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(s > 0, min_signal / (s * contrast**2), np.inf)
    return special.gammaincc(k, x)


def draw_detected(rng, shape: tuple[int, int], probability: np.ndarray,
                  corr_px: tuple[float, float]) -> np.ndarray:
    """Flat (H * W,) bool: detected where a correlated uniform draw falls below ``probability``.

    The uniform draws are Phi of a :func:`correlated_field`, so they are uniform in every
    cell and correlated like the speckle; certain outcomes (p = 0 or 1) use no randomness.
    ``rng`` as in :func:`draw_peak_error_px`.
    """
    xp = _ops(probability)
    if xp is _NP:
        probability = np.asarray(probability, np.float64)
    return xp.ndtr(_draws(rng).field(shape, corr_px)) < probability


def _row_border_distance(m: np.ndarray, spacing: float, cuts: np.ndarray | None = None) -> np.ndarray:
    """(R, W) distance along each row of ``m`` (R, W) bool to its nearest border: half a cell beyond
    an unmeasurable cell, or the middle between cells j and j + 1 where ``cuts[:, j]`` (+inf where
    the row holds none on either side; 0 on unmeasurable cells)."""
    R, W = m.shape
    j = np.arange(W)
    left = np.maximum.accumulate(np.where(m, -1, j), axis=1)  # the last unmeasurable cell at or before j
    right = np.minimum.accumulate(np.where(m, W, j)[:, ::-1], axis=1)[:, ::-1]  # the first at or after
    if cuts is not None and cuts.any():
        # a cut between b and b + 1 borders cell b + 1 as an unmeasurable b would, and cell b as b + 1 would
        last = np.maximum.accumulate(np.where(cuts, j, -1), axis=1)
        left = np.maximum(left, np.concatenate([np.full((R, 1), -1), last[:, :-1]], axis=1))
        right = np.minimum(right, np.minimum.accumulate(np.where(cuts, j + 1, W)[:, ::-1], axis=1)[:, ::-1])
    with np.errstate(invalid="ignore"):
        steps = np.minimum(np.where(left >= 0, j - left, np.inf), np.where(right < W, right - j, np.inf))
    return np.where(m, np.maximum(steps * spacing - 0.5 * spacing, 0.0), 0.0)


def border_distance(measurable: np.ndarray, sampling: tuple[float, float] = (1.0, 1.0),
                    where: np.ndarray | None = None, cuts: np.ndarray | None = None) -> np.ndarray:
    """Distance from each cell to the nearest outline or shadow border **along its row**, flat (H * W,).

    The stripe's width profile lies along the row (the axis the peak is located on, the
    sweep's direction): a border crossing the row cuts it, one running along the row (the
    end of the stripe's line) does not, so only the distance along the row counts
    (Curless and Levoy's truncated stripe).

    ``measurable`` (H, W) bool: cells whose surface the stripe reaches (not a miss, shadow
    or out of range). The border lies half a cell beyond the last measurable cell, so a
    cell next to it gets half a cell's spacing. ``cuts`` (H, W) bool, optional: a border
    between cells j and j + 1 that are both measurable (an occluding edge over a measured
    background: the stripe's light beyond it lands on the far surface, elsewhere in the
    image, so the near surface's stripe ends there too). ``sampling``: cell spacing (rows,
    columns) in the output's unit (the columns' is used). Cells whose row holds no border get +inf.

    ``where`` (H * W,) bool, optional: only these cells are needed (the other measurable
    cells get +inf, the unmeasurable ones 0); :func:`border_distance_at` answers them.

    Examples
    --------
    >>> m = np.ones((5, 7), bool); m[:, 0] = False
    >>> border_distance(m)[:7].tolist()
    [0.0, 0.5, 1.5, 2.5, 3.5, 4.5, 5.5]
    >>> m = np.ones((5, 7), bool); m[0] = False   # a border along the rows cuts no stripe
    >>> border_distance(m)[7:14].tolist()
    [inf, inf, inf, inf, inf, inf, inf]
    >>> cut = np.zeros((5, 7), bool); cut[:, 2] = True   # a step between columns 2 and 3
    >>> border_distance(np.ones((5, 7), bool), cuts=cut)[:7].tolist()
    [2.5, 1.5, 0.5, 0.5, 1.5, 2.5, 3.5]
    """
    m = np.asarray(measurable, bool)
    cuts = None if cuts is None else np.asarray(cuts, bool).reshape(m.shape)
    if m.all() and (cuts is None or not cuts.any()):
        return np.full(m.size, np.inf)
    if where is None:
        return _row_border_distance(m, float(sampling[1]), cuts).reshape(-1)
    out = np.full(m.size, np.inf)
    out[np.flatnonzero(~m.reshape(-1))] = 0.0
    ask = np.flatnonzero(np.asarray(where, bool).reshape(-1) & m.reshape(-1))
    out[ask] = border_distance_at(m, ask, sampling, cuts)
    return out


def border_distance_at(measurable: np.ndarray, cells: np.ndarray,
                       sampling: tuple[float, float] = (1.0, 1.0), cuts: np.ndarray | None = None) -> np.ndarray:
    """:func:`border_distance` of the measurable cells ``cells`` only (flat indices), (K,).

    Only the rows holding an asked cell are scanned (a few rows' work when few cells are
    asked; no full-size array is made).
    """
    m = np.asarray(measurable, bool)
    cells = np.asarray(cells, np.int64)
    cuts = None if cuts is None else np.asarray(cuts, bool).reshape(m.shape)
    if cells.size == 0 or (m.all() and (cuts is None or not cuts.any())):
        return np.full(cells.size, np.inf)
    rows, cols = np.divmod(cells, m.shape[1])
    needed, at = np.unique(rows, return_inverse=True)
    return _row_border_distance(m[needed], float(sampling[1]), None if cuts is None else cuts[needed])[at, cols]


@dataclass
class StripeDraw:
    """What :func:`simulate` decides for every cell of the grid (flat, H * W).

    Attributes
    ----------
    error_px : float64 array
        Peak error, pixels (0 where the cell is not a candidate).
    sigma_px : float64 array
        The model's predicted std of the peak error, pixels (NaN where not a candidate).
    detected : bool array
        Candidates that pass the dropout draw.
    """

    error_px: np.ndarray
    sigma_px: np.ndarray
    detected: np.ndarray


def simulate(noise: StripeNoise, rng: "np.random.Generator | NumPyDraws | PixelDraws", shape: tuple[int, int], *, candidate: np.ndarray,
             signal: np.ndarray, cos_incidence: np.ndarray, amplitude: np.ndarray, magnification: np.ndarray,
             reference_magnification: float, speckle_px: np.ndarray, border_mm: "np.ndarray | Callable",
             corr_px: tuple[float, float]) -> StripeDraw:
    """Dropouts, predicted std and peak errors of one scan: the one mechanism every scanner calls.

    Parameters
    ----------
    noise : StripeNoise
    rng : numpy.random.Generator, NumPyDraws or PixelDraws
        Draws in a fixed order: dropout field (only when ``noise.signal_contrast`` > 0), then
        the white normals, the correlated field and the quantiser phases. With Dr.Jit arrays
        as inputs (the geometric scanner) pass a :class:`PixelDraws`: the arithmetic and the
        white draws then stay lazy Dr.Jit expressions that fuse into the scan's kernels.
    shape : (H, W)
    candidate : (N,) bool
        Cells that would be measured before the dropout draw (lit, seen, in range).
    signal : (N,) array
        Mean return S (the dropout law); times :func:`partial_stripe_fraction` near borders.
    cos_incidence, amplitude, magnification : (N,) arrays
        Laser incidence cosine, image brightness A, pixels per mm across the stripe.
    reference_magnification : float
        Pixels per mm at the reference distance (the facing stripe's width w0).
    speckle_px : (N,) array
        Dorsch limit in pixels.
    border_mm : (N,) array, or a callable ``border_mm(where) -> array``
        Distance to the nearest outline or shadow border on the surface, mm. A callable is
        called only when a term needs it, with the cells that need it (the distance is the
        costliest step; see :func:`border_distance`'s ``where``).
    corr_px : (rows, columns)
        Correlation std of the correlated terms, cells.
    """
    draws = _draws(rng)
    xp = _ops(signal, candidate)
    if xp is _NP:
        candidate = np.asarray(candidate, bool).reshape(-1)
        signal = np.asarray(signal, np.float32)
    s = noise.stripe_width_mm
    # a stripe cut by an outline or shadow border is dimmer: the detector sees S Phi(t) with
    # Phi >= 1/2, so only returns below twice the threshold can be tipped over by it
    need_border = s > 0 and (noise.edge_gain > 0 or noise.signal_contrast > 0 or (
        noise.min_signal > 0 and xp.any(candidate & (signal < 2 * noise.min_signal))))
    border = None
    if need_border:
        if callable(border_mm):
            # only the cells a term needs: all candidates for the partial-stripe shift or a dropout
            # probability, else those dim enough for the truncation to tip them under the threshold
            everywhere = noise.edge_gain > 0 or noise.signal_contrast > 0
            border = border_mm(candidate if everywhere else candidate & (signal < 2 * noise.min_signal))
        else:
            border = border_mm
    if border is not None:
        signal = signal * xp.f32(partial_stripe_fraction(border, cos_incidence, s))
    if noise.signal_contrast > 0 and noise.min_signal > 0:
        # the regularised gamma function has no Dr.Jit counterpart: P(valid) is made in NumPy
        p = detection_probability(xp.numpy(signal), noise.min_signal, noise.signal_contrast)
        p = xp.like(np.where(xp.numpy(candidate), p, 0.0), signal)
        detected = candidate & draw_detected(draws, shape, p, corr_px)
    else:
        detected = candidate & (signal >= noise.min_signal)
    if s > 0:
        w = stripe_width_px(cos_incidence, magnification, s, noise.psf_px)
        w0 = float(stripe_width_px(np.ones(1), reference_magnification, s, noise.psf_px)[0])
        ratio = xp.f32(w / w0)
    else:  # no footprint: the imaged stripe is the blur alone, whatever the incidence
        ratio = xp.f32(xp.full_like(signal, 1.0))
    if noise.edge_gain > 0 and s > 0:
        # erfcx (a stable phi / Phi) has no Dr.Jit counterpart either
        edge_px = partial_stripe_shift_mm(xp.numpy(border), xp.numpy(cos_incidence), s) * xp.numpy(magnification)
        edge_px = xp.like(edge_px.astype(np.float32), signal)
    else:
        edge_px = xp.f32(xp.full_like(signal, 0.0))
    sigmas = peak_sigma_px(noise, width_ratio=ratio, amplitude=amplitude, speckle_px=speckle_px, edge_px=edge_px)
    sigmas = {k: xp.where(candidate, v, np.float32(0)) for k, v in sigmas.items()}
    error = draw_peak_error_px(draws, shape, sigmas, noise.quantization_px, corr_px)
    return StripeDraw(error_px=xp.where(detected, error, np.float32(0)),
                      sigma_px=xp.where(detected, sigmas["total"], np.float32(np.nan)), detected=detected)
