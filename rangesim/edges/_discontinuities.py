"""Depth discontinuities (jump edges), rims of the measured surface, and the broken
neighbour pairs that finite differences must not cross.

Analysis layer: pure NumPy over arrays. :func:`find_discontinuities` is the rule of PCL's
``OrganizedEdgeBase`` (neighbours whose depths differ by more than a threshold), with a
search across NaN gaps against the pixel's own surface continued across them, an optional
*fold* test (a steep but continuous surface is not a jump) and *rims* (the measured
surface ending against pixels that saw nothing); :func:`discontinuities` applies it the
way every detector does by default: :data:`JUMP_THRESHOLD` pixel footprints plus the
depth quantum of quantised scans, folds on, rims from the scan's status.
:func:`segment_broken` tells whether a run of steps along an axis crosses a
discontinuity.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core.constants import EdgeLabel, Status
from rangesim.core.errors import RangesimError
from rangesim.edges._gap_folds import FoldTest, gap_fold_test
from rangesim.edges._grid import AXES, NEIGHBOURS, nonzero2, pad_last2, padded_view
from rangesim.edges._noise import depth_quantum, predicted_noise
from rangesim.edges._pair_kernels import pair_tests, search_gaps
from rangesim.edges._scan_access import PixelGeometry, pixel_geometry
from rangesim.edges._self_shadow import CasterTest, shadow_gaps
from rangesim.edges._thinning import drop_specks, thin_staircases

__all__ = [
    "JUMP_THRESHOLD", "QUANTUM_STEPS", "SIGMA_STEPS", "Discontinuities", "discontinuities", "empty_pixels",
    "find_discontinuities", "segment_broken", "with_gap_creases",
]

#: the detectors' default jump rule, in pixel footprints: a step between neighbours deeper
#: than cot(15 deg) = 3.73 footprints, i.e. a continuous surface jumps only when seen at
#: more than 75 degrees slant; the rule of rangesim.evaluate's ground truth (a 3D step
#: within 15 degrees of the viewing ray). For a pinhole camera it is 3.73 / f times the
#: depth (0.0028 z for the White Scanner's f = 1317 px, 0.014 z at f = 275 px); PCL's
#: fixed 0.02 z is 0.02 f footprints (10.5 for a Kinect), blind to shallow steps.
JUMP_THRESHOLD = float(1.0 / np.tan(np.radians(15.0)))

#: quanta added to the jump threshold of quantised scans (:func:`discontinuities`): rounding
#: moves two neighbours apart by up to one quantum, and structured-light matching errs by
#: whole disparity levels, correlated over its window, so smooth faces step by up to ~3
#: quanta (measured on a flat table by the kinect_v1 preset and on the PCL / mOSD Kinect
#: frames: 0.4-1 % of horizontal neighbour steps exceed 2.5 quanta, 0.1-0.4 % exceed 3.5)
QUANTUM_STEPS = 3.0

#: predicted noise standard deviations of a neighbour pair's depth difference added to the
#: jump threshold where the scan carries its noise model's ``sigma`` (:func:`discontinuities`);
#: chosen on the machined parts' seeds 0-19: 2 gains a little more F1 on inria_laser and
#: loses 2 of 69 hole rims on cyberware_3030 with its noise, 1 loses none
SIGMA_STEPS = 1.0

#: the least jump threshold in standard deviations of a neighbour pair's depth difference,
#: ``sqrt(2) sigma``, where the scan carries its noise model's ``sigma`` and its pixels'
#: errors are their own (not block-matched: a matcher's errors are shared over its window and
#: cancel between neighbours; :func:`discontinuities`): a two-sided Gaussian tail of 1e-4 per
#: pair, so that a face whose noise outgrows the footprint (sigma over about 0.9 footprints: a
#: grazing face, or a noisier stripe than the presets') is no salt of jump pixels. Below that
#: the footprint rule plus :data:`SIGMA_STEPS` is the higher and decides alone. The value
#: follows from the tail; it was checked (not chosen) on a White Scanner view with the
#: stripe noise raised 8-16x (edge F1 0.60 / 0.37 -> 0.93 / 0.90, gradient) and on the machined
#: parts' tuning seeds. Where part of the noise is spatially correlated (``noise.correlation_mm``:
#: cyberware_3030's 0.42 mm, ~0.8 px) neighbours share it and their difference is smaller, so
#: the floor is that much more conservative there (about 7 standard deviations of its
#: correlated part)
FALSE_JUMP_Z = 3.9

#: a nearer surface found across a laser-shadow gap by more than this many jump thresholds
#: (of the pixel's surface continued and of its own depth) is taken for the shadow's caster,
#: and the border no rim (:func:`find_discontinuities`, ``caster_test``)
CASTER_STEPS = 3.0

#: the caster test of a shadow gap is asked at its first shadow pixel and at up to this many
#: further ones along the search, where they are shadow too (all must see no caster): see
#: :func:`find_discontinuities`
SHADOW_DEPTH_PX = 1

#: a shadow gap with fewer shadow pixels than this in the 5 x 5 window around its first
#: pixel is a speck, whose caster the depth image cannot resolve (no rim). The case was found
#: on the Green Piece's tilted view (valleys between thread crests); the value follows from
#: a caster within a pixel or two (a speck of 1-5 pixels, a shadow band 2 px wide fills 10)
#: and was checked there and on the machined parts' tuning seeds 0-7 before the one run on
#: the report seeds, so the Green Piece figures are not held out for it
SPECK_PX = 6

#: detectors mark the two ends of a gap that a face the scanner did not measure explains as
#: creases (:mod:`~._gap_folds`)
GAP_FOLDS = True


def empty_pixels(scan: Any, valid: np.ndarray) -> tuple[np.ndarray, bool]:
    """Invalid pixels that saw no surface at all: where a rim of the measured surface can be.

    A synthetic scan says why a pixel has no point (``scan.status``): ``MISS`` (the camera
    ray hit nothing: the view through a through-hole, past a part's silhouette) is empty;
    ``SHADOW``, ``DROPOUT`` and ``OUT_OF_RANGE`` pixels saw a surface that was not measured,
    possibly the neighbour's own surface continued, and are not. Recorded readers mark
    every missing return ``MISS``, and a scan without ``status`` says nothing: there every
    invalid pixel counts as empty (what a depth image can tell, as PCL's NaN boundary).

    Parameters
    ----------
    scan : RangeScan or any object with ``status`` (H, W) uint8, optional attribute
    valid : (H, W) bool
        Pixels with a measured point.

    Returns
    -------
    empty : (H, W) bool
    certain : bool
        True when the status tells causes apart (a synthetic scan: no ``meta["source"]``,
        which recorded readers set): a pixel that saw nothing is then known to, and its
        neighbour is a rim whatever a search across the gap finds beyond.
    """
    status = getattr(scan, "status", None)
    if status is None or np.shape(status) != valid.shape:
        return ~valid, False
    recorded = "source" in (getattr(scan, "meta", None) or {})
    return ~valid & (np.asarray(status) == Status.MISS), not recorded


def discontinuities(
    scan: Any, z: np.ndarray, jump_threshold: float, max_search: int,
) -> tuple["Discontinuities", PixelGeometry]:
    """The detectors' jump rule, and the scan's :class:`~rangesim.edges._scan_access.PixelGeometry`.

    :func:`find_discontinuities` with a per-pixel threshold of ``jump_threshold`` pixel
    footprints plus :data:`QUANTUM_STEPS` depth quanta
    (:func:`~rangesim.edges._noise.depth_quantum`; nothing on scans whose depths are not
    quantised), plus :data:`SIGMA_STEPS` standard deviation of a pair's difference,
    ``sqrt(2) sigma``, where the scan carries the noise model's predicted ``sigma`` (mm;
    the least over the pixel's 5 x 5 neighbourhood, :func:`~rangesim.edges._noise.predicted_noise`):
    noise grows steeply with incidence, and a face seen at 70-75 degrees, whose neighbours
    already differ by 3 footprints, is otherwise a band of jumps wherever the noise adds
    the rest (on the machined parts' seeds 0-7, inria_laser's noisy gradient F1 0.63 -> 0.81);
    and never under :data:`FALSE_JUMP_Z` (3.9) such standard deviations where the scan is not
    block-matched (a face noisier than ~0.9 footprints).
    Rounding moves each of two neighbours by at most half a quantum, so their
    difference by at most one, and a structured-light matcher errs by whole disparity
    levels on top of that: a Kinect's quantised table (steps of 1.5-3 footprints at 1-2 m)
    is then no band of jump dashes, while real depth edges (tens of quanta) stay. Folds
    are on (a steep continuous surface such as a lit hole wall is not a band of jumps),
    rims come from :func:`empty_pixels` and, on synthetic scans, from laser-shadow gaps that
    no caster explains (:func:`~rangesim.edges._self_shadow.shadow_gaps`). The jump and rim
    pixels are then thinned to 8-connected 1 px lines like the truth's contours
    (:func:`~rangesim.edges._thinning.thin_staircases`: the inner corner of each 4-connected
    step goes): where the data ends at a ragged gap (a block matcher's occluding boundary)
    every pixel beside it is a jump, corners included. On the machined parts' tuning seeds
    0-7 / check seeds 8-15, block-matched F1 +0.005-0.011 / +0.005-0.006 for gradient,
    normal, line_fit and curvature, laser-stripe -0.001-+0.004.
    """
    from rangesim.edges._matching_scale import matching_window  # (it imports this module)

    geo = pixel_geometry(scan, z)
    thr = np.float32(jump_threshold) * geo.footprint
    quantum = depth_quantum(z)
    if quantum is not None:
        thr = thr + np.float32(QUANTUM_STEPS) * quantum
    sigma = predicted_noise(scan, z=z, quantum=quantum)
    if sigma is not None:
        pair_sd = np.float32(np.sqrt(2.0)) * sigma
        thr = thr + np.float32(SIGMA_STEPS) * pair_sd
        if matching_window(scan) is None:  # a matcher's errors, shared over its window, cancel between neighbours
            thr = np.maximum(thr, np.float32(FALSE_JUMP_Z) * pair_sd)
    empty, certain = empty_pixels(scan, np.isfinite(z))
    shadows = shadow_gaps(scan, z, geo.footprint, sigma, quantum) if geo.perspective else None
    unlit, caster_test = shadows if shadows is not None else (None, None)
    # what the threshold adds to the jump rule's footprints (quanta, noise): once over a gap
    fold_test = (gap_fold_test(scan, geo.footprint, float(jump_threshold),
                               thr - np.float32(jump_threshold) * geo.footprint)
                 if geo.perspective and GAP_FOLDS else None)
    disc = find_discontinuities(z, thr, max_search, perspective=geo.perspective, folds=True,
                                empty=empty, empty_certain=certain, unlit=unlit, caster_test=caster_test,
                                fold_test=fold_test)
    disc.noise, disc.quantum = sigma, quantum
    # 1 px lines, as the truth's contours: every pixel beside a ragged gap is a jump, and
    # the inner corners of the 4-connected staircases that leaves match no true pixel
    marks = disc.occluding | disc.rim
    kept = thin_staircases(marks, keep_corners=True)
    disc.occluding &= kept
    disc.rim &= kept
    # a face the scanner did not measure: its near end a convex crease, its far end (the
    # occluded side, thinned the same way) a concave one
    if disc.gap_fold.any():
        far = disc.occluded & disc.gap_fold & ~disc.occluding & ~disc.rim
        far &= thin_staircases(far, keep_corners=True)
        # an end of a pixel or two is a speck of dropout (noise over the threshold), not a wall's
        far = drop_specks(far, far)
        creases = np.zeros(z.shape, np.uint8)
        creases[far] = EdgeLabel.CONCAVE
        near = disc.occluding & disc.gap_fold
        creases[drop_specks(near, near)] = EdgeLabel.CONVEX
        disc.gap_creases = creases
    return disc, geo


def with_gap_creases(mask: np.ndarray, labels: np.ndarray, disc: "Discontinuities",
                     offset: np.ndarray | None = None) -> np.ndarray:
    """A detector's edge mask with the gap creases of ``disc`` (:mod:`~._gap_folds`) added;
    ``labels`` (H, W) uint8 set to their type in place (over a jump's), and ``offset``
    (H, W, 2), if given, to the contour offsets of the far ends (the foot lies towards the
    gap, as a jump's contour does).

    Returns
    -------
    (H, W) bool
    """
    creases = disc.gap_creases
    if creases is None or not creases.any():
        return mask
    at = creases > 0
    labels[at] = creases[at]
    if offset is not None:
        far = np.flatnonzero(creases == EdgeLabel.CONCAVE)
        offset.reshape(-1, 2)[far] = disc.contour.reshape(-1, 2)[far]
    return mask | at


@dataclass
class Discontinuities:
    """Depth discontinuities (jump edges) of a depth image; see :func:`find_discontinuities`.

    Attributes
    ----------
    occluding : (H, W) bool
        Near side of a discontinuity (the pixel is nearer than its neighbour across it);
        from :func:`discontinuities`, together with ``rim``, thinned to 8-connected lines
        (the inner corner of each one-pixel step dropped; true corners kept).
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
    rim : (H, W) bool
        (Thinned with ``occluding`` by :func:`discontinuities`.) Valid pixels next to an *empty* pixel (one that saw no surface, ``empty`` of
        :func:`find_discontinuities`) that are not occluding (nor, unless the emptiness is
        certain, occluded): the measured
        surface ends there against nothing measured (a through-hole's rim over an absent
        floor, a part's silhouette against empty space). All False when ``empty`` is None.
    quantum : (H, W) float32 or None
        The depth's quantisation step, mm (:func:`~rangesim.edges._noise.depth_quantum`; None
        for continuous depth; set by :func:`discontinuities`, for the detectors' noise rules).
    noise : (H, W) float32 or None
        The predicted depth noise (mm) the jump threshold allowed for
        (:func:`~rangesim.edges._noise.predicted_noise`; set by :func:`discontinuities`),
        None where the scan carries none.
    contour : (H, W, 2) float32
        At occluding, occluded and rim pixels: (dx, dy), pixels, from the pixel's centre to
        the expected position of the contour it borders (:func:`contour_offsets`); 0
        elsewhere. A jump lies somewhere between the pixel's centre and its neighbour's
        across it, so the pixel's centre is half a pixel spacing off, always to one side.
    gap_fold : (H, W) bool
        Occluding and occluded pixels whose jump was found across a gap that a face the
        scanner did not measure explains (:mod:`~._gap_folds`; ``fold_test`` of
        :func:`find_discontinuities`).
    gap_creases : (H, W) uint8 or None
        Set by :func:`discontinuities`: EdgeLabel CONVEX at the near end of such a face
        (an occluding pixel, which stays one), CONCAVE at its far end (occluded pixels,
        thinned to 1 px lines), 0 elsewhere; the detectors add them
        (:func:`with_gap_creases`).
    """

    occluding: np.ndarray
    occluded: np.ndarray
    nan_boundary: np.ndarray
    pairs: np.ndarray
    direction: np.ndarray
    rim: np.ndarray | None = None
    noise: np.ndarray | None = None
    contour: np.ndarray | None = None
    quantum: np.ndarray | None = None
    gap_fold: np.ndarray | None = None
    gap_creases: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.rim is None:
            self.rim = np.zeros(self.occluding.shape, bool)
        if self.contour is None:
            self.contour = np.zeros(self.occluding.shape + (2,), np.float32)
        if self.gap_fold is None:
            self.gap_fold = np.zeros(self.occluding.shape, bool)

    def offsets_at(self, where: np.ndarray) -> np.ndarray:
        """``contour`` at the pixels ``where`` (H, W) bool, 0 elsewhere: an
        :attr:`EdgeMap.offset <rangesim.edges.EdgeMap.offset>` for a detector's jump and rim pixels."""
        out = np.zeros_like(self.contour)
        at = np.flatnonzero(where)
        out.reshape(-1, 2)[at] = self.contour.reshape(-1, 2)[at]
        return out

    @property
    def touching(self) -> np.ndarray:
        """Pixels on either side of a discontinuity between valid neighbours."""
        t = np.zeros(self.pairs.shape[1:], bool)
        for a, (dr, dc) in enumerate(AXES):
            t |= self.pairs[a]
            _or_shifted(t, self.pairs[a], dr, dc)
        return t


def _or_shifted(dst: np.ndarray, src: np.ndarray, dr: int, dc: int) -> None:
    """``dst[i + dr, j + dc] |= src[i, j]`` where both are inside the image (in place)."""
    h, w = src.shape
    r0, r1 = max(dr, 0), h + min(dr, 0)
    c0, c1 = max(dc, 0), w + min(dc, 0)
    dst[r0:r1, c0:c1] |= src[r0 - dr:r1 - dr, c0 - dc:c1 - dc]


def find_discontinuities(
    z: np.ndarray,
    threshold: float | np.ndarray = 0.02,
    max_search: int = 50,
    rule: str = "any",
    extrapolate: bool = True,
    connectivity: int | None = None,
    perspective: bool = True,
    folds: bool = False,
    empty: np.ndarray | None = None,
    empty_certain: bool = False,
    unlit: np.ndarray | None = None,
    caster_test: "CasterTest | None" = None,
    fold_test: "FoldTest | None" = None,
) -> Discontinuities:
    """Jump edges: neighbours whose depths differ by more than a threshold; and rims.

    The rule of PCL's ``OrganizedEdgeBase`` (depth-discontinuity threshold proportional to
    depth, default 0.02 z): a pixel ``p`` is *occluding* when a neighbour ``q`` is farther,
    ``z_q - z_p > t_p``, and *occluded* when a neighbour is nearer, ``z_p - z_q > t_q``,
    with ``t = threshold * z`` (or a given per-pixel threshold); the nearer pixel's
    threshold applies, so every broken pair has one occluding and one occluded pixel.

    With ``folds`` a step is not a jump where one side's own surface, continued linearly
    one pixel across it (from the pixel and the one behind it; in inverse depth with
    ``perspective``, exact for planes), reaches the other side: the far surface continued
    back comes within ``t`` of the near pixel (a hole's wall seen at grazing incidence
    below its rim, a convex fold), or the near surface continued forward gets within
    ``t`` of the far pixel (the foot of that wall on the floor, a concave one). The two are
    one continuous surface that folds. Without it every pixel pair of a face steeper than
    ``atan(t / footprint)`` is a jump and the face becomes a band of jump pixels; with it
    only the face's end, where it meets an occluder or nothing, is one, and its creases
    are left to the crease operators. A true occlusion stays a jump: the hidden surface
    continued towards the occluder passes behind it, and the occluder continued forward
    stays in front of the hidden one.

    Across invalid (NaN) pixels, as in PCL, a valid pixel with invalid neighbours searches
    for the first valid pixel along the mean direction of those neighbours (normalised to
    one pixel per step along its larger axis, so every step moves; PCL's floor() can stay
    put) for up to ``max_search`` steps and compares depths with it. Unlike PCL, with
    ``extrapolate`` the comparison is against the pixel's own surface continued across
    the gap (inverse depth, or depth without ``perspective``, extrapolated linearly from
    the pixels behind it, up to 3 back: exact for planes), so a hole in a tilted plane is
    not a jump.
    A pixel whose search finds nothing is a *NaN boundary*.

    Rims (``empty`` given): a valid pixel next to an empty pixel (one whose camera ray saw
    no surface) that the rules above leave not occluding (see ``empty_certain``). Why this rule:
    a rim is where the measured surface ends. It ends at a depth discontinuity (the
    jump rule and the search across gaps find those: occluding, when the far side was
    measured somewhere along the search), or against nothing at all. A pixel that saw
    nothing cannot hide the neighbour's surface continued (its ray would have hit it), so
    the neighbour is the near side of a step to infinity, even when the search across the
    gap finds the same surface again beyond it (the other side of a through-hole over an
    absent floor). A gap that saw a surface (a laser shadow, a signal dropout, a pixel out
    of the working range) may be the neighbour's own surface continued, and only the
    search decides: a farther surface beyond is a jump, the same surface continued is a
    dropout and no edge (a speckle hole in a face), a nearer surface makes the pixel the
    far side of an occluder (the end of a shadow on a floor: the occluder is the edge),
    and a search that finds nothing leaves it untyped (the outline of a shadow on a
    floor, which is no edge of anything). PCL has no such split: its NaN boundary is every
    search that finds nothing, whatever the gap saw.

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
        invalid, and that make a rim). Default 8 for ``"dominant"`` (PCL), 4 for
        ``"any"``: the near side of a jump is then a thin 8-connected line, as the ground
        truth marks it, instead of a 4-connected staircase. ``pairs`` always covers all 8
        directions.
    perspective : bool
        Extrapolate inverse depth (pinhole camera at the origin) or depth (grids of
        constant spacing) across gaps and folds.
    folds : bool
        Apply the fold test above (the detectors do; PCL does not).
    empty : (H, W) bool, optional
        Invalid pixels that saw no surface (:func:`empty_pixels`); None: no rims.
    empty_certain : bool
        ``empty`` is known (a synthetic scan's status), not merely "no return": a pixel
        next to it is a rim even where the search across the gap calls it occluded (the
        search extrapolates the pixel's surface from one neighbour, so on noisy scans a
        long gap can make it look occluded). Otherwise (recorded data) an occluded pixel
        is the far end of a shadow and no rim. Known empty pixels are also looked for
        across a gap: a surface whose search meets at most :data:`EMPTY_GAP_PX` (1)
        unmeasured pixel and then an empty one, before any measured pixel, ends in that gap
        against nothing (a block matcher's window that straddled its silhouette, a dropout
        at a grazing outline) and is a rim too. (Behind a thin nearer object that went
        wholly unmeasured such a pixel would be the occluded side; one pixel leaves no room
        for one.)
    unlit, caster_test : optional
        Laser-shadow pixels (H, W) bool and a caster test (:func:`~._self_shadow.shadow_gaps`).
        A pixel whose search finds no farther surface beyond a gap is a rim when the gap's
        first shadow pixel, at the depth the pixel's surface continued predicts for it,
        would have no caster between it and the light: that gap cannot be the surface
        continued (:mod:`~._self_shadow`; a through-hole whose inside the laser cannot
        reach). Without them such a pixel is no edge, as described above.
    fold_test : optional
        :func:`~._gap_folds.gap_fold_test` for this scan: a jump found across a gap of at
        least 2 steps is a *gap fold* (``gap_fold``) where the test calls the gap a face the
        scanner did not measure (:mod:`~._gap_folds`); its pixel stays occluding or occluded.

    Returns
    -------
    Discontinuities
    """
    if rule not in ("any", "dominant"):
        raise RangesimError(f"rule must be 'any' or 'dominant', not {rule!r}")
    if connectivity is None:
        connectivity = 8 if rule == "dominant" else 4
    if connectivity not in (4, 8):
        raise RangesimError(f"connectivity must be 4 or 8, got {connectivity}")
    z = np.ascontiguousarray(z, dtype=np.float32)
    h, w = z.shape
    valid = np.isfinite(z)
    if np.ndim(threshold) == 0:
        thr = np.abs(z) * np.float32(threshold)
    else:
        # broadcast to the image (a row or column of thresholds works), contiguous for the kernel
        thr = np.ascontiguousarray(np.broadcast_to(np.asarray(threshold, dtype=np.float32), z.shape))
    zt = z + thr                                  # a neighbour beyond zt_p is a jump away
    dominant = rule == "dominant"
    # every axis pair (p, p + d) once, with the fold test, in one compiled pass
    occluding, occluded, pairs, far, near = pair_tests(z, thr, zt, bool(folds), bool(perspective),
                                                        connectivity == 4, dominant)
    # valid pixels with an invalid neighbour (an out-of-image neighbour is not one: PCL
    # skips the border instead)
    invp = np.pad(~valid, 1, constant_values=False)
    nbrs = NEIGHBOURS if connectivity == 8 else ((-1, 0), (0, -1), (0, 1), (1, 0))
    has_invalid = np.zeros((h, w), bool)
    for dr, dc in nbrs:
        has_invalid |= invp[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
    has_invalid &= valid
    if dominant:
        # PCL: one label from the dominant difference; only the search where a neighbour is NaN
        occluding &= (far >= near) & ~has_invalid
        occluded &= (near > far) & ~has_invalid
    direction = np.full((h, w), np.nan, np.float32)
    across = []  # (rows, cols, x, y): a vector towards the other side, any length; last wins
    nan_boundary = np.zeros((h, w), bool)
    rim = np.zeros((h, w), bool)
    gap_fold = np.zeros((h, w), bool)

    ii, jj = nonzero2(has_invalid)
    if ii.size:
        vpad = np.pad(valid, 1, constant_values=True)
        if empty is not None:
            epad = np.pad(np.asarray(empty, bool), 1, constant_values=False)
            near_empty = np.zeros(ii.size, bool)
            for dr, dc in nbrs:
                near_empty |= epad[ii + 1 + dr, jj + 1 + dc]
    if ii.size and max_search > 0:
        # mean offset of the invalid neighbours: the direction to search along
        vx = np.zeros(ii.size, np.float32)
        vy = np.zeros(ii.size, np.float32)
        for dr, dc in NEIGHBOURS:
            inv = ~vpad[ii + 1 + dr, jj + 1 + dc]
            vx += inv * dc
            vy += inv * dr
        scale = np.maximum(np.abs(vx), np.abs(vy))
        moving = scale > 0
        si, sj = ii[moving], jj[moving]
        vx, vy, scale = vx[moving], vy[moving], scale[moving]
        sx, sy = vx / scale, vy / scale
        z0 = z[si, sj].astype(np.float64)
        t0 = thr[si, sj].astype(np.float64)
        # the pixels behind continue the pixel's own surface across the gap: the slope
        # from the farthest of 3, 2, 1 steps back that is valid and on the same surface
        # (within k thresholds; a longer base divides the noise of the slope by k, which
        # the search multiplies by the gap's width)
        slope = np.zeros(si.size)        # per step, of 1 / z (perspective) or z
        # no pixel behind on the same surface: slope unknown (without ``extrapolate`` the
        # surface continues at its own depth, known everywhere)
        todo = np.full(si.size, bool(extrapolate))
        if extrapolate:
            for k in (3, 2, 1):
                bi = si - np.rint(k * sy).astype(np.intp)
                bj = sj - np.rint(k * sx).astype(np.intp)
                inside = todo & (bi >= 0) & (bi < h) & (bj >= 0) & (bj < w)
                zb = np.full(si.size, np.nan)
                zb[inside] = z[bi[inside], bj[inside]]
                smooth = np.isfinite(zb) & (np.abs(zb - z0) <= k * t0)
                if perspective:
                    slope[smooth] = (1.0 / z0[smooth] - 1.0 / zb[smooth]) / k
                else:
                    slope[smooth] = (z0[smooth] - zb[smooth]) / k
                todo &= ~smooth
        shade = np.asarray(unlit, bool) if unlit is not None and caster_test is not None else None
        # each pixel steps along (sx, sy) to the first valid pixel within max_search, noting
        # the first laser-shadow pixel on the way (a dim pixel may come before it); compiled
        found_z, found_t, found_s, unlit_s = search_gaps(
            z, thr, np.ascontiguousarray(shade) if shade is not None else np.zeros((1, 1), bool), shade is not None,
            si, sj, np.ascontiguousarray(sx, np.float32), np.ascontiguousarray(sy, np.float32), int(max_search))
        ok = np.isfinite(found_z)
        pred = _continued(z0, slope, found_s, perspective)
        occl = ok & (found_z - pred > t0)
        occd = ok & (pred - found_z > found_t)
        occluding[si[occl], sj[occl]] = True
        occluded[si[occd], sj[occd]] = True
        nan_boundary[si[~ok], sj[~ok]] = True
        jump = occl | occd
        direction[si[jump], sj[jump]] = np.mod(np.arctan2(sy[jump], sx[jump]), np.pi)
        if fold_test is not None:
            f = np.flatnonzero(jump & (found_s >= 2))
            # the found pixel, as the search stepped to it (float32 products, rounded half to even)
            steps = found_s[f].astype(np.float32)
            ai = si[f] + np.rint(sy[f] * steps).astype(np.intp)
            aj = sj[f] + np.rint(sx[f] * steps).astype(np.intp)
            f = f[fold_test(si[f], sj[f], z0[f], ai, aj, found_z[f], sy[f], sx[f], found_s[f])]
            gap_fold[si[f], sj[f]] = True
        # either side of a jump across a gap: the contour lies towards the gap
        across.append((si[jump], sj[jump], sx[jump], sy[jump]))
        if shade is not None:
            # a shadow gap that is not the surface continued: no caster could shadow it.
            # Asked of the occluded too, unless the nearer surface found across the gap
            # stands clearly in front (by CASTER_STEPS thresholds, of the depth continued and
            # of the pixel's own): a noisy slope extrapolated across a wide gap often calls
            # the same surface nearer, while a clearly nearer one is the likely caster even
            # where the test cannot see it (a boss whose shadow falls through its own unlit
            # wall, which the camera sees and the scanner does not measure).
            # Only of surfaces known behind the pixel (a corner's pixel has none to continue)
            # that step less than half the jump threshold a pixel: a steep face (a lit hole
            # wall at grazing incidence) continued across a gap is a guess, and its caster
            # (the hole's far wall, which faces away from the laser) is itself in shadow.
            step1 = _continued(z0, slope, 1.0, perspective)
            with np.errstate(invalid="ignore"):
                caster = ok & (pred - found_z > CASTER_STEPS * found_t) & (z0 - found_z > CASTER_STEPS * t0)
            a = np.flatnonzero(~occl & ~caster & ~todo & (unlit_s > 0) & (np.abs(step1 - z0) <= 0.5 * t0))
            gi = si[a] + np.rint(sy[a] * unlit_s[a]).astype(np.intp)
            gj = sj[a] + np.rint(sx[a] * unlit_s[a]).astype(np.intp)
            lit = caster_test(gi, gj, _continued(z0[a], slope[a], unlit_s[a], perspective))
            # a speck of shadow (fewer than SPECK_PX shadow pixels in the 5 x 5 window around
            # its first pixel: a valley between thread crests) has its caster within a pixel
            # or two, below what the depth image resolves: no rim
            lit &= _count_in_window(shade, gi, gj, 2) >= SPECK_PX
            # and the next gap pixels up to SHADOW_DEPTH_PX deeper, where they are shadow too:
            # the path from a cast shadow's first pixel grazes its caster's edge (that is
            # where the shadow begins), by less than the tolerance; deeper ones pass it clearly
            for extra in range(1, SHADOW_DEPTH_PX + 1):
                d = np.flatnonzero(lit)
                s2 = unlit_s[a[d]] + extra
                hi = si[a[d]] + np.rint(sy[a[d]] * s2).astype(np.intp)
                hj = sj[a[d]] + np.rint(sx[a[d]] * s2).astype(np.intp)
                deeper = ((s2 < found_s[a[d]]) | ~ok[a[d]]) & (hi >= 0) & (hi < h) & (hj >= 0) & (hj < w)
                deeper[deeper] = shade[hi[deeper], hj[deeper]]
                d, s2, hi, hj = d[deeper], s2[deeper], hi[deeper], hj[deeper]
                lit[d] = caster_test(hi, hj, _continued(z0[a[d]], slope[a[d]], s2, perspective))
            a = a[lit]
            rim[si[a], sj[a]] = True
            direction[si[a], sj[a]] = np.mod(np.arctan2(sy[a], sx[a]), np.pi)
            across.append((si[a], sj[a], sx[a], sy[a]))
    gap_end = None
    if ii.size and empty is not None and max_search > 0 and empty_certain:
        # a few unmeasured pixels (a dropout at a silhouette, a block matcher's window that
        # straddled the edge) and then nothing: the surface ends within that gap, against nothing
        reach = _empty_within(np.asarray(empty, bool), valid, si, sj, sx, sy, EMPTY_GAP_PX + 1) & ~ok
        reach &= ~near_empty[moving] & ~occluding[si, sj]
        near_empty[np.flatnonzero(moving)[reach]] = True
        # (no empty neighbour to point to it: the surface ends along the search)
        gap_end = (si[reach], sj[reach], sx[reach], sy[reach])
    if ii.size and empty is not None:
        # the measured surface ends against nothing: see the docstring
        e_i, e_j = ii[near_empty], jj[near_empty]
        keep = ~occluding[e_i, e_j]
        if not empty_certain:
            keep &= ~occluded[e_i, e_j]
        e_i, e_j = e_i[keep], e_j[keep]
        rim[e_i, e_j] = True
        # the surface ends towards its empty neighbours (their mean offset)
        ex = np.zeros(e_i.size, np.float32)
        ey = np.zeros(e_i.size, np.float32)
        for dr, dc in nbrs:
            e = epad[e_i + 1 + dr, e_j + 1 + dc]
            ex += e * dc
            ey += e * dr
        across.append((e_i, e_j, ex, ey))
        if gap_end is not None:  # after: their (ex, ey) above are 0, the last entry wins
            across.append(gap_end)

    # direction across the jump from the broken neighbour pairs (gradient of "is far")
    ei, ej = nonzero2((occluding | occluded) & np.isnan(direction))
    if ei.size:
        gx = np.zeros(ei.size, np.float32)
        gy = np.zeros(ei.size, np.float32)
        zc, ztc = z[ei, ej], zt[ei, ej]
        for dr, dc in NEIGHBOURS:
            ri, rj = ei + dr, ej + dc
            inside = (ri >= 0) & (ri < h) & (rj >= 0) & (rj < w)   # outside: NaN, never a jump
            zq = np.full(ei.size, np.nan, np.float32)
            ztq = np.full(ei.size, np.nan, np.float32)
            zq[inside], ztq[inside] = z[ri[inside], rj[inside]], zt[ri[inside], rj[inside]]
            step = (zq > ztc).astype(np.float32) - (zc > ztq)
            gx += step * dc
            gy += step * dr
        direction[ei, ej] = np.mod(np.arctan2(gy, gx), np.pi)
        # (gx, gy) points to the far side: the other side of an occluding pixel, away from
        # it for an occluded one (a pixel that is both, a sliver, counts as occluding)
        sense = np.where(occluding[ei, ej], 1.0, -1.0).astype(np.float32)
        across.append((ei, ej, sense * gx, sense * gy))
    contour = np.zeros((h, w, 2), np.float32)
    if across:
        ci, cj, cx, cy = (np.concatenate(v) for v in zip(*across))
        contour[ci, cj] = contour_offsets(np.column_stack([cx, cy]), connectivity)
    return Discontinuities(occluding, occluded, nan_boundary, pairs, direction, rim, contour=contour,
                           gap_fold=gap_fold)


#: longest gap of unmeasured pixels (px) between a measured surface and empty pixels (the
#: camera ray hit nothing) across which the surface is taken to end against nothing: the
#: contour pixel itself lost (a block matcher's window straddling the silhouette, a dropout at
#: a grazing outline), as :func:`rangesim.evaluate.visible_truth` marks such a contour on the
#: data's end beside it; a wider gap's far side is not known to be the silhouette (a thin
#: nearer object could stand there unmeasured)
EMPTY_GAP_PX = 1


def _empty_within(empty: np.ndarray, valid: np.ndarray, si: np.ndarray, sj: np.ndarray, sx: np.ndarray,
                  sy: np.ndarray, steps: int) -> np.ndarray:
    """For each pixel (si, sj) stepping along (sx, sy): whether an empty pixel comes within
    ``steps`` steps (after at most ``steps - 1`` unmeasured ones) with no measured pixel and
    no image border before it."""
    h, w = empty.shape
    reach = np.zeros(si.size, bool)
    stopped = np.zeros(si.size, bool)
    for k in range(1, steps + 1):
        gi = si + np.rint(sy * np.float32(k)).astype(np.intp)
        gj = sj + np.rint(sx * np.float32(k)).astype(np.intp)
        stopped |= (gi < 0) | (gi >= h) | (gj < 0) | (gj >= w)
        gi, gj = np.clip(gi, 0, h - 1), np.clip(gj, 0, w - 1)
        hit = ~stopped & empty[gi, gj]
        reach |= hit
        stopped |= hit | valid[gi, gj]
    return reach


def _continued(z0: np.ndarray, slope: np.ndarray, steps, perspective: bool) -> np.ndarray:
    """Depth of a pixel's surface continued ``steps`` pixels along its search: linear in
    inverse depth (``perspective``; a receding surface at most 2 z0) or in depth."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if perspective:
            return 1.0 / np.fmax(1.0 / z0 + steps * slope, 0.5 / z0)
        return z0 + steps * slope


def _count_in_window(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray, half: int) -> np.ndarray:
    """(N,) how many pixels of ``mask`` lie in the (2 half + 1)^2 window around each
    (rows, cols) (outside the image: none)."""
    pad = np.pad(np.asarray(mask, bool), half)
    count = np.zeros(len(rows), np.int64)
    for dr in range(-half, half + 1):
        for dc in range(-half, half + 1):
            count += pad[rows + half + dr, cols + half + dc]
    return count


def contour_offsets(across: np.ndarray, connectivity: int = 4) -> np.ndarray:
    """Where a contour lies from the centres of the pixels that border it.

    A straight contour with unit normal u (towards the other side) is bordered by the
    pixels with a neighbour across it: with 4-neighbours (8) those whose centre lies within
    ``m = max(|ux|, |uy|)`` (``|ux| + |uy|``) px of it. Over the positions of the contour
    in the pixel grid that distance is uniform on (0, m), so the expected contour lies
    ``m / 2`` px from the pixel's centre along u: half a pixel for a contour along a row or
    column, 0.35 px (4-neighbours) or 0.71 px (8) for a diagonal one. Sub-pixel fits of rims
    and lines through the centres alone are off by that much, always outwards.

    Parameters
    ----------
    across : (..., 2) float
        A vector (x, y) towards the other side of the contour at pixels that border it, of
        any length; zero (or non-finite) where there is none.
    connectivity : {4, 8}
        The neighbours that made the pixels border the contour.

    Returns
    -------
    (..., 2) float32
        (dx, dy), pixels; 0 where ``across`` is zero.

    Examples
    --------
    >>> a = np.zeros((1, 2, 2)); a[0, 0] = (3.0, 0.0); a[0, 1] = (1.0, 1.0)
    >>> contour_offsets(a).round(3).tolist()
    [[[0.5, 0.0], [0.25, 0.25]]]
    """
    a = np.nan_to_num(np.asarray(across, np.float64))
    norm = np.hypot(a[..., 0], a[..., 1])
    u = a / np.where(norm > 0, norm, 1.0)[..., None]
    ax, ay = np.abs(u[..., 0]), np.abs(u[..., 1])
    spacing = np.maximum(ax, ay) if connectivity == 4 else ax + ay
    return (0.5 * spacing[..., None] * u).astype(np.float32)


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

