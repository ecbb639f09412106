"""Depth discontinuities (jump edges): the detectors' jump rule, and the broken neighbour
pairs that finite differences must not cross.

Analysis layer: pure NumPy over arrays. :func:`find_discontinuities` is the rule of PCL's
``OrganizedEdgeBase`` (neighbours whose depths differ by more than a threshold), with a
search across NaN gaps against the pixel's own surface continued across them;
:func:`discontinuities` applies it with :data:`JUMP_THRESHOLD` pixel footprints, the rule
every detector uses by default. :func:`segment_broken` tells whether a run of steps along
an axis crosses a discontinuity.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.edges._grid import AXES, NEIGHBOURS, pad_last2, padded_view, shift
from rangesim.edges._scan_access import PixelGeometry, pixel_geometry

__all__ = [
    "JUMP_THRESHOLD", "Discontinuities", "discontinuities", "find_discontinuities",
    "segment_broken",
]

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
    footprints, and the scan's :class:`~rangesim.edges._scan_access.PixelGeometry`."""
    geo = pixel_geometry(scan, z)
    disc = find_discontinuities(z, np.float32(jump_threshold) * geo.footprint, max_search,
                                perspective=geo.perspective)
    return disc, geo


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

