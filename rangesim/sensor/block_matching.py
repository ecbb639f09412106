"""Block matching of an IR image against the reference pattern, along the rows.

For every camera pixel (i, j) and integer disparity d in [d_min, d_max] the score is the
zero-mean normalised cross-correlation (ZNCC) of the ``window`` x ``window`` block of the
image around (i, j) with the block of the reference around (i, j - d); box sums come from
integral images, so each disparity costs one product and one box sum over the image.

* best integer disparity: the highest score;
* sub-pixel: the vertex of the parabola through the logarithms of the scores at d - 1, d,
  d + 1 (:func:`subpixel_offset`: a Gaussian peak, as the dots' autocorrelation is), quantised
  to steps of 1 / ``subpixel_steps`` (PrimeSense reports 1/8 px);
* rejected (NaN) where the best score is below ``min_score`` (no texture, shadow, too dark),
  where it is ambiguous (the best score outside d +- 1 is nearly as good:
  (1 - second) <= (1 + uniqueness) (1 - best)), where the block leaves the image, and, with
  ``lr_check``, where matching the reference pixel back into the image does not return to
  within 1 px of the pixel (occlusions).

A window straddling a depth edge is dominated by whichever side has more texture; where the
foreground wins, the edge moves outwards by up to half the window (the "fattening" of block
matching; 0.2-1.5 px measured at a box's outline over a plane with ``kinect_v1``).
"""
from __future__ import annotations

import numpy as np

__all__ = ["block_match", "box_sum", "subpixel_offset"]


def box_sum(a: np.ndarray, r: int) -> np.ndarray:
    """Sum of ``a`` over the (2r + 1)^2 block around every pixel; NaN where the block leaves the image.

    Examples
    --------
    >>> float(box_sum(np.ones((5, 5)), 1)[2, 2]), bool(np.isnan(box_sum(np.ones((5, 5)), 1)[0, 0]))
    (9.0, True)
    """
    h, w = a.shape
    c = np.zeros((h + 1, w + 1))
    np.cumsum(np.cumsum(a, axis=0, dtype=np.float64), axis=1, out=c[1:, 1:])
    k = 2 * r + 1
    out = np.full((h, w), np.nan)
    out[r:h - r, r:w - r] = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    return out


def subpixel_offset(below: np.ndarray, best: np.ndarray, above: np.ndarray) -> np.ndarray:
    """Sub-pixel offset of a correlation peak from its best integer shift, px, in [-0.5, 0.5].

    The vertex of the parabola through the logarithms of the three scores (a Gaussian fit):
    the pattern's dots are Gaussian spots, so near the peak the ZNCC of a block falls with
    the shift as the pattern's autocorrelation, a Gaussian, whose logarithm is a parabola.
    A parabola through the scores themselves is biased towards whole pixels (pixel locking:
    +-0.05 px on a plane at 40 degrees, the 1/8 px levels filled 0.07-0.18 where a recorded
    Kinect frame fills them evenly); this fit leaves +-0.01 px with independent dots. Dots kept
    apart (``dot_min_spacing_px``) narrow the peak's flanks below the Gaussian: +-0.04 px at
    2 px spacing. Where a score is not positive, the plain parabola.

    Parameters
    ----------
    below, best, above : (H, W) float
        Scores at the best integer shift d - 1, d and d + 1 (``best`` the largest).

    Returns
    -------
    (H, W) float, 0 where the three scores give no peak.

    Examples
    --------
    >>> g = lambda x: np.exp(-0.5 * ((x - 0.3) / 1.2) ** 2)  # a Gaussian peak at +0.3
    >>> round(float(subpixel_offset(np.array(g(-1.0)), np.array(g(0.0)), np.array(g(1.0)))), 6)
    0.3
    """
    below, best, above = (np.asarray(v, np.float64) for v in (below, best, above))
    positive = (below > 0) & (best > 0) & (above > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        lb, lc, la = (np.log(np.where(positive, v, 1.0)) for v in (below, best, above))
        a, b, c = (np.where(positive, lv, v) for lv, v in ((lb, below), (lc, best), (la, above)))
        curv = a - 2 * b + c
        delta = np.where(np.isfinite(curv) & (curv < 0), 0.5 * (a - c) / curv, 0.0)
    return np.clip(np.nan_to_num(delta), -0.5, 0.5)


def _shift(a: np.ndarray, d: int, fill: float = np.nan) -> np.ndarray:
    """b[:, j] = a[:, j - d] for either sign of d (``fill`` where j - d leaves the image)."""
    out = np.full_like(a, fill)
    w = a.shape[1]
    if 0 <= d < w:
        out[:, d:] = a[:, : w - d]
    elif -w < d < 0:
        out[:, : w + d] = a[:, -d:]
    return out


def _columns(a: np.ndarray, start: int, width: int, fill: float) -> np.ndarray:
    """a[:, start:start + width], with ``fill`` where that leaves ``a``."""
    out = np.full((a.shape[0], width), fill, dtype=a.dtype)
    lo, hi = max(start, 0), min(start + width, a.shape[1])
    if hi > lo:
        out[:, lo - start:hi - start] = a[:, lo:hi]
    return out


def block_match(image: np.ndarray, reference: np.ndarray, d_min: int, d_max: int, *, window: int = 9,
                subpixel_steps: int = 8, min_score: float = 0.5, uniqueness: float = 0.1,
                lr_check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Disparity of every pixel of ``image`` against ``reference`` (see the module docstring).

    Parameters
    ----------
    image : (H, W) array
        The camera's IR image.
    reference : (H, W + 2 m) array
        The reference pattern on the same rows, with m extra columns on either side (m >= 0):
        ``reference[:, m + j]`` is column j of the image grid. ``image[:, j]`` is compared
        with column j - d of the grid.
    d_min, d_max : int
        Disparity search range, pixels (either sign).
    window : int
        Odd block size, pixels.
    subpixel_steps : int
        Disparities are quantised to 1 / subpixel_steps pixel.
    min_score, uniqueness : float
        Acceptance thresholds.
    lr_check : bool
        Left-right consistency check.

    Returns
    -------
    disparity : (H, W) float64, NaN where rejected
    score : (H, W) float32, the best ZNCC (NaN outside the image's valid blocks)

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> ref = rng.random((40, 80))
    >>> img = np.roll(ref, 7, axis=1)
    >>> d, _ = block_match(img, ref, 2, 12, window=7)
    >>> float(np.nanmedian(d))
    7.0
    """
    img = np.asarray(image, np.float64)
    ref = np.asarray(reference, np.float64)
    h, w = img.shape
    r = window // 2
    n = float(window * window)
    d_min, d_max = int(d_min), max(int(d_max), int(d_min) + 2)
    sum_i, sum_ii = box_sum(img, r), box_sum(img * img, r)
    var_i = sum_ii - sum_i * sum_i / n
    margin = (ref.shape[1] - w) // 2
    if ref.shape[0] != h or margin < 0 or ref.shape[1] != w + 2 * margin:
        raise ValueError(f"reference {ref.shape} must have the image's rows and W + 2 m columns (image {img.shape})")
    sum_r, sum_rr = box_sum(ref, r), box_sum(ref * ref, r)
    var_r = sum_rr - sum_r * sum_r / n
    # box sums of the wide reference are valid up to its own borders, not the image's
    sum_r[:, :r] = sum_r[:, -r:] = np.nan
    disparities = np.arange(d_min - 1, d_max + 2)  # one beyond each end for the parabola
    volume = np.full((disparities.size, h, w), -np.inf, np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, d in enumerate(disparities):
            start = margin - int(d)
            cross = box_sum(img * _columns(ref, start, w, 0.0), r)
            cov = cross - sum_i * _columns(sum_r, start, w, np.nan) / n
            score = cov / np.sqrt(var_i * _columns(var_r, start, w, np.nan))
            volume[k] = np.where(np.isfinite(score), score, -np.inf)
    # best candidate d_min..d_max, by a running maximum (cheaper than argmax over axis 0)
    best = volume[1].copy()
    best_k = np.ones((h, w), np.int64)
    for k in range(2, disparities.size - 1):
        better = volume[k] > best
        best[better] = volume[k][better]
        best_k[better] = k
    rows, cols = np.indices((h, w))
    below, above = volume[best_k - 1, rows, cols], volume[best_k + 1, rows, cols]
    # the second best outside best +- 1
    second = np.full((h, w), -np.inf, np.float32)
    for k in range(1, disparities.size - 1):
        far_off = np.abs(k - best_k) > 1
        np.maximum(second, np.where(far_off, volume[k], -np.inf), out=second)
    delta = subpixel_offset(below, best, above)
    sub = disparities[best_k] + np.round(delta * subpixel_steps) / subpixel_steps
    ok = np.isfinite(best) & (best >= min_score)
    ok &= ~np.isfinite(second) | ((1 - second) > (1 + uniqueness) * (1 - best))
    if lr_check:
        # the reference pixel (i, j - d) matched back: the best d' over image pixels (i, j - d + d')
        back_best = np.full((h, w), -np.inf, np.float32)
        back_d = np.zeros((h, w), np.int64)
        for k in range(1, disparities.size - 1):
            d = int(disparities[k])
            back = _shift(volume[k], -d, -np.inf)  # back[:, j_ref] = score of image pixel j_ref + d
            better = back > back_best
            back_best[better] = back[better]
            back_d[better] = d
        j_ref = cols - disparities[best_k]
        # a reference column outside the image grid has no image block to come back from: not checked
        inside = (j_ref >= r) & (j_ref < w - r)
        again = back_d[rows, np.clip(j_ref, 0, w - 1)]
        ok &= ~inside | (np.abs(again - disparities[best_k]) <= 1)
    disparity = np.where(ok, sub, np.nan)
    return disparity, np.where(np.isfinite(best), best, np.nan).astype(np.float32)
