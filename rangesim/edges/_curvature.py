"""Curvature edge points on scans: ridges of the largest principal curvature (creases), or
both principal curvatures large (the paper's Fig. 12 rule: corners)."""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.constants import EdgeLabel
from rangesim.curvature import curvature_edges, curvature_scan
from rangesim.edges._curvature_chords import matched_creases
from rangesim.edges._discontinuities import JUMP_THRESHOLD, discontinuities, with_gap_creases
from rangesim.edges._grid import pad_last2, padded_view
from rangesim.edges._matching_scale import matching_window
from rangesim.edges._noise import (
    NOISE_FLOOR,
    carries_sigma,
    estimate_depth_noise,
    local_noise_scale,
    noise_threshold,
    raised_threshold,
)
from rangesim.edges._scan_access import scan_depth
from rangesim.edges._thinning import nonmax_suppress, thin_staircases
from rangesim.edges.edgemap import RIM, EdgeMap

__all__ = ["curvature"]

#: default threshold as a multiple of 1 / (window // 2 * footprint): a 90 degree corner in
#: the fit window gives about 1.0, a straight crease crossing it obliquely leaks about 0.3
#: into its small principal curvature (see rangesim.curvature.curvature_edges)
DEFAULT_RELATIVE_THRESHOLD = 0.5

#: the extrema rule's default threshold on |k| R (R the fit block's half-width, mm): a
#: least-squares quadric over a block straddling a crease of bend theta has curvature
#: about 1.9 tan(theta / 2) / R (0.33 / R at 20 degrees, the ground truth's least crease;
#: 0.25 / R is a 15 degree bend, the gradient detector's noise-free threshold)
EXTREMA_RELATIVE_THRESHOLD = 0.25

#: on noisy scans the extrema threshold is at least this many times the median |k| R over
#: the valid pixels (the fit's noise level)
NOISE_K_CURVATURE = 6.0

RULES = ("extrema", "both")
#: fit-block size without a block matcher, pixels
DEFAULT_WINDOW = 5
#: ... and on scans noisier than :data:`NOISY_BLOCK_NOISE` pixel footprints (depth noise,
#: :func:`~rangesim.edges._noise.estimate_depth_noise`): a quadric's curvature noise falls as
#: the square of the block's half-width while the threshold (a multiple of 1 / (h fp)) falls
#: as its first power, so a noisier scan needs a wider block for the same false-alarm rate.
#: Chosen on the machined parts' tuning seeds 0-7 (noisy, laser-stripe presets; curvature F1
#: with 5 / 7 / 9 px blocks): inria_laser (noise 0.73-0.77 footprints) 0.713 / 0.836 / 0.816,
#: cyberware_3030 (0.24-0.46) 0.807 / 0.845 / 0.820, white_scanner (0.24-0.26) 0.911 / 0.899 /
#: 0.830; the step sits at 0.5 footprints, far from both groups, so the White Scanner and the
#: Cyberware presets keep 5 px and the INRIA preset takes 7
NOISY_BLOCK_WINDOW = 7
NOISY_BLOCK_NOISE = 0.5
#: pixels of face the fit block reaches beyond a block matcher's rounding on either side
#: (:func:`matching_block`)
FACE_MARGIN_PX = 2


def matching_block(matcher_window: int | None) -> int:
    """Default fit-block size (odd, pixels) of :func:`curvature` for a block matcher's window.

    :data:`DEFAULT_WINDOW` without a matcher. A matcher of window ``w`` rounds a crease over
    ``w // 2`` pixels on either side; the quadric's block then reaches
    :data:`FACE_MARGIN_PX` = 2 pixels of each face beyond that, ``2 (w // 2 + 2) + 1`` (13 for
    the presets' 9), so that it is fitted to the two faces and the rounding between them
    (whose fitted curvature is the crease's, ~1.9 tan(theta / 2) / R) rather than to the
    rounding alone. Why 2: on the machined parts' tuning seeds 0-7 (kinect_v1,
    structured_light_bench) blocks of 9, 13 and 19 px raised curvature F1 from 0.57 to about
    0.59, 0.64 and 0.61 (larger blocks lose the creases near gaps and jumps, which they
    must not contain); 13 was then checked on seeds 8-15 (0.53 -> 0.58-0.62).

    Examples
    --------
    >>> matching_block(None), matching_block(9)
    (5, 13)
    """
    if matcher_window is None:
        return DEFAULT_WINDOW
    return 2 * (int(matcher_window) // 2 + FACE_MARGIN_PX) + 1


def curvature(
    scan: Any,
    threshold: float | None = None,
    window: int | None = None,
    jump_threshold: float = JUMP_THRESHOLD,
    max_search: int = 50,
    rule: str = "extrema",
    full_block: bool = True,
) -> EdgeMap:
    """Edge points of high curvature on per-pixel quadric fits, with convex/concave labels.

    Curvatures come from :func:`rangesim.curvature.curvature_scan` (``window`` x ``window``
    blocks, NaN-aware). Two rules of the founding paper:

    * ``rule="extrema"`` (default): edges "as the local extrema of curvature" (section 3).
      The principal curvature of larger magnitude, ``k``, is kept where ``|k|`` exceeds the
      threshold and is a maximum across the crease: non-maximum suppression along the
      image projection of ``k``'s principal direction (which runs across a crease), then
      1 px diagonals as in :func:`~rangesim.edges.gradient`. It marks creases, corners and
      tight blends.
    * ``rule="both"``: the rule of the paper's Fig. 12, :func:`rangesim.curvature.curvature_edges`:
      ``|k1| > threshold`` and ``|k2| > threshold``. It marks corners, tips and tight
      doubly-curved blends; a straight crease (one principal curvature ~0) is, by design,
      not marked, except where the fit leaks curvature into the along-crease direction.

    On block-matched scans (``meta["sensor"]`` with ``mode = "structured_light"``, its
    ``window``), with the default ``window`` and ``rule="extrema"``, the curvatures are not
    block fits but the shape operator at the matcher's scale
    (:func:`~rangesim.edges._curvature_chords.matched_creases`): normals from the chords
    ``+-h`` (``h = window // 2``), their change per length of surface between ``+-h``
    (one-sided where a chord would cross a gap or a jump, so creases beside ragged shadows and
    fattened jumps are kept), the fundamental forms averaged over ``h / sqrt 12`` px. The
    ridge of the larger principal curvature is thinned across its principal direction on its
    *bend* (``|k|`` times the ``2h`` px of surface between the normals, over the share of a
    box-rounded crease they see: the crease's angle, radians) smoothed over the matcher's
    support, and kept by hysteresis between 3.5 and 4.5 times the bend's median over the scan
    (its measured noise; at least 15 and 20 degrees), or where ``|k| > threshold``; no crease
    within 2 px of a discontinuity. ``params["scale"]`` says which: ``"sensor"`` or
    ``"blocks"``; on the sensor path ``params["window"]`` is still the block the fits would
    use, ``params["step"]`` is ``h`` and ``params["bend_threshold"]`` the hysteresis pair.

    Type from the mean curvature, in :mod:`rangesim.curvature`'s convention (normal towards
    the camera, positive where the surface bends towards it): H < 0 convex, H > 0 concave.
    Jumps: :func:`~rangesim.edges._discontinuities.find_discontinuities` (steps deeper than
    ``jump_threshold`` pixel footprints, searched across NaN gaps), JUMP on the near side;
    curvature points whose fit window contains a discontinuity are dropped (a fit across a
    step is not a surface).

    Parameters
    ----------
    scan : RangeScan
        Uses ``xyz``, ``depth``, ``valid`` (mm, camera frame) and ``meta["K"]`` for the
        footprint (without it, see :func:`~rangesim.edges._scan_access.pixel_geometry`).
    threshold : float, optional
        Curvature threshold, 1/mm (finite, > 0). Default (None): range-adaptive, a multiple of ``1 / R``
        per pixel, with R = ``window // 2 * footprint`` mm the block's half-width
        (``footprint = z / f`` mm per pixel); a fit over the block cannot resolve radii
        below ~R. ``extrema``: :data:`EXTREMA_RELATIVE_THRESHOLD` = 0.25 / R (a crease of
        bend theta gives ~1.9 tan(theta / 2) / R, so 15 degrees), on noisy scans (depth
        noise of :func:`~rangesim.edges._noise.estimate_depth_noise` above
        :data:`~rangesim.edges._noise.NOISE_FLOOR` footprints) at least
        :data:`NOISE_K_CURVATURE` times the median ``|k| R``, and per pixel times
        :func:`~rangesim.edges._noise.local_noise_scale` where the scan carries its noise
        model's ``sigma``. ``both``:
        :data:`DEFAULT_RELATIVE_THRESHOLD` = 0.5 / R (a 90 degree corner responds with
        ~1 / R in both directions, a crease leaks ~0.3 / R).
    window : int, optional
        Odd fit-block size, pixels (3 to 255). Default (None): 5 (7 on scans that carry their noise
        model's ``sigma`` and whose depth noise is :data:`NOISY_BLOCK_NOISE` = 0.5 pixel
        footprints or more), or on block-matched scans
        (``meta["sensor"]`` with ``mode = "structured_light"``) :func:`matching_block` of
        the matcher's window (13 for its 9 px): the matcher rounds every crease over its
        window, and a 5 x 5 quadric fitted inside the rounding sees a gentle blend under
        the matcher's noise, not a crease.
        Left at None on such scans, ``rule="extrema"`` uses the chords at the matcher's
        scale instead of block fits (above; 0.4 s instead of 4-5 s a 640 x 480 scan); an
        explicit ``window`` keeps the fits.
    jump_threshold : float
        Depth-discontinuity threshold in pixel footprints (finite, > 0): neighbours whose depths differ by
        more than this many footprints (``z / f`` mm) are a jump. Default
        :data:`~rangesim.edges._discontinuities.JUMP_THRESHOLD` = cot(15 deg) = 3.73, the ground
        truth's rule (a continuous surface jumps only beyond 75 degrees slant); for a pinhole
        camera it is ``jump_threshold / f`` times the depth (PCL's 0.02 z is 0.02 f).
    max_search : int
        Pixels searched across NaN gaps for the jump rule, >= 0 (0: only direct neighbours).
    rule : {"extrema", "both"}
        Which rule marks the edge points (above).
    full_block : bool
        ``extrema`` only: mark only pixels whose whole fit block is valid. A block cut by a
        gap (a laser shadow beside a crease, the image border) fits off-centre, and its
        curvature peak moves away from the gap by up to a pixel or two.

    Returns
    -------
    EdgeMap
        ``method="curvature"``; ``strength`` in 1/mm (NaN where the fit failed): the larger
        ``|k|`` (``extrema``) or ``min(|k1|, |k2|)`` (``both``); ``labels``
        CONVEX/CONCAVE/JUMP; ``direction``: the angle in [0, pi) of the image vector across
        the crease (``extrema``), None (``both``).

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> edges = rs.edges.curvature(scan)
    >>> edges.method, bool(edges.mask.any())
    ('curvature', True)
    >>> corners = rs.edges.curvature(scan, rule="both")     # Fig. 12: corners only
    >>> jump = rs.core.constants.EdgeLabel.JUMP
    >>> bool((corners.mask & (corners.labels != jump)).sum() <= (edges.mask & (edges.labels != jump)).sum())
    True

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    .. [2] P. J. Besl, R. C. Jain, "Invariant surface characteristics for 3D object recognition
       in range images", Computer Vision, Graphics, and Image Processing 33(1), 33-80 (1986),
       doi:10.1016/0734-189X(86)90220-3.
    """
    threshold = P.number(threshold, "threshold", 0, lo_open=True, what="curvature", unit="1/mm", none=True)
    window = P.odd_window(window, "window")
    jump_threshold, max_search = P.jump_rule(jump_threshold, max_search)
    rule = P.choice(rule, "rule", RULES)
    full_block = P.flag(full_block, "full_block")
    matcher = matching_window(scan)
    # block-matched scans, default window, extrema rule: curvature at the matcher's scale
    # from chords (rangesim.edges._curvature_chords) instead of quadric fits on blocks
    sensor_scale = matcher is not None and window is None and rule == "extrema"
    z, valid = scan_depth(scan)
    disc, geo = discontinuities(scan, z, jump_threshold, max_search)
    noise = estimate_depth_noise(scan, z=z, fp=geo.footprint, quantum=disc.quantum) if not sensor_scale else None
    if window is None and matcher is None and carries_sigma(scan):
        # (scans with a noise model; a recording's noise measured from its depth alone is left
        # at 5 px: the mOSD Kinect frames measure 0.46-0.54 footprints, across the step)
        window = NOISY_BLOCK_WINDOW if noise >= NOISY_BLOCK_NOISE else DEFAULT_WINDOW
    window = int(matching_block(matcher) if window is None else window)
    if sensor_scale:
        points, curv, info = matched_creases(scan, valid, disc, matcher, threshold)
        strength = np.abs(curv["k"])
        direction = curv["direction"]
        mean = curv["H"]
        relative = None
    else:
        points, strength, direction, mean, relative = _block_points(
            scan, z, valid, disc, geo, window, threshold, rule, full_block, noise)
        info = {}
    jump = disc.occluding
    if rule == "extrema":
        # 1 px diagonals: NMS leaves 4-connected staircases, the truth is 8-connected
        points = thin_staircases(points | jump | disc.rim, points)
    with np.errstate(invalid="ignore"):
        labels = np.where(mean > 0, EdgeLabel.CONCAVE, EdgeLabel.CONVEX).astype(np.uint8)
    labels[disc.rim] = RIM
    labels[jump] = EdgeLabel.JUMP
    offset = disc.offsets_at(jump | disc.rim)
    mask = with_gap_creases(points | jump | disc.rim, labels, disc, offset) & valid
    labels[~mask] = 0
    params = {
        "rule": rule, "full_block": bool(full_block), "threshold": None if threshold is None else float(threshold),
        "relative_threshold": relative,
        "window": window, "jump_threshold": float(jump_threshold), "max_search": int(max_search),
        "scale": "sensor" if sensor_scale else "blocks", "matching_window": matcher,
    }
    params.update(info)
    return EdgeMap(mask=mask, labels=labels, strength=strength, direction=direction,
                   method="curvature", params=params, offset=offset)


def _block_points(scan: Any, z: np.ndarray, valid: np.ndarray, disc: Any, geo: Any, window: int,
                  threshold: float | None, rule: str, full_block: bool, noise: float) -> tuple[Any, ...]:
    """Edge points of quadric fits on ``window`` x ``window`` blocks (the path of every scan
    but a block-matched one's default ``extrema``): points, strength, direction, mean
    curvature and the relative threshold (or None); ``noise``: the scan's depth noise,
    footprints (:func:`~rangesim.edges._noise.estimate_depth_noise`)."""
    r = window // 2
    curv = curvature_scan(scan, window=window)
    k1, k2, mean = curv["k1"], curv["k2"], curv["H"]
    half_width = (r * geo.footprint).astype(np.float64)    # R, mm: curvature in units of 1 / R
    direction = None
    relative = None
    if rule == "both":
        strength = np.fmin(np.abs(k1), np.abs(k2))
        if threshold is None:
            relative = DEFAULT_RELATIVE_THRESHOLD
            points = curvature_edges(k1 * half_width, k2 * half_width, relative)
        else:
            points = curvature_edges(k1, k2, float(threshold))
    else:
        first = np.abs(k1) >= np.abs(k2)
        strength = np.where(first, np.abs(k1), np.abs(k2))
        direction = _image_angle(np.where(first[..., None], curv["dir1"], curv["dir2"]), scan, z,
                                 geo.perspective)
        if threshold is None:
            relative_strength = strength * half_width
            relative = EXTREMA_RELATIVE_THRESHOLD
            pixel_relative: float | np.ndarray = relative
            if noise >= NOISE_FLOOR:
                relative = noise_threshold(relative_strength, valid, relative, NOISE_K_CURVATURE)
                # per pixel: raised where the noise model predicts more noise than the median
                pixel_relative = raised_threshold(relative, local_noise_scale(scan, valid, geo.footprint, disc.noise))
            with np.errstate(invalid="ignore"):
                above = relative_strength > pixel_relative
        else:
            with np.errstate(invalid="ignore"):
                above = strength > float(threshold)
        if full_block:
            # a block cut by a gap (a laser shadow beside a crease) fits off-centre: its
            # curvature peak moves away from the gap by up to a pixel
            above &= curv["n_points"] == window * window
        points = nonmax_suppress(strength, direction, above)
    # drop fits whose block holds a discontinuity (either side of one)
    touching = pad_last2(disc.touching, r, False)
    near_jump = np.zeros(z.shape, bool)
    for dr in range(-r, r + 1):
        for dc in range(-r, r + 1):
            near_jump |= padded_view(touching, r, dr, dc, z.shape)
    points &= ~near_jump
    return points, strength, direction, mean, relative


def _image_angle(d: np.ndarray, scan: Any, z: np.ndarray, perspective: bool = True) -> np.ndarray:
    """Angle in [0, pi) of the image motion along 3D directions ``d`` (H, W, 3) at each pixel.

    A step ``d`` from the camera-frame point (x, y, z) moves its image by
    ``f / z * (d_x - x d_z / z, d_y - y d_z / z)`` (pinhole): the direction, not the length,
    is kept. Without ``perspective`` (a grid of constant spacing, such as a sweep scanner's,
    whose depth need not be a distance from a camera) by ``(d_x, d_y)``. NaN where ``d`` or
    the point is undefined.
    """
    if perspective:
        xyz = np.asarray(scan.xyz, np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = d[..., 0] - xyz[..., 0] / z * d[..., 2]
            v = d[..., 1] - xyz[..., 1] / z * d[..., 2]
    else:
        u, v = d[..., 0], d[..., 1]
    with np.errstate(invalid="ignore"):
        angle = np.mod(np.arctan2(v, u), np.pi)
    return angle.astype(np.float32)
