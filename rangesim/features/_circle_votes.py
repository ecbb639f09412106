"""The directional Hough accumulator of the circle finder (the paper's section 5), sparse and
banded: every edge point votes only along its edge normal, both senses, and the radii are cut
into octave bands, each with a 2D centre accumulator whose cells grow with the radius."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangesim.features._circle_kernels import accumulate, block_peaks, block_voters


@dataclass(frozen=True)
class Band:
    """One radius band: radii ``lo..hi`` px, centre cells of ``cell`` px, a padded grid of
    ``rows x cols`` cells whose flat indices start at ``offset``."""

    lo: float
    hi: float
    cell: float
    pad: int
    rows: int
    cols: int
    offset: int


def radius_bands(shape: tuple[int, int], radii: tuple[float, float], cell_px: float,
                 rel_cell: float) -> list[Band]:
    """Octave bands of ``radii`` with cells ``max(cell_px, rel_cell * lo)`` px.

    A cell proportional to the radius keeps the centre's vote cloud (edge-direction error
    times r) about one cell wide in every band, so one threshold fraction serves all radii,
    and the work is about the same per octave.
    """
    H, W = shape
    lo = max(2.0, float(radii[0]))
    hi_all = max(lo + 1.0, float(radii[1]))
    bands, offset = [], 0
    while lo < hi_all:
        hi = min(2 * lo, hi_all)
        if hi_all - hi < 0.25 * hi:  # no sliver band at the top
            hi = hi_all
        cell = max(float(cell_px), rel_cell * lo)
        pad = int(np.ceil(hi / cell)) + 2
        rows, cols = int(np.ceil(H / cell)) + 2 * pad, int(np.ceil(W / cell)) + 2 * pad
        bands.append(Band(lo, hi, cell, pad, rows, cols, offset))
        offset += rows * cols
        lo = hi
    return bands


def n_cells(bands: list[Band]) -> int:
    """Cells of all the bands' accumulators together."""
    return bands[-1].offset + bands[-1].rows * bands[-1].cols


def vote_table(bands: list[Band], angle_tol: float) -> tuple[np.ndarray, ...]:
    """Per-vote constants (one column per (band, radius sample, angle offset)).

    Radius samples every ``cell`` px across the band (a circle's centre falls within half a
    cell of one of them); angle offsets ``k * cell / r`` (the paper's angular step, prop. to
    1 / r: one vote per cell of arc) while ``|k cell / r| <= angle_tol``.

    Returns
    -------
    rc, rs : (M,) float32
        ``r cos a / cell`` and ``r sin a / cell`` of each column (cells).
    band : (M,) int
        Band index of each column.
    r : (M,) float
        Radius sample, px.
    """
    cols = {k: [] for k in ("rc", "rs", "band", "r")}
    for b, bd in enumerate(bands):
        n_r = max(1, int(np.ceil((bd.hi - bd.lo) / bd.cell)))
        r = bd.lo + bd.cell * (np.arange(n_r) + 0.5)
        n_k = np.floor(angle_tol * r / bd.cell).astype(int)
        r_of = np.repeat(r, 2 * n_k + 1)
        a_of = np.concatenate([np.arange(-k, k + 1) for k in n_k]) * bd.cell / r_of
        cols["rc"].append(r_of * np.cos(a_of) / bd.cell)
        cols["rs"].append(r_of * np.sin(a_of) / bd.cell)
        cols["band"].append(np.full(len(r_of), b))
        cols["r"].append(r_of)
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    return cat["rc"].astype(np.float32), cat["rs"].astype(np.float32), cat["band"], cat["r"]


def cast_votes(xy: np.ndarray, theta: np.ndarray, bands: list[Band],
               angle_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The accumulator: votes per cell, all bands back to back.

    Each point votes in both senses along its edge normal at every column of
    :func:`vote_table` (cos/sin of (theta + a) by angle addition, cells by truncation in a
    padded grid, so no bounds tests), in one compiled pass (:func:`._circle_kernels.accumulate`).

    Returns
    -------
    acc : (total cells,) int64
    flat : (N, M, 2) int32
        The cell of every vote (point, column, sense), for :func:`voters`.
    """
    rc, rs, band, _ = vote_table(bands, angle_tol)
    return accumulate(np.ascontiguousarray(xy[:, 0], np.float64), np.ascontiguousarray(xy[:, 1], np.float64),
                      np.cos(theta).astype(np.float64), np.sin(theta).astype(np.float64),
                      rc.astype(np.float64), rs.astype(np.float64), band.astype(np.int64),
                      np.array([1.0 / b.cell for b in bands]), np.array([float(b.pad) for b in bands]),
                      np.array([b.cols for b in bands], np.int64), np.array([b.offset for b in bands], np.int64),
                      n_cells(bands))


def peaks(acc: np.ndarray, bands: list[Band], shape: tuple[int, int],
          threshold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centre candidates: local maxima of 2 x 2 cell sums, per band.

    A centre's votes spread over about one cell, so they lie in some 2 x 2 block, which a
    point's ray crosses with about two radius samples (one per cell); so a block counts when
    its sum reaches ``threshold * 2 * 2 pi lo`` (that fraction of a circle of the band's
    smallest radius: a threshold proportional to r) and no neighbouring block (3 x 3)
    beats it (ties: the first in scan order wins). Sparse: only the blocks around cells
    holding a quarter of that are visited, not the whole grid.

    Returns
    -------
    center : (K, 2) float
        Centre of each block (its shared cell corner), px.
    band : (K,) int
    votes : (K,) int
        Block sums.
    cells : (K, 4) int
        Flat accumulator indices of the block's cells.
    """
    H, W = shape
    as_int = lambda f: np.array([f(bd) for bd in bands], np.int64)  # noqa: E731
    t = as_int(lambda bd: max(4, int(np.ceil(threshold * 4 * np.pi * bd.lo))))
    pad = as_int(lambda bd: bd.pad)
    blk, band, v = block_peaks(acc, as_int(lambda bd: bd.offset), as_int(lambda bd: bd.rows),
                               as_int(lambda bd: bd.cols), pad, pad + as_int(lambda bd: int(np.ceil(H / bd.cell))),
                               pad + as_int(lambda bd: int(np.ceil(W / bd.cell))), t)
    C = np.array([bd.cols for bd in bands])[band]
    cell = np.array([bd.cell for bd in bands])[band]
    local = blk - np.array([bd.offset for bd in bands])[band]
    cx = (local % C + 1 - pad[band]) * cell - 0.5
    cy = (local // C + 1 - pad[band]) * cell - 0.5
    inside = (cx >= -0.5) & (cx <= W - 0.5) & (cy >= -0.5) & (cy <= H - 0.5)
    blk, v, band, C, cx, cy = blk[inside], v[inside], band[inside], C[inside], cx[inside], cy[inside]
    return (np.column_stack([cx, cy]), band, v.astype(int),
            np.column_stack([blk, blk + 1, blk + C, blk + C + 1]))


def voters(flat: np.ndarray, acc: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(candidate, point) pairs: the points that voted into each candidate's block, once each
    (a point's ray may cross its block with two radius samples), in point order."""
    lookup = np.full(len(acc), -1, np.int32)
    lookup[cells.ravel()] = np.repeat(np.arange(len(cells), dtype=np.int32), 4)
    return block_voters(flat, lookup, len(cells), int(acc[cells.ravel()].sum()))
