"""The projected pseudo-random dot pattern of a structured-light sensor (PrimeSense type).

The projector casts a fixed pattern of laser dots, fixed per device (``pattern_seed``): dot
centres drawn uniformly over the projector image, ``dot_density`` dots per projector pixel,
each a Gaussian spot of std ``dot_sigma_px`` and peak 1. With ``min_spacing_px`` D > 0 no two
centres lie closer than D (random sequential placement, :func:`spaced_dots`): a designed
pattern spreads its dots evenly, while independent (Poisson) dots cluster. That matters on
slanted surfaces: a block matcher returns the disparity where its window's texture is
centred, off the pixel by about 1 / sqrt(12 density) px for Poisson dots (0.9 px at 0.1 per
pixel), 0.55 px with D = 2, and the disparity error there is that offset times the surface's
disparity gradient. The pattern is rendered on a grid
``OVERSAMPLE`` times finer than the projector's pixels, so sampling it at the sub-pixel
positions where scene points project is a smooth bilinear look-up.

Coordinates: projector image coordinates (x, y) in pixels, the pixel (i, j) covering
[j, j + 1) x [i, i + 1) (the camera's convention, :attr:`rangesim.sensor.Sensor.K`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import ndimage

__all__ = ["DotPattern", "OVERSAMPLE", "spaced_coverage", "spaced_dots"]

#: pattern samples per projector pixel along each axis
OVERSAMPLE = 4


@dataclass(frozen=True)
class DotPattern:
    """A rendered dot pattern.

    Attributes
    ----------
    grid : (H * OVERSAMPLE + margin, W * OVERSAMPLE + margin) float32
        Irradiance of the pattern (1 at a dot's centre), on the fine grid.
    width, height : int
        Projector image size, pixels.
    dots : (N, 2) float64
        Dot centres (x, y), projector pixels.
    """

    grid: np.ndarray
    width: int
    height: int
    dots: np.ndarray
    x_min: float = 0.0

    @classmethod
    def generate(cls, width: int, height: int, density: float, dot_sigma_px: float, seed: int,
                 x_min: float = 0.0, min_spacing_px: float = 0.0) -> "DotPattern":
        """Draw and render the pattern over x in [x_min, x_min + width), y in [0, height).

        Deterministic per ``seed`` (and cached: a device's pattern is fixed).

        Examples
        --------
        >>> p = DotPattern.generate(64, 48, 0.1, 0.6, seed=0)
        >>> p.dots.shape[0] == round(0.1 * 64 * 48), float(p.grid.max()) > 0.9
        (True, True)
        >>> from scipy.spatial import cKDTree
        >>> q = DotPattern.generate(64, 48, 0.1, 0.6, seed=0, min_spacing_px=2.0)
        >>> q.dots.shape[0] == p.dots.shape[0], bool(cKDTree(q.dots).query(q.dots, k=2)[0][:, 1].min() >= 2.0)
        (True, True)
        """
        return _generate(int(width), int(height), float(density), float(dot_sigma_px), int(seed), float(x_min),
                         float(min_spacing_px))

    @classmethod
    def _render(cls, width: int, height: int, density: float, dot_sigma_px: float, seed: int,
                x_min: float, min_spacing_px: float = 0.0) -> "DotPattern":
        rng = np.random.default_rng([int(seed), 0xD07])
        n = int(round(density * width * height))
        if min_spacing_px > 0:
            dots = spaced_dots(rng, n, width, height, min_spacing_px)
        else:
            dots = rng.random((n, 2)) * [width, height]
        s = OVERSAMPLE
        grid = np.zeros((height * s, width * s), np.float32)
        # splat each dot bilinearly on the fine grid, then blur to the dot's Gaussian profile
        fx, fy = dots[:, 0] * s - 0.5, dots[:, 1] * s - 0.5
        x0, y0 = np.floor(fx).astype(int), np.floor(fy).astype(int)
        ax, ay = fx - x0, fy - y0
        for dx, dy, w in ((0, 0, (1 - ax) * (1 - ay)), (1, 0, ax * (1 - ay)), (0, 1, (1 - ax) * ay), (1, 1, ax * ay)):
            xi, yi = x0 + dx, y0 + dy
            ok = (xi >= 0) & (xi < grid.shape[1]) & (yi >= 0) & (yi < grid.shape[0])
            np.add.at(grid, (yi[ok], xi[ok]), w[ok])
        sigma = dot_sigma_px * s
        grid = ndimage.gaussian_filter(grid, sigma, mode="constant", truncate=4.0)
        grid *= np.float32(2 * math.pi * sigma * sigma)  # a lone dot peaks at 1
        grid.setflags(write=False)
        return cls(grid=grid, width=int(width), height=int(height), dots=dots + [x_min, 0.0], x_min=float(x_min))

    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Pattern irradiance at projector coordinates (x, y) (pixels); 0 outside the image.

        Parameters
        ----------
        x, y : arrays of one shape
            Projector image coordinates, pixels.

        Returns
        -------
        float32 array of the same shape.
        """
        s = OVERSAMPLE
        coords = np.stack([np.asarray(y, np.float64) * s - 0.5, (np.asarray(x, np.float64) - self.x_min) * s - 0.5])
        flat = coords.reshape(2, -1)
        finite = np.isfinite(flat).all(axis=0)
        out = np.zeros(flat.shape[1], np.float32)
        if finite.any():
            out[finite] = ndimage.map_coordinates(self.grid, flat[:, finite], order=1, mode="constant", cval=0.0)
        return out.reshape(np.shape(x))

    def reference(self, width: int, height: int, disparity_px: float, margin: int = 0) -> np.ndarray:
        """(height, width + 2 margin) float32: the matcher's reference.

        The pattern as a camera sharing the projector's intrinsics sees it on a fronto-parallel
        plane of disparity ``disparity_px`` (f b / z0), over the camera's columns and
        ``margin`` more on either side (a device stores its projector's whole field).
        """
        j, i = np.meshgrid(np.arange(-margin, width + margin) + 0.5, np.arange(height) + 0.5)
        return self.sample(j - disparity_px, i)


#: the largest share of the plane the spaced dots' exclusion disks (diameter D) may cover: random
#: sequential placement jams at about 0.547 (Feder 1980) and slows long before (0.45 failed to
#: place the last dots of a Kinect-sized pattern; 0.40 places them in about 2 s)
MAX_SPACED_COVERAGE = 0.40


def spaced_coverage(density: float, min_spacing_px: float) -> float:
    """Share of the pattern the dots' exclusion disks (diameter ``min_spacing_px``) cover at
    ``density`` dots per pixel."""
    return float(density) * math.pi * float(min_spacing_px) ** 2 / 4


def spaced_dots(rng: np.random.Generator, n: int, width: int, height: int, min_spacing_px: float) -> np.ndarray:
    """(n, 2) dot centres over [0, width) x [0, height), no two closer than ``min_spacing_px``.

    Random sequential placement, in batches: uniform candidates, each dropped when within D of
    a dot kept before or of an earlier candidate of its batch, kept or not (so every kept pair
    is at least D apart; against one-by-one placement at kinect_v1's coverage the pair
    correlation at contact is 1.46 against 1.50), until ``n`` are kept. Refused when the dots'
    disks of diameter D would cover more than :data:`MAX_SPACED_COVERAGE` of the image.
    """
    from scipy.spatial import cKDTree

    from rangesim.core.errors import RangesimError

    d = float(min_spacing_px)
    coverage = spaced_coverage(n / (width * height), d)
    if coverage > MAX_SPACED_COVERAGE:
        raise RangesimError(f"structured_light.dot_min_spacing_px: {n} dots {d:g} px apart cover {coverage:.2f} of "
                            f"the pattern (at most {MAX_SPACED_COVERAGE})")
    kept = np.zeros((0, 2))
    for _ in range(200):
        need = n - len(kept)
        if need <= 0:
            break
        cand = rng.random((2 * need + 64, 2)) * [width, height]
        if len(kept):
            dist, _ = cKDTree(kept).query(cand, distance_upper_bound=d)
            cand = cand[~(dist < d)]
        if len(cand) > 1:  # within the batch: the later of each close pair goes
            pairs = cKDTree(cand).query_pairs(d, output_type="ndarray")
            drop = np.zeros(len(cand), bool)
            drop[pairs.max(axis=1)] = True
            cand = cand[~drop]
        kept = np.concatenate([kept, cand[:need]])
    if len(kept) < n:
        raise RangesimError(f"structured_light.dot_min_spacing_px: only {len(kept)} of {n} dots could be placed "
                            f"{d:g} px apart; lower it or structured_light.dot_density")
    return kept


@lru_cache(maxsize=8)
def _generate(width: int, height: int, density: float, dot_sigma_px: float, seed: int, x_min: float,
              min_spacing_px: float = 0.0) -> DotPattern:
    return DotPattern._render(width, height, density, dot_sigma_px, seed, x_min, min_spacing_px)
