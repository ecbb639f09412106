"""Shadows without a caster: a laser-shadow gap that cannot be the measured surface continued.

A point in laser shadow has something between it and its light source. Where a gap of
shadowed pixels (``Status.SHADOW``: the camera saw a surface the laser did not reach)
borders a measured surface, the search across the gap (:func:`~._discontinuities.find_discontinuities`)
asks whether the gap is that surface continued. Continued, a gap pixel's point is lit from
the same side as its measured neighbour; it can only be in shadow if some other surface
blocks its path to the light. That surface would stand in front of the path, so wherever
the path's image crosses measured pixels, one of them would be nearer to the camera than
the path. When none is (the path runs over the part's own lit face in front of it, or out
of the image), no caster exists: the gap is not the surface continued but a drop behind
its edge, which shadows itself. That is the rim of a hole whose inside the laser cannot
reach (a part held above its table, a deep hole seen head-on), and the edge is marked as
one (a rim). A shadow cast by another part onto a floor has its caster in front of the
path and stays no edge.

The test marches the path's image pixel by pixel (the screen-space shadow test of real-time
rendering), from the first gap pixel at the depth the search predicts for it, towards the
source (:func:`rangesim.core.light.light_sources`), until it leaves the image or reaches the
source. It can be wrong where a caster is hidden from the camera or outside the image (a
false rim), or where a surface in front of the path does not in fact block it (no rim).
A face turned away from the laser is SHADOW too: the edge of a lit face against it (a
convex fold whose far face is unlit) is then a rim rather than a crease, which is where
that edge is, under another label.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numba
import numpy as np

from rangesim.core.constants import Status
from rangesim.core.light import light_sources

#: sensor modes whose scans the test applies to: the laser-stripe ones. A block matcher
#: (``structured_light``) fattens the near surface over its projector shadows by up to half
#: its window, so the surface "continued" from its edge is the smeared foreground; on the
#: machined parts' tuning seeds 0-7 the rule found no new rim there and its false rims made
#: false circles (round-feature precision 0.67 -> 0.33 on kinect_v1, 0.33 -> 0.18 on
#: structured_light_bench), while on the laser presets it found the rims over shadow
LASER_MODES = ("geometric", "rendered")

#: test(rows, cols, depth) -> (N,) bool: True where the gap pixel (rows, cols) at ``depth``
#: (mm, camera z) would have no caster between it and its light source
CasterTest = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def shadow_gaps(scan: Any, z: np.ndarray, footprint: np.ndarray, sigma: np.ndarray | None = None,
                quantum: np.ndarray | float | None = None) -> tuple[np.ndarray, CasterTest] | None:
    """The scan's laser-shadow pixels and a caster test for them; None where it cannot tell.

    Needs what a synthetic laser-stripe scan carries (:data:`LASER_MODES`): ``status`` (which
    invalid pixels are shadow), ``meta["K"]`` and ``meta["sensor"]`` (where the light comes
    from). Recorded scans, which say only that a return is missing, structured-light scans
    and sensors without a light source get None.

    Parameters
    ----------
    scan : RangeScan
    z : (H, W) float
        The scan's depth image (camera z, mm), NaN where not measured.
    footprint : (H, W) float
        Pixel footprint, mm.
    sigma : (H, W) float, optional
        Predicted depth noise, mm.
    quantum : float or (H, W), optional
        Depth quantum, mm.

    A measured pixel blocks a path where it stands nearer than the path by more than the
    noise of a pixel pair (2 sqrt(2) sigma), a footprint and a quantum: not the jump
    threshold, since a path that grazes its caster's edge, at the end of a shadow, passes
    it by less than a jump.

    Returns
    -------
    unlit : (H, W) bool
        Invalid pixels in laser shadow.
    test : callable
        ``test(rows, cols, depth)``: :func:`uncast`, for this depth image, camera, light and
        tolerance.
    """
    valid = np.isfinite(z)
    status = getattr(scan, "status", None)
    meta = getattr(scan, "meta", None) or {}
    if status is None or np.shape(status) != valid.shape or "source" in meta:
        return None
    sensor, K = meta.get("sensor"), meta.get("K")
    if not isinstance(sensor, dict) or K is None or light_sources(np.zeros((1, 3)), sensor) is None:
        return None
    if sensor.get("mode") not in LASER_MODES:
        return None
    unlit = ~valid & (np.asarray(status) == Status.SHADOW)
    if not unlit.any():
        return None
    tolerance = footprint if sigma is None else footprint + np.float32(2.0 * np.sqrt(2.0)) * sigma
    if quantum is not None:
        tolerance = tolerance + quantum
    nearest = _nearest(z)

    def test(rows: np.ndarray, cols: np.ndarray, depth: np.ndarray) -> np.ndarray:
        return uncast(z, tolerance, K, sensor, rows, cols, depth, nearest=nearest)

    return unlit, test


def uncast(z: np.ndarray, thr: np.ndarray, K: np.ndarray, sensor: dict, rows: np.ndarray, cols: np.ndarray,
           depth: np.ndarray, nearest: float | None = None) -> np.ndarray:
    """Whether points at pixels (rows, cols) and ``depth`` would see their light source.

    Parameters
    ----------
    z : (H, W) float32
        Depth image, mm (camera z), NaN where not measured.
    thr : (H, W) float32
        How much nearer than the path a measured pixel must be to block it, mm.
    K : (3, 3) float
        Pinhole intrinsics; pixel (row i, column j) looks along K^-1 (j + 0.5, i + 0.5, 1)
        (no skew: rangesim's cameras have none).
    sensor : dict
        The scan's ``meta["sensor"]`` (:func:`rangesim.core.light.light_sources`).
    rows, cols : (N,) int
    depth : (N,) float
        Camera z of each point, mm.
    nearest : float, optional
        The least measured depth of ``z`` (computed when not given): a path nearer than it
        has nothing left in front of it.

    Returns
    -------
    (N,) bool
        True where no measured pixel stands in front of the path to the source.
    """
    depth = np.asarray(depth, np.float64)
    K = np.asarray(K, np.float64).reshape(3, 3)  # a scan may hold K flat (9 values)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    points = np.column_stack([(cols + 0.5 - cx) / fx * depth, (rows + 0.5 - cy) / fy * depth, depth])
    sources = light_sources(points, sensor)
    good = np.isfinite(depth) & (depth > 0)
    out = np.zeros(len(depth), bool)
    if good.any():
        nearest = _nearest(z) if nearest is None else nearest
        out[good] = _march(np.ascontiguousarray(z, np.float32), np.ascontiguousarray(thr, np.float32),
                           fx, fy, cx, cy, points[good], sources[good], max(z.shape) + 1, nearest)
    return out


def _nearest(z: np.ndarray) -> float:
    """The least finite depth of ``z`` (inf when none)."""
    return float(np.nanmin(z)) if np.isfinite(z).any() else np.inf


@numba.njit(cache=True, nogil=True)
def _march(z, thr, fx, fy, cx, cy, points, sources, max_px, nearest):  # pragma: no cover - compiled
    """For each segment point -> source: False when its image crosses a measured pixel nearer
    than the segment by more than ``thr`` there (a caster), else True. The march ends where the
    path is nearer than ``nearest`` (the least measured depth): no pixel can stand in front."""
    h, w = z.shape
    n = points.shape[0]
    out = np.ones(n, np.bool_)
    for k in range(n):
        x0, y0, z0 = points[k, 0], points[k, 1], points[k, 2]
        dx, dy, dz = sources[k, 0] - x0, sources[k, 1] - y0, sources[k, 2] - z0
        # image motion at the start, d(u, v)/dt: step the faster coordinate by 1 px; the
        # image of a segment is a straight line, so the other moves by at most 1 px a step
        du = fx * (dx * z0 - x0 * dz) / (z0 * z0)
        dv = fy * (dy * z0 - y0 * dz) / (z0 * z0)
        along_u = abs(du) >= abs(dv)
        if max(abs(du), abs(dv)) == 0.0:
            continue
        sense = 1.0 if (du if along_u else dv) > 0 else -1.0
        u0 = fx * x0 / z0 + cx
        v0 = fy * y0 / z0 + cy
        for s in range(1, max_px):
            # the segment parameter t where the image coordinate reaches u0 + s (or v0 + s)
            if along_u:
                c = u0 + sense * s - cx
                den = fx * dx - c * dz
                t = (c * z0 - fx * x0) / den if den != 0.0 else -1.0
            else:
                c = v0 + sense * s - cy
                den = fy * dy - c * dz
                t = (c * z0 - fy * y0) / den if den != 0.0 else -1.0
            if not (0.0 < t < 1.0):
                break
            pz = z0 + t * dz
            if pz <= 0.0 or (pz <= nearest and dz <= 0.0):
                break
            u = fx * (x0 + t * dx) / pz + cx
            v = fy * (y0 + t * dy) / pz + cy
            j, i = int(np.floor(u)), int(np.floor(v))
            if i < 0 or i >= h or j < 0 or j >= w:
                break
            zq = z[i, j]
            if zq == zq and zq < pz - thr[i, j]:
                out[k] = False
                break
    return out
