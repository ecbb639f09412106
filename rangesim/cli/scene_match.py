"""Does ``--scene`` belong to the scan it scores? A check before any score is computed.

A synthetic scan carries its own noise-free hits (``xyz_true``), its pose and its pinhole
intrinsics. The scene given with ``--scene`` is ray-cast from that pose through those pixels
(the scanner's own primary ray cast, :func:`rangesim.sensor.rays.cast_primary`) and must hit a
surface at the scan's true depth on most pixels where the scan hit one; else the ground truth
drawn from it describes another object and every score against it is meaningless.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError

#: the least share of the scan's true-hit pixels the scene must hit at the same depth. The
#: scene that made the scan hits all of them (the same rays; only the shared-edge re-casts and
#: float32 rounding differ, a handful of pixels); another part, another placement or other units
#: hit at most a fraction (plate.exr against the Green Piece: well under half)
MIN_SCENE_MATCH = 0.9
#: depth agreement for a pixel to count as matched: this many mm plus this share of the depth
#: (float32 hits at a few hundred mm agree to ~1e-4 mm; a wrong scene misses by mm to metres)
MATCH_TOL_MM, MATCH_TOL_REL = 0.5, 0.005


#: objects imaged on fewer pixels than this are not checked on their own (their share is noise)
MIN_PART_PIXELS = 50


def scene_match_share(scan, scene) -> float:
    """Share of the scan's true-hit pixels that ``scene``, cast from the scan's view, hits at the same
    depth: the least over the scan's objects (``scan.part``) imaged on at least
    :data:`MIN_PART_PIXELS` pixels, so that a table filling most of the view cannot vouch for a
    part moved or turned (a box turned 30 degrees passed at 92 % over all pixels)."""
    from rangesim.sensor.rays import cast_primary

    truth = np.asarray(scan.xyz_true, dtype=np.float64)
    has = np.isfinite(truth).all(axis=2)
    if not has.any():
        return 1.0  # nothing to compare: an empty scan scores nothing anyway
    h, w = scan.shape
    depth = truth[..., 2]
    maxt = 4.0 * float(np.linalg.norm(truth[has], axis=1).max()) + 1.0
    watertight = np.array([o.watertight for o in scene.objects])
    hits = cast_primary(scene.mitsuba_scene(), scan.K, h, w, np.asarray(scan.pose, dtype=np.float64), maxt,
                        watertight)
    t = np.asarray(hits.t, dtype=np.float64).reshape(h, w)
    rays = np.asarray(hits.rays, dtype=np.float64)  # camera frame, z = 1
    if rays.ndim == 2 and rays.shape[0] == 3:
        rays = rays.T
    z = t / np.linalg.norm(rays, axis=1).reshape(h, w)  # depth along the optical axis
    close = np.isfinite(z) & (np.abs(z - depth) <= MATCH_TOL_MM + MATCH_TOL_REL * np.abs(depth))
    shares = [float(np.count_nonzero(close & has) / np.count_nonzero(has))]
    part = getattr(scan, "part", None)
    if part is not None and np.shape(part) == (h, w):
        for k in np.unique(part[has]):
            mine = has & (part == k)
            if np.count_nonzero(mine) >= MIN_PART_PIXELS:
                shares.append(float(np.count_nonzero(close & mine) / np.count_nonzero(mine)))
    return min(shares)


def require_matching_scene(scan, scene, scan_path: Path | str, scene_path: Path | str) -> None:
    """Refuse a ``--scene`` that does not match the synthetic scan (see :data:`MIN_SCENE_MATCH`)."""
    if scan.K is None:
        raise RangesimError("--scene needs a synthetic scan with its camera intrinsics (meta K); this scan has "
                            "none", source=scan_path)
    share = scene_match_share(scan, scene)
    if share < MIN_SCENE_MATCH:
        raise RangesimError(
            f"--scene {scene_path} does not match this scan: cast from the scan's pose, it hits the scan's true "
            f"surface on {100 * share:.1f} % of its pixels (at least {100 * MIN_SCENE_MATCH:.0f} % needed); give "
            "the scene the scan was made from", source=scan_path)


def warn_if_named_scene_is_gone(scan, scan_path: Path | str, lost: str) -> None:
    """A synthetic scan whose named scene file (``meta["scene"]``) is gone (the folder moved or
    copied) loses what the scene gives (``lost``: "no ground truth, no scores"): say so in one
    line rather than leave it out unasked."""
    from rangesim.scene.scene import MESH_SUFFIXES

    named = scan.meta.get("scene") if scan.xyz_true is not None else None
    # (a scene built in memory is named "memory": no file to miss)
    is_file_name = bool(named) and Path(str(named)).suffix.lower() in {".toml", *MESH_SUFFIXES}
    if is_file_name and not Path(str(named)).is_file():
        import warnings

        warnings.warn(f"{scan_path}: the scene it was scanned from ({named}) is not there (moved or renamed?): "
                      f"{lost}; give --scene", stacklevel=2)


def require_synthetic(scan, scan_path: Path | str, scene_path: Path | str | None) -> None:
    """``--scene`` gives the ground truth of a synthetic scan; a recording has none to draw from it."""
    if scene_path is not None and scan.xyz_true is None:
        raise RangesimError(f"--scene {scene_path} applies to synthetic scans (with their noise-free hits, "
                            ".exr or .npz from rangesim); a recorded scan has no ground truth to score against",
                            source=scan_path)
