"""A baseline from the wider field: PCL's OrganizedEdgeFromNormals, in NumPy."""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.edges._differences import central_difference, dot3, measured_normals
from rangesim.edges._discontinuities import JUMP_THRESHOLD, find_discontinuities
from rangesim.edges._grid import AXES, pad_last2, padded_view
from rangesim.edges._matching_scale import matching_window, ridge_sigma
from rangesim.edges._noise import NOISE_FLOOR, NOISE_K_PCL, estimate_depth_noise, noise_threshold, stencil_window
from rangesim.edges._pcl_scale import (
    K_HIGH,
    K_LOW,
    chord_normals,
    crease_step,
    nan_gaussian,
    strength_noise,
    strided_sobel,
)
from rangesim.edges._scan_access import PixelGeometry, pixel_geometry, scan_depth, scan_points
from rangesim.edges._thinning import (
    JUMP_CLEARANCE,
    hysteresis,
    near_mask,
    nearest_axis,
    nonmax_suppress,
    thin_staircases,
)
from rangesim.edges._trig import half_atan2
from rangesim.edges.edgemap import EdgeMap

__all__ = ["pcl_organized", "OrganizedEdgeMap", "EDGE_TYPES"]

#: PCL's edge classes, in the order of its label bits
EDGE_TYPES = ("nan_boundary", "occluding", "occluded", "high_curvature")

#: |(P_B - P_A) . (n_A - n_B)| / (|P_B - P_A| |n_A - n_B|) below this: the type is not told
_MIN_SIDE_COSINE = 0.2


@dataclass(repr=False)
class OrganizedEdgeMap(EdgeMap):
    """An :class:`EdgeMap` with PCL's four edge classes as separate masks.

    Attributes
    ----------
    occluding, occluded, nan_boundary, high_curvature : (H, W) bool or None
        PCL's classes (before ``edge_types`` selects which enter ``mask``). Occluding and
        occluded pixels are both labelled JUMP in ``labels``; NaN-boundary pixels 0.
    """

    occluding: np.ndarray | None = None
    occluded: np.ndarray | None = None
    nan_boundary: np.ndarray | None = None
    high_curvature: np.ndarray | None = None


#: 3-tap Gaussian, sigma 1 (PCL's Canny smooths with a 3 x 3 one): centre and side weights
_GAUSS3 = (1.0, float(np.exp(-0.5)))


def _smooth3(a: np.ndarray, axis: int, weights: tuple[float, float] = (2.0, 1.0)) -> np.ndarray:
    """NaN-aware 3-tap smoothing of a (C, H, W) stack along image axis 0 (y) or 1 (x).

    ``weights`` = (centre, side), normalised over the valid taps; (2, 1) is Sobel's.
    """
    ok = ~np.isnan(a[0])
    filled = np.where(ok, a, np.float32(0))
    wgt = ok.astype(np.float32)
    dr, dc = (1, 0) if axis == 0 else (0, 1)
    shape = ok.shape
    centre, side = (np.float32(w) for w in weights)
    fp, wp = pad_last2(filled, 1, 0.0), pad_last2(wgt, 1, 0.0)
    num = centre * filled + side * (padded_view(fp, 1, dr, dc, shape)
                                    + padded_view(fp, 1, -dr, -dc, shape))
    den = centre * wgt + side * (padded_view(wp, 1, dr, dc, shape)
                                 + padded_view(wp, 1, -dr, -dc, shape))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[:, ~ok] = np.nan
    return out


def _depth_threshold(xyz: np.ndarray, z: np.ndarray, valid: np.ndarray, geo: PixelGeometry, relative: float,
                     distance_mm: float | np.ndarray | None) -> np.ndarray:
    """(H, W) float32 jump threshold, mm: ``relative`` times the distance to the sensor.

    The distance is ``distance_mm`` where given, ``|xyz|`` for camera-frame points (a
    pinhole at the origin sees every point at positive depth); a grid in a scanner frame
    has no distance to its sensor: then :data:`JUMP_THRESHOLD` pixel footprints, with a
    warning (PCL's rule on such a grid, ``relative * z`` about 0, would flood it).
    """
    if distance_mm is not None:
        try:
            if isinstance(distance_mm, (str, bytes, bool, np.bool_)) or np.asarray(distance_mm).dtype.kind not in "iuf":
                raise TypeError  # '3' and True would convert, to 3 mm and 1 mm
            d = np.asarray(distance_mm, dtype=np.float32)
        except (TypeError, ValueError):
            raise RangesimError(f"distance_mm must be a number or an {z.shape} array, got {distance_mm!r:.60}") from None
        if d.ndim == 0:
            d = np.full(z.shape, d, np.float32)
        if d.shape != z.shape:
            raise RangesimError(f"distance_mm must be a number or an {z.shape} array, got shape {d.shape}")
        bad = valid & ~((d > 0) & np.isfinite(d))
        if bad.any():
            raise RangesimError(f"distance_mm must be finite and positive (mm from the sensor) at every valid pixel, "
                                f"got {float(d[bad][0]):g} at {int(bad.sum())} of them")
        return np.float32(relative) * d
    zv = z[valid]
    if geo.perspective and zv.size and np.all(zv > 0):
        return np.float32(relative) * np.sqrt(dot3(xyz, xyz))
    if not zv.size:  # nothing measured: no threshold is used, and nothing to warn about
        return np.float32(JUMP_THRESHOLD) * geo.footprint
    warnings.warn(
        "pcl_organized: the scan's depth is not the distance to the sensor (a grid in the scanner's frame); "
        f"jump threshold {JUMP_THRESHOLD:.2f} pixel footprints instead of {relative} x distance "
        "(pass distance_mm= to use PCL's rule)", RuntimeWarning, stacklevel=3)
    return np.float32(JUMP_THRESHOLD) * geo.footprint


def _distance_source(z: np.ndarray, valid: np.ndarray, geo: PixelGeometry, distance_mm: Any) -> str:
    """What the jump threshold was relative to (for ``params``): given, |xyz| or footprints."""
    if distance_mm is not None:
        return "distance_mm"
    zv = z[valid]
    return "|xyz|" if geo.perspective and zv.size and np.all(zv > 0) else "footprints"


def pcl_organized(
    scan: Any,
    depth_discontinuity: float = 0.02,
    max_search: int = 50,
    curvature_threshold: tuple[float, float] | None = None,
    edge_types: tuple[str, ...] = EDGE_TYPES,
    normal_window: int | None = None,
    distance_mm: float | np.ndarray | None = None,
    scale: str | None = None,
) -> OrganizedEdgeMap:
    """Organized-cloud edges as in PCL's ``OrganizedEdgeFromNormals``, written in NumPy.

    Depth edges follow ``OrganizedEdgeBase::extractEdges``: where all 8 neighbours are
    valid, the dominant depth difference decides (farther neighbour by more than
    ``depth_discontinuity * d``: *occluding*; nearer: *occluded*, with ``d`` the distance
    from the sensor to the point, see ``distance_mm``); where some are NaN, the
    first valid pixel along the mean direction of the NaN neighbours, up to ``max_search``
    pixels away, is compared instead, and a pixel with none is a *NaN boundary* (see
    :func:`~rangesim.edges._discontinuities.find_discontinuities` with ``rule="dominant"``; that
    function documents the small deviations from PCL: every search step moves, the
    threshold scales with the nearer of the two depths, and the depth across a gap is
    compared with the pixel's own surface extrapolated, so holes in tilted planes are not
    jumps).

    High-curvature edges follow ``OrganizedEdgeFromNormals``, which runs Canny on the
    normal images: here a 3 x 3 Gaussian (sigma 1, as PCL's Canny) and the Sobel gradient of
    the normal field (all three components, so it does not depend on the camera's roll;
    differences never cross a depth jump or a NaN), non-maximum suppression across its
    dominant direction, and hysteresis between ``curvature_threshold`` (8-connected);
    then, unlike PCL but as :func:`~rangesim.edges.gradient` and
    :func:`~rangesim.edges.normal`, NMS staircases are thinned to 1-px diagonals and
    high-curvature pixels within 2 px of a depth jump dropped (the crest beside an
    occluding edge is the jump itself).
    Normals are estimated from the measured points
    (:func:`~rangesim.edges._differences.measured_normals`; PCL uses integral-image normals). A
    crease bending the normal by beta radians peaks at about 2.9 beta (raw Sobel units), so
    PCL's defaults (0.4, 1.1) start an edge at creases of ~22 degrees and continue it down
    to ~8.

    That 3 x 3 Canny is kept for clean laser scans. On block-matched scans (the scan's
    ``meta["sensor"]`` says ``structured_light`` and its ``window``,
    :func:`~rangesim.edges._matching_scale.matching_window`) and on noisy ones (depth noise
    of at least :data:`~rangesim.edges._noise.NOISE_FLOOR` footprints) it runs at the scale
    the sensor resolves, step ``h`` (:mod:`rangesim.edges._pcl_scale`): normals from the
    chords ``P(p +- h)`` (PCL's average-3D-gradient normals at a smoothing size of
    ``2h + 1``), Sobel at stride ``h`` divided by the share of a matcher's box-rounded crease
    those normals see (a crease of ``beta`` radians gives about ``8 sin(beta / 2)`` raw units),
    non-maximum suppression on the strength smoothed over the matcher's support (a Gaussian
    of ``w / sqrt 12``; ``2h / sqrt 12`` without a matcher) and hysteresis between
    :data:`~rangesim.edges._pcl_scale.K_LOW` = 4 and
    :data:`~rangesim.edges._pcl_scale.K_HIGH` = 6 sigmas of the strength's noise, PCL's
    (0.4, 1.1) as floors. ``h`` is ``window // 2`` on block-matched scans (the normals either
    side of a crease reach past the ``+-window / 2`` rounding: 4 for the presets' 9), else the
    smallest step whose predicted normal noise is at most 0.22 rad
    (:func:`~rangesim.edges._pcl_scale.crease_step`: 1 at the White Scanner preset's noise, 3
    at the INRIA preset's). The noise sigma is predicted per pixel where the scan carries its
    noise model's ``sigma`` (independent errors of ``s`` footprints: ``3 s / h`` raw units,
    :func:`~rangesim.edges._pcl_scale.predicted_noise_law`), else measured on the strength
    (its median over the chi-4 median; a matcher's errors are correlated over its window, so
    no independent-error law holds there). At the presets' noise an edge then needs a stretch
    of about 70 degrees to start and continues down to about 45.

    Labels: occluding and occluded pixels are both JUMP (which is which is kept in the
    returned map's ``occluding`` / ``occluded`` masks); NaN boundaries 0; high-curvature
    pixels CONVEX or CONCAVE from the sign of ``(P_B - P_A) . (n_A - n_B)`` across the edge
    (as in :func:`~rangesim.edges.normal`), 0 where that is too weak to tell.

    The depth threshold is relative to the distance from the sensor: PCL's ``0.02 z`` holds
    for camera-frame points (z the depth from the viewpoint), where it fires on a surface
    seen beyond ``atan(0.02 f)`` slant; on a grid in another frame (the Cyberware's scanner
    frame, whose range axis is centred on 0) ``0.02 z`` is about 0 and floods the scan.
    So the distance is ``|xyz|`` on camera-frame scans (a pinhole at the origin, all depths
    positive), ``distance_mm`` where given, and otherwise, with a warning, the threshold
    falls back to the other detectors' rule,
    :data:`~rangesim.edges._discontinuities.JUMP_THRESHOLD` pixel footprints.

    Parameters
    ----------
    scan : RangeScan
        Uses ``xyz``, ``depth``, ``valid`` (mm).
    depth_discontinuity : float
        Relative depth-discontinuity threshold (PCL's ``th_depth_discon``, 0.02): a
        fraction of the distance to the sensor (finite, > 0).
    max_search : int
        PCL's ``max_search_neighbors``: pixels searched across NaN gaps (50), an integer >= 0.
    curvature_threshold : (float, float), optional
        Canny hysteresis (low, high) on the Sobel magnitude of the normal field, raw Sobel
        units as in PCL, finite, 0 <= low <= high (``th_hc_canny_low``/``high``, 0.4 and 1.1, the noise-free
        default). Default (None) on block-matched and noisy scans (depth noise from
        :func:`~rangesim.edges._noise.estimate_depth_noise` above
        :data:`~rangesim.edges._noise.NOISE_FLOOR` footprints): ``max(0.4, 4 sigma)`` and
        ``max(1.1, 6 sigma)`` per pixel, sigma the strength's noise at the sensor's scale
        (see above; ``params["curvature_threshold"]`` reports their medians and
        ``params["curvature_noise"]`` whether sigma was ``"sigma"``, predicted, or
        ``"measured"``).
    edge_types : tuple of str
        Classes that enter ``mask`` (PCL's ``setEdgeType``): any of :data:`EDGE_TYPES`.
    normal_window : int, optional
        Odd stencil size of the normal estimate, pixels (3 to 255): ``2h + 1`` at the sensor's
        scale. Default (None): 3 on clean laser scans, else ``2h + 1`` with ``h`` as above
        (9 on the block-matched presets).
    distance_mm : float or (H, W) float array, optional
        Distance from the sensor to each point, mm (one number: the same for every pixel,
        e.g. a scanner's stand-off). Default: ``|xyz|`` on camera-frame scans; none on
        grids in a scanner frame (see above).
    scale : {None, "3x3", "sensor"}, optional
        ``"3x3"``: PCL's own pipeline (3 x 3 Gaussian-weighted normals, Sobel, Canny) on any
        scan, to compare with PCL itself; ``"sensor"``: the chord normals and strided Sobel at
        the sensor's scale; default (None): ``"sensor"`` on block-matched and noisy scans,
        ``"3x3"`` on clean laser scans.

    Returns
    -------
    OrganizedEdgeMap
        ``method="pcl_organized"``; ``strength`` is the Sobel magnitude of the normal field
        (raw units, at the sensor's scale where that is used; NaN where undefined);
        ``direction`` None; the four class masks. ``params["scale"]``: ``"3x3"`` (PCL's) or
        ``"sensor"``; ``params["matching_window"]``: the matcher's window or None.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> edges = rs.edges.pcl_organized(scan)
    >>> edges.method, bool(edges.mask.any())
    ('pcl_organized', True)

    References
    ----------
    .. [1] R. B. Rusu, S. Cousins, "3D is here: Point Cloud Library (PCL)", ICRA 2011,
       doi:10.1109/ICRA.2011.5980567 (``pcl::OrganizedEdgeFromNormals``).
    .. [2] C. Choi, A. J. B. Trevor, H. I. Christensen, "RGB-D edge detection and edge-based
       registration", IROS 2013 (the organized edge detector PCL implements).
    """
    if isinstance(scale, np.ndarray) or scale not in (None, "3x3", "sensor"):
        raise RangesimError(f"scale must be None, '3x3' or 'sensor', got {scale!r:.60}")
    depth_discontinuity = P.number(depth_discontinuity, "depth_discontinuity", 0, lo_open=True,
                                   what="fraction of the distance to the sensor")
    max_search = P.whole(max_search, "max_search", 0, unit="pixels")
    if isinstance(edge_types, str):  # one type named alone
        edge_types = (edge_types,)
    try:
        edge_types = tuple(edge_types)
    except TypeError:
        raise RangesimError(f"edge_types must be a tuple of names from {EDGE_TYPES}, got {edge_types!r:.60}") from None
    if not all(isinstance(t, str) for t in edge_types):
        raise RangesimError(f"edge_types must be a tuple of names from {EDGE_TYPES}, got {edge_types!r:.60}")
    if curvature_threshold is not None:
        try:
            low_high = [float(t) for t in curvature_threshold]
        except (TypeError, ValueError):
            low_high = []
        if len(low_high) != 2 or not all(np.isfinite(low_high)) or not 0 <= low_high[0] <= low_high[1]:
            raise RangesimError(f"curvature_threshold must be two numbers 0 <= low <= high (finite), "
                                f"got {curvature_threshold!r:.60}")
    unknown = set(edge_types) - set(EDGE_TYPES)
    if unknown:
        raise RangesimError(f"unknown edge types {sorted(unknown)}; choose from {EDGE_TYPES}")
    normal_window = P.odd_window(normal_window, "normal_window")
    z, valid = scan_depth(scan)
    geo = pixel_geometry(scan, z)
    window = matching_window(scan)
    noise = None
    if normal_window is None or curvature_threshold is None or window is None:
        noise = estimate_depth_noise(scan, z=z, fp=geo.footprint)
    noisy = noise is not None and noise >= NOISE_FLOOR
    # PCL's 3 x 3 Canny on clean laser scans; at the sensor's scale on block-matched or noisy ones
    scaled = (window is not None or noisy) if scale is None else scale == "sensor"
    auto_threshold = curvature_threshold is None
    low, high = (0.4, 1.1) if auto_threshold else (float(t) for t in curvature_threshold)
    xyz = scan_points(scan, valid, component_major=True)
    threshold = _depth_threshold(xyz, z, valid, geo, float(depth_discontinuity), distance_mm)
    disc = find_discontinuities(z, threshold, max_search, rule="dominant", perspective=geo.perspective)
    camera_frame = _distance_source(z, valid, geo, None) == "|xyz|"
    noise_source = None
    if scaled:
        step = crease_step(window, noise) if normal_window is None else normal_window // 2
        normal_window = 2 * step + 1
        n = chord_normals(xyz, disc.pairs, step)
    else:
        normal_window = stencil_window(normal_window, "normal_window", noise)
        step = normal_window // 2
        n = measured_normals(xyz, disc.pairs, step)
    if not camera_frame:
        # not a camera frame: n . p <= 0 flips wherever the range axis crosses 0, a false
        # crease; the grid looks along +z (smaller z is nearer), so turn every normal to -z
        np.multiply(n, np.where(n[2] > 0, np.float32(-1), np.float32(1)), out=n)

    pixel_low: float | np.ndarray = low
    pixel_high: float | np.ndarray = high
    if scaled:
        # Canny at step h (rangesim.edges._pcl_scale): Sobel of the chord normals at stride h,
        # over the share of a matcher's rounded crease it sees; NMS on the strength smoothed
        # over the matcher's support (or the stencil's), thresholds in noise sigmas
        gx, gy = strided_sobel(n, disc.pairs, step, window)
        jxx, jyy, jxy = dot3(gx, gx), dot3(gy, gy), dot3(gx, gy)
        magnitude = np.sqrt(jxx + jyy)
        if auto_threshold:
            sigma, noise_source = strength_noise(scan, magnitude, valid, geo.footprint, step, window)
            pixel_low = np.maximum(np.float32(low), np.float32(K_LOW) * sigma)
            pixel_high = np.maximum(np.float32(high), np.float32(K_HIGH) * sigma)
            low, high = (float(np.median(t[valid])) if np.ndim(t) and valid.any() else float(np.max(t))
                         for t in (pixel_low, pixel_high))
        ridge = nan_gaussian(magnitude, ridge_sigma(window, 2 * step))
    else:
        # PCL's Canny: 3 x 3 Gaussian (sigma 1), then Sobel of each normal component (central
        # difference along, [1 2 1] across, times 8 for raw Sobel units)
        n = _smooth3(_smooth3(n, 0, _GAUSS3), 1, _GAUSS3)
        gx = _smooth3(central_difference(n, 0, disc.pairs), 0) * np.float32(8)
        gy = _smooth3(central_difference(n, 2, disc.pairs), 1) * np.float32(8)
        jxx, jyy, jxy = dot3(gx, gx), dot3(gy, gy), dot3(gx, gy)
        magnitude = np.sqrt(jxx + jyy)
        if auto_threshold and noisy:
            low = noise_threshold(magnitude, valid, low, NOISE_K_PCL)
            high = low * 1.1 / 0.4
        pixel_low, pixel_high = low, high
        ridge = magnitude
    theta = half_atan2(2 * jxy, jxx - jyy)
    axis = nearest_axis(theta)
    with np.errstate(invalid="ignore"):
        thin = nonmax_suppress(ridge, theta, magnitude > pixel_low)
    high_curvature = hysteresis(np.where(thin, magnitude, 0), pixel_low, pixel_high) & valid
    # as gradient and normal: NMS staircases thinned to 1-px diagonals (the 8-connected
    # truth matches one pixel per pixel), and no crease within 2 px of a depth jump (the
    # normals bend beside an occluding edge: that crest is the jump itself)
    high_curvature = thin_staircases(high_curvature)
    high_curvature &= ~near_mask(high_curvature, disc.occluding | disc.occluded, JUMP_CLEARANCE)

    # convex / concave from the neighbours across the edge
    # (the normals one step either side: 1 px on PCL's path, h at the sensor's scale)
    shape = z.shape
    r = step if scaled else 1
    npad, xpad = pad_last2(n, r, np.nan), pad_last2(xyz, r, np.nan)
    side = np.zeros(shape, np.float32)
    for a, (dr, dc) in enumerate(AXES):
        sel = axis == a
        na = padded_view(npad, r, -r * dr, -r * dc, shape)
        nb = padded_view(npad, r, r * dr, r * dc, shape)
        chord = padded_view(xpad, r, r * dr, r * dc, shape) - padded_view(xpad, r, -r * dr, -r * dc, shape)
        dn = na - nb
        with np.errstate(invalid="ignore", divide="ignore"):
            c = dot3(chord, dn) / np.sqrt(dot3(chord, chord) * dot3(dn, dn))
        side[sel] = c[sel]
    hc_label = np.where(side < -_MIN_SIDE_COSINE, EdgeLabel.CONVEX,
                        np.where(side > _MIN_SIDE_COSINE, EdgeLabel.CONCAVE, EdgeLabel.NONE))

    classes = {
        "nan_boundary": disc.nan_boundary, "occluding": disc.occluding,
        "occluded": disc.occluded, "high_curvature": high_curvature,
    }
    mask = np.zeros(shape, bool)
    for name in edge_types:
        mask |= classes[name]
    labels = np.zeros(shape, np.uint8)
    if "high_curvature" in edge_types:
        labels[high_curvature] = hc_label[high_curvature]
    if "nan_boundary" in edge_types:
        labels[disc.nan_boundary] = EdgeLabel.NONE
    jumps = np.zeros(shape, bool)
    for name in ("occluding", "occluded"):
        if name in edge_types:
            labels[classes[name]] = EdgeLabel.JUMP
            jumps |= classes[name]
    params = {
        "depth_discontinuity": float(depth_discontinuity), "max_search": int(max_search),
        "distance": _distance_source(z, valid, geo, distance_mm),
        "curvature_threshold": [low, high], "edge_types": list(edge_types),
        "normal_window": normal_window, "noise": None if noise is None else float(noise),
        "scale": "sensor" if scaled else "3x3", "matching_window": window,
        "curvature_noise": noise_source,
    }
    return OrganizedEdgeMap(
        mask=mask & valid, labels=labels, strength=magnitude, method="pcl_organized",
        params=params, offset=disc.offsets_at(jumps), occluding=disc.occluding, occluded=disc.occluded,
        nan_boundary=disc.nan_boundary, high_curvature=high_curvature,
    )
