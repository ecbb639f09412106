"""Pictures of volumetric models: a part tree with each node's solid, and generalized
cylinders (surface, axis, cross-sections), including the recursion stages of figure 18.
Matplotlib's object API (``Figure`` + ``FigureCanvasAgg``), written atomically."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import trimesh
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from rangesim.io.atomic import atomic_path

_LIGHT = np.array([0.4, -0.5, 0.77])
_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"]


def decimate(mesh: trimesh.Trimesh, cells: int = 40) -> trimesh.Trimesh:
    """Vertex clustering on a ``cells``-per-longest-side grid (for small renders only)."""
    v = np.asarray(mesh.vertices)
    lo, size = v.min(0), max(float(np.ptp(v, 0).max()), 1e-12)
    key = np.floor((v - lo) / size * cells).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    sums = np.zeros((len(first), 3))
    np.add.at(sums, inv, v)
    verts = sums / np.bincount(inv)[:, None]
    f = inv[mesh.faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    return trimesh.Trimesh(verts, np.unique(f, axis=0), process=False)


def _draw_mesh(ax, mesh: trimesh.Trimesh, colour: str = "#8fa8c8", alpha: float = 1.0,
               max_faces: int = 4000) -> None:
    if len(mesh.faces) > max_faces:
        cells = 40
        small = decimate(mesh, cells)
        while len(small.faces) > max_faces and cells > 8:
            cells = int(cells * 0.75)
            small = decimate(mesh, cells)
        mesh = small
    tris = mesh.vertices[mesh.faces]
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    shade = 0.35 + 0.65 * np.clip(n @ (_LIGHT / np.linalg.norm(_LIGHT)), 0, 1)
    from matplotlib.colors import to_rgb

    rgb = np.clip(np.array(to_rgb(colour))[None] * shade[:, None], 0, 1)
    ax.add_collection3d(Poly3DCollection(tris, facecolors=np.column_stack([rgb, np.full(len(rgb), alpha)]),
                                         edgecolors="none", linewidths=0))


def _frame(ax, points: np.ndarray, elev: float = 25, azim: float = -60) -> None:
    lo, hi = points.min(0), points.max(0)
    c, r = (lo + hi) / 2, max(float((hi - lo).max()) * 0.36, 1e-9)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


def cutter_ids(tree) -> set[int]:
    """``id`` of every node a difference takes away: each child of a difference after the
    first, and all below it (drawn red, as the legend says, whatever its function: a step or
    a slot cuts as a hole does)."""
    cutters: set[int] = set()
    for node in tree.walk():  # parents before their children
        if id(node) in cutters:
            cutters.update(id(c) for c in node.children)
        elif node.operation == "difference":
            cutters.update(id(c) for c in node.children[1:])
    return cutters


def save_part_tree(tree, path: str | Path, cell_in: float = 1.25, dpi: int = 130) -> Path:
    """Draw a part tree (:class:`~rangesim.cad.part.PartNode`): each node's solid in a tree layout.

    Leaves spread left to right in tree order; an inner node sits above the middle of its
    children; each cell shows the node's name, operation and volume (mm^3).
    """
    from rangesim.cad.part import evaluate, manifold_to_trimesh

    evaluate(tree)
    pos: dict[int, tuple[float, int]] = {}
    counter = [0]

    def layout(node, depth):
        if not node.children:
            pos[id(node)] = (counter[0], depth)
            counter[0] += 1
        else:
            for c in node.children:
                layout(c, depth + 1)
            pos[id(node)] = (float(np.mean([pos[id(c)][0] for c in node.children])), depth)

    layout(tree, 0)
    n_cols = counter[0]
    n_rows = 1 + max(d for _, d in pos.values())
    fig_w, fig_h = n_cols * cell_in, n_rows * cell_in * 1.7 + 0.4
    fig = Figure(figsize=(fig_w, fig_h), dpi=dpi)
    FigureCanvasAgg(fig)
    back = fig.add_axes((0, 0, 1, 1))
    back.set_xlim(0, fig_w)
    back.set_ylim(0, fig_h)
    back.set_axis_off()

    def centre(node):
        x, d = pos[id(node)]
        return (x + 0.5) * cell_in, fig_h - 0.4 - (d + 0.5) * cell_in * 1.7

    symbol = {"union": "∪", "difference": "−", "solid": ""}
    cutters = cutter_ids(tree)
    for node in tree.walk():
        cx, cy = centre(node)
        for c in node.children:
            ccx, ccy = centre(c)
            back.plot([cx, ccx], [cy - 0.82 * cell_in, ccy + 0.66 * cell_in], color="0.6", lw=0.8, zorder=0)
        w = 0.9 * cell_in
        ax = fig.add_axes(((cx - w / 2) / fig_w, (cy - w / 2 - 0.08 * cell_in) / fig_h, w / fig_w, w / fig_h),
                          projection="3d")
        mesh = manifold_to_trimesh(node.solid)
        colour = "#c86464" if id(node) in cutters else "#6f8fbf"
        _draw_mesh(ax, mesh, colour, max_faces=2500)
        _frame(ax, mesh.vertices)
        op = f" ({symbol[node.operation]})" if node.operation != "solid" else ""
        vol = node.properties.get("volume", 0.0)
        # figure texts draw over every axes: a tall solid's panel no longer covers its caption
        fig.text(cx / fig_w, (cy + 0.5 * cell_in) / fig_h, f"{node.name}{op}", ha="center", va="bottom",
                 fontsize=8, fontweight="bold" if node.operation != "solid" else "normal")
        fig.text(cx / fig_w, (cy - 0.52 * cell_in) / fig_h, f"{node.function}\n{vol:,.0f} mm\u00b3", ha="center",
                 va="top", fontsize=7.5, color="0.25")
    back.text(0.1, fig_h - 0.1, f"Part tree of {tree.name}: − difference (first child minus the others), "
              "∪ union; blue: material, red: cutters", fontsize=8.5, va="top")
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


def draw_gcs(ax, gcs: Sequence, surface: trimesh.Trimesh | None = None, alpha: float = 0.18,
             colours: Sequence[str] = _COLOURS) -> None:
    """Draw generalized cylinders on a 3D axes: axis polylines, cross-section loops, faint surface."""
    if surface is not None:
        _draw_mesh(ax, surface, "#a0a0a0", alpha=alpha, max_faces=3000)
    for k, gc in enumerate(gcs):
        col = colours[k % len(colours)]
        loops = [np.vstack([s.points, s.points[:1]]) for s in gc.sections]
        segs = [np.stack([lp[:-1], lp[1:]], axis=1) for lp in loops]
        ax.add_collection3d(Line3DCollection(np.concatenate(segs), colors=col, linewidths=0.9))
        ax.plot(*gc.axis.T, color="k", lw=1.8, marker="o", ms=2.0)


def save_gc_figure(panels: Sequence[tuple[str, Sequence, trimesh.Trimesh | None]], path: str | Path,
                   elev: float = 25, azim: float = -60, panel_in: float = 3.6, dpi: int = 100) -> Path:
    """One 3D panel per (title, generalized cylinders, surface[, (elev, azim)]) in a row; atomic write."""
    fig = Figure(figsize=(panel_in * len(panels), panel_in + 0.3), dpi=dpi)
    FigureCanvasAgg(fig)
    for k, (title, gcs, surface, *view) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        draw_gcs(ax, gcs, surface)
        pts = np.vstack([surface.vertices] if surface is not None else [g.axis for g in gcs])
        _frame(ax, pts, *(view[0] if view else (elev, azim)))
        ax.set_title(title, fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


def save_gc_recursions(mesh: trimesh.Trimesh, path: str | Path, resolution: float,
                       recursions: Sequence[int] = (1, 3, 5), **kwargs) -> Path:
    """The paper's figure 18: the generalized cylinder after 1, 3 and 5 recursions."""
    from rangesim.volumes.gc import generalized_cylinders

    panels = []
    for r in recursions:
        gcs = generalized_cylinders(mesh, resolution, max_recursions=r, **kwargs)
        n = sum(len(g.sections) for g in gcs)
        panels.append((f"after {r} recursion{'s' if r > 1 else ''}: {n} sections", gcs, mesh))
    return save_gc_figure(panels, path)
