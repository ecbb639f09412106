"""Preview pictures of a range scan: colour-mapped, hill-shaded depth with status colours.

One mechanism, many callers: :func:`depth_rgb` builds the picture as an RGB array (so
other figures, e.g. detected edges over a scan, can draw on top of it) and
:data:`STATUS_COLORS` fixes one colour per status code for every picture the project
makes. :func:`save_preview` wraps both into a labelled PNG.

Matplotlib is used through its object-oriented API only (``Figure`` +
``FigureCanvasAgg``), never ``pyplot``: no global state, so previews can be written from
worker threads and the caller's interactive backend is left alone.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import Colormap

from rangesim.core.constants import Status, status_name
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.viz.figure import ColorbarSpec, save_labelled_image

RGB = tuple[float, float, float]

#: Fixed colour (RGB in [0, 1]) per invalid status code, shared by every picture.
#: Muted and low in saturation on purpose: the depth colormaps (turbo, viridis) are
#: saturated everywhere, so a greyish colour can never be mistaken for a depth -- in
#: particular turbo's own dark-violet and dark-red ends stay distinct from shadow and
#: out-of-range.
STATUS_COLORS: dict[Status, RGB] = {
    Status.MISS: (0.20, 0.20, 0.20),          # dark grey: nothing there
    Status.SHADOW: (0.42, 0.38, 0.58),        # muted blue-violet
    Status.DROPOUT: (0.58, 0.44, 0.29),       # muted brown / dark orange
    Status.OUT_OF_RANGE: (0.58, 0.29, 0.31),  # muted dark red
}
#: Colour for status codes without an entry above (codes added later, inconsistent pixels).
UNKNOWN_STATUS_COLOR: RGB = (0.85, 0.85, 0.85)

#: Direction towards the light in the camera frame (x right, y down, z forward): from the
#: image's upper left and from the camera's side, 45 degrees above the image plane -- the
#: cartographic convention, so bumps read as bumps and not as dents.
_ALTITUDE = math.radians(45.0)
_LIGHT = np.array(
    [-math.cos(_ALTITUDE) * math.sqrt(0.5), -math.cos(_ALTITUDE) * math.sqrt(0.5), -math.sin(_ALTITUDE)]
)


def status_colors() -> dict[Status, RGB]:
    """Colour per invalid status code, a copy of :data:`STATUS_COLORS`.

    Returns
    -------
    dict of Status -> (3,) tuple of float
        RGB in [0, 1]. ``Status.VALID`` has no entry: valid pixels show their depth.
    """
    return dict(STATUS_COLORS)


def status_color(code: int) -> RGB:
    """RGB in [0, 1] for one status code; :data:`UNKNOWN_STATUS_COLOR` if it has none."""
    try:
        return STATUS_COLORS.get(Status(int(code)), UNKNOWN_STATUS_COLOR)
    except ValueError:  # not a Status member
        return UNKNOWN_STATUS_COLOR


def _valid_depth_mask(scan: RangeScan) -> np.ndarray:
    """(H, W) bool: pixels that show a depth (valid *and* finite, whatever the flags say)."""
    return scan.valid & np.isfinite(scan.depth)


def depth_limits(
    scan: RangeScan, percentiles: tuple[float, float] = (1.0, 99.0)
) -> tuple[float, float]:
    """Robust colour limits of the valid depth.

    Percentiles rather than min/max so that a few phantom points (multipath, spikes)
    do not squeeze the real surface into one colour.

    Parameters
    ----------
    scan : RangeScan
        The scan.
    percentiles : (2,) float
        Lower and upper percentile of the valid depth, in [0, 100].

    Returns
    -------
    (lo, hi) : tuple of float
        Depth limits in mm (scene units), ``lo < hi``. ``(0, 1)`` when nothing is valid;
        widened to +-0.5 mm around a constant depth.
    """
    d = scan.depth[_valid_depth_mask(scan)]
    if d.size == 0:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(d.astype(np.float64), percentiles))
    if not hi > lo:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


def _tangents(p: np.ndarray, axis: int) -> np.ndarray:
    """(H, W, 3) finite-difference tangent of ``p`` along ``axis`` (0 rows, 1 columns).

    Mean of the forward and backward differences where both exist, else whichever does:
    pixels on the rim of a valid region (next to a NaN) still get a tangent.
    """
    fwd = np.full_like(p, np.nan)
    bwd = np.full_like(p, np.nan)
    if p.shape[axis] > 1:
        diff = np.diff(p, axis=axis)
        if axis == 0:
            fwd[:-1], bwd[1:] = diff, diff
        else:
            fwd[:, :-1], bwd[:, 1:] = diff, diff
    # no np.nanmean: its all-NaN warning would need warnings.catch_warnings, which
    # is process-global state and so not thread-safe
    return np.where(np.isnan(fwd), bwd, np.where(np.isnan(bwd), fwd, 0.5 * (fwd + bwd)))


def estimate_normals(scan: RangeScan) -> np.ndarray:
    """Surface normals from the measured geometry, for scans whose ``normal`` is NaN.

    Uses ``scan.xyz``; where that is NaN but the depth is finite (hand-built scans),
    back-projects the depth through ``K`` (or, without ``K``, treats one pixel as one
    unit laterally -- right in shape, not in scale).

    Parameters
    ----------
    scan : RangeScan
        The scan.

    Returns
    -------
    (H, W, 3) float64
        Unit normals in the camera frame, facing the camera (``n_z <= 0``); NaN where
        there is no depth or no neighbour to difference with.
    """
    h, w = scan.shape
    p = scan.xyz.astype(np.float64)
    z = np.where(_valid_depth_mask(scan), scan.depth, np.nan).astype(np.float64)
    missing = np.isnan(p).any(axis=-1) & np.isfinite(z)
    if missing.any():
        jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        K = scan.K
        if K is not None:
            # pixel (i, j) looks along K^-1 (j + 0.5, i + 0.5, 1); scale that ray to depth z
            rays = np.stack([jj, ii, np.ones_like(jj)], axis=-1) @ np.linalg.inv(K).T
            q = rays / rays[..., 2:3] * z[..., None]
        else:
            q = np.stack([jj, ii, z], axis=-1)
        p = np.where(missing[..., None], q, p)
    p[~np.isfinite(z)] = np.nan
    # rows grow along +y, columns along +x; their cross product points along +z (away),
    # the sign fix below turns every normal towards the camera
    n = np.cross(_tangents(p, 1), _tangents(p, 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n *= np.where(n[..., 2:3] > 0, -1.0, 1.0)
    return n


def hillshade(scan: RangeScan) -> np.ndarray:
    """Lambertian shading of the scanned surface under a fixed light (upper left, 45 deg).

    Uses ``scan.normal`` where it is finite and :func:`estimate_normals` elsewhere.

    Parameters
    ----------
    scan : RangeScan
        The scan.

    Returns
    -------
    (H, W) float64
        ``n . l`` in [0, 1], where ``l`` is the unit direction towards the light;
        ``sin(45 deg) ~ 0.71`` on a surface facing the camera; NaN without depth or
        without a normal (an isolated pixel with no valid neighbour to difference with).
    """
    n = scan.normal.astype(np.float64)
    need = _valid_depth_mask(scan) & ~np.isfinite(n).all(axis=-1)
    if need.any():
        n[need] = estimate_normals(scan)[need]
    shade = np.clip(n @ _LIGHT, 0.0, 1.0)
    shade[~_valid_depth_mask(scan)] = np.nan
    return shade


def _fill_nan_shade(shade: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W) shade with NaN at valid pixels replaced by their 3x3 neighbours' mean.

    Isolated pixels (between dropouts) have no normal; left unshaded they would sparkle.
    Whatever has no shaded neighbour either gets the scan's median shade.
    """
    missing = valid & np.isnan(shade)
    if not missing.any():
        return shade
    h, w = shade.shape
    known = np.isfinite(shade)
    pad_v = np.pad(np.where(known, shade, 0.0), 1)
    pad_n = np.pad(known.astype(np.float64), 1)
    total = sum(pad_v[di:di + h, dj:dj + w] for di in range(3) for dj in range(3))
    count = sum(pad_n[di:di + h, dj:dj + w] for di in range(3) for dj in range(3))
    overall = float(np.median(shade[known])) if known.any() else 1.0
    out = shade.copy()
    has = count[missing] > 0
    out[missing] = np.where(has, total[missing] / np.maximum(count[missing], 1.0), overall)
    return out


def _cmap(cmap: str | Colormap) -> Colormap:
    return colormaps[cmap] if isinstance(cmap, str) else cmap


def depth_rgb(
    scan: RangeScan,
    *,
    cmap: str | Colormap = "turbo",
    limits: tuple[float, float] | None = None,
    shade: bool = True,
    shade_strength: float = 0.6,
) -> np.ndarray:
    """The scan as a picture: colour-mapped depth, hill-shaded, invalid pixels by status.

    Parameters
    ----------
    scan : RangeScan
        The scan.
    cmap : str or Colormap
        Colormap for the depth, low depth (near) at its start.
    limits : (lo, hi) float, optional
        Depth in mm mapped to the colormap's ends; depths outside are clipped to them.
        Default :func:`depth_limits` (1st-99th percentile of the valid depth).
    shade : bool
        Modulate valid pixels by :func:`hillshade`, which makes holes, scratches and
        steps visible that the colormap alone hides.
    shade_strength : float
        In [0, 1]: 0 leaves the colours alone; at 1 a surface turned fully away from
        the light goes black. Brightness is relative to the scan's median shade, so a
        uniformly tilted surface keeps the colour bar's colours.

    Returns
    -------
    (H, W, 3) float64
        RGB in [0, 1]. Invalid pixels get exactly their :data:`STATUS_COLORS` colour
        (never shaded, so they always match the legend).
    """
    h, w = scan.shape
    lo, hi = depth_limits(scan) if limits is None else (float(limits[0]), float(limits[1]))
    valid = _valid_depth_mask(scan)

    rgb = np.empty((h, w, 3), dtype=np.float64)
    t = np.clip((scan.depth[valid].astype(np.float64) - lo) / (hi - lo), 0.0, 1.0)
    rgb[valid] = _cmap(cmap)(t)[:, :3]

    if shade and valid.any() and shade_strength > 0:
        hs = _fill_nan_shade(hillshade(scan), valid)
        # relative to the scan's typical shade, not to a camera-facing plane: a part
        # that is tilted as a whole keeps the colours of the colour bar, and only local
        # relief (holes, scratches, steps) changes brightness. < 1 darkens, > 1
        # lightens towards white.
        rel = hs[valid] / max(float(np.median(hs[valid])), 0.05)
        # lightening capped at 60 % towards white so a lit slope keeps its hue (its depth)
        f = np.clip(1.0 - shade_strength + shade_strength * rel, 0.0, 1.6)[:, None]
        c = rgb[valid]
        rgb[valid] = np.where(f <= 1.0, c * f, c + (1.0 - c) * (f - 1.0))

    for code in np.unique(scan.status[~valid]):
        rgb[~valid & (scan.status == code)] = status_color(code)
    return rgb


def _status_counts(scan: RangeScan) -> dict[int, int]:
    """Pixel count per status code among pixels that show no depth, in code order."""
    codes, counts = np.unique(scan.status[~_valid_depth_mask(scan)], return_counts=True)
    return {int(c): int(n) for c, n in zip(codes, counts)}


def _status_label(code: int, mode: str | None = None) -> str:
    if code == Status.VALID:  # flagged valid yet without a finite depth: inconsistent data
        return "valid, no depth"
    try:
        return status_name(code, mode)
    except (ValueError, KeyError):
        return f"status {code}"


def status_legend(scan: RangeScan, dim: float = 1.0) -> list[tuple[RGB, str]]:
    """(colour, "<status>: <n> px (<p> %)") of every status among the pixels without a depth,
    for a picture's legend; ``dim`` scales the colours as the picture drew them."""
    total = scan.shape[0] * scan.shape[1]
    return [(tuple(dim * v for v in status_color(c)),
             f"{_status_label(c, scan.meta.get('mode'))}: {n:,} px ({_percent(n, total)})")
            for c, n in _status_counts(scan).items()]


def _percent(n: int, total: int) -> str:
    """``n / total`` as a percentage that never shows a non-zero count as "0.0 %"."""
    p = 100.0 * n / max(total, 1)
    if n == 0 or p >= 0.1:
        return f"{p:.1f} %"
    return f"{p:.2f} %" if p >= 0.01 else "< 0.01 %"


def default_title(scan: RangeScan) -> str:
    """``"<sensor> -- W × H px, N valid (P %)"``, width first as the command line prints it.

    The sensor name comes from ``scan.meta``.
    """
    h, w = scan.shape
    name = (scan.meta.get("sensor") or {}).get("name") or "range scan"
    n_valid = int(_valid_depth_mask(scan).sum())
    return f"{name} — {w} × {h} px (W × H), {n_valid:,} valid ({100.0 * n_valid / max(h * w, 1):.1f} %)"


#: a scan wider or taller than this (pixels) is previewed from every k-th pixel (a PNG of
#: 10000 x 10000 pixels would take GBs to draw and shows no more on a screen)
MAX_PREVIEW_PX = 2048


def _thinned(scan: RangeScan) -> RangeScan:
    """``scan`` itself, or every k-th row and column of it when it exceeds :data:`MAX_PREVIEW_PX`."""
    k = -(-max(scan.shape) // MAX_PREVIEW_PX)
    if k <= 1:
        return scan
    fields = {f: None if getattr(scan, f) is None else getattr(scan, f)[::k, ::k]
              for f in ("depth", "xyz", "valid", "normal", "intensity", "part", "face", "status", "xyz_true", "sigma")}
    return RangeScan(pose=scan.pose, meta=scan.meta, **fields)


def save_preview(
    scan: RangeScan,
    path: str | Path,
    *,
    title: str | None = None,
    cmap: str | Colormap = "turbo",
    dpi: int = 150,
    shade: bool = True,
    limits: tuple[float, float] | None = None,
) -> Path:
    """Write a labelled PNG preview of the scan's depth.

    The picture is :func:`depth_rgb` drawn pixel for pixel (nearest neighbour, square
    pixels, integer magnification for small scans; scans larger than
    :data:`MAX_PREVIEW_PX` from every k-th pixel), with a colour bar of the depth, a
    legend of the invalid statuses present and their pixel counts, and a title. The
    figure's proportions follow the scan's. Written atomically: a failure leaves no
    partial file.

    Parameters
    ----------
    scan : RangeScan
        The scan.
    path : str or Path
        Output file; must end in ``.png``. Parent directories are created.
    title : str, optional
        Default :func:`default_title` (sensor name, image size, valid count).
    cmap : str or Colormap
        Depth colormap (perceptual; ``"turbo"`` by default, ``"viridis"`` for print).
    dpi : int
        Resolution of the PNG; fonts and margins scale with it.
    shade : bool
        Hill-shade the depth (see :func:`depth_rgb`).
    limits : (lo, hi) float, optional
        Depth range of the colormap in mm; default 1st-99th percentile of valid depth.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    RangesimError
        If ``path`` does not end in ``.png``.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120

    >>> import tempfile, pathlib
    >>> from rangesim.viz import save_preview
    >>> path = save_preview(scan, pathlib.Path(tempfile.mkdtemp()) / "scan.png")
    >>> path.name, path.stat().st_size > 1000
    ('scan.png', True)
    """
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise RangesimError("preview must be a .png file", source=path)

    h, w = scan.shape
    view = _thinned(scan)
    lo, hi = depth_limits(view) if limits is None else (float(limits[0]), float(limits[1]))
    rgb = depth_rgb(view, cmap=cmap, limits=(lo, hi), shade=shade)
    legend = status_legend(scan)
    valid_d = view.depth[_valid_depth_mask(view)]
    below, above = bool((valid_d < lo).any()), bool((valid_d > hi).any())
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max"}.get(
        (below, above), "both"
    )  # the arrows say "clipped here", so robust limits never hide that data go beyond
    colorbar = ColorbarSpec(_cmap(cmap), lo, hi, "depth z [mm]", extend)
    return save_labelled_image(
        rgb, path, title=default_title(scan) if title is None else title,
        legend=legend, colorbar=colorbar, dpi=dpi, image_size=(w, h),
    )
