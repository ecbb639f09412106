"""Pieces shared by the edge detectors: scan arrays, pixel footprint, the depth-discontinuity
(jump) rule, discontinuity-aware finite differences and normals, non-maximum suppression.

Analysis layer: pure NumPy/SciPy over arrays. Conventions used by every detector:

* images are (H, W), row ``i`` grows downwards (image y), column ``j`` rightwards (image x);
  directions are angles of (x = column, y = row) vectors, radians;
* the four neighbour axes are indexed 0..3 with (drow, dcol) steps ``AXES`` = (0, 1), (1, 1),
  (1, 0), (1, -1), i.e. angles 0, 45, 90 and 135 degrees (``AXIS_ANGLES``);
* depth ``z`` is the camera-frame z of the measured point, mm, NaN where invalid; the camera
  looks along +z, so "near" means smaller z (recorded grids without a camera model: the
  scanner's z, see :func:`pixel_geometry`);
* thresholds are relative: in pixel footprints (the lateral size of a pixel on the surface,
  ``z / f`` mm) or angles, so they hold at every range.

Noise-adaptive defaults (every detector, same estimator): :func:`estimate_depth_noise`
measures the depth noise of the scan itself, in pixel footprints: the median absolute
deviation of the second difference ``z(i-1) - 2 z(i) + z(i+1)`` along rows and columns
(valid triples only, each divided by the centre's footprint), times 1.4826 (MAD to sigma
of a Gaussian) over sqrt(6) (a second difference of i.i.d. noise has variance 6 sigma^2).
Planes, smooth surfaces and the few percent of pixels on edges barely move the median, so
a noise-free scan measures ~0 and the White Scanner preset (0.25 footprints) its true
noise within a few percent. Below :data:`NOISE_FLOOR` a scan counts as noise-free and the
detectors use their noise-free defaults unchanged; above it they smooth / widen their
stencils (each documents how) and raise their threshold to
``max(noise-free default, k * median of the strength over valid pixels)``
(:func:`noise_threshold`): edges cover a few percent of the pixels, so the median is the
strength's noise level, and ``k`` (per detector, :data:`NOISE_K_GRADIENT` etc.) puts the
threshold ~4 noise standard deviations above it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "AXES", "AXIS_ANGLES", "NEIGHBOURS", "JUMP_THRESHOLD", "Discontinuities", "PixelGeometry",
    "scan_arrays", "scan_depth", "scan_points", "focal_length_px", "pixel_geometry", "footprint",
    "discontinuities", "find_discontinuities", "shift", "pad_last2", "padded_view",
    "segment_broken", "central_difference", "eno_tangent", "measured_normals", "dot3",
    "nonmax_suppress", "nearest_axis", "estimate_depth_noise", "noise_threshold", "NOISE_FLOOR",
    "NOISE_K_GRADIENT", "NOISE_K_NORMAL", "NOISE_K_PCL",
]

#: (drow, dcol) steps of the four neighbour axes: 0, 45, 90, 135 degrees in (x, y) = (col, row)
AXES: tuple[tuple[int, int], ...] = ((0, 1), (1, 1), (1, 0), (1, -1))
#: angles of the AXES, radians
AXIS_ANGLES = np.array([0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4])
#: the 8 neighbours as (drow, dcol)
NEIGHBOURS: tuple[tuple[int, int], ...] = tuple(
    (dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)
)


# -- scan access ---------------------------------------------------------------------------
def scan_arrays(scan: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured points, depth and validity of a scan, NaN wherever a pixel is unusable.

    Parameters
    ----------
    scan : RangeScan
        ``scan.xyz`` (mm, camera frame), ``scan.depth`` and ``scan.valid`` are used.

    Returns
    -------
    xyz : (H, W, 3) float32
        Points, NaN at invalid pixels.
    z : (H, W) float32
        Depth (mm), NaN at invalid pixels.
    valid : (H, W) bool
        ``scan.valid`` and a finite depth.
    """
    z, valid = scan_depth(scan)
    return scan_points(scan, valid), z, valid


def scan_depth(scan: Any) -> tuple[np.ndarray, np.ndarray]:
    """Depth (H, W) float32 with NaN at unusable pixels, and validity; see :func:`scan_arrays`."""
    z = np.asarray(scan.depth, dtype=np.float32)
    valid = np.asarray(scan.valid, dtype=bool) & np.isfinite(z)
    return np.where(valid, z, np.float32(np.nan)), valid


def scan_points(scan: Any, valid: np.ndarray, component_major: bool = False) -> np.ndarray:
    """Points with NaN where ``valid`` is False; see :func:`scan_arrays`.

    (H, W, 3) float32, or (3, H, W) contiguous with ``component_major``.
    """
    xyz = np.asarray(scan.xyz, dtype=np.float32)
    if component_major:
        xyz = np.ascontiguousarray(xyz.transpose(2, 0, 1))
        xyz[:, ~valid] = np.nan
        return xyz
    xyz = xyz.copy()
    np.copyto(xyz, np.nan, where=~valid[..., None])
    return xyz


def focal_length_px(scan: Any) -> float | None:
    """Focal length in pixels, sqrt(fx fy) of ``scan.meta["K"]``; None without intrinsics."""
    meta = getattr(scan, "meta", None) or {}
    K = meta.get("K")
    if K is None:
        return None
    K = np.asarray(K, dtype=np.float64)
    f = float(np.sqrt(abs(K[0, 0] * K[1, 1])))
    return f if np.isfinite(f) and f > 0 else None


@dataclass
class PixelGeometry:
    """How big a pixel is on the surface; see :func:`pixel_geometry`.

    Attributes
    ----------
    footprint : (H, W) float32
        Lateral size of one pixel on the surface, mm (NaN where the depth is NaN).
    perspective : bool
        True for a pinhole camera at the origin (footprint ``z / f``, inverse depth linear
        on planes); False for grids of constant spacing (translating-sweep scanners).
    focal_length : float or None
        f in pixels when perspective.
    """

    footprint: np.ndarray
    perspective: bool
    focal_length: float | None


def _spread(v: np.ndarray) -> float:
    """Relative spread (interquartile range over median) of positive samples."""
    q1, q2, q3 = np.percentile(v, [25, 50, 75])
    return float((q3 - q1) / q2) if q2 > 0 else np.inf


def pixel_geometry(scan: Any, z: np.ndarray | None = None) -> PixelGeometry:
    """Pixel footprint of a scan: ``z / f`` from ``meta["K"]``, or estimated from the points.

    Synthetic scans carry ``K``. Recorded ones may not: then the lateral spacing ``d`` of
    horizontal and vertical neighbours (``|(dx, dy)|``) decides between a pinhole camera
    (``d / z`` nearly constant: f = 1 / median(d / z); Kinect-class PCD files) and a grid of
    constant spacing (``d`` nearly constant, or depths not all positive: footprint =
    median(d); the Cyberware's translating sweep), whichever has the smaller relative spread.

    Parameters
    ----------
    scan : RangeScan
    z : (H, W) float array, optional
        Depth with NaN where invalid (default: from the scan).

    Returns
    -------
    PixelGeometry
    """
    if z is None:
        z, _ = scan_depth(scan)
    f = focal_length_px(scan)
    if f is not None:
        return PixelGeometry((z / np.float32(f)).astype(np.float32), True, f)
    xyz, _, _ = scan_arrays(scan)
    xyz = xyz.astype(np.float64)
    d_all, z_all = [], []
    for a, b in ((xyz[:, 1:], xyz[:, :-1]), (xyz[1:], xyz[:-1])):
        d = np.hypot(a[..., 0] - b[..., 0], a[..., 1] - b[..., 1])
        zz = np.fmin(a[..., 2], b[..., 2])
        ok = np.isfinite(d) & np.isfinite(zz) & (d > 0)
        d_all.append(d[ok])
        z_all.append(zz[ok])
    d, zz = np.concatenate(d_all), np.concatenate(z_all)
    if d.size == 0:
        return PixelGeometry(np.where(np.isfinite(z), 1.0, np.nan).astype(np.float32), False, None)
    if np.all(zz > 0) and _spread(d / zz) < _spread(d):
        f = 1.0 / float(np.median(d / zz))
        return PixelGeometry((z / np.float32(f)).astype(np.float32), True, f)
    fp = np.float32(np.median(d))
    return PixelGeometry(np.where(np.isfinite(z), fp, np.nan).astype(np.float32), False, None)


def footprint(scan: Any, z: np.ndarray | None = None) -> np.ndarray:
    """(H, W) float32 lateral size of a pixel on the surface, mm (see :func:`pixel_geometry`)."""
    return pixel_geometry(scan, z).footprint


#: the detectors' default jump rule, in pixel footprints: a step between neighbours deeper
#: than cot(15 deg) = 3.73 footprints, i.e. a continuous surface jumps only when seen at
#: more than 75 degrees slant; the rule of rangesim.evaluate's ground truth (a 3D step
#: within 15 degrees of the viewing ray). For a pinhole camera it is 3.73 / f times the
#: depth (0.0028 z for the White Scanner's f = 1317 px, 0.014 z at f = 275 px); PCL's
#: fixed 0.02 z is 0.02 f footprints (10.5 for a Kinect), blind to shallow steps.
JUMP_THRESHOLD = float(1.0 / np.tan(np.radians(15.0)))


def discontinuities(
    scan: Any, z: np.ndarray, jump_threshold: float, max_search: int,
) -> tuple["Discontinuities", PixelGeometry]:
    """The detectors' jump rule: :func:`find_discontinuities` with ``jump_threshold`` pixel
    footprints, and the scan's :class:`PixelGeometry`."""
    geo = pixel_geometry(scan, z)
    disc = find_discontinuities(z, np.float32(jump_threshold) * geo.footprint, max_search,
                                perspective=geo.perspective)
    return disc, geo


# -- noise ------------------------------------------------------------------------------------
#: depth noise (pixel footprints) below which a scan counts as noise-free: the detectors'
#: noise-free defaults hold unchanged (a noise-free scan measures < 0.001)
NOISE_FLOOR = 0.05
#: threshold multiples of the median strength on noisy scans (see the module docstring):
#: the gradient's noise bend ``2 atan(max response)`` (an upper estimate, as if the
#: neighbour across responded as much; 3 medians ~ 4 sigma of the bend estimate), the normal detector's pair angle (Rayleigh-like:
#: median 1.18 scale, 4.5 medians ~ 5.3 scale, ~1e-6 tail per pair) and PCL's Sobel
#: magnitude of the normal field (low hysteresis threshold; high scales with it)
NOISE_K_GRADIENT = 3.0
NOISE_K_NORMAL = 4.5
NOISE_K_PCL = 4.0


def estimate_depth_noise(scan: Any = None, z: np.ndarray | None = None,
                         fp: np.ndarray | None = None) -> float:
    """Depth noise of a scan, in pixel footprints (sigma_z / (z / f)).

    A scan that carries its noise model's prediction (``scan.sigma``, mm, as simulated
    laser-stripe scans do) gives the median of ``sigma / footprint`` over its valid pixels:
    the model knows its noise, correlated or not, which the data's second differences
    underestimate when neighbouring errors are correlated. Otherwise, from the data itself:
    the robust estimator of the module docstring: ``1.4826 * MAD / sqrt(6)`` of the second
    differences of depth along rows and columns over valid triples, each divided by the
    pixel footprint at its centre (median taken about 0: on a noise-free piecewise-smooth
    surface almost every second difference is ~0). Works on recorded scans too (footprint
    from :func:`pixel_geometry`); quantised depth (Kinect) counts as noise.

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
    """
    if z is None:
        z, _ = scan_depth(scan)
    if fp is None:
        fp = pixel_geometry(scan, z).footprint
    predicted = getattr(scan, "sigma", None) if scan is not None else None
    if predicted is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.asarray(predicted, np.float64) / fp
        ratio = ratio[np.isfinite(ratio) & np.isfinite(z)]
        if ratio.size >= 100:
            return float(np.median(ratio))
    z = np.asarray(z, np.float32)
    # every 4th column / row is plenty for a median (and 4x cheaper)
    zc, fc = z[:, ::4], fp[:, ::4]
    zr, fr = z[::4], fp[::4]
    with np.errstate(invalid="ignore", divide="ignore"):
        d0 = (zc[:-2] - 2 * zc[1:-1] + zc[2:]) / fc[1:-1]
        d1 = (zr[:, :-2] - 2 * zr[:, 1:-1] + zr[:, 2:]) / fr[:, 1:-1]
    d = np.concatenate([d0[np.isfinite(d0)], d1[np.isfinite(d1)]])
    if d.size < 100:
        return 0.0
    return float(1.4826 * np.median(np.abs(d)) / np.sqrt(6.0))


def noise_threshold(strength: np.ndarray, valid: np.ndarray, default: float, k: float) -> float:
    """``max(default, k * median(strength))`` over valid pixels with a finite strength.

    The median is taken on every 4th row and column (1/16 of the pixels): plenty for a
    robust noise level, and 16 times cheaper than over a megapixel.
    """
    sub = (slice(None, None, 4), slice(None, None, 4))
    st = strength[sub][valid[sub] & np.isfinite(strength[sub])]
    if st.size == 0:
        return float(default)
    return float(max(default, k * float(np.median(st))))


# -- shifting ------------------------------------------------------------------------------
def shift(a: np.ndarray, dr: int, dc: int, fill: Any) -> np.ndarray:
    """``out[i, j] = a[i + dr, j + dc]``, ``fill`` outside the image (leading two axes)."""
    h, w = a.shape[:2]
    out = np.empty_like(a)
    if abs(dr) >= h or abs(dc) >= w:
        out[...] = fill
        return out
    r0, r1 = max(0, -dr), min(h, h - dr)
    c0, c1 = max(0, -dc), min(w, w - dc)
    out[r0:r1, c0:c1] = a[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
    out[:r0] = fill
    out[r1:] = fill
    out[:, :c0] = fill
    out[:, c1:] = fill
    return out


# -- depth discontinuities -----------------------------------------------------------------
@dataclass
class Discontinuities:
    """Depth discontinuities (jump edges) of a depth image; see :func:`find_discontinuities`.

    Attributes
    ----------
    occluding : (H, W) bool
        Near side of a discontinuity (the pixel is nearer than its neighbour across it).
    occluded : (H, W) bool
        Far side.
    nan_boundary : (H, W) bool
        Valid pixels next to invalid ones where the search across the gap found no valid
        pixel within ``max_search`` (or left the image): the type cannot be told.
    pairs : (4, H, W) bool
        ``pairs[a, i, j]``: the pixel and its neighbour one step along ``AXES[a]`` lie on
        either side of a discontinuity (both valid). Finite differences must not cross them.
    direction : (H, W) float32
        At occluding/occluded pixels: angle in [0, pi) of the (x, y) vector across the
        discontinuity; NaN elsewhere.
    """

    occluding: np.ndarray
    occluded: np.ndarray
    nan_boundary: np.ndarray
    pairs: np.ndarray
    direction: np.ndarray

    @property
    def touching(self) -> np.ndarray:
        """Pixels on either side of a discontinuity between valid neighbours."""
        t = np.zeros(self.pairs.shape[1:], bool)
        for a, (dr, dc) in enumerate(AXES):
            t |= self.pairs[a] | shift(self.pairs[a], -dr, -dc, False)
        return t


def find_discontinuities(
    z: np.ndarray,
    threshold: float | np.ndarray = 0.02,
    max_search: int = 50,
    rule: str = "any",
    extrapolate: bool = True,
    connectivity: int | None = None,
    perspective: bool = True,
) -> Discontinuities:
    """Jump edges: neighbours whose depths differ by more than a threshold.

    The rule of PCL's ``OrganizedEdgeBase`` (depth-discontinuity threshold proportional to
    depth, default 0.02 z): a pixel ``p`` is *occluding* when a neighbour ``q`` is farther,
    ``z_q - z_p > t_p``, and *occluded* when a neighbour is nearer, ``z_p - z_q > t_q``,
    with ``t = threshold * z`` (or a given per-pixel threshold); the nearer pixel's
    threshold applies, so every broken pair has one occluding and one occluded pixel.

    Across invalid (NaN) pixels, as in PCL, a valid pixel with invalid neighbours searches
    for the first valid pixel along the mean direction of those neighbours (normalised to
    one pixel per step along its larger axis, so every step moves; PCL's floor() can stay
    put) for up to ``max_search`` steps and compares depths with it. Unlike PCL, with
    ``extrapolate`` the comparison is against the pixel's own surface continued across
    the gap (inverse depth, or depth without ``perspective``, extrapolated linearly from
    the pixel behind it: exact for planes), so a hole in a tilted plane is not a jump.
    A pixel whose search finds nothing is a *NaN boundary*.

    Parameters
    ----------
    z : (H, W) float array
        Depth, mm, NaN where invalid.
    threshold : float or (H, W) float array
        A float: relative jump threshold, fraction of the depth (0.02 is PCL's default; a
        surface seen at slant phi steps ``z tan(phi) / f`` per pixel, so it stays silent on
        continuous surfaces up to ``atan(0.02 f)``: 80 deg at f = 275 px, 88 deg at
        f = 1300 px). An array: per-pixel threshold in mm (the detectors pass a multiple
        of the pixel footprint, see :data:`JUMP_THRESHOLD`).
    max_search : int
        Most steps searched across an invalid gap (pixels); 0 disables the search.
    rule : {"any", "dominant"}
        ``"any"``: a pixel may be both occluding and occluded (thin slivers), and the search
        across gaps adds to the neighbour tests. ``"dominant"``: PCL's rule; where all 8
        neighbours are valid only the largest depth difference counts (one label), where
        some are invalid only the search result counts.
    extrapolate : bool
        Compare with the extrapolated depth across gaps (see above) instead of the raw one.
    connectivity : {4, 8}, optional
        Neighbours that make a pixel occluding / occluded (and that start a search when
        invalid). Default 8 for ``"dominant"`` (PCL), 4 for ``"any"``: the near side of a
        jump is then a thin 8-connected line, as the ground truth marks it, instead of a
        4-connected staircase. ``pairs`` always covers all 8 directions.
    perspective : bool
        Extrapolate inverse depth (pinhole camera at the origin) or depth (grids of
        constant spacing) across gaps.

    Returns
    -------
    Discontinuities
    """
    if rule not in ("any", "dominant"):
        raise ValueError(f"rule must be 'any' or 'dominant', not {rule!r}")
    if connectivity is None:
        connectivity = 8 if rule == "dominant" else 4
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    z = np.asarray(z, dtype=np.float32)
    h, w = z.shape
    valid = np.isfinite(z)
    if np.ndim(threshold) == 0:
        thr = np.abs(z) * np.float32(threshold)
    else:
        thr = np.asarray(threshold, dtype=np.float32)
    zt = z + thr                                  # a neighbour beyond zt_p is a jump away
    zp = np.pad(z, 1, constant_values=np.nan)
    ztp = np.pad(zt, 1, constant_values=np.nan)
    # an out-of-image neighbour is not an invalid one (PCL skips the border instead)
    vp = np.pad(valid, 1, constant_values=True)
    occluding = np.zeros((h, w), bool)
    occluded = np.zeros((h, w), bool)
    has_invalid = np.zeros((h, w), bool)
    pairs = np.zeros((4, h, w), bool)
    far = np.full((h, w), -np.inf, np.float32) if rule == "dominant" else None
    near = np.full((h, w), -np.inf, np.float32) if rule == "dominant" else None
    occl = np.empty((h, w), bool)
    occd = np.empty((h, w), bool)
    for dr, dc in NEIGHBOURS:
        view = (slice(1 + dr, 1 + dr + h), slice(1 + dc, 1 + dc + w))
        zq = zp[view]
        np.greater(zq, zt, out=occl)                 # NaN compares False
        np.greater(z, ztp[view], out=occd)
        if (dr, dc) in AXES:
            np.logical_or(occl, occd, out=pairs[AXES.index((dr, dc))])
        if connectivity == 4 and dr != 0 and dc != 0:
            continue
        occluding |= occl
        occluded |= occd
        has_invalid |= ~vp[view]
        if far is not None:
            e = zq - z
            np.fmax(far, e, out=far)
            np.fmax(near, -e, out=near)
    has_invalid &= valid
    if rule == "dominant":
        # PCL: one label from the dominant difference; only the search where a neighbour is NaN
        occluding &= (far >= near) & ~has_invalid
        occluded &= (near > far) & ~has_invalid
    direction = np.full((h, w), np.nan, np.float32)
    nan_boundary = np.zeros((h, w), bool)

    ii, jj = np.nonzero(has_invalid)
    if ii.size and max_search > 0:
        # mean offset of the invalid neighbours: the direction to search along
        vx = np.zeros(ii.size, np.float32)
        vy = np.zeros(ii.size, np.float32)
        vpad = np.pad(valid, 1, constant_values=True)
        for dr, dc in NEIGHBOURS:
            inv = ~vpad[ii + 1 + dr, jj + 1 + dc]
            vx += inv * dc
            vy += inv * dr
        scale = np.maximum(np.abs(vx), np.abs(vy))
        moving = scale > 0
        ii, jj, vx, vy, scale = ii[moving], jj[moving], vx[moving], vy[moving], scale[moving]
        sx, sy = vx / scale, vy / scale
        z0 = z[ii, jj].astype(np.float64)
        t0 = thr[ii, jj].astype(np.float64)
        # the pixel behind: continues the pixel's own surface across the gap
        bi = ii - np.rint(sy).astype(np.intp)
        bj = jj - np.rint(sx).astype(np.intp)
        inside = (bi >= 0) & (bi < h) & (bj >= 0) & (bj < w)
        zb = np.full(ii.size, np.nan)
        zb[inside] = z[bi[inside], bj[inside]]
        slope = np.zeros(ii.size)        # per step, of 1 / z (perspective) or z
        if extrapolate:
            smooth = np.isfinite(zb) & (np.abs(zb - z0) <= t0)
            if perspective:
                slope[smooth] = 1.0 / z0[smooth] - 1.0 / zb[smooth]
            else:
                slope[smooth] = z0[smooth] - zb[smooth]
        found_z = np.full(ii.size, np.nan)
        found_t = np.full(ii.size, np.nan)
        found_s = np.zeros(ii.size)
        active = np.arange(ii.size)
        for s in range(1, int(max_search) + 1):
            ri = ii[active] + np.rint(sy[active] * s).astype(np.intp)
            rj = jj[active] + np.rint(sx[active] * s).astype(np.intp)
            inside = (ri >= 0) & (ri < h) & (rj >= 0) & (rj < w)
            active, ri, rj = active[inside], ri[inside], rj[inside]
            zq = z[ri, rj]
            hit = np.isfinite(zq)
            found_z[active[hit]] = zq[hit]
            found_t[active[hit]] = thr[ri[hit], rj[hit]]
            found_s[active[hit]] = s
            active = active[~hit]
            if active.size == 0:
                break
        ok = np.isfinite(found_z)
        with np.errstate(divide="ignore", invalid="ignore"):
            if perspective:
                inv_pred = 1.0 / z0 + found_s * slope
                pred = 1.0 / np.fmax(inv_pred, 0.5 / z0)  # a receding surface: at most 2 z0
            else:
                pred = z0 + found_s * slope
        occl = ok & (found_z - pred > t0)
        occd = ok & (pred - found_z > found_t)
        occluding[ii[occl], jj[occl]] = True
        occluded[ii[occd], jj[occd]] = True
        nan_boundary[ii[~ok], jj[~ok]] = True
        jump = occl | occd
        direction[ii[jump], jj[jump]] = np.mod(np.arctan2(sy[jump], sx[jump]), np.pi)

    # direction across the jump from the broken neighbour pairs (gradient of "is far")
    ei, ej = np.nonzero((occluding | occluded) & np.isnan(direction))
    if ei.size:
        zpad = np.pad(z, 1, constant_values=np.nan)
        gx = np.zeros(ei.size, np.float32)
        gy = np.zeros(ei.size, np.float32)
        ztpad = np.pad(zt, 1, constant_values=np.nan)
        zc, ztc = z[ei, ej], zt[ei, ej]
        for dr, dc in NEIGHBOURS:
            zq = zpad[ei + 1 + dr, ej + 1 + dc]
            step = (zq > ztc).astype(np.float32) - (zc > ztpad[ei + 1 + dr, ej + 1 + dc])
            gx += step * dc
            gy += step * dr
        direction[ei, ej] = np.mod(np.arctan2(gy, gx), np.pi)
    return Discontinuities(occluding, occluded, nan_boundary, pairs, direction)


def padded_view(p: np.ndarray, r: int, dr: int, dc: int, shape: tuple[int, int]) -> np.ndarray:
    """View of an array padded by ``r`` on its last two axes, shifted by (dr, dc)."""
    h, w = shape
    return p[..., r + dr:r + dr + h, r + dc:r + dc + w]


def pad_last2(a: np.ndarray, r: int, fill: Any) -> np.ndarray:
    """``a`` padded by ``r`` with ``fill`` on its last two axes."""
    widths = [(0, 0)] * (a.ndim - 2) + [(r, r), (r, r)]
    return np.pad(a, widths, constant_values=fill)


def segment_broken(pairs: np.ndarray, axis: int, k0: int, k1: int) -> np.ndarray:
    """True where the steps ``p + k d -> p + (k + 1) d``, k0 <= k < k1, cross a discontinuity.

    ``d = AXES[axis]``; ``pairs`` (4, H, W) from :class:`Discontinuities` (or any such
    per-axis mask of broken neighbour pairs).
    """
    dr, dc = AXES[axis]
    shape = pairs.shape[1:]
    r = max(abs(k0), abs(k1), 1)
    pp = pad_last2(pairs[axis], r, False)
    out = np.zeros(shape, bool)
    for k in range(k0, k1):
        out |= padded_view(pp, r, k * dr, k * dc, shape)
    return out


# -- finite differences and normals --------------------------------------------------------
def _sides(a: np.ndarray, axis: int, pairs: np.ndarray | None, step: int) -> tuple[np.ndarray, ...]:
    """End points of the discontinuity-aware difference of ``a`` (..., H, W) along an axis.

    Returns (A, B, n): ``A`` is ``a(p + s d)`` where that side is usable (valid, no jump in
    between) else ``a(p)``, ``B`` likewise on the minus side, ``n`` the number of usable
    sides (0, 1, 2) as float32, so ``(A - B) / (s n)`` is the central or one-sided difference.
    """
    dr, dc = AXES[axis]
    s = int(step)
    shape = a.shape[-2:]
    ok = ~np.isnan(a if a.ndim == 2 else a[0])
    okp = pad_last2(ok, s, False)
    fok = padded_view(okp, s, s * dr, s * dc, shape) & ok
    bok = padded_view(okp, s, -s * dr, -s * dc, shape) & ok
    if pairs is not None:
        fok &= ~segment_broken(pairs, axis, 0, s)
        bok &= ~segment_broken(pairs, axis, -s, 0)
    ap = pad_last2(a, s, np.nan)
    A = np.where(fok, padded_view(ap, s, s * dr, s * dc, shape), a)
    B = np.where(bok, padded_view(ap, s, -s * dr, -s * dc, shape), a)
    return A, B, fok.view(np.int8) + bok.view(np.int8)


def central_difference(
    a: np.ndarray, axis: int, pairs: np.ndarray | None, step: int = 1
) -> np.ndarray:
    """Derivative of ``a`` per pixel along ``AXES[axis]`` (0: x, 2: y; any of the four).

    Central difference ``(a(p + s d) - a(p - s d)) / 2s`` where both sides are valid and no
    discontinuity lies between; otherwise the one-sided difference that is; NaN if neither.

    Parameters
    ----------
    a : (H, W) or (C, H, W) float array
        Image or component-major stack (a pixel is valid where ``a`` (its first component)
        is not NaN).
    axis : int
        Index into ``AXES``.
    pairs : (4, H, W) bool or None
        Discontinuity pairs (:class:`Discontinuities`); differences never cross them.
    step : int
        Half-width s, pixels.

    Returns
    -------
    array like ``a``
    """
    A, B, n = _sides(a, axis, pairs, step)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = (A - B) / (n * np.asarray(step, a.dtype))
    return d.astype(a.dtype, copy=False)


#: WENO regulariser, relative to the squared step length (smaller: sharper side choice)
_WENO_EPS = 1e-4


def eno_tangent(xyz: np.ndarray, axis: int, pairs: np.ndarray | None, step: int = 1) -> np.ndarray:
    """Edge-preserving tangent of a point image along an axis (WENO-weighted differences).

    The forward difference ``P(p + s d) - P(p)`` and the backward one ``P(p) - P(p - s d)``
    are blended with weights ``1 / (eps + S)^2``, S the squared norm of the second
    difference that continues each side (``P(p + 2s d) - 2 P(p + s d) + P(p)``, and its
    mirror): on a smooth surface both are small and the blend is the central difference;
    next to a crease the side that straddles it has a large S and drops out, so the
    tangent (and the normal) stays that of the pixel's own face right up to the crease
    instead of mixing both faces over ``s`` pixels. Sides that are invalid or cross a
    discontinuity are not used; a side whose continuation is unknown has S = infinity.

    Parameters
    ----------
    xyz : (3, H, W) float array
        Points, component-major, NaN where invalid.
    axis : int
        Index into ``AXES`` (0: x, 2: y).
    pairs : (4, H, W) bool or None
        Discontinuity pairs (:class:`Discontinuities`).
    step : int
        Difference step s, pixels.

    Returns
    -------
    (3, H, W) array
        Tangent per pixel step (mm / px); NaN where neither side is usable.
    """
    dr, dc = AXES[axis]
    s = int(step)
    shape = xyz.shape[-2:]
    r = 2 * s
    ok = ~np.isnan(xyz[0])
    if pairs is not None:
        ok_step = [~segment_broken(pairs, axis, k * s, (k + 1) * s) for k in (-2, -1, 0, 1)]
    else:
        ok_step = [np.ones(shape, bool)] * 4
    okp = pad_last2(ok, r, False)
    pp = pad_last2(xyz, r, np.nan)

    def at(k: int) -> tuple[np.ndarray, np.ndarray]:
        return (padded_view(pp, r, k * s * dr, k * s * dc, shape),
                padded_view(okp, r, k * s * dr, k * s * dc, shape))

    (pm2, om2), (pm1, om1), (pp1, op1), (pp2, op2) = at(-2), at(-1), at(1), at(2)
    fok = ok & op1 & ok_step[2]
    bok = ok & om1 & ok_step[1]
    fwd = np.where(fok, pp1 - xyz, 0).astype(xyz.dtype, copy=False)
    bwd = np.where(bok, xyz - pm1, 0).astype(xyz.dtype, copy=False)
    big = np.float32(1e30)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        f2 = pp2 - 2 * pp1 + xyz
        f2 = np.where(fok & op2 & ok_step[3], dot3(f2, f2), big)
        b2 = xyz - 2 * pm1 + pm2
        b2 = np.where(bok & om2 & ok_step[0], dot3(b2, b2), big)
        eps = np.float32(_WENO_EPS) * (dot3(fwd, fwd) + dot3(bwd, bwd)) + np.float32(1e-30)
        wf = fok / (eps + f2) ** 2
        wb = bok / (eps + b2) ** 2
        total = wf + wb
        wf /= total
        wb /= total
    return fwd * wf + bwd * wb


def measured_normals(xyz: np.ndarray, pairs: np.ndarray | None, step: int = 1) -> np.ndarray:
    """Unit surface normals from the measured points, facing the camera, sharp at creases.

    The cross product of the edge-preserving tangents along image y and x
    (:func:`eno_tangent`): on smooth surfaces the central-difference normal over
    ``step`` pixels each side, next to a crease the normal of the pixel's own face (one-sided
    differences away from the crease), so normals change abruptly where the surface does.
    Differences never cross a NaN or a depth discontinuity.

    Parameters
    ----------
    xyz : (3, H, W) float array
        Points, component-major, camera frame (origin at the viewpoint), NaN where invalid.
    pairs : (4, H, W) bool or None
        Discontinuity pairs (:class:`Discontinuities`); differences never cross them.
    step : int
        Difference step, pixels (larger: smoother normals on noisy data).

    Returns
    -------
    (3, H, W) array of xyz's dtype
        Unit normals with ``n . p <= 0`` (towards the camera); NaN where a tangent is missing.
    """
    tx = eno_tangent(xyz, 0, pairs, step)
    ty = eno_tangent(xyz, 2, pairs, step)
    # y-tangent x x-tangent points towards the camera (-z) for an image of a visible surface
    n = np.stack([ty[1] * tx[2] - ty[2] * tx[1],
                  ty[2] * tx[0] - ty[0] * tx[2],
                  ty[0] * tx[1] - ty[1] * tx[0]])
    norm = np.sqrt(dot3(n, n))
    facing = dot3(n, xyz)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(facing > 0, -1, 1).astype(n.dtype) / norm
    np.copyto(scale, np.nan, where=~(norm > 0))
    n *= scale
    return n


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel dot product of component-major (3, H, W) stacks."""
    out = a[0] * b[0]
    out += a[1] * b[1]
    out += a[2] * b[2]
    return out


# -- thinning ------------------------------------------------------------------------------
def nearest_axis(direction: np.ndarray) -> np.ndarray:
    """Index (0..3) of the ``AXES`` nearest to each direction (radians, any range); int8."""
    d = np.where(np.isnan(direction), np.float32(0), direction)
    return np.rint(d * np.float32(4 / np.pi)).astype(np.int8) & 3


def nonmax_suppress(
    strength: np.ndarray,
    direction: np.ndarray,
    candidates: np.ndarray | None = None,
    return_sides: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Keep pixels that are maxima of ``strength`` across the edge (Canny's thinning).

    The strength one pixel away on either side along ``direction`` is interpolated
    linearly between the two neighbours that bracket it (an axis and a diagonal
    neighbour), so lines at any angle come out thin. A pixel survives if its strength is
    strictly above the minus side and at least the plus side: of a two-pixel plateau (an
    edge running between pixel centres) exactly one is kept. NaN strength never survives
    and counts as nothing beside a pixel.

    Parameters
    ----------
    strength : (H, W) float array
    direction : (H, W) float array
        Angle of the (x, y) vector across the edge, radians (any range; NaN: 0).
    candidates : (H, W) bool, optional
        Only these pixels are tested (e.g. those above a threshold; much faster when they
        are few); default all pixels with a finite strength.
    return_sides : bool
        Also return the larger of the two interpolated side strengths.

    Returns
    -------
    keep : (H, W) bool
    sides : (H, W) float32, only with ``return_sides``
        At the tested pixels the larger interpolated strength beside them (NaN where there
        is none), NaN elsewhere.
    """
    h, w = strength.shape
    if candidates is None:
        candidates = ~np.isnan(strength)
    ii, jj = np.nonzero(candidates & ~np.isnan(strength))
    keep = np.zeros((h, w), bool)
    sides = np.full((h, w), np.nan, np.float32) if return_sides else None
    if ii.size == 0:
        return (keep, sides) if return_sides else keep
    low = np.float32(-1e30)                      # not -inf: 0 * -inf would be NaN
    sp = np.pad(np.where(np.isnan(strength), low, strength).astype(np.float32), 1,
                constant_values=low).ravel()
    stride = w + 2
    base = (ii + 1) * stride + (jj + 1)
    d = direction[ii, jj]
    theta = np.mod(np.where(np.isnan(d), 0, d), np.pi)
    c, sn = np.abs(np.cos(theta)), np.sin(theta)          # sin >= 0 on [0, pi)
    xmajor = c >= sn
    wgt = np.minimum(c, sn) / np.maximum(c, sn)           # tan of the angle off the axis
    dx = np.where(theta > np.pi / 2, -1, 1)               # x component's sign
    # plus side: the axis neighbour (x or y) and the diagonal one bracketing the direction;
    # minus side: their mirror images
    prim = np.where(xmajor, dx, stride)
    diag = stride + dx
    s0 = sp[base]
    plus = sp[base + prim] * (1 - wgt) + sp[base + diag] * wgt
    minus = sp[base - prim] * (1 - wgt) + sp[base - diag] * wgt
    keep[ii, jj] = (s0 > minus) & (s0 >= plus)
    if not return_sides:
        return keep
    side = np.maximum(plus, minus)
    sides[ii, jj] = np.where(side > low / 2, side, np.nan)
    return keep, sides



def thin_staircases(mask: np.ndarray, droppable: np.ndarray | None = None) -> np.ndarray:
    """Drop the inner corners of 2-px staircases, keeping 8-connectivity (1 px diagonals).

    Non-maximum suppression leaves diagonal edges as 4-connected staircases (a corner
    pixel at every step), which an 8-connected 1-px truth does not match one-to-one. A
    pixel is dropped when two of its 4-neighbours at a right angle (e.g. north and east)
    are set, the diagonal pixel between them is not (an L, not a 2x2 block), and the
    opposite 4-neighbours and diagonal are clear: the two stay 8-connected without it
    and nothing else depends on it. Pixels are removed in two passes by checkerboard
    parity, so two 4-adjacent pixels are never dropped together (a step's two corners).

    Parameters
    ----------
    mask : (H, W) bool
        Edge pixels (all of them count as neighbours).
    droppable : (H, W) bool, optional
        Only these may be dropped (default: all of ``mask``).

    Returns
    -------
    (H, W) bool
        The thinned mask (a new array).
    """
    h, w = mask.shape
    stride = w + 2
    p = np.pad(mask, 1).ravel()
    cand = mask if droppable is None else (mask & droppable)
    ii, jj = np.nonzero(cand)
    if ii.size == 0:
        return mask.copy()
    base = (ii + 1) * stride + (jj + 1)
    n, s, e, wst = -stride, stride, 1, -1
    # (a, b, their diagonal, opposite a, opposite b, opposite diagonal)
    corners = ((n, e, n + e, s, wst, s + wst), (e, s, s + e, wst, n, n + wst),
               (s, wst, s + wst, n, e, n + e), (wst, n, n + wst, e, s, s + e))
    parity = ((ii + jj) & 1).astype(bool)
    for ph in (False, True):
        b = base[parity == ph]
        drop = np.zeros(b.size, bool)
        for a_, b_, d_, oa, ob, od in corners:
            drop |= p[b + a_] & p[b + b_] & ~p[b + d_] & ~p[b + oa] & ~p[b + ob] & ~p[b + od]
        p[b[drop]] = False
    return p.reshape(h + 2, w + 2)[1:-1, 1:-1].copy()


#: no crease is kept within this many pixels of a jump: the crest beside an occluding edge
#: (and the surface just beyond it) is the jump itself, not a roof
JUMP_CLEARANCE = 2


def near_mask(where: np.ndarray, ref: np.ndarray, r: int) -> np.ndarray:
    """True at pixels of ``where`` within chessboard distance ``r`` of a ``ref`` pixel.

    Sparse: only the pixels of ``where`` look at their (2r+1)^2 window (cheap when
    ``where`` is thin, e.g. edge candidates); False elsewhere.
    """
    h, w = where.shape
    out = np.zeros((h, w), bool)
    ii, jj = np.nonzero(where)
    if ii.size == 0 or r <= 0:
        return out
    stride = w + 2 * r
    rp = np.pad(ref, r).ravel()
    base = (ii + r) * stride + (jj + r)
    hit = np.zeros(ii.size, bool)
    for dr in range(-r, r + 1):
        for dc in range(-r, r + 1):
            hit |= rp[base + dr * stride + dc]
    out[ii[hit], jj[hit]] = True
    return out
