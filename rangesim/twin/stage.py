"""The simulated twin of a recorded moving-head scan (Cyberware 3030 style).

The recorded grid is in the scanner frame: columns are head positions along x (the sweep),
rows are samples along the stripe (y), z is the range axis. Twin cell (i, j) looks along
the cell's *sample line*: the line on which the recording puts that cell's sample,
fitted from the recorded points as

    x = a0 + a1 j + a2 (i mod 2) + a3 z        (interlaced rows shift by a2)
    y = b0 + b1 i + (b2 + b3 i) z               (rows fan out slightly with range)

i.e. an (almost) orthographic ray along the range axis. One ``ray_intersect`` finds the
first mesh hit of every cell from the scanner's side (+z or -z, whichever side puts the
recorded points nearest to the hits). A hit is measured when

* the laser reaches it: one ``ray_test`` towards the laser direction, in the sheet (y-z
  plane), tilted by ``alpha_deg`` from the range axis (else status SHADOW);
* the camera sees it: one ``ray_test`` towards the camera direction, in the x-z plane,
  ``theta_deg`` from the range axis, either sign (else status SHADOW); with
  ``camera_views = 2`` the stripe is watched from both sides (+-theta, the mirror pair of a
  Cyberware head) and a cell is seen when either view sees it;
* the return is strong enough: the cosines of incidence of laser and camera both exceed
  ``min_cos`` (else status DROPOUT, a grazing dropout).

Measured depths get the range error of :mod:`rangesim.sensor.stripe_noise`, the model the
geometric scanner uses: the stripe-peak error (estimator floor, detector noise growing with
the imaged stripe's width and falling with its brightness, spatially correlated speckle,
partial stripes at outlines and shadow borders, quantisation) triangulated into range
through the sensor's dz/du, and dropouts drawn with the probability that the
speckle-modulated return exceeds ``noise.min_signal``. The grid has no camera pixels, so the
sensor's camera stands in for the Cyberware's: magnification f / z_ref and
dz/du = z_ref / (f tan t), t the triangulation angle (``laser.tilt_deg`` for a translating
sweep, atan(baseline / z_ref) for a rotating one), z_ref the sensor's mid-range. Lengths on
the surface (stripe footprint, correlation length, border distance) are converted to cells
with the grid's own steps. ``sigma_mm``, when given, replaces the range-error terms by the
legacy white range noise of that std (the dropout curve stays).

:class:`TwinStage` holds the geometry that does not depend on those parameters (the mesh
in the scanner frame, the Mitsuba scene, the primary hits) so a calibration can try many
parameter sets at the cost of one ``ray_test`` per angle.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.sensor.stripe_noise import StripeNoise, border_distance, dorsch_sigma_mm, simulate

__all__ = ["TwinStage", "twin", "DEFAULT_PARAMS", "load_mesh_mm"]

#: parameters of the twin when neither the caller nor the sensor sets them
DEFAULT_PARAMS: dict[str, float] = {"theta_deg": 20.0, "alpha_deg": 0.0, "sigma_mm": 0.1, "min_cos": 0.1,
                                    "camera_views": 1}
#: the geometry parameters (sensor table ``[twin]``)
GEOMETRY = ("theta_deg", "alpha_deg", "min_cos", "camera_views")


def load_mesh_mm(mesh: Any, scale: float | str = "auto", reference: np.ndarray | None = None):
    """A trimesh (copy) in millimetres from a trimesh or a mesh file.

    ``scale="auto"``: a mesh whose bounding box is under 5 units across while the
    ``reference`` points span more than 5 mm is taken to be in metres (x 1000).
    """
    from rangesim.cad.meshes import check_mesh_arrays, load_mesh

    source = None
    if isinstance(mesh, (str, Path)):
        # the scanner's own reader: a truncated STL, a directory or an OBJ index out of range
        # named as such (trimesh alone called them all an empty mesh or an index error)
        source = Path(mesh)
        mesh = load_mesh(source)

    check_mesh_arrays(mesh, source)
    mesh = mesh.copy()
    if isinstance(scale, str) and scale != "auto":
        try:  # "1000", as a command line gives it
            scale = float(scale)
        except ValueError:
            raise RangesimError(f'mesh_scale must be a number > 0 or "auto", got {scale!r:.40}') from None
    if isinstance(scale, str):
        extent = float(np.ptp(mesh.vertices, axis=0).max())
        ref = 0.0 if reference is None or len(reference) == 0 else float(np.ptp(reference, axis=0).max())
        scale = 1000.0 if extent < 5.0 and ref > 5.0 else 1.0
    # 0, negative or NaN scales made an empty or mirrored twin without a word
    scale = P.number(scale, "mesh_scale", 0, lo_open=True, what="scale", unit='mm per mesh unit, or "auto"')
    mesh.apply_scale(float(scale))
    return mesh


#: the twin's parameters and their ranges (lo, hi, open at both ends, unit)
TWIN_PARAM_RANGES = {
    "theta_deg": (-90.0, 90.0, True, "degrees"),   # the camera's angle off the sheet, x-z plane
    "alpha_deg": (-90.0, 90.0, True, "degrees"),   # the laser sheet's tilt, y-z plane
    "sigma_mm": (0.0, math.inf, False, "mm"),      # legacy white range noise
    "min_cos": (0.0, 1.0, False, ""),              # grazing-dropout cosine threshold
}


def check_twin_param(name: str, value: Any) -> float | int:
    """``value`` checked for the twin parameter ``name`` (:data:`TWIN_PARAM_RANGES`;
    ``camera_views`` 1 or 2)."""
    if name == "camera_views":
        v = P.whole(value, "camera_views", 1)
        if v > 2:
            raise RangesimError(f"camera_views must be 1 or 2, got {value!r:.40}")
        return v
    if name not in TWIN_PARAM_RANGES:
        raise RangesimError(f"unknown twin parameter {name!r}; known: {', '.join(TWIN_PARAM_RANGES)}, camera_views")
    lo, hi, open_, unit = TWIN_PARAM_RANGES[name]
    return P.number(value, name, lo, hi, lo_open=open_, hi_open=open_, unit=unit)


def _as_sensor(sensor: Any):
    if sensor is not None and isinstance(sensor, (str, Path, dict)):
        from rangesim.sensor import load_sensor

        sensor = load_sensor(sensor)
    if getattr(sensor, "mode", None) == "structured_light":
        # the stage twins a laser-stripe scan (sheet, camera views, stripe noise): a projector's
        # numbers would silently drive that model
        raise RangesimError(f"sensor {sensor.name!r} is a structured-light sensor; the twin of a recording with "
                            "a mesh is a laser-stripe scanner's: give a laser-stripe preset (a labelled "
                            "Kinect-type frame is twinned without a mesh)")
    return sensor


def _sensor_defaults(sensor: Any) -> dict[str, float]:
    """Twin parameters a sensor gives: its ``[twin]`` table, else camera tilt -> theta.

    Without a sensor the legacy white range noise ``sigma_mm`` applies; with one, the
    sensor's noise model does (``sigma_mm`` None).
    """
    params: dict[str, Any] = dict(DEFAULT_PARAMS)
    if sensor is None:
        return params
    p = getattr(sensor, "params", {}) or {}
    twin_table = p.get("twin", {})
    tilt = p.get("laser", {}).get("tilt_deg")
    if twin_table.get("theta_deg") is not None:
        params["theta_deg"] = float(twin_table["theta_deg"])
    elif tilt is not None:
        params["theta_deg"] = float(tilt)
    if twin_table.get("alpha_deg") is not None:
        params["alpha_deg"] = float(twin_table["alpha_deg"])
    if twin_table.get("camera_views") is not None:
        params["camera_views"] = int(twin_table["camera_views"])
    min_signal = p.get("noise", {}).get("min_signal")
    if twin_table.get("min_cos") is not None:
        params["min_cos"] = float(twin_table["min_cos"])
    elif min_signal is not None:
        params["min_cos"] = float(min_signal)
    params["sigma_mm"] = None
    return params


#: the misregistration's range effect is capped at this incidence (the gradient grows without bound)
REGISTRATION_MAX_INCIDENCE_DEG = 85.0


@dataclass(frozen=True)
class Registration:
    """Lateral misregistration between a recording and its reference mesh (not a scanner effect).

    A recording's residuals to a mesh merged from registered scans (the Stanford bunny's
    ``bun_zipper.ply``) hold the registration error of its ``.conf`` pose and of the merge
    (``shared/notes/measuring-realism.md``). A lateral error delta moves the surface along the
    range axis by grad z . delta, std ``std_mm * tan(incidence)``: it grows steeply at grazing
    angles and is smooth over ``length_mm``. The twin adds it so that both sides of a
    comparison hold it (``[twin] registration_mm``, ``registration_length_mm``); 0 gives the
    scanner alone.
    """

    std_mm: float = 0.0
    length_mm: float = 3.0

    @classmethod
    def from_sensor(cls, sensor: Any) -> "Registration":
        table = (getattr(sensor, "params", {}) or {}).get("twin", {}) if sensor is not None else {}
        return cls(std_mm=float(table.get("registration_mm", 0.0) or 0.0),
                   length_mm=float(table.get("registration_length_mm", 3.0) or 3.0))


@dataclass(frozen=True)
class TwinOptics:
    """The sensor constants that turn the peak-error model into range error on the grid.

    Attributes
    ----------
    dz_du : float
        Range error (mm) per pixel of peak shift, z_ref / (f tan t).
    magnification : float
        Pixels per mm on the surface at z_ref (f / z_ref).
    speckle_px : float
        The Dorsch limit at z_ref in pixels.
    """

    dz_du: float = 1.0
    magnification: float = 1.0
    speckle_px: float = 0.0

    @classmethod
    def from_sensor(cls, sensor: Any, noise: StripeNoise) -> "TwinOptics":
        if sensor is None:
            return cls()
        f, z_ref = float(sensor.focal_px), float(sensor.reference_distance)
        laser = sensor.params["laser"]
        angle = sensor.tilt_rad if laser["sweep"] == "translating" else math.atan2(laser["baseline"], z_ref)
        dz_du = z_ref / (f * math.tan(abs(angle)))
        speckle_mm = float(dorsch_sigma_mm(z_ref, math.sin(abs(angle)), noise.speckle_contrast, noise.wavelength_nm,
                                           noise.aperture_mm))
        return cls(dz_du=dz_du, magnification=f / z_ref, speckle_px=speckle_mm / dz_du)


def _sensor_name(sensor: Any) -> str | None:
    if sensor is None:
        return None
    return sensor if isinstance(sensor, str) else getattr(sensor, "name", str(sensor))


#: the largest RMS distance (in grid steps, x and y) of a recording's points from their cells'
#: fitted sample lines (:func:`fit_grid`): the Stanford bunny's range grids stray 0.00 and 0.15, a
#: perspective image of a box 2 (the mOSD Kinect frames 30-1,700)
GRID_MAX_RESIDUAL = 1.0


@dataclass
class GridModel:
    """The sample line of every cell (see the module docstring); coefficients a, b."""

    a: np.ndarray  # (4,)
    b: np.ndarray  # (4,)
    z_ref: float

    def line(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point at z = z_ref, direction with z component 1), each (N, 3) float64."""
        i, j = rows.astype(np.float64), cols.astype(np.float64)
        a, b, z = self.a, self.b, self.z_ref
        x = a[0] + a[1] * j + a[2] * (i % 2) + a[3] * z
        slope_y = b[2] + b[3] * i
        y = b[0] + b[1] * i + slope_y * z
        origin = np.stack([x, y, np.full_like(x, z)], axis=1)
        direction = np.stack([np.full_like(x, a[3]), slope_y, np.ones_like(x)], axis=1)
        return origin, direction

    def as_dict(self) -> dict[str, Any]:
        return {"a": self.a.tolist(), "b": self.b.tolist(), "z_ref": self.z_ref}


def fit_grid(scan: RangeScan) -> GridModel:
    """Fit the sample lines of a recorded organized scan from its valid points."""
    valid = scan.valid & np.isfinite(scan.xyz).all(axis=2)
    if np.count_nonzero(valid) < 10:
        raise RangesimError("the recorded scan has fewer than 10 valid points: cannot fit its grid")
    i, j = np.nonzero(valid)
    p = scan.xyz[valid].astype(np.float64)
    z_ref = float(np.median(p[:, 2]))
    z = p[:, 2] - z_ref
    fi, fj = i.astype(np.float64), j.astype(np.float64)
    one = np.ones_like(fi)
    # the range terms only where the points spread in range (else they are not determined)
    use_z = np.std(z) > 2.0
    zc = z if use_z else np.zeros_like(z)
    ax, *_ = np.linalg.lstsq(np.c_[one, fj, fi % 2, zc], p[:, 0], rcond=None)
    by, *_ = np.linalg.lstsq(np.c_[one, fi, zc, fi * zc], p[:, 1], rcond=None)
    # coefficients were fitted around z_ref: express the lines through z = z_ref
    a = np.array([ax[0] - ax[3] * z_ref, ax[1], ax[2], ax[3]])
    b = np.array([by[0] - by[2] * z_ref, by[1] - by[3] * z_ref, by[2], by[3]])
    if abs(a[1]) < 1e-9 or abs(b[1]) < 1e-9:
        raise RangesimError("the recorded grid does not step in x along rows and in y down columns")
    grid = GridModel(a, b, z_ref)
    # the points must lie on their cells' sample lines: a perspective image (x and y growing
    # with z) fits them with a step near 0 and residuals of many steps, and its twin's
    # correlation lengths in cells come out in the millions
    origin, direction = grid.line(i, j)
    near = origin + direction * (p[:, 2] - z_ref)[:, None]
    rms = np.sqrt(np.mean(np.square(near[:, :2] - p[:, :2]), axis=0))
    off = rms / np.abs([a[1], b[1]])
    if np.max(off) > GRID_MAX_RESIDUAL:
        axis = "x along the rows" if off[0] >= off[1] else "y down the columns"
        raise RangesimError(f"the recorded points do not lie on a range grid's sample lines: {axis} they stray "
                            f"{np.max(off):.3g} grid steps (RMS) from the best fit; a twin needs a sweep's range "
                            f"grid (a Cyberware scan), not a camera image (for a perspective scan use "
                            f"rangesim diff, or --sensor kinect_v1 for a Kinect frame)")
    return grid


def _mi_vec(mi, arr: np.ndarray, kind: str = "Vector3f"):
    from rangesim.core.backend import aligned

    arr = np.asarray(arr, dtype=np.float32)
    return getattr(mi, kind)(mi.Float(aligned(arr[:, 0])), mi.Float(aligned(arr[:, 1])),
                             mi.Float(aligned(arr[:, 2])))


class TwinStage:
    """The mesh in the recorded scan's frame and the primary hits of its grid.

    Parameters
    ----------
    recorded : RangeScan
        An organized recorded scan (scanner frame, mm) with ``pose`` scanner-to-world.
    mesh : trimesh.Trimesh or path
        The object, world frame (metres are detected and converted, see :func:`load_mesh_mm`).
    sensor : str or Sensor, optional
        Sensor preset whose name goes into ``meta`` and whose tilt / min_signal give
        default angles.
    side : {+1, -1, None}
        The scanner's side along z (+1: the scanner sits at +z looking towards -z); None
        picks the side whose hits lie nearest the recorded points.
    """

    def __init__(self, recorded: RangeScan, mesh: Any, sensor: Any = None, *, side: int | None = None,
                 mesh_scale: float | str = "auto") -> None:
        from rangesim.core.backend import mitsuba
        from rangesim.scene.mitsuba_scene import numpy_to_mitsuba_mesh

        if side is not None and (isinstance(side, bool) or side not in (1, -1)):
            raise RangesimError(f"side must be 1, -1 or None (both tried), got {side!r:.40}")
        self.recorded = recorded
        self.sensor = sensor = _as_sensor(sensor)
        self.defaults = _sensor_defaults(sensor)
        self.noise = StripeNoise.from_params(sensor.params) if sensor is not None else StripeNoise()
        self.optics = TwinOptics.from_sensor(sensor, self.noise)
        self.registration = Registration.from_sensor(sensor)
        h, w = recorded.shape
        self.shape = (h, w)
        pose = np.asarray(recorded.pose, dtype=np.float64)
        world_ref = recorded.points("world") if recorded.valid.any() else None
        mesh = load_mesh_mm(mesh, mesh_scale, world_ref)
        # world -> scanner frame: p = R^T (p_world - t)
        verts = (np.asarray(mesh.vertices, dtype=np.float64) - pose[:3, 3]) @ pose[:3, :3]
        self.vertices, self.faces = verts, np.asarray(mesh.faces, dtype=np.int64)
        self.grid = fit_grid(recorded)

        self.mi = mi = mitsuba()
        shape = numpy_to_mitsuba_mesh("twin_mesh", verts, self.faces)
        self.scene = mi.load_dict({"type": "scene", "mesh": shape})

        rows, cols = np.indices((h, w)).reshape(2, -1)
        origin, direction = self.grid.line(rows, cols)
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        self.reach = float(np.linalg.norm(hi - lo) + abs(self.grid.z_ref) + 1000.0)
        sides = (side,) if side is not None else (1, -1)
        best = None
        for s in sides:
            hits = self._cast(origin, direction, s)
            score = self._side_score(hits)
            if best is None or score < best[0]:
                best = (score, s, hits)
        _, self.side, (self.hit, self.point, self.normal) = best
        self.direction = direction / np.linalg.norm(direction, axis=1, keepdims=True)
        self.hit_index = np.flatnonzero(self.hit)
        pts = self.point[self.hit_index]
        nrm = self.normal[self.hit_index]
        self._mi_points = _mi_vec(mi, pts, "Point3f")
        self._mi_normals = _mi_vec(mi, nrm)
        self._cache: dict[tuple[str, float], tuple[np.ndarray, np.ndarray]] = {}
        self._border_cache: dict[str, Any] = {}

    # -- geometry ------------------------------------------------------------------------
    def _cast(self, origin: np.ndarray, direction: np.ndarray, side: int):
        """First hits along every sample line, travelling towards -side * z."""
        import drjit as dr

        mi = self.mi
        d = -side * direction / np.linalg.norm(direction, axis=1, keepdims=True)
        # start on the scanner's side, far outside the mesh
        start = origin - d * (self.reach / np.abs(d[:, 2:3]))
        ray = mi.Ray3f(_mi_vec(mi, start, "Point3f"), _mi_vec(mi, d))
        ray.maxt = 4.0 * self.reach / float(np.abs(d[:, 2]).min())
        si = self.scene.ray_intersect(ray)
        valid = si.is_valid()
        dr.eval(si.p, si.n, valid)
        hit = np.array(valid, dtype=bool)
        point = np.array(si.p, dtype=np.float64).reshape(3, -1).T if dr.width(si.p) else np.zeros((0, 3))
        normal = np.array(si.n, dtype=np.float64).reshape(3, -1).T
        point[~hit] = np.nan
        normal[~hit] = np.nan
        # normals facing the scanner (against the ray)
        flip = np.sum(normal * d, axis=1) > 0
        normal[flip] *= -1
        return hit, point, normal

    def _side_score(self, hits) -> float:
        hit, point, _ = hits
        rec = self.recorded.valid.reshape(-1) & hit
        if not rec.any():
            return math.inf
        dz = self.recorded.xyz.reshape(-1, 3)[rec, 2] - point[rec, 2]
        return float(np.median(np.abs(dz)))

    def laser_direction(self, alpha_deg: float) -> np.ndarray:
        """Unit vector from a surface point towards the laser (y-z plane)."""
        a = math.radians(alpha_deg)
        return np.array([0.0, math.sin(a), self.side * math.cos(a)])

    def camera_direction(self, theta_deg: float) -> np.ndarray:
        """Unit vector from a surface point towards the camera (x-z plane)."""
        t = math.radians(theta_deg)
        return np.array([math.sin(t), 0.0, self.side * math.cos(t)])

    def _reach(self, kind: str, angle: float) -> tuple[np.ndarray, np.ndarray]:
        """(unblocked, cos of incidence) over the hit cells, towards the laser or camera."""
        key = (kind, round(float(angle), 6))
        if key not in self._cache:
            import drjit as dr

            from rangesim.sensor.shadows import occluded

            mi = self.mi
            u = self.laser_direction(angle) if kind == "laser" else self.camera_direction(angle)
            cos = self.normal[self.hit_index] @ u
            facing = cos > 0
            if self.hit_index.size:
                source = self._mi_points + mi.Vector3f(*(u * 2.0 * self.reach).tolist())
                blocked = occluded(
                    SimpleNamespace(scene=self.scene), self._mi_points, self._mi_normals, source,
                    mi.Bool(facing),
                )
                dr.eval(blocked)
                blocked = np.array(blocked, dtype=bool)
            else:
                blocked = np.zeros(0, dtype=bool)
            self._cache[key] = (facing & ~blocked, cos)
        return self._cache[key]

    def camera_reach(self, theta_deg: float, views: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(seen, cos of the best view) over the hit cells, for one camera view or two.

        ``views=2``: the stripe is watched from both sides of the sheet (at +theta and -theta,
        the mirror pair of a Cyberware head); a cell is seen when either view sees it, and
        its return is the brighter view's.
        """
        seen, cos = self._reach("camera", theta_deg)
        if int(views) == 2 and theta_deg != 0:
            seen_b, cos_b = self._reach("camera", -theta_deg)
            cos = np.where(seen & seen_b, np.maximum(cos, cos_b), np.where(seen_b, cos_b, cos))
            seen = seen | seen_b
        return seen, cos

    def status_codes(self, theta_deg: float, alpha_deg: float, min_cos: float, views: int = 1) -> np.ndarray:
        """(H * W,) uint8 status of every cell under the given geometry."""
        status = np.full(self.hit.size, np.uint8(Status.MISS))
        lit, cos_l = self._reach("laser", alpha_deg)
        seen, cos_c = self.camera_reach(theta_deg, views)
        code = np.full(self.hit_index.size, np.uint8(Status.VALID))
        code[(cos_l < min_cos) | (cos_c < min_cos)] = Status.DROPOUT
        code[~lit | ~seen] = Status.SHADOW
        status[self.hit_index] = code
        return status

    def valid_hit_mask(self, theta_deg: float, alpha_deg: float, min_cos: float, views: int = 1) -> np.ndarray:
        """Validity over the hit cells only (for fast IoU during calibration)."""
        lit, cos_l = self._reach("laser", alpha_deg)
        seen, cos_c = self.camera_reach(theta_deg, views)
        return lit & seen & (cos_l >= min_cos) & (cos_c >= min_cos)

    # -- the twin ------------------------------------------------------------------------
    def params(self, **given: float | None) -> dict[str, float | None]:
        """The sensor's twin parameters with ``given`` ones (not None) in their place, checked:
        a NaN angle, a ``min_cos`` over 1 or a view count of 0 made an empty twin silently."""
        out = dict(self.defaults)
        for name, value in given.items():
            if value is not None:
                out[name] = check_twin_param(name, value)
        return out

    @property
    def cell_mm(self) -> tuple[float, float]:
        """Grid spacing (down a column, along a row), mm: the fitted y and x steps."""
        return abs(float(self.grid.b[1])), abs(float(self.grid.a[1]))

    def _on_grid(self, values: np.ndarray) -> np.ndarray:
        """Values over the hit cells spread to the full grid (0 elsewhere), float64."""
        out = np.zeros(self.hit.size)
        out[self.hit_index] = values
        return out

    def draw(self, params: dict[str, Any], *, seed: int = 0, noise: StripeNoise | None = None,
             quiet: bool = False, registration: "Registration | None" = None, optics: "TwinOptics | None" = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Status, range error (mm) and predicted std (mm) of every cell, flat (H * W,).

        ``noise``, ``registration`` and ``optics`` replace the sensor's (a calibration tries
        many); ``quiet`` draws nothing: the geometry's status, zero error.
        """
        status = self.status_codes(params["theta_deg"], params["alpha_deg"], params["min_cos"],
                                   int(params.get("camera_views", 1)))
        n = status.size
        if quiet:
            return status, np.zeros(n), np.where(status == Status.VALID, 0.0, np.nan)
        noise = self.noise if noise is None else noise
        optics = self.optics if optics is None else optics
        if params.get("sigma_mm") is not None:  # the legacy twin: white range noise of that std alone
            noise = StripeNoise(sigma_px=float(params["sigma_mm"]) / optics.dz_du, min_signal=noise.min_signal,
                                signal_contrast=noise.signal_contrast, stripe_width_mm=noise.stripe_width_mm)
        cells = self.stripe_cells(params, status, noise)
        m = optics.magnification
        result = simulate(noise, np.random.default_rng(seed), self.shape, candidate=cells["candidate"],
                          signal=cells["signal"], cos_incidence=cells["cos_laser"], amplitude=cells["cos_laser"],
                          magnification=np.full(n, m), reference_magnification=m,
                          speckle_px=np.full(n, optics.speckle_px), border_mm=cells["border_mm"],
                          corr_px=cells["corr_px"])
        candidate = cells["candidate"]
        status = status.copy()
        status[candidate & ~result.detected] = Status.DROPOUT
        error, sigma = result.error_px * optics.dz_du, result.sigma_px * optics.dz_du
        reg = self.registration if registration is None else registration
        if reg.std_mm > 0 and params.get("sigma_mm") is None:  # the legacy white noise stands alone
            reg_error, reg_sigma = self._registration_error(reg, seed)
            detected = result.detected
            error = np.where(detected, error + reg_error, 0.0)
            sigma = np.where(detected, np.hypot(sigma, reg_sigma), np.nan)
        return status, error, sigma

    def stripe_cells(self, params: dict[str, Any], status: np.ndarray, noise: StripeNoise) -> dict[str, Any]:
        """What the stripe model needs of every cell (flat): candidates, S, laser cosine, border, correlation.

        ``status``: the geometry's codes (:meth:`status_codes`). The border is the distance
        along the row (mm, the columns' spacing; +inf on a row without one) to the nearest cell
        the stripe cannot reach (no surface, shadow): :func:`~rangesim.sensor.stripe_noise.border_distance`.
        """
        cos_l = self._on_grid(np.clip(self._reach("laser", params["alpha_deg"])[1], 0.0, 1.0))
        cos_c = self._on_grid(np.clip(self.camera_reach(params["theta_deg"], int(params.get("camera_views", 1)))[1],
                                      0.0, 1.0))
        candidate = status == Status.VALID
        reached = candidate | (status == Status.DROPOUT)
        row_mm, col_mm = self.cell_mm
        # the border depends on the geometry only: a calibration trying many noise models reuses it
        key = reached.tobytes()
        if self._border_cache.get("key") != key:
            self._border_cache = {"key": key, "border": border_distance(reached.reshape(self.shape),
                                                                       sampling=(row_mm, col_mm))}
        return {
            "candidate": candidate, "signal": cos_l * cos_c, "cos_laser": cos_l,
            "border_mm": self._border_cache["border"],
            "corr_px": (noise.correlation_mm / row_mm, noise.correlation_mm / col_mm),
        }

    def _registration_error(self, reg: "Registration", seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Range error (mm) of a lateral misregistration field, and its std: grad z . delta.

        delta (mm, x and y) is a correlated Gaussian field of std ``reg.std_mm`` and
        correlation length ``reg.length_mm``; a surface of gradient g = -(n_x, n_y) / n_z
        moves by g . delta along the range axis, std ``std_mm |g|``.
        """
        from rangesim.sensor.stripe_noise import correlated_field

        n = self.normal
        with np.errstate(invalid="ignore", divide="ignore"):
            nz = np.where(np.abs(n[:, 2]) > 1e-9, n[:, 2], np.nan)
            grad = -n[:, :2] / nz[:, None]
        norm = np.linalg.norm(grad, axis=1)
        cap = math.tan(math.radians(REGISTRATION_MAX_INCIDENCE_DEG))
        grad = np.where((norm > cap)[:, None], grad * (cap / np.maximum(norm, 1e-12))[:, None], grad)
        grad = np.nan_to_num(grad)
        row_mm, col_mm = self.cell_mm
        corr = (reg.length_mm / row_mm, reg.length_mm / col_mm)
        rng = np.random.default_rng([int(seed), 0x5EED])  # its own stream: the scanner's draws stay as they are
        dx = correlated_field(rng, self.shape, corr).reshape(-1) * reg.std_mm
        dy = correlated_field(rng, self.shape, corr).reshape(-1) * reg.std_mm
        return grad[:, 0] * dx + grad[:, 1] * dy, reg.std_mm * np.linalg.norm(grad, axis=1)

    def scan(self, *, theta_deg: float | None = None, alpha_deg: float | None = None,
             sigma_mm: float | None = None, min_cos: float | None = None, seed: int = 0,
             noise: StripeNoise | None = None, quiet: bool = False, camera_views: int | None = None) -> RangeScan:
        """The twin RangeScan under the given parameters (defaults: the sensor's).

        ``noise`` replaces the sensor's noise model; ``quiet=True`` gives the noise-free
        geometry (no range error, no drawn dropouts).
        """
        p = self.params(theta_deg=theta_deg, alpha_deg=alpha_deg, sigma_mm=sigma_mm, min_cos=min_cos,
                        camera_views=camera_views)
        p["camera_views"] = int(p["camera_views"])
        h, w = self.shape
        status, error, sigma = self.draw(p, seed=seed, noise=noise, quiet=quiet)
        valid = status == Status.VALID
        # move along the sample line so the measured point stays on it (dz = error)
        line_dir = self.direction / self.direction[:, 2:3]
        xyz = self.point + error[:, None] * line_dir
        xyz[~valid] = np.nan
        normal = self.normal.copy()
        intensity = np.zeros(status.size, dtype=np.float32)
        lit, cos_l = self._reach("laser", p["alpha_deg"])
        intensity[self.hit_index] = np.clip(cos_l, 0.0, 1.0)
        face = np.full(status.size, -1, dtype=np.int32)
        part = np.where(self.hit, 0, -1).astype(np.int32)
        counts = {
            "laser_blocked": int(np.count_nonzero(~lit)),
            "camera_blocked": int(np.count_nonzero(~self.camera_reach(p["theta_deg"], int(p["camera_views"]))[0])),
        }
        noise_used = self.noise if noise is None else noise
        meta = {
            "units": "mm", "frame": self.recorded.meta.get("frame", "scanner"), "organized": True,
            "twin": {
                "model": "moving_head_orthographic", **p, "seed": int(seed), "side": int(self.side),
                "grid": self.grid.as_dict(), "source": self.recorded.meta.get("source"), **counts,
                "noise": None if quiet else asdict(noise_used), "dz_du_mm": self.optics.dz_du,
            },
            "sensor": {"name": _sensor_name(self.sensor) or "twin"},
            "seed": int(seed),
        }
        return RangeScan(
            depth=xyz[:, 2].reshape(h, w), xyz=xyz.reshape(h, w, 3), valid=valid.reshape(h, w),
            normal=normal.reshape(h, w, 3), intensity=intensity.reshape(h, w), part=part.reshape(h, w),
            face=face.reshape(h, w), status=status.reshape(h, w), pose=self.recorded.pose.copy(), meta=meta,
            xyz_true=self.point.reshape(h, w, 3), sigma=np.where(valid, sigma, np.nan).reshape(h, w),
        )


def twin(recorded_scan: RangeScan, mesh: Any, sensor: Any = None, *, theta_deg: float | None = None,
         alpha_deg: float | None = None, sigma_mm: float | None = None, min_cos: float | None = None,
         seed: int = 0, stage: TwinStage | None = None, quiet: bool = False,
         camera_views: int | None = None) -> RangeScan:
    """Scan ``mesh`` from the recorded scan's viewpoint on the same grid (see module docs).

    Parameters
    ----------
    recorded_scan : RangeScan
        Organized recorded scan, scanner frame, ``pose`` scanner-to-world.
    mesh : trimesh.Trimesh or path
        World (mesh) frame.
    sensor : str or Sensor, optional
        Preset for default angles and ``meta``.
    theta_deg, alpha_deg, min_cos : float, optional
        Camera angle (x-z plane, signed), laser angle (y-z plane) and the grazing-dropout
        cosine threshold (defaults: the sensor's ``[twin]`` table).
    sigma_mm : float, optional
        A white range noise (mm) in place of the sensor's range-error model (legacy).
    quiet : bool
        The noise-free geometry (no range error, no drawn dropouts).
    camera_views : {1, 2}, optional
        Camera views watching the stripe (2: one on either side of the sheet).
    seed : int
        Noise seed.
    stage : TwinStage, optional
        A prepared stage (reuses the ray casts).

    Examples
    --------
    Needs the shared data (``../shared/data``, or ``$RANGESIM_DATA``), so not run as a test:

    >>> import rangesim as rs
    >>> bunny = "../shared/data/stanford-bunny/"
    >>> recorded = rs.load_scan(bunny + "bun000.ply", conf=bunny + "bun.conf")            # doctest: +SKIP
    >>> sim = rs.twin(recorded, bunny + "reconstruction/bun_zipper.ply", "cyberware_3030")   # doctest: +SKIP
    >>> sim.shape == recorded.shape                                                          # doctest: +SKIP
    True

    References
    ----------
    .. [1] R. G. Dorsch, G. Haeusler, J. M. Herrmann, "Laser triangulation: fundamental
       uncertainty in distance measurement", Applied Optics 33(7), 1306-1314 (1994),
       doi:10.1364/AO.33.001306.
    .. [2] B. Curless, M. Levoy, "Better optical triangulation through spacetime analysis", ICCV
       1995, 987-994, doi:10.1109/ICCV.1995.466772.
    """
    if stage is None:
        stage = TwinStage(recorded_scan, mesh, sensor)
    return stage.scan(theta_deg=theta_deg, alpha_deg=alpha_deg, sigma_mm=sigma_mm, min_cos=min_cos, seed=seed,
                      quiet=quiet, camera_views=camera_views)
