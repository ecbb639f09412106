"""The block-plane bends of :func:`rangesim.edges.normal` on noisy scans: block sizes,
noise, threshold floor and the crease test (the compiled fits: :mod:`rangesim.edges._normal_planes`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.edges._noise import scan_sigma
from rangesim.edges._normal_planes import block_pair_bends, block_planes, noise_gain

__all__ = ["block_bends", "BlockBends", "BLOCK_SIZES", "BLOCK_FLOOR_DEG", "BLOCK_K", "BLOCK_FILL", "BLOCK_STOP"]

#: block sides tried, pixels, smallest first (a block is as small as its noise allows)
BLOCK_SIZES = (3, 5, 7, 9)
#: noise multiple of the pair threshold ``k sqrt(v_A + v_B)``: for two fits of one plane
#: ``P(angle > k sqrt(v_A + v_B)) = exp(-k^2)``, 1e-7 per pair at 4
BLOCK_K = 4.0
#: least bend, degrees, on noisy scans. The ground truth's creases are 20 degrees and more,
#: but a smooth surface of curvature kappa bends a pair of blocks r px either side by about
#: ``2 r kappa`` footprints: the 5-9 px blocks a noisy scan needs see hole walls and
#: cylinders as 20-35 degree bends. Chosen on the machined parts' tuning seeds (0-7, the
#: laser presets; 20-29, inria_laser): floors 20 / 25 / 30 / 35 / 40 gave inria_laser F1 with
#: noise 0.863 / 0.879 / 0.883 / 0.889 / - (0-7) and 0.855 / - / 0.863 / 0.868 / 0.868 (20-29),
#: white_scanner 0.91 / 0.93 / 0.94 / 0.94, cyberware_3030 0.86 / 0.89 / 0.90 / 0.91 (0-7)
BLOCK_FLOOR_DEG = 35.0
#: least share of a block's pixels that must be measured for a fit
BLOCK_FILL = 0.6
#: a larger block is fitted only while more than this share of the blocks is too noisy
#: for the floor (the few left get a raised threshold)
BLOCK_STOP = 0.02


@dataclass
class BlockBends:
    """What :func:`block_bends` found; see :func:`~rangesim.edges._normal_planes.block_pair_bends`."""

    chord: np.ndarray
    strength: np.ndarray
    ratio: np.ndarray
    concave: np.ndarray
    sizes: tuple[int, ...]
    gains: tuple[float, ...]
    floor_deg: float


def block_bends(scan: Any, valid: np.ndarray, xyz: np.ndarray, disc: Any,
                threshold_deg: float | None = None) -> BlockBends:
    """Plane fits on blocks of every size needed, and the bend between the blocks either
    side of each pixel, tested against the predicted noise of the fitted normals.

    The predicted depth variance of each point is ``scan.sigma ** 2`` (0 where the scan
    carries none; on quantised depth with the rounding's ``q^2 / 12``, :func:`~rangesim.edges._noise.scan_sigma`); each size's variances are multiplied by the scan's measured
    :func:`~rangesim.edges._normal_planes.noise_gain` (correlated noise). A block cut by a
    depth jump or a gap is fitted on its centre's own side only (issue 14: inria_laser
    tuning seeds 20-29 F1 0.868 -> 0.872, cyberware_3030 0-7 0.904 -> 0.908, white_scanner
    0.944 -> 0.943). Sizes :data:`BLOCK_SIZES` are fitted in turn
    until at most :data:`BLOCK_STOP` of the fitted blocks is noisier than the floor.
    """
    floor_deg = BLOCK_FLOOR_DEG if threshold_deg is None else float(threshold_deg)
    floor = np.radians(floor_deg)
    sigma = scan_sigma(scan, quantum=disc.quantum)  # with the rounding of quantised depth, where the data show it
    h, w = valid.shape
    if sigma is None:
        s2 = np.zeros((h, w), np.float32)
    else:
        s = np.asarray(sigma, np.float32)
        s2 = np.where(np.isfinite(s), s * s, 0).astype(np.float32)
    bad = np.ascontiguousarray((disc.touching | disc.occluding | disc.occluded) & valid)
    xyz = np.ascontiguousarray(xyz, np.float32)
    use = np.ascontiguousarray(valid)
    ns = len(BLOCK_SIZES)
    normals = np.empty((ns, 3, h, w), np.float32)
    variances = np.empty((ns, h, w), np.float32)
    centroids = np.empty((ns, 3, h, w), np.float32)
    gains = []
    used = 0
    for si, b in enumerate(BLOCK_SIZES):
        block_planes(xyz, use, bad, s2, b, BLOCK_FILL, normals[si], variances[si], centroids[si])
        used = si + 1
        gain = noise_gain(normals[si], variances[si], b // 2)
        gains.append(gain)
        variances[si] *= np.float32(gain)
        sub = variances[si, ::2, ::2]
        with np.errstate(invalid="ignore"):
            loud = np.count_nonzero(BLOCK_K * np.sqrt(2 * sub) > floor)
        if loud <= BLOCK_STOP * np.count_nonzero(sub >= 0):
            break
    halves = np.array([b // 2 for b in BLOCK_SIZES[:used]], np.int64)
    chord, strength, ratio, concave = block_pair_bends(
        normals[:used], variances[:used], centroids[:used], halves, np.full(used, floor), BLOCK_K)
    return BlockBends(chord, strength, ratio, concave, tuple(BLOCK_SIZES[:used]), tuple(gains), floor_deg)
