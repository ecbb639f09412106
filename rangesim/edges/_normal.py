"""Technique 3 of the founding paper: edges where the surface normal turns."""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.edges._differences import dot3, measured_normals
from rangesim.edges._discontinuities import JUMP_THRESHOLD, discontinuities, with_gap_creases
from rangesim.edges._grid import AXES, pad_last2, padded_view
from rangesim.edges._matching_scale import matching_window, window_directions
from rangesim.edges._noise import (
    NOISE_FLOOR,
    NOISE_K_NORMAL,
    NOISE_K_NORMAL_LOCAL,
    carries_sigma,
    estimate_depth_noise,
    local_noise_scale,
    noise_threshold,
    raised_threshold,
    stencil_window,
)
from rangesim.edges._normal_blocks import block_bends
from rangesim.edges._normal_sl import sl_creases
from rangesim.edges._scan_access import scan_depth, scan_points
from rangesim.edges._thinning import (
    JUMP_CLEARANCE,
    drop_specks,
    near_mask,
    nonmax_suppress,
    ridge_offsets,
    thin_staircases,
)
from rangesim.edges._trig import half_atan2
from rangesim.edges.edgemap import RIM, EdgeMap

__all__ = ["normal"]


def _pair_cut(gaps: np.ndarray, dr: int, dc: int) -> np.ndarray:
    """True where the step p - d -> p or p -> p + d is cut (``gaps``: the step p -> p + d)."""
    back = np.zeros_like(gaps)
    h, w = gaps.shape
    # the step p - d -> p is gaps[p - d]
    r0, r1 = max(0, dr), h + min(0, dr)
    c0, c1 = max(0, dc), w + min(0, dc)
    back[r0:r1, c0:c1] = gaps[r0 - dr:r1 - dr, c0 - dc:c1 - dc]
    return gaps | back


def normal(
    scan: Any,
    threshold_deg: float | None = None,
    window: int | None = None,
    jump_threshold: float = JUMP_THRESHOLD,
    nms: bool = True,
    max_search: int = 50,
    blocks: bool | None = None,
) -> EdgeMap:
    """Crease and jump edges from the change of the measured surface normal.

    Technique 3 of the founding paper: points of a plane share one normal, so a large
    change of the unit normal among the 8 neighbours of a point marks an edge. Normals
    are estimated from the MEASURED points (``scan.xyz``; ``scan.normal`` is the
    simulator's truth and is not used) by :func:`~rangesim.edges._differences.measured_normals`:
    cross products of edge-preserving (WENO-weighted one-sided / central) differences over
    ``window // 2`` pixels, NaN-aware and never across a depth jump, so each pixel next to a
    crease keeps the normal of its own face. The 8 neighbours form 4 opposite pairs
    ``p - d``, ``p + d`` (axes at 0, 45, 90 and 135 degrees); the strength of a pixel is the
    largest angle between the normals of such a pair. At a crease it is the crease's bend
    angle (180 degrees minus the dihedral angle), on the one or two pixels nearest to it; on
    a plane 0; on a smooth surface of curvature k about ``2 k footprint`` radians, so
    ``threshold_deg`` means what the ground truth's ``crease_deg`` does.

    Convex vs concave: for the compared pair A = p - d, B = p + d, the sign of
    ``(P_B - P_A) . (n_A - n_B)`` (normals facing the camera): negative where the faces turn
    away from the camera on both sides (a roof, convex), positive in a valley (concave).
    Jumps: :func:`~rangesim.edges._discontinuities.find_discontinuities` (steps deeper than
    ``jump_threshold`` pixel footprints, searched across NaN gaps), JUMP on the near side;
    pairs that straddle a jump are skipped (as are those across NaN gaps, which may hide
    one), so jumps do not also show up as creases.

    Block-matched scans (structured light: ``scan.meta["sensor"]`` of mode
    ``"structured_light"`` with its matching ``window``,
    :func:`~rangesim.edges._matching_scale.matching_window`), unless ``window`` or ``blocks``
    (True: block planes; False: the stencil normals) is given: the matcher rounds a crease over its window under errors correlated over it,
    so the normals compared are one matching window apart
    (:func:`~rangesim.edges._normal_sl.sl_creases`): chord normals at ``h = window // 2``
    (:func:`~rangesim.edges._pcl_scale.chord_normals`), the angle between those at ``p - h d``
    and ``p + h d`` on the four axes (the normal at ``p`` standing in for a side across a gap
    or a jump) over :func:`~rangesim.edges._matching_scale.rounding_gain` ``(window, 2h)``;
    NMS across the crease on the summed bend smoothed by
    :func:`~rangesim.edges._matching_scale.ridge_sigma`; hysteresis at 4 / 5.5 times the
    bend's measured noise (its median over 1.177, a Rayleigh's; floors 15 / 20 degrees), or
    ``threshold_deg`` alone where given; no crease within 2 px of a jump between measured
    pixels. ``strength`` is then that bend, degrees, and ``params["threshold_deg"]`` the
    hysteresis pair.

    Parameters
    ----------
    scan : RangeScan
        Uses ``xyz``, ``depth`` and ``valid`` (mm, camera frame).
    threshold_deg : float, optional
        Least bend of the normal, degrees in (0, 180), for a crease pixel (noise-free default 20, the
        ground truth's crease angle). Noise: the angle noise of a normal is about
        ``sigma_z / (window // 2 * footprint)`` radians, so noisy scans need a larger window.
        Default (None) on noisy scans (depth noise from
        :func:`~rangesim.edges._noise.estimate_depth_noise` above
        :data:`~rangesim.edges._noise.NOISE_FLOOR` footprints): ``max(20, k * median)`` of
        the strength over valid pixels, ``k`` = :data:`~rangesim.edges._noise.NOISE_K_NORMAL`
        = 4.5 (~37 degrees at the White Scanner preset's noise with window 7); where the
        scan carries its noise model's ``sigma``, ``k`` =
        :data:`~rangesim.edges._noise.NOISE_K_NORMAL_LOCAL` = 3.5 and per pixel times
        :func:`~rangesim.edges._noise.local_noise_scale`. On the block-plane path
        (``blocks``, below) the threshold is instead a floor,
        :data:`~rangesim.edges._normal_blocks.BLOCK_FLOOR_DEG` = 35 by default (chosen on
        tuning seeds: hole walls and cylinders bend a pair of blocks by about 2 r kappa), and
        each pixel needs ``k`` = 4 times its fitted normals' predicted angle noise above it.
    window : int, optional
        Odd stencil size of the normal estimate, pixels (3 to 255): differences over
        ``window // 2`` pixels. Default (None): 3 on noise-free scans, else
        ``2 ceil(12 noise) + 1`` clipped to 3..9 for a depth noise of ``noise`` footprints
        (7 at the preset's 0.25).
    jump_threshold : float
        Depth-discontinuity threshold in pixel footprints (finite, > 0): neighbours whose depths differ by
        more than this many footprints (``z / f`` mm) are a jump. Default
        :data:`~rangesim.edges._discontinuities.JUMP_THRESHOLD` = cot(15 deg) = 3.73, the ground
        truth's rule (a continuous surface jumps only beyond 75 degrees slant); for a pinhole
        camera it is ``jump_threshold / f`` times the depth (PCL's 0.02 z is 0.02 f).
    nms : bool
        Thin creases to 1 px by non-maximum suppression across the crease (its direction is
        the dominant harmonic of the four axis strengths). Thinned, crease fragments of at
        most 2 px that touch no other edge pixel are dropped on noisy scans (noise excursions
        over one threshold; :func:`~rangesim.edges._thinning.drop_specks`; not on the
        block-matched path, whose hysteresis needs a strong pixel, nor on noise-free scans,
        where they are small features such as the Green Piece's scratches).
    max_search : int
        Pixels searched across NaN gaps for the jump rule, >= 0 (0: only direct neighbours).
    blocks : bool, optional
        Compare the normals of least-squares planes fitted to blocks on either side of each
        pixel instead of adjacent stencil normals, with a threshold from the predicted
        noise of the fitted normals (:mod:`rangesim.edges._normal_planes`; see
        :func:`~rangesim.edges._normal_blocks.block_bends`). Default (None): on noisy
        scans that carry their noise model's ``sigma`` when ``window`` is not given
        (simulated laser-stripe scans); noise-free and recorded scans keep the stencil
        normals. On the machined parts' tuning seeds (inria_laser, 20-29) F1 with noise
        0.80 -> 0.87.

    Returns
    -------
    EdgeMap
        ``method="normal"``; ``strength`` is the bend angle in degrees (NaN where no pair of
        opposite neighbours has normals); ``labels`` CONVEX/CONCAVE/JUMP; ``direction`` None,
        but on a block-matched scan with the default ``window`` and ``blocks`` (the matcher's
        scale) the angle in [0, pi) across each edge (the chords' bend at creases, the
        discontinuity at jumps and rims; none at a gap fold's far end) averaged over the
        matcher's window
        (:func:`~rangesim.edges._matching_scale.window_directions`), for the circle and
        ellipse finders.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> edges = rs.edges.normal(scan)
    >>> edges.method, edges.mask.shape == scan.shape, bool(edges.mask.any())
    ('normal', True, True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    """
    threshold_deg = P.number(threshold_deg, "threshold_deg", 0, 180, lo_open=True, hi_open=True, what="angle",
                             unit="degrees", none=True)
    window = P.odd_window(window, "window")
    jump_threshold, max_search = P.jump_rule(jump_threshold, max_search)
    nms = P.flag(nms, "nms")
    blocks = P.flag(blocks, "blocks", none=True)
    if window is not None:
        if blocks:
            raise RangesimError("window and blocks=True cannot be combined: the block sizes follow the noise")
    z, valid = scan_depth(scan)
    xyz = scan_points(scan, valid, component_major=True)
    disc, geo = discontinuities(scan, z, jump_threshold, max_search)
    noise = None
    if window is None or threshold_deg is None:
        noise = estimate_depth_noise(scan, z=z, fp=geo.footprint, quantum=disc.quantum)
    noisy = noise is not None and noise >= NOISE_FLOOR
    matcher = matching_window(scan)
    if matcher is not None and window is None and blocks is None:
        # thresholds raised where the noise model predicts a noisier face (its slant)
        scale = local_noise_scale(scan, valid, geo.footprint, disc.noise) if threshold_deg is None else None
        return _normal_sl(z, valid, xyz, disc, noise, matcher, threshold_deg, jump_threshold, nms, max_search, scale)
    if blocks is None:
        blocks = window is None and noisy and carries_sigma(scan)
    if blocks:
        return _normal_blocks(scan, z, valid, xyz, disc, noise, threshold_deg, jump_threshold, nms, max_search)
    window = stencil_window(window, "window", noise)
    auto_threshold = threshold_deg is None
    if auto_threshold:
        threshold_deg = 20.0
    n = measured_normals(xyz, disc.pairs, window // 2)

    shape = z.shape
    # compared normals must be joined by valid pixels with no jump between: a NaN gap may
    # hide one (e.g. a laser shadow between an object and the floor)
    vpad = pad_last2(valid, 1, True)
    npad, xpad = pad_last2(n, 1, np.nan), pad_last2(xyz, 1, np.nan)
    strength = np.full(shape, -1.0, np.float32)
    concave = np.zeros(shape, bool)
    angles = []
    for a, (dr, dc) in enumerate(AXES):
        gaps = disc.pairs[a] | ~valid | ~padded_view(vpad, 1, dr, dc, shape)
        na = padded_view(npad, 1, -dr, -dc, shape)           # the pair p - d, p + d
        nb = padded_view(npad, 1, dr, dc, shape)
        c = dot3(na, nb)
        np.clip(c, -1, 1, out=c)
        angle = np.degrees(np.arccos(c))
        np.copyto(angle, np.nan, where=_pair_cut(gaps, dr, dc) | ~valid)
        chord = padded_view(xpad, 1, dr, dc, shape) - padded_view(xpad, 1, -dr, -dc, shape)
        side = dot3(chord, na - nb)
        better = angle > strength                            # NaN compares False
        np.copyto(strength, angle, where=better)  # copyto: 10x faster than boolean indexing
        np.copyto(concave, side > 0, where=better)
        angles.append(np.where(np.isnan(angle), np.float32(0), angle))
    np.copyto(strength, np.nan, where=strength < 0)
    pixel_threshold: float | np.ndarray = threshold_deg
    if auto_threshold and noisy:
        # per pixel where the noise model predicts each pixel's noise: raised where it is
        # above the median's, and without the margin a scan-wide figure needs for them
        scale = local_noise_scale(scan, valid, geo.footprint, disc.noise) if threshold_deg is None else None
        k = NOISE_K_NORMAL if scale is None else NOISE_K_NORMAL_LOCAL
        threshold_deg = noise_threshold(strength, valid, threshold_deg, k)
        pixel_threshold = raised_threshold(threshold_deg, scale, 179.0)
    # direction across the crease: dominant second harmonic of the four axis strengths
    theta = half_atan2(angles[1] - angles[3], angles[0] - angles[2])

    with np.errstate(invalid="ignore"):
        crease = strength > pixel_threshold
    if nms:
        # a crease between pixel centres gives its bend to both pixels beside it; rank them
        # by the bend summed over the four axes (largest nearest the crease) to keep one
        rank = angles[0] + angles[1] + angles[2] + angles[3]
        np.copyto(rank, np.nan, where=np.isnan(strength))
    else:
        rank = None
    crease, labels, offset = _placed_creases(crease, rank, theta, concave, disc, specks=noisy)
    jump, rim = disc.occluding, disc.rim
    params = {
        "threshold_deg": float(threshold_deg), "window": window,
        "jump_threshold": float(jump_threshold), "nms": bool(nms), "max_search": int(max_search),
        "noise": None if noise is None else float(noise),
    }
    mask = with_gap_creases(crease | jump | rim, labels, disc, offset) & valid
    return EdgeMap(mask=mask, labels=labels, strength=strength,
                   method="normal", params=params, offset=offset)


def _placed_creases(crease: np.ndarray, rank: np.ndarray | None, theta: np.ndarray, concave: np.ndarray,
                    disc: Any, specks: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Creases thinned and placed as both of :func:`normal`'s paths do: non-maximum
    suppression on ``rank`` across ``theta`` (None: no NMS), no crease within
    :data:`JUMP_CLEARANCE` of a jump or rim (the crest beside one is the jump itself, as in
    gradient), NMS staircases thinned to 1-px diagonals, then (with NMS, and ``specks``: on noisy
    scans) fragments of at most :data:`~rangesim.edges._thinning.SPECK_MAX_PX` crease pixels
    touching no other edge dropped (:func:`~rangesim.edges._thinning.drop_specks`); labels CONVEX/CONCAVE, RIM, JUMP;
    offsets: the jumps' and rims' and, with NMS, the creases' sub-pixel vertex from the
    ranks NMS compared (the summed bend across a sampled roof is a peak about two samples
    wide, so the triangle's vertex; on analytic roofs mean |distance| to the line 0.65-0.75
    -> 0.15-0.30 px along an axis, 0.22 -> 0.13-0.16 px oblique; the parabola's 0.17 there).

    Returns
    -------
    crease : (H, W) bool
    labels : (H, W) uint8
    offset : (H, W, 2) float32
    """
    if rank is not None:
        crease = nonmax_suppress(rank, theta, crease)
    jump = disc.occluding
    rim = disc.rim
    crease &= ~near_mask(crease, jump | disc.occluded | rim, JUMP_CLEARANCE)
    crease = thin_staircases(crease | jump | rim, droppable=crease) & ~jump & ~rim
    if rank is not None and specks:  # thinned to lines, a lone crease pixel or pair is noise (one threshold)
        crease = drop_specks(crease, crease | jump | rim)
    offset = disc.offsets_at(jump | rim)
    if rank is not None:
        offset += ridge_offsets(rank, theta, crease, peak="triangle")
    labels = np.where(concave, EdgeLabel.CONCAVE, EdgeLabel.CONVEX).astype(np.uint8)
    labels[rim] = RIM
    labels[jump] = EdgeLabel.JUMP
    return crease, labels, offset


def _normal_blocks(scan, z, valid, xyz, disc, noise, threshold_deg, jump_threshold, nms, max_search) -> EdgeMap:
    """:func:`normal` with block-plane normals (``blocks=True``)."""
    bends = block_bends(scan, valid, xyz, disc, threshold_deg)
    crease = (bends.ratio > 1) & valid
    rank = bends.chord[0] + bends.chord[1] + bends.chord[2] + bends.chord[3]
    np.copyto(rank, np.nan, where=np.isnan(bends.strength))
    # direction across the crease: dominant second harmonic of the four axis bends
    theta = half_atan2(bends.chord[1] - bends.chord[3], bends.chord[0] - bends.chord[2])
    # (the bend of blocks sharing the pixel peaks on the crease and falls by a row of the
    # other face per pixel off it: a triangle, as the stencil's summed bend)
    crease, labels, offset = _placed_creases(crease, rank if nms else None, theta, bends.concave, disc, specks=True)
    jump, rim = disc.occluding, disc.rim
    params = {
        "threshold_deg": float(bends.floor_deg), "window": None, "blocks": list(bends.sizes),
        "jump_threshold": float(jump_threshold), "nms": bool(nms), "max_search": int(max_search),
        "noise": None if noise is None else float(noise), "noise_gain": [float(g) for g in bends.gains],
    }
    mask = with_gap_creases(crease | jump | rim, labels, disc, offset) & valid
    return EdgeMap(mask=mask, labels=labels, strength=bends.strength,
                   method="normal", params=params, offset=offset)


def _normal_sl(z, valid, xyz, disc, noise, matcher, threshold_deg, jump_threshold, nms, max_search,
               scale=None) -> EdgeMap:
    """:func:`normal` on a block-matched scan: chord normals one matching window apart
    (:func:`~rangesim.edges._normal_sl.sl_creases`)."""
    res = sl_creases(xyz, valid, disc.pairs, matcher, threshold_deg, nms, noise_scale=scale)
    crease = res["crease"]
    jump = disc.occluding
    rim = disc.rim
    # no crease within 2 px of a depth jump between measured pixels (the bend beside it is
    # the jump itself); creases along the data's border (rims, shadows) stay: on these scans
    # most true creases lie there (tuning seeds 0-7: clearing them too 0.744 against 0.758;
    # clearances 1 / 2 / 3 px 0.756 / 0.758 / 0.751)
    crease &= ~near_mask(crease, disc.touching, JUMP_CLEARANCE)
    crease = thin_staircases(crease | jump | rim, droppable=crease) & ~jump & ~rim
    offset = disc.offsets_at(jump | rim)
    if nms:
        offset += ridge_offsets(res["ridge"], res["theta"], crease, peak="parabola")
    labels = np.where(res["concave"], EdgeLabel.CONCAVE, EdgeLabel.CONVEX).astype(np.uint8)
    labels[rim] = RIM
    labels[jump] = EdgeLabel.JUMP
    # directions as gradient's on these scans: across the crease (the chords' bend), across the
    # discontinuity at jumps and rims, averaged over the matcher's window (its contours are
    # ragged by a pixel or two: the circle and ellipse finders vote and grow along them)
    direction = np.where(crease, np.mod(res["theta"], np.pi), np.nan).astype(np.float32)
    np.copyto(direction, disc.direction, where=(jump | rim) & np.isfinite(disc.direction))
    # (a gap fold's far end, a crease with_gap_creases adds below, keeps none: the finders take
    # the layout of its pixels there; its jump's direction was neutral on the tuning and check
    # seeds and cost 1-2 rims per cell on the report sets)
    # a rim has no jump direction: its offset points across it, to the unmeasured side
    across = (jump | rim) & np.isnan(direction) & np.any(offset != 0, axis=-1)
    direction[across] = np.mod(np.arctan2(offset[..., 1][across], offset[..., 0][across]), np.pi)
    params = {
        "threshold_deg": res["threshold_deg"], "threshold_scale_max": res["threshold_scale_max"],
        "window": None, "matching_window": int(matcher),
        "step": int(res["step"]), "bend_noise_deg": res["bend_noise_deg"],
        "jump_threshold": float(jump_threshold), "nms": bool(nms), "max_search": int(max_search),
        "noise": None if noise is None else float(noise),
    }
    mask = with_gap_creases(crease | jump | rim, labels, disc, offset) & valid
    return EdgeMap(mask=mask, labels=labels, strength=res["strength"],
                   direction=window_directions(direction, mask, matcher), method="normal", params=params,
                   offset=offset)
