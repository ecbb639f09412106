"""The rendered laser-stripe scanner: path-traced frames and spacetime triangulation.

Where the geometric scanner decides visibility, signal and noise by rule, this one renders
what the camera records while the laser sheet sweeps the scene and measures the range the
way a real scanner does:

1. ``rays``: one ``ray_intersect`` through the pixel centres gives the ground truth (true
   point, normal, part, face) and the sweep span that covers every visible surface.
2. ``stripe_paths``: ``render.spp`` paths per pixel, traced once through the scene's
   materials with next-event estimation towards the laser (``render.max_depth``: 2 =
   direct light, 3 = one interreflection, ...).
3. ``frames``: every lit vertex is spread into the frames whose sheet passes through it
   (the sheet's Gaussian thickness), then the camera's noise: speckle (Gamma), photon shot
   noise (Poisson), saturation at the full well, read noise (Gaussian).
4. ``peaks``: per pixel, the frame of peak intensity to a fraction of a frame (Gaussian or
   parabolic fit on the temporal profile).
5. The camera ray through the pixel centre meets the sheet of that sub-frame sweep
   position: the measured point. Interreflections, a glossy surface's lobe and texture
   bias it exactly as they bias the real peak.

Validity: a pixel is measured when its peak is a proper local maximum inside the sweep,
brighter than ``noise.min_signal`` (relative to the white reference target) and than
five read-noise sigmas, and not much wider than the stripe's own temporal width.
Status precedence as in the geometric scanner: miss > out of range > laser shadow
(no peak, and the laser cannot reach the surface directly) > dropout.

Work is done in tiles of image rows so the frame stack never exceeds ``STACK_CELLS``
cells; the path-tracing kernels are compiled for the first tile and reused for the others
(their varying scalars are opaque), which ``meta["kernels"]`` records.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import drjit as dr
import numpy as np

from rangesim.core.backend import mitsuba
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.progress import Progress
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.config import Sensor
from rangesim.sensor.frames import FWHM_PER_SIGMA, PROFILE_CUTOFF, expose, pixel_speckle_contrast, splat_frames
from rangesim.sensor.laser import intersect_sheet, sheet_coordinate, sheet_through
from rangesim.sensor.metadata import scan_meta
from rangesim.sensor.peaks import find_peaks
from rangesim.sensor.rays import camera_hits
from rangesim.sensor.shadows import laser_reach
from rangesim.sensor.stripe_paths import trace_stripe_paths

#: largest frame stack (pixels x frames) held at once; sets the tile height
STACK_CELLS = 1 << 23
#: the spacetime peak needs the stripe to cover at least this many frames (FWHM)
MIN_FRAMES_PER_FWHM = 1.5
#: most frames a sweep may have
MAX_FRAMES = 20000
#: a peak wider than this multiple of the stripe's own temporal width (plus one frame) is rejected
MAX_WIDTH_RATIO = 2.5
#: the peak must exceed this many read-noise sigmas
DETECTION_SIGMAS = 5.0
#: oldest libLLVM known to lower Mitsuba's BSDF kernels (16 and older abort on llvm.maximum)
MIN_LLVM = (19, 0, 0)


@dataclass
class FrameStack:
    """The raw frames of a rendered scan (what ``--keep-frames`` saves).

    Attributes
    ----------
    frames : (F, H, W) float32
        Electrons per pixel and sweep position, noise included.
    s0, ds : float
        Sweep coordinate of frame 0 and the step (rad for a rotating sweep, mm for a
        translating one; see :func:`rangesim.sensor.laser.sheet_coordinate`).
    sweep : str
    """

    frames: np.ndarray
    s0: float
    ds: float
    sweep: str

    def save(self, path) -> None:
        """Write an ``.npz`` (atomic): ``frames``, ``s0``, ``ds``, ``sweep``."""
        from rangesim.io.atomic import atomic_path

        with atomic_path(path) as tmp:
            with open(tmp, "wb") as handle:
                np.savez(handle, frames=self.frames, s0=self.s0, ds=self.ds, sweep=self.sweep)


def check_backend() -> None:
    """Refuse to run Mitsuba's BSDF kernels on a libLLVM that cannot compile them."""
    mi = mitsuba()
    if mi.variant().startswith("llvm"):
        version = tuple(dr.detail.llvm_version())
        if version < MIN_LLVM:
            raise RangesimError(
                f"the rendered mode needs libLLVM {MIN_LLVM[0]} or newer for Mitsuba's BSDFs on the CPU "
                f"(found {'.'.join(map(str, version))}); on Debian: apt-get install libllvm19"
            )


def sweep_frames(sensor: Sensor, s_visible: np.ndarray, lam_visible: np.ndarray) -> tuple[float, float, int]:
    """First sweep coordinate, step and number of frames covering the visible surfaces.

    The sweep spans the visible surfaces' coordinates plus the stripe's profile cut-off on
    either side. ``render.frames = "auto"`` steps ``laser.step`` mm at the reference
    distance; a number spreads that many frames over the span.

    Raises
    ------
    RangesimError
        The stripe covers fewer than ``MIN_FRAMES_PER_FWHM`` frames (no sub-frame peak can
        be fitted), or the sweep would need more than ``MAX_FRAMES`` frames.
    """
    p = sensor.params
    fwhm = p["laser"]["stripe_width"]
    if fwhm <= 0:
        raise RangesimError("the rendered mode needs laser.stripe_width > 0 (the sheet's thickness)",
                            source=sensor.source)
    sigma = fwhm / FWHM_PER_SIGMA
    rotating = p["laser"]["sweep"] == "rotating"
    lam_ref = math.hypot(p["laser"]["baseline"], sensor.reference_distance) if rotating else 1.0
    margin = PROFILE_CUTOFF * sigma / lam_visible
    lo, hi = float(np.min(s_visible - margin)), float(np.max(s_visible + margin))
    frames = p["render"]["frames"]
    if frames == "auto":
        ds = p["laser"]["step"] / lam_ref
        frames = int(math.floor((hi - lo) / ds)) + 1
    else:
        ds = (hi - lo) / (frames - 1)
    per_fwhm = fwhm / (lam_ref * ds)
    if per_fwhm < MIN_FRAMES_PER_FWHM:
        need = int(math.ceil((hi - lo) * lam_ref * MIN_FRAMES_PER_FWHM / fwhm)) + 1
        raise RangesimError(
            f"the stripe (laser.stripe_width {fwhm:g} mm FWHM) spans {per_fwhm:.2f} sweep steps of "
            f"{lam_ref * ds:.3g} mm; a sub-frame peak needs {MIN_FRAMES_PER_FWHM}: set render.frames >= {need} "
            f"or widen the stripe",
            source=sensor.source,
        )
    if frames > MAX_FRAMES:
        raise RangesimError(f"the sweep needs {frames} frames (more than {MAX_FRAMES}); raise laser.step",
                            source=sensor.source)
    return lo, ds, frames


def _kernel_counts(history: list[dict]) -> tuple[int, int]:
    launches = [k for k in history if k.get("type") == dr.KernelType.JIT]
    return len(launches), sum(1 for k in launches if k.get("cache_hit"))


def scan_rendered(scene, sensor: Sensor, pose: np.ndarray, seed: int, keep_frames: bool = False):
    """Render and triangulate a scan; see the module docstring.

    Returns
    -------
    RangeScan, or (RangeScan, FrameStack) with ``keep_frames``.
    """
    check_backend()
    clock = {"start": time.perf_counter()}
    timing = {"primary": 0.0, "paths": 0.0, "frames": 0.0, "noise": 0.0, "peaks": 0.0, "triangulation": 0.0}

    def lap(stage: str) -> None:
        now = time.perf_counter()
        timing[stage] += now - clock["start"]
        clock["start"] = now

    p = sensor.params
    h, w = sensor.height, sensor.width
    K = sensor.K
    near, far = p["range"]["near"], p["range"]["far"]
    laser = {"sweep": p["laser"]["sweep"], "baseline": p["laser"]["baseline"], "tilt_rad": sensor.tilt_rad}
    render = p["render"]
    mscene = scene.mitsuba_scene()

    # 1. ground truth through the pixel centres, and the laser's direct reach
    view = camera_hits(scene, sensor, pose)
    hits, points, normals = view.hits, view.points, view.normals
    sources, _ = sheet_through(points, laser["sweep"], laser["baseline"], laser["tilt_rad"])
    in_range, reachable = laser_reach(mscene, view, sources, pose, near, far)
    dr.eval(points, normals, reachable, in_range)
    xyz_true = np.asarray(dr.ravel(points)).reshape(h * w, 3).astype(np.float64)
    hit = np.isfinite(xyz_true[:, 2])
    xyz_true[~hit] = np.nan
    in_range_np = np.asarray(in_range, dtype=bool)
    reachable_np = np.asarray(reachable, dtype=bool)
    if not in_range_np.any():
        raise RangesimError("no surface lies within the working range in this view", source=sensor.source)
    s_true, lam_true = sheet_coordinate(xyz_true, laser["sweep"], laser["baseline"], laser["tilt_rad"])
    s0, ds, n_frames = sweep_frames(sensor, s_true[in_range_np], lam_true[in_range_np])

    # expected temporal width of the stripe at each pixel: sheet thickness and pixel footprint
    sigma_mm = p["laser"]["stripe_width"] / FWHM_PER_SIGMA
    s_grid = np.where(hit, s_true, np.nan).reshape(h, w)
    with np.errstate(invalid="ignore"):
        # (one column has no neighbour across it to measure the footprint by: none)
        slope = np.gradient(s_grid, axis=1) if w > 1 else np.zeros_like(s_grid)
        footprint = np.nan_to_num(np.abs(slope), nan=0.0).ravel() / ds
        expected = np.sqrt((sigma_mm / (lam_true * ds)) ** 2 + footprint**2 / 12.0)

    speckle = pixel_speckle_contrast(np.linalg.norm(xyz_true, axis=1), p["noise"]["speckle_contrast"],
                                     p["laser"]["wavelength_nm"], p["camera"]["aperture_mm"], float(K[0, 0]))

    lap("primary")

    # 2-4. tiles: paths -> frames -> noise -> peaks
    rows_per_tile = max(1, min(h, STACK_CELLS // max(1, w * n_frames)))
    # paths and noise draw from separate streams of the seed; a tile's noise depends on its first row only
    path_state = int(np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(0,))).integers(0, 2**63))
    exposure = float(render["exposure_e"])
    full_well = float(p["camera"]["full_well_e"])
    read_noise = float(p["camera"]["read_noise_e"])
    position = np.full(h * w, np.nan)
    height = np.zeros(h * w, np.float32)
    width_ok = np.zeros(h * w, bool)
    frames_out = np.zeros((n_frames, h, w), np.float32) if keep_frames else None
    history_flag = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # clear
    first_tile = later = (0, 0)
    bar = Progress(-(-h // rows_per_tile), f"rendered scan {w}x{h}", unit="tile")
    try:
        for tile, row0 in enumerate(range(0, h, rows_per_tile)):
            rows = min(rows_per_tile, h - row0)
            n_pix = rows * w
            vertices = trace_stripe_paths(mscene, pose, K, w, row0, rows, int(render["spp"]),
                                          int(render["max_depth"]), laser, sensor.reference_distance, path_state)
            lap("paths")
            counts = _kernel_counts(dr.kernel_history())
            if tile == 0:
                first_tile = counts
            else:
                later = (later[0] + counts[0], later[1] + counts[1])
            sl = slice(row0 * w, row0 * w + n_pix)
            stack = splat_frames(vertices.pixel, vertices.weight, vertices.s, vertices.lam, n_pix,
                                 s0, ds, n_frames, sigma_mm)
            lap("frames")
            rng = (np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(1, row0)))
                   if render["image_noise"] else None)
            electrons = expose(stack, exposure, full_well, read_noise, speckle[sl], rng)
            lap("noise")
            peaks = find_peaks(electrons, render["peak"], full_well)
            position[sl] = peaks.position
            height[sl] = peaks.height
            limit = MAX_WIDTH_RATIO * expected[sl] + 1.0
            width_ok[sl] = peaks.saturated | (render["peak"] != "gaussian") | (peaks.sigma <= limit)
            if frames_out is not None:
                frames_out[:, row0:row0 + rows, :] = electrons.T.reshape(n_frames, rows, w)
            lap("peaks")
            bar.update()
    finally:
        bar.close()
        dr.set_flag(dr.JitFlag.KernelHistory, history_flag)

    # 5. triangulation against the sheet at the sub-frame peak
    threshold = max(p["noise"]["min_signal"] * exposure, DETECTION_SIGMAS * read_noise if render["image_noise"] else 0.0)
    detected = np.isfinite(position) & (height > threshold) & (height > 0) & width_ok
    rays = np.asarray(dr.ravel(hits.rays)).reshape(h * w, 3).astype(np.float64)
    measured = np.full((h * w, 3), np.nan)
    measured[detected] = intersect_sheet(rays[detected], s0 + position[detected] * ds,
                                         laser["sweep"], laser["baseline"], laser["tilt_rad"])
    z = measured[:, 2]
    with np.errstate(invalid="ignore"):
        measured_in_range = (z >= near) & (z <= far)
    status = np.full(h * w, np.uint8(Status.VALID))
    status[~detected] = Status.DROPOUT
    status[~detected & ~reachable_np] = Status.SHADOW
    status[~in_range_np | (detected & ~measured_in_range)] = Status.OUT_OF_RANGE
    status[~hit] = Status.MISS
    valid = status == Status.VALID
    measured[~valid] = np.nan

    lap("triangulation")
    normal = np.asarray(dr.ravel(normals)).reshape(h * w, 3)
    normal[~hit] = np.nan
    meta = scan_meta(
        scene, sensor, seed, "rendered", frames=n_frames, sweep_start=s0, sweep_step=ds,
        tiles=int(math.ceil(h / rows_per_tile)), seconds={stage: round(v, 4) for stage, v in timing.items()},
        kernels={"first_tile": first_tile[0], "later_tiles": later[0], "later_cache_hits": later[1]},
        recast_rays=hits.recast,
    )
    xyz = measured.reshape(h, w, 3).astype(np.float32)
    result = RangeScan(
        depth=xyz[..., 2].copy(),
        xyz=xyz,
        valid=valid.reshape(h, w),
        normal=normal.reshape(h, w, 3).astype(np.float32),
        intensity=np.where(hit, height / exposure, 0.0).reshape(h, w).astype(np.float32),
        part=np.asarray(hits.part).reshape(h, w),
        face=np.asarray(hits.face).reshape(h, w),
        status=status.reshape(h, w),
        pose=pose,
        meta=meta,
        xyz_true=xyz_true.reshape(h, w, 3).astype(np.float32),
    )
    if keep_frames:
        return result, FrameStack(frames_out, s0, ds, laser["sweep"])
    return result
