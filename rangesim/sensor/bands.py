"""Scans too large for memory in one piece, made in bands of image rows.

A geometric scan needs about ``BYTES_PER_PIXEL["geometric"]`` bytes per pixel while it runs
(Dr.Jit's buffers of rays, hits, shadow rays and noise terms, and their NumPy copies), but
its result only :data:`RESULT_BYTES_PER_PIXEL`. When the whole image does not fit the
memory budget (:func:`rangesim.core.memory.memory_budget`), :func:`band_rows` plans bands
of rows whose working set fits next to the result, and :func:`scan_in_bands` scans them one
after the other into the full arrays.

Every per-pixel step is exact across bands: a pixel's ray, its laser shadow ray, its white
noise draws (a PCG32 stream per image pixel) and any correlated noise field (made once over
the whole image) are the ones it gets in the whole image; the mixed-pixel window runs along
rows, and so does the truncated stripe's distance to an outline or shadow border
(:func:`rangesim.sensor.stripe_noise.border_distance`). One step looks at neighbouring rows,
the shared-edge guard (one row), so each band is scanned with :data:`MARGIN_ROWS` extra rows on
either side and cut back. A scan in bands therefore equals the scan in one piece.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from rangesim.core.rangescan import OPTIONAL_PIXEL_FIELDS, PIXEL_FIELDS, RangeScan
from rangesim.sensor.config import Sensor

#: extra rows scanned on each side of a band (see the module docstring): the shared-edge guard's
#: one row and one to spare (64 while the truncated stripe's border distance looked across rows)
MARGIN_ROWS = 2
#: bytes per pixel of a finished RangeScan with ``xyz_true`` and ``sigma`` (58), rounded up
RESULT_BYTES_PER_PIXEL = 64
#: a band narrower than this is not worth scanning: refuse instead
MIN_BAND_ROWS = 16


def band_rows(sensor: Sensor, budget: float, base_bytes: float, bytes_per_pixel: float) -> int | None:
    """Rows per band that fit ``budget`` bytes, or None when no band of ``MIN_BAND_ROWS`` rows fits.

    Parameters
    ----------
    sensor : Sensor
        A geometric-mode sensor (its image size and noise correlation).
    budget : float
        Bytes the scan may use.
    base_bytes, bytes_per_pixel : float
        Fixed cost of a scan and its working memory per pixel.

    Examples
    --------
    >>> import rangesim as rs
    >>> s = rs.load_sensor("white_scanner").with_params({"camera.width": 1000, "camera.height": 1000})
    >>> band_rows(s, 300e6 + 64e6 + 104 * 1000 * 500, 300e6, 500)   # 100 rows and a margin of 2 on each side
    100
    """
    w, h = sensor.width, sensor.height
    result = float(w) * h * (RESULT_BYTES_PER_PIXEL + (4 if sensor.params["noise"].get("correlation_mm") else 0))
    free = budget - base_bytes - result
    rows = int(math.floor(free / (bytes_per_pixel * w))) - 2 * MARGIN_ROWS
    return rows if rows >= MIN_BAND_ROWS else None


def scan_in_bands(scene, sensor: Sensor, pose: np.ndarray, seed: int, rows_per_band: int) -> RangeScan:
    """A geometric scan made in bands of ``rows_per_band`` image rows (see the module docstring).

    ``meta["bands"]`` gives the number of bands (kept out of scan files: it depends on the
    memory free at the time, the scan does not).
    """
    from rangesim.sensor.geometric import scan_geometric

    h, w = sensor.height, sensor.width
    out: dict[str, np.ndarray] = {}
    fields: dict = {}
    meta: dict = {}
    recast = 0
    starts = range(0, h, rows_per_band)
    for first in starts:
        stop = min(h, first + rows_per_band)
        lo, hi = max(0, first - MARGIN_ROWS), min(h, stop + MARGIN_ROWS)
        band = scan_geometric(scene, sensor, pose, seed, rows=(lo, hi), fields=fields)
        for name, _, _ in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
            value = getattr(band, name)
            if value is None:
                continue
            if name not in out:
                out[name] = np.empty((h, w) + tuple(value.shape[2:]), dtype=value.dtype)
            out[name][first:stop] = value[first - lo:stop - lo]
        recast += int(band.meta.get("recast_rays", 0))
        meta = band.meta
        del band
    meta = dict(meta, recast_rays=recast, bands=len(starts))
    # Dr.Jit keeps freed buffers for reuse: a band's worth of GBs the caller (writing the
    # result, say) needs now
    dr.flush_malloc_cache()
    return RangeScan(pose=np.asarray(pose, np.float64), meta=meta, **out)
