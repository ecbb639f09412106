"""Scan access for the edge detectors: a scan's points, depth and validity as arrays (NaN
wherever a pixel is unusable), its focal length and the pixel footprint.

Analysis layer: pure NumPy over arrays. Conventions used by every detector (image axes:
:mod:`rangesim.edges._grid`):

* depth ``z`` is the camera-frame z of the measured point, mm, NaN where invalid; the camera
  looks along +z, so "near" means smaller z (recorded grids without a camera model: the
  scanner's z, see :func:`pixel_geometry`);
* thresholds are relative: in pixel footprints (the lateral size of a pixel on the surface,
  ``z / f`` mm, :func:`footprint`) or angles, so they hold at every range.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError

__all__ = [
    "PixelGeometry", "check_scan", "scan_arrays", "scan_depth", "scan_points", "focal_length_px",
    "pixel_geometry", "footprint",
]


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
    xyz = scan_points(scan, valid)
    # a valid pixel with a finite depth but no finite point (an edited or odd file) has no point
    unusable = valid & ~np.isfinite(xyz).all(axis=-1)
    if unusable.any():
        valid &= ~unusable
        z[unusable] = np.nan
        xyz[unusable] = np.nan
    return xyz, z, valid


#: the per-pixel fields the detectors read: name -> (trailing shape, dtype kinds accepted, required)
PIXEL_FIELDS = {
    "depth": ((), "biuf", True),
    "valid": ((), "biuf", True),         # (a float 0 / 1 mask is read as bool)
    "xyz": ((3,), "biuf", False),        # (required where read: scan_points checks it again)
    "sigma": ((), "biuf", False),
    "status": ((), "biu", False),
}


def _field_shape(name: str, value: Any, expected: tuple[int, ...], kinds: str) -> None:
    arr = np.asarray(value)
    if arr.shape != expected:
        raise RangesimError(f"has shape {arr.shape}; the scan's {expected[0]} x {expected[1]} depth image needs "
                            f"{expected}", f"scan.{name}")
    if arr.dtype.kind not in kinds:
        want = "bool or integer" if "f" not in kinds else "numeric (bool, integer or float)"
        raise RangesimError(f"must be {want}, got dtype {arr.dtype}", f"scan.{name}")


def check_scan(scan: Any) -> tuple[int, int]:
    """Refuse a scan whose per-pixel fields do not fit together; return its (H, W).

    Every detector calls this (through :func:`scan_depth`) before any computation: a
    field of another shape (``xyz`` of (H, W, 2) or (W, H, 3), a ``valid`` one row short,
    a ``sigma`` or ``status`` of another size) or of a non-numeric dtype raises
    :class:`~rangesim.core.errors.RangesimError` naming the field and both shapes, and no
    compiled kernel ever indexes an array by another's shape. ``sigma`` and ``status``
    may be None (recorded data); ``xyz`` is checked here when present and again where it is
    read (:func:`scan_points`). An unorganized point list (``meta["organized"]`` False: a
    1 x N "image" of a PLY or PCD point cloud) is refused: its neighbours in the list are
    not neighbours on the surface (:func:`~rangesim.edges.line_fit` takes its points).
    """
    if not (hasattr(scan, "depth") and hasattr(scan, "valid")):
        raise RangesimError(f"the edge detectors take a RangeScan (depth, valid, xyz, meta), got {type(scan).__name__}")
    depth = np.asarray(scan.depth)
    if depth.ndim != 2 or 0 in depth.shape:
        raise RangesimError(f"must be a non-empty (H, W) image, got shape {depth.shape}", "scan.depth")
    h, w = depth.shape
    meta = getattr(scan, "meta", None)
    if isinstance(meta, dict) and meta.get("organized") is False:
        # a point list's 1 x N "image" has no neighbours: its edges would be between list entries
        raise RangesimError(f"is an unorganized point list ({h} x {w}, no image grid): the edge detectors need an "
                            "organized scan; line_fit takes its points, line_fit(scan.points())", "scan")
    for name, (trailing, kinds, required) in PIXEL_FIELDS.items():
        value = getattr(scan, name, None)
        if value is None and not required:
            continue
        _field_shape(name, value, (h, w) + trailing, kinds)
    return h, w


def scan_depth(scan: Any) -> tuple[np.ndarray, np.ndarray]:
    """Depth (H, W) float32 with NaN at unusable pixels, and validity; see :func:`scan_arrays`.

    The scan's fields are checked first (:func:`check_scan`). A pixel marked valid must have
    a finite depth (NaN counts as a hole: an edited scan may punch them without updating
    ``valid``; +-inf is refused, no measurement is infinitely far), and on a pinhole scan
    (``meta["K"]``: depth is the camera-frame z) a positive one: z <= 0 is behind the
    camera. Grids without a camera model may carry any finite depth (a scanner's range axis
    may be centred on 0: the Cyberware's, see :func:`pixel_geometry`).
    """
    check_scan(scan)
    z = np.array(scan.depth, dtype=np.float32)          # a copy: NaN goes in below
    marked = np.asarray(scan.valid, dtype=bool)
    valid = marked & np.isfinite(z)
    # the rare bad pixels are looked at only where the cheap tests say there are any (marked
    # but not finite: NaN or inf; for a pinhole, finite but not in front of the camera)
    odd = marked & ~valid
    if odd.any():
        infinite = int(np.count_nonzero(np.isinf(z[odd])))
        if infinite:
            raise RangesimError(f"{infinite} pixels marked valid have an infinite depth: mark them invalid "
                                "(valid False, depth NaN)", "scan.depth")
    if focal_length_px(scan) is not None:
        with np.errstate(invalid="ignore"):
            behind = int(np.count_nonzero(z[valid] <= 0)) if not (np.fmin.reduce(z, axis=None) > 0) else 0
        if behind:
            raise RangesimError(f"{behind} pixels marked valid have a depth <= 0, behind a pinhole camera "
                                "(meta['K']: depth is the camera-frame z, > 0); mark them invalid, or drop "
                                "meta['K'] for a grid whose depth axis is not the camera's", "scan.depth")
    np.copyto(z, np.nan, where=~valid)                  # (np.where is ~5x slower)
    return z, valid


def scan_points(scan: Any, valid: np.ndarray, component_major: bool = False) -> np.ndarray:
    """Points with NaN where ``valid`` is False; see :func:`scan_arrays`.

    (H, W, 3) float32, or (3, H, W) contiguous with ``component_major``.
    """
    xyz = np.asarray(scan.xyz, dtype=np.float32)
    if xyz.shape != valid.shape + (3,):   # (checked on entry by check_scan; kernels index by it)
        raise RangesimError(f"has shape {xyz.shape}, the depth image needs {valid.shape + (3,)}", "scan.xyz")
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
    try:
        K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError):
        raise RangesimError(f"the scan's meta['K'] must be a 3 x 3 intrinsic matrix, got {K!r:.60}") from None
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
        return PixelGeometry((z / np.float32(f)).astype(np.float32, copy=False), True, f)
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
