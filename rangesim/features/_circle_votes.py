"""The directional Hough accumulator of the circle finder (the paper's section 5), sparse and
banded: every edge point votes only along its edge normal, both senses, and the radii are cut
into octave bands, each with a 2D centre accumulator whose cells grow with the radius."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    inv_cell, pad, cols, offset : (M,) float32 / int32
        The column's band constants.
    band : (M,) int
        Band index of each column.
    r : (M,) float
        Radius sample, px.
    """
    cols = {k: [] for k in ("rc", "rs", "inv", "pad", "cols", "off", "band", "r")}
    for b, bd in enumerate(bands):
        n_r = max(1, int(np.ceil((bd.hi - bd.lo) / bd.cell)))
        r = bd.lo + bd.cell * (np.arange(n_r) + 0.5)
        n_k = np.floor(angle_tol * r / bd.cell).astype(int)
        r_of = np.repeat(r, 2 * n_k + 1)
        a_of = np.concatenate([np.arange(-k, k + 1) for k in n_k]) * bd.cell / r_of
        m = len(r_of)
        cols["rc"].append(r_of * np.cos(a_of) / bd.cell)
        cols["rs"].append(r_of * np.sin(a_of) / bd.cell)
        cols["inv"].append(np.full(m, 1.0 / bd.cell))
        cols["pad"].append(np.full(m, bd.pad))
        cols["cols"].append(np.full(m, bd.cols))
        cols["off"].append(np.full(m, bd.offset))
        cols["band"].append(np.full(m, b))
        cols["r"].append(r_of)
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    return (cat["rc"].astype(np.float32), cat["rs"].astype(np.float32), cat["inv"].astype(np.float32),
            cat["pad"].astype(np.float32), cat["cols"].astype(np.int32), cat["off"].astype(np.int32),
            cat["band"], cat["r"])


def cast_votes(xy: np.ndarray, theta: np.ndarray, bands: list[Band],
               angle_tol: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Flat accumulator index of every vote, and the accumulator.

    Returns
    -------
    flat : (2, M, N) int32
        Cell of each vote (sense, column, point).
    acc : (total cells,) int64
        Votes per cell, all bands back to back.
    m : int
        Columns per point and sense.
    """
    rc, rs, _, _, _, _, band, _ = vote_table(bands, angle_tol)
    total = n_cells(bands)
    n, m = len(xy), len(rc)
    # per band (scalar cell and padding), float32, laid out (column, point) so that the inner
    # loops run over the points; cos/sin of (theta + a) by angle addition from per-point and
    # per-column tables (no trig over the grid); the minus sense as 2 u - (u + d); cells by
    # truncation in a padded grid (no bounds masks); then one np.bincount over all the bands
    ct, st = np.cos(theta).astype(np.float32), np.sin(theta).astype(np.float32)
    x = xy[:, 0].astype(np.float32) + np.float32(0.5)
    y = xy[:, 1].astype(np.float32) + np.float32(0.5)
    flat = np.empty((2, m, n), np.int32)
    for b, bd in enumerate(bands):
        cols = np.nonzero(band == b)[0]
        sl = slice(cols[0], cols[-1] + 1)
        inv, pad = np.float32(1 / bd.cell), np.float32(bd.pad)
        u, v = x * inv + pad, y * inv + pad
        rcb, rsb = rc[sl, None], rs[sl, None]
        if np.any(rsb):
            dx, dy = rcb * ct - rsb * st, rcb * st + rsb * ct
        else:  # no angle offsets in this band: votes on the normal only
            dx, dy = rcb * ct, rcb * st
        dx += u
        dy += v
        for s, (fu, fv) in enumerate(((dx, dy), (2 * u - dx, 2 * v - dy))):
            iv = fv.astype(np.int32)
            iv *= bd.cols
            iv += fu.astype(np.int32)
            iv += bd.offset
            flat[s, sl] = iv
    acc = np.bincount(flat.ravel(), minlength=total)
    return flat, acc, m


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
    blks, ts, bs = [], [], []
    for b, bd in enumerate(bands):
        a = acc[bd.offset:bd.offset + bd.rows * bd.cols]
        C = bd.cols
        t = max(4, int(np.ceil(threshold * 4 * np.pi * bd.lo)))
        hot = np.nonzero(a >= (t + 3) // 4)[0]
        if len(hot) == 0:
            continue
        # the 4 blocks (by top-left cell) holding each hot cell, whose corner lies in the
        # image (the padding leaves room for the neighbour tests)
        mark = np.zeros(len(a), bool)
        for o in (0, 1, C, C + 1):
            mark[hot - o] = True
        y1, x1 = bd.pad + int(np.ceil(H / bd.cell)), bd.pad + int(np.ceil(W / bd.cell))
        mark = mark.reshape(bd.rows, C)[bd.pad - 1:y1, bd.pad - 1:x1]
        yy, xx = np.nonzero(mark)
        blks.append(bd.offset + (yy + bd.pad - 1) * C + xx + bd.pad - 1)
        ts.append(np.full(len(yy), t))
        bs.append(np.full(len(yy), b))
    if not blks:
        return np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4), int)
    # all bands at once from here: flat indices into acc, each with its band's row length
    blk, t, band = np.concatenate(blks), np.concatenate(ts), np.concatenate(bs)
    C = np.array([bd.cols for bd in bands])[band]
    v = _box(acc, blk, C)
    keep = v >= t
    blk, v, band, C = blk[keep], v[keep], band[keep], C[keep]
    ok = np.ones(len(blk), bool)
    for oy in (-1, 0, 1):
        for ox in (-1, 0, 1):
            if oy or ox:
                nb = _box(acc, blk + oy * C + ox, C)
                ok &= (v > nb) if (oy, ox) < (0, 0) else (v >= nb)
    blk, v, band, C = blk[ok], v[ok], band[ok], C[ok]
    cell = np.array([bd.cell for bd in bands])[band]
    pad = np.array([bd.pad for bd in bands])[band]
    local = blk - np.array([bd.offset for bd in bands])[band]
    cx = (local % C + 1 - pad) * cell - 0.5
    cy = (local // C + 1 - pad) * cell - 0.5
    inside = (cx >= -0.5) & (cx <= W - 0.5) & (cy >= -0.5) & (cy <= H - 0.5)
    blk, v, band, C, cx, cy = blk[inside], v[inside], band[inside], C[inside], cx[inside], cy[inside]
    return (np.column_stack([cx, cy]), band, v.astype(int),
            np.column_stack([blk, blk + 1, blk + C, blk + C + 1]))


def _box(a: np.ndarray, f: np.ndarray, cols: int | np.ndarray) -> np.ndarray:
    """Sums of the 2 x 2 blocks whose top-left cells are ``f`` (flat indices, ``cols`` wide)."""
    return a[f] + a[f + 1] + a[f + cols] + a[f + cols + 1]


def voters(flat: np.ndarray, cells: np.ndarray, n_cells: int, n_points: int,
           m: int) -> tuple[np.ndarray, np.ndarray]:
    """(candidate, point) pairs: the points that voted into each candidate's block, once each."""
    lookup = np.full(n_cells, -1, np.int32)
    lookup[cells.ravel()] = np.repeat(np.arange(len(cells), dtype=np.int32), 4)
    lab = lookup[flat.ravel()]
    vid = np.nonzero(lab >= 0)[0]
    # once each: a point's ray may cross its block with two radius samples
    key = np.unique(lab[vid].astype(np.int64) * n_points + vid % n_points)
    return key // n_points, key % n_points
