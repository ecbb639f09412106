"""Pictures of surface points with their normals (the paper's Fig. 9).

Matplotlib through its object API only (``Figure`` + ``FigureCanvasAgg``), like the scan
previews: no ``pyplot`` state, safe from worker threads.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from rangesim.core.errors import RangesimError
from rangesim.io.atomic import atomic_path

#: direction towards the light for shading the points (world frame, from above and aside)
_LIGHT = np.array([0.4, -0.5, 0.77]) / np.linalg.norm([0.4, -0.5, 0.77])


def save_points_preview(
    points: np.ndarray,
    normals: np.ndarray | None,
    path: str | Path,
    *,
    normal_length: float | None = None,
    max_normals: int = 4000,
    title: str | None = None,
    elev: float = 25.0,
    azim: float = -60.0,
    dpi: int = 150,
    seed: int = 0,
) -> Path:
    """Write a PNG of 3-D points, with their normals drawn as short line segments.

    Points are shaded by their normal against a fixed light (bright = facing it) so the
    shape reads without a mesh; the axes have equal scale (mm).

    Parameters
    ----------
    points : (N, 3) float
        Positions, mm.
    normals : (N, 3) float or None
        Unit normals; None draws the points only.
    path : str or Path
        Output file, ``.png``; parent directories are created; written atomically.
    normal_length : float, optional
        Length of the drawn normals, mm. Default 4 % of the largest extent.
    max_normals : int
        Draw the normals of at most this many points, spread over the surface
        (:func:`spread_subset`: one per cell of a grid a normal long), so a
        cloud dense in places (threads, fillets) stays readable.
    title : str, optional
        Default ``"<N> surface points"``.
    elev, azim : float
        View angles in degrees (matplotlib's 3-D convention).
    dpi : int
        Resolution of the PNG.
    seed : int
        Seed of the subset whose normals are drawn (when the grid still leaves too many).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    RangesimError
        ``path`` is not ``.png``, or the arrays have the wrong shapes.
    """
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise RangesimError("preview must be a .png file", source=path)
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise RangesimError(f"points must have shape (N, 3), got {points.shape}")
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64)
        if normals.shape != points.shape:
            raise RangesimError(f"normals must have the shape of points {points.shape}, got {normals.shape}")

    fig = Figure(figsize=(7.0, 6.0), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    if len(points):
        lo, hi = points.min(axis=0), points.max(axis=0)
        extent = float((hi - lo).max()) or 1.0
        if normals is not None:
            light = np.clip(normals @ _LIGHT, 0.0, 1.0)
            colors = np.repeat((0.25 + 0.6 * light)[:, None], 3, axis=1) * [0.55, 0.7, 1.0]
        else:
            colors = np.tile([0.2, 0.35, 0.6], (len(points), 1))
        size = max(0.5, min(8.0, 4000.0 / len(points)))  # dots shrink as the cloud grows
        ax.scatter(*points.T, c=colors, s=size, depthshade=False, linewidths=0)
        if normals is not None:
            length = 0.04 * extent if normal_length is None else float(normal_length)
            pick = spread_subset(points, length, max_normals, seed)
            shown = len(pick)
            segments = np.stack([points[pick], points[pick] + length * normals[pick]], axis=1)
            ax.add_collection3d(Line3DCollection(segments, colors=[(0.85, 0.25, 0.15)], linewidths=0.5))
        # equal scale on all axes: a cube around the centre
        centre = (lo + hi) / 2
        half = 0.55 * extent
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.view_init(elev=elev, azim=azim)
    ax.set_xlabel("x [mm]", fontsize=8)
    ax.set_ylabel("y [mm]", fontsize=8)
    ax.set_zlabel("z [mm]", fontsize=8)
    ax.tick_params(labelsize=7)
    if title is None:
        title = f"{len(points):,} surface points"
        if normals is not None and len(points) and shown < len(points):
            title += f" (normals of {shown:,} spread over the surface)"
    ax.set_title(title, fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, metadata={"Software": "rangesim"})
    return path


def spread_subset(points: np.ndarray, cell: float, limit: int, seed: int = 0) -> np.ndarray:
    """Indices of at most ``limit`` points spread over the cloud: the first point of each cubic cell.

    Parameters
    ----------
    points : (N, 3) float
    cell : float
        Cell size, the unit of ``points`` (a dense patch keeps one point per cell).
    limit : int
        At most this many (a fixed random subset of the cells' points beyond it).
    seed : int

    Returns
    -------
    (M,) int, sorted, M <= min(N, limit)

    Examples
    --------
    >>> dense = np.c_[np.zeros((1000, 2)), np.linspace(0, 1, 1000)]   # 1000 points within 1 mm
    >>> sparse = np.c_[np.arange(10.0) * 5 + 10, np.zeros((10, 2))]
    >>> len(spread_subset(np.r_[dense, sparse], 2.0, 100))             # one for the dense patch
    11
    """
    points = np.asarray(points, np.float64)
    if len(points) == 0:
        return np.zeros(0, int)
    keys = np.floor((points - points.min(axis=0)) / max(float(cell), 1e-12)).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    pick = np.sort(first)
    if len(pick) > limit:
        pick = np.sort(np.random.default_rng(seed).choice(pick, limit, replace=False))
    return pick
