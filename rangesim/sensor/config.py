"""Sensor descriptions: camera, laser sheet, working range and noise, from TOML or a dict.

Presets live in the repository's ``sensors/`` folder (``RANGESIM_SENSORS`` adds another
folder). Every key is documented in ``sensors/README.md``; lengths are millimetres.
"""
from __future__ import annotations

import copy
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.light import reference_distance, sheet_tilt_rad
from rangesim.core.params import MAX_WINDOW_PX
from rangesim.core.tomlfile import check_keys, read_toml

#: the repository's preset folder (the package is installed in editable mode from the repo)
PRESET_DIR = Path(__file__).resolve().parents[2] / "sensors"

SWEEPS = ("rotating", "translating")
MODES = ("geometric", "rendered", "structured_light")
#: sub-frame estimators of the rendered mode's spacetime peak
PEAK_FITS = ("gaussian", "parabolic")

#: the largest structured_light.exposure_e (electrons at a dot's peak) and ambient (relative to
#: that peak): a pixel's full well holds 1e4-1e5 electrons, so these leave any image saturated,
#: and they keep the Poisson means well under NumPy's limit (about 9e18)
MAX_EXPOSURE_E = 1e9
MAX_AMBIENT = 1e3
#: the most disparities (in image widths) a structured-light sensor's working range may span
MAX_SPAN_WIDTHS = 4
#: the most bounces of the rendered mode's path tracer: past a few interreflections the stripe's
#: light is gone (albedo^n), and the paths' bounce counts are stored as int8
MAX_RENDER_DEPTH = 32
#: the widest structured-light dot (Gaussian std, projector pixels): the pattern has at most one
#: dot per pixel, so dots this wide already overlap into a nearly flat field with nothing to match
MAX_DOT_SIGMA_PX = 10.0

def focal_px(width: int, fov_deg: float) -> float:
    """Focal length (px) of a pinhole camera ``width`` px wide with horizontal field ``fov_deg`` degrees."""
    return width / 2 / math.tan(math.radians(fov_deg) / 2)


#: every table and key a sensor accepts, with defaults (None: required)
SCHEMA: dict[str, dict[str, Any]] = {
    "camera": {
        "width": None, "height": None, "fov_deg": None, "aperture_mm": 5.0,
        "full_well_e": 20000.0,  # rendered mode: saturation level, electrons
        "read_noise_e": 10.0,  # rendered mode: read noise, electrons rms
        "psf_px": 1.0,  # optical blur FWHM, pixels (imaged stripe width, rangesim.sensor.stripe_noise)
    },
    "laser": {
        "baseline": None,
        "sweep": "rotating",
        "step": 0.5,
        "tilt_deg": None,  # translating sweep: default aims the sheet at mid-range on the axis
        "stripe_width": 0.0,
        "wavelength_nm": 670.0,
    },
    # reference: the photometric and noise reference distance, mm (default mid-range; see
    # reference_distance)
    "range": {"near": None, "far": None, "reference": None},
    "noise": {
        "sigma_px": 0.0,
        "quantization_px": 0.0,
        "min_signal": 0.0,
        "speckle_contrast": 0.0,
        # rangesim.sensor.stripe_noise: all off by default, so a quiet sensor stays exact
        "signal_px": 0.0,  # detector/shot-noise peak error of the facing white stripe, pixels
        "correlation_mm": 0.0,  # speckle correlation length (Gaussian std), mm at z_ref (fixed px on the sensor)
        "edge_gain": 0.0,  # fraction of a truncated stripe's centroid shift that reaches the peak
        "signal_contrast": 0.0,  # speckle contrast of the detected amplitude (dropout probability)
    },
    # the simulated twin of a recording (rangesim.twin): the grid's view geometry
    "twin": {
        "theta_deg": None,  # camera direction from the range axis, x-z plane (default laser.tilt_deg)
        "alpha_deg": 0.0,  # laser direction from the range axis, y-z plane
        "min_cos": None,  # grazing cut-off on both cosines (default noise.min_signal)
        "camera_views": 1,  # 2: the stripe is watched from both sides of the sheet (+-theta_deg)
        # not the scanner: the recording's misregistration against the reference mesh, so the
        # twin's residuals hold what the recorded ones hold (rangesim.twin.stage)
        "registration_mm": 0.0,  # std of the lateral misregistration, mm
        "registration_length_mm": 3.0,  # its correlation length (Gaussian std) on the grid, mm
    },
    # rendered mode only (mode = "rendered"): see rangesim.sensor.rendered
    "render": {
        "frames": "auto",  # sweep positions; "auto": one per laser.step
        "spp": 4,  # paths per pixel
        "max_depth": 3,  # Mitsuba's convention: 2 = direct light only, 3 = one interreflection
        "exposure_e": 4000.0,  # electrons at the stripe peak on the white reference target
        "image_noise": True,  # shot, read and speckle noise on the frames
        "peak": "gaussian",  # sub-frame peak estimator: gaussian or parabolic
    },
    # structured-light mode only (mode = "structured_light"): see rangesim.sensor.structured_light.
    # The projector sits at laser.baseline on the camera's x axis (either sign) and shares the camera's intrinsics.
    "structured_light": {
        "pattern_seed": 0,  # the projected pseudo-random dot pattern (fixed per device)
        "dot_density": 0.1,  # dots per projector pixel
        "dot_sigma_px": 0.6,  # Gaussian std of one dot, projector pixels
        "dot_min_spacing_px": 0.0,  # no two dots closer than this, projector pixels (0: independent dots)
        "exposure_e": 2000.0,  # electrons at a dot's peak on a white facing target at mid-range
        "ambient": 0.02,  # ambient IR irradiance, relative to a dot's peak at mid-range
        "window": 9,  # block-matching window (odd), pixels
        "subpixel_steps": 8,  # disparity quantised to 1 / steps pixel
        "depth_unit_mm": 0.0,  # depth written in whole units of this (a Kinect's uint16 mm: 1); 0: not rounded
        "min_score": 0.5,  # lowest accepted zero-mean normalised cross-correlation
        "uniqueness": 0.1,  # (1 - second best) must exceed (1 + uniqueness) (1 - best)
        "lr_check": True,  # left-right consistency (within 1 px)
        "speckle_window": 100,  # disparity regions under this many pixels are rejected (0: off)
        "speckle_range": 2.0,  # largest disparity step (px) between 4-neighbours of one region
        # predicted disparity error (rangesim.sensor.matching_noise), px: sqrt(s0^2 + (a s)^2 + (c s^2)^2),
        # s = window x the surface's disparity gradient; calibrated on tilted planes
        # (benchmarks/calibrate_matching_noise.py; these are for the default pattern, independent
        # dots, with structured_light_bench's optics: a sensor with another pattern, window or
        # noise should have its own fitted)
        "match_sigma_px": 0.067,  # s0: on a fronto-parallel plane
        "slant_linear": 0.086,  # a
        "slant_quadratic": 0.035,  # c, per px
    },
}
TOP_KEYS = {"name", "description", "mode", *SCHEMA}
#: keys whose None default means "derived from other keys" rather than "required"
OPTIONAL_KEYS = {"tilt_deg", "theta_deg", "min_cos", "reference"}


#: keys a mode reads nothing from: the structured-light mode's noise comes from its IR image and
#: block matcher (``structured_light.*``), not from the laser stripe's peak-error model, sweep or
#: blur; the rendered mode's from its frames (photon counts, speckle), with ``noise.min_signal``
#: and ``noise.speckle_contrast`` alone of the stripe model's keys; the geometric mode's from the
#: stripe model alone (no frames, no IR image: no render keys, no matching, no full well or read
#: noise). Set on a sensor of that mode they change nothing in its scans (:func:`unused_keys`)
_RENDER_KEYS = tuple(f"render.{k}" for k in SCHEMA["render"])
_MATCHING_KEYS = tuple(f"structured_light.{k}" for k in SCHEMA["structured_light"])
UNUSED_BY_MODE: dict[str, tuple[str, ...]] = {
    "geometric": ("camera.full_well_e", "camera.read_noise_e", "laser.step", *_RENDER_KEYS, *_MATCHING_KEYS),
    "structured_light": ("camera.psf_px", "laser.sweep", "laser.step", "laser.stripe_width", "laser.tilt_deg",
                         "noise.sigma_px", "noise.quantization_px", "noise.min_signal", "noise.signal_px",
                         "noise.correlation_mm", "noise.edge_gain", "noise.signal_contrast", *_RENDER_KEYS),
    "rendered": ("camera.psf_px", "noise.sigma_px", "noise.quantization_px", "noise.signal_px",
                 "noise.correlation_mm", "noise.edge_gain", "noise.signal_contrast", *_MATCHING_KEYS),
}
#: keys of :data:`UNUSED_BY_MODE` that a sensor file of that mode may carry for another mode
#: without a warning (the presets set ``laser.step``, the rendered mode's sheet spacing, for a
#: switch to it); set by ``with_params``, ``--set`` or a sweep they still get one
CARRIED_FOR_OTHER_MODES: dict[str, tuple[str, ...]] = {"geometric": ("laser.step",)}
_WHY_UNUSED = {
    "geometric": "laser.step (the rendered mode's frame spacing), the render and structured_light keys and the "
                 "camera's full well and read noise are the rendered and structured-light modes' (its noise is the "
                 "stripe model's)",
    "structured_light": "its noise comes from the IR image and the block matcher (the structured_light keys)",
    "rendered": "its range error comes from the rendered frames",
}


class UnusedSensorKeyWarning(UserWarning):
    """A sensor sets keys its mode does not read (:data:`UNUSED_BY_MODE`)."""


def unused_keys(params: Mapping[str, Mapping[str, Any]], mode: str) -> list[str]:
    """The dotted keys of ``params`` that ``mode`` does not read and that differ from their defaults."""
    out = []
    for dotted in UNUSED_BY_MODE.get(mode, ()):
        table, key = dotted.split(".")
        if params.get(table, {}).get(key, SCHEMA[table][key]) != SCHEMA[table][key]:
            out.append(dotted)
    return out


@dataclass(frozen=True)
class Sensor:
    """A laser-stripe triangulation sensor.

    Attributes
    ----------
    params : dict
        Nested tables ``camera``, ``laser``, ``range``, ``noise`` with every key filled in
        (defaults applied), as in the TOML file.
    name, description, mode : str
    source : str
        The preset name, file or "dict" the sensor came from.
    """

    params: Mapping[str, Mapping[str, Any]]
    name: str = "sensor"
    description: str = ""
    mode: str = "geometric"
    source: str = "dict"

    # -- convenient views of the parameters -------------------------------------------
    @property
    def width(self) -> int:
        return int(self.params["camera"]["width"])

    @property
    def height(self) -> int:
        return int(self.params["camera"]["height"])

    @property
    def focal_px(self) -> float:
        """Focal length in pixels, from the horizontal field of view."""
        return focal_px(self.width, self.params["camera"]["fov_deg"])

    @property
    def K(self) -> np.ndarray:
        """3x3 pinhole intrinsics; pixel (row i, col j) looks along K^-1 (j + .5, i + .5, 1)."""
        f = self.focal_px
        return np.array([[f, 0, self.width / 2], [0, f, self.height / 2], [0, 0, 1]], float)

    @property
    def laser_origin(self) -> np.ndarray:
        """(3,) laser origin in the camera frame, mm: on the camera's +x axis at ``baseline``."""
        return np.array([self.params["laser"]["baseline"], 0.0, 0.0])

    @property
    def reference_distance(self) -> float:
        """Distance (mm) at which a white target facing both the laser and the camera (at this distance
        from each) returns signal 1: ``range.reference``, else mid-range (:func:`reference_distance`)."""
        return reference_distance(self.params["range"])

    @property
    def tilt_rad(self) -> float:
        """Translating sweep: angle of the sheet from the optical axis, towards the camera (rad)."""
        laser = self.params["laser"]
        return sheet_tilt_rad(laser["tilt_deg"], laser["baseline"], self.reference_distance)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict with the TOML's keys (what ``load_sensor`` accepts back)."""
        out: dict[str, Any] = {"name": self.name, "description": self.description, "mode": self.mode}
        for table, values in self.params.items():
            out[table] = {k: v for k, v in values.items() if v is not None}
        return out

    def with_params(self, changes: Mapping[str, Any]) -> "Sensor":
        """A copy with dotted keys replaced, e.g. ``{"noise.sigma_px": 0, "laser.baseline": 90}``."""
        if not isinstance(changes, Mapping):
            raise RangesimError(f"with_params takes a mapping of dotted keys to values, got {type(changes).__name__}",
                                source=self.source)
        data = self.to_dict()
        for dotted, value in changes.items():
            table, _, key = dotted.partition(".")
            if not key:
                data[table] = value
            elif not isinstance(data.setdefault(table, {}), dict):
                raise RangesimError(f"cannot set {dotted}: {table!r} is not a table", source=self.source)
            else:
                data[table][key] = value
        source = str(self.source)
        # changed twice is still "modified", once; of the keys the mode does not read, only those
        # set here are news (a preset switched to another mode keeps its own, as the docs say)
        return sensor_from_dict(data, source=source if source.endswith(" (modified)") else f"{source} (modified)",
                                warn_unused=set(changes))


def sensor_from_dict(data: Mapping[str, Any], source: str = "dict", *, warn_unused: set[str] | None = None) -> Sensor:
    """Validate a sensor description and fill in defaults.

    Keys its mode does not read (:data:`UNUSED_BY_MODE`) set off their defaults get a one-line
    :class:`UnusedSensorKeyWarning`; with ``warn_unused``, only those among these dotted keys.

    Raises
    ------
    RangesimError
        Unknown tables or keys, missing required keys, or values out of range
        (non-positive resolution, field of view or baseline, near >= far, ...).
    """
    data = copy.deepcopy(dict(data))
    check_keys(data, TOP_KEYS, "the sensor", source)
    params: dict[str, dict[str, Any]] = {}
    for table, defaults in SCHEMA.items():
        given = data.get(table, {})
        if not isinstance(given, Mapping):
            raise RangesimError(f"[{table}] must be a table", source=source)
        check_keys(given, set(defaults), f"[{table}]", source)
        filled = {}
        for key, default in defaults.items():
            value = given.get(key, default)
            if value is None and default is None and key not in OPTIONAL_KEYS:
                raise RangesimError(f"missing required key {table}.{key}", source=source)
            filled[key] = value
        params[table] = filled
    for key in ("name", "description", "mode"):  # `name = 5` was taken as the name "5"
        if key in data and not isinstance(data[key], str):
            raise RangesimError(f"{key} must be a text in quotes, got {data[key]!r}", source=source)
    mode = str(data.get("mode", "geometric"))
    if mode not in MODES:
        raise RangesimError(
            f"mode {mode!r} is not available; available: {', '.join(MODES)}", source=source
        )
    _validate(params, source, mode)
    unused = [k for k in unused_keys(params, mode)
              if (k not in CARRIED_FOR_OTHER_MODES.get(mode, ()) if warn_unused is None else k in warn_unused)]
    if unused:  # a sweep or a --set over them would change nothing, silently
        warnings.warn(f"{source}: the {mode} mode does not use {', '.join(unused)}: {_WHY_UNUSED[mode]}; "
                      "they change nothing in its scans", UnusedSensorKeyWarning, stacklevel=3)
    return Sensor(
        params=params,
        name=str(data.get("name", Path(str(source)).stem)),
        description=str(data.get("description", "")),
        mode=mode,
        source=str(source),
    )


def _number(params, table, key, source, *, positive=False, nonneg=False, integer=False, upper=None):
    value = params[table][key]
    if isinstance(value, bool):  # float(True) == 1.0: a boolean is never meant as a number
        raise RangesimError(f"{table}.{key} must be a number, got {value!r}", source=source)
    if isinstance(value, str):  # float("0.5") would take a quoted TOML text as a number
        raise RangesimError(f"{table}.{key} must be a number, got the text {value!r} (write numbers without quotes)",
                            source=source)
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise RangesimError(f"{table}.{key} must be a number, got {value!r}", source=source) from None
    if not math.isfinite(number):
        raise RangesimError(f"{table}.{key} must be finite, got {value!r}", source=source)
    if positive and number <= 0:
        raise RangesimError(f"{table}.{key} must be positive, got {value!r}", source=source)
    if nonneg and number < 0:
        raise RangesimError(f"{table}.{key} must not be negative, got {value!r}", source=source)
    if upper is not None and number >= upper:
        raise RangesimError(f"{table}.{key} must be below {upper}, got {value!r}", source=source)
    if integer:
        if number != int(number):
            raise RangesimError(f"{table}.{key} must be an integer, got {value!r}", source=source)
        params[table][key] = int(number)
    else:
        params[table][key] = number


def _validate(params: dict[str, dict[str, Any]], source, mode: str = "geometric") -> None:
    for key in ("width", "height"):
        _number(params, "camera", key, source, positive=True, integer=True)
    _number(params, "camera", "fov_deg", source, positive=True, upper=180)
    _number(params, "camera", "aperture_mm", source, positive=True)
    if mode == "structured_light":  # the projector may sit on either side of the camera
        _number(params, "laser", "baseline", source)
        if params["laser"]["baseline"] == 0:
            raise RangesimError("laser.baseline must not be 0 (the projector's offset along the camera's x axis)",
                                source=source)
    else:
        _number(params, "laser", "baseline", source, positive=True)
    _number(params, "laser", "step", source, positive=True)
    _number(params, "laser", "stripe_width", source, nonneg=True)
    _number(params, "laser", "wavelength_nm", source, positive=True)
    if params["laser"]["tilt_deg"] is not None:
        _number(params, "laser", "tilt_deg", source)
        if abs(params["laser"]["tilt_deg"]) >= 89:
            raise RangesimError("laser.tilt_deg must lie within (-89, 89)", source=source)
    if params["laser"]["sweep"] not in SWEEPS:
        raise RangesimError(
            f"laser.sweep must be one of {', '.join(SWEEPS)}, got {params['laser']['sweep']!r}",
            source=source,
        )
    _number(params, "range", "near", source, positive=True)
    _number(params, "range", "far", source, positive=True)
    if params["range"]["near"] >= params["range"]["far"]:
        raise RangesimError(
            f"range.near ({params['range']['near']}) must be less than range.far "
            f"({params['range']['far']})",
            source=source,
        )
    if params["range"]["reference"] is not None:
        _number(params, "range", "reference", source, positive=True)
    for key in ("sigma_px", "quantization_px", "speckle_contrast", "signal_px", "correlation_mm", "edge_gain",
                "signal_contrast"):
        _number(params, "noise", key, source, nonneg=True)
    for key in ("speckle_contrast", "signal_contrast"):
        if params["noise"][key] > 1:  # the unit-mean Gamma's std; fully developed speckle is the exponential's 1
            raise RangesimError(f"noise.{key} must lie in [0, 1] (fully developed speckle has contrast 1, "
                                f"averaging over a pixel or the aperture lowers it), got {params['noise'][key]:g}",
                                source=source)
    cam = params["camera"]
    corr_px = params["noise"]["correlation_mm"] * focal_px(cam["width"], cam["fov_deg"]) / reference_distance(params["range"])
    if corr_px > max(cam["width"], cam["height"]):
        # a field correlated over more than the image is one offset of the whole scan (and its
        # smoothing kernel would outgrow memory): a calibration error, not speckle
        raise RangesimError(f"noise.correlation_mm = {params['noise']['correlation_mm']:g} mm is {corr_px:,.0f} px at "
                            f"the reference distance, more than the image's {max(cam['width'], cam['height'])} px; speckle "
                            "correlates over a few pixels", source=source)
    _number(params, "camera", "psf_px", source, nonneg=True)
    for key in ("theta_deg", "alpha_deg", "min_cos"):
        if params["twin"][key] is not None:
            _number(params, "twin", key, source)
    _number(params, "twin", "camera_views", source, positive=True, integer=True)
    if params["twin"]["camera_views"] not in (1, 2):
        raise RangesimError(f"twin.camera_views must be 1 or 2, got {params['twin']['camera_views']}", source=source)
    _number(params, "twin", "registration_mm", source, nonneg=True)
    _number(params, "twin", "registration_length_mm", source, nonneg=True)
    _number(params, "noise", "min_signal", source, nonneg=True)
    _number(params, "camera", "full_well_e", source, positive=True)
    _number(params, "camera", "read_noise_e", source, nonneg=True)
    _validate_render(params, source)
    _validate_structured_light(params, source)
    if mode == "structured_light":
        _validate_disparities(params, source)


def _validate_structured_light(params: dict[str, dict[str, Any]], source) -> None:
    sl = params["structured_light"]
    _number(params, "structured_light", "pattern_seed", source, nonneg=True, integer=True)
    for key in ("dot_density", "dot_sigma_px", "exposure_e"):
        _number(params, "structured_light", key, source, positive=True)
    if sl["dot_sigma_px"] > MAX_DOT_SIGMA_PX:
        raise RangesimError(f"structured_light.dot_sigma_px must be at most {MAX_DOT_SIGMA_PX:g} projector pixels "
                            f"(wider dots blur the pattern flat), got {sl['dot_sigma_px']:g}", source=source)
    if sl["dot_density"] > 1:
        raise RangesimError(f"structured_light.dot_density must be at most 1 dot per pixel, got {sl['dot_density']}",
                            source=source)
    _number(params, "structured_light", "dot_min_spacing_px", source, nonneg=True)
    from rangesim.sensor.dot_pattern import MAX_SPACED_COVERAGE, spaced_coverage

    coverage = spaced_coverage(sl["dot_density"], sl["dot_min_spacing_px"])
    if coverage > MAX_SPACED_COVERAGE:
        raise RangesimError(f"structured_light.dot_min_spacing_px = {sl['dot_min_spacing_px']:g} at dot_density "
                            f"{sl['dot_density']:g}: the dots' exclusion disks would cover {coverage:.2f} of the "
                            f"pattern, more than the {MAX_SPACED_COVERAGE} random placement reaches; lower either",
                            source=source)
    _number(params, "structured_light", "ambient", source, nonneg=True)
    # beyond these the image is saturated (or the pattern drowned) anyway, and NumPy's
    # Poisson draw refuses means above about 9e18 electrons
    if sl["exposure_e"] > MAX_EXPOSURE_E:
        raise RangesimError(f"structured_light.exposure_e must lie in (0, {MAX_EXPOSURE_E:.0e}] electrons, "
                            f"got {sl['exposure_e']:g}", source=source)
    if sl["ambient"] > MAX_AMBIENT:
        raise RangesimError(f"structured_light.ambient must lie in [0, {MAX_AMBIENT:g}] (relative to a dot's peak), "
                            f"got {sl['ambient']:g}", source=source)
    _number(params, "structured_light", "window", source, positive=True, integer=True)
    # (the detectors take the window as their scale: at most MAX_WINDOW_PX, as any window they take)
    if sl["window"] < 3 or sl["window"] % 2 == 0 or sl["window"] > MAX_WINDOW_PX:
        raise RangesimError(f"structured_light.window must be an odd integer from 3 to {MAX_WINDOW_PX}, "
                            f"got {sl['window']}", source=source)
    _number(params, "structured_light", "subpixel_steps", source, positive=True, integer=True)
    _number(params, "structured_light", "min_score", source, upper=1)
    if sl["min_score"] < -1:  # a ZNCC is never below -1: a lower threshold would silently switch the test off
        raise RangesimError(f"structured_light.min_score must lie in [-1, 1) (a normalised cross-correlation), "
                            f"got {sl['min_score']:g}", source=source)
    _number(params, "structured_light", "uniqueness", source, nonneg=True)
    if not isinstance(sl["lr_check"], bool):
        raise RangesimError(f"structured_light.lr_check must be true or false, got {sl['lr_check']!r}", source=source)
    _number(params, "structured_light", "speckle_window", source, nonneg=True, integer=True)
    _number(params, "structured_light", "speckle_range", source, nonneg=True)
    for key in ("match_sigma_px", "slant_linear", "slant_quadratic", "depth_unit_mm"):
        _number(params, "structured_light", key, source, nonneg=True)
    if sl["depth_unit_mm"] > params["range"]["near"]:
        raise RangesimError(f"structured_light.depth_unit_mm ({sl['depth_unit_mm']:g}) exceeds range.near "
                            f"({params['range']['near']:g} mm): every depth would round to a few values", source=source)


def _validate_disparities(params: dict[str, dict[str, Any]], source) -> None:
    """The disparities f |b| / z of the working range must span at least one sub-pixel step and at
    most :data:`MAX_SPAN_WIDTHS` image widths (structured-light mode; camera, laser and range
    already checked). What fits in memory is checked when a scan starts."""
    cam, rng = params["camera"], params["range"]
    width, near, far = cam["width"], rng["near"], rng["far"]
    f = focal_px(width, cam["fov_deg"])
    b = params["laser"]["baseline"]
    steps = params["structured_light"]["subpixel_steps"]
    fb = f * abs(b)
    d_lo, d_hi = fb / far, fb / near
    span = d_hi - d_lo
    implied = (f"disparities f |b| / z = {d_lo:.4g}-{d_hi:.4g} px over range.near-range.far = {near:g}-{far:g} mm "
               f"(f = {f:.1f} px from camera.width and camera.fov_deg, laser.baseline = {b:g} mm)")
    if span > MAX_SPAN_WIDTHS * width:
        # far beyond any device (a Kinect searches about 0.1 image widths, the bench preset 0.3):
        # the matcher's cost volume (pixels x disparities) and pattern grow out of all proportion
        raise RangesimError(f"{implied}: a search over {span:,.0f} px of disparity, more than {MAX_SPAN_WIDTHS} "
                            f"times the image's {width} columns; raise range.near or shorten laser.baseline",
                            source=source)
    if span * steps < 1:
        # one 1/steps px step covers the whole range: at most one depth level lies in it
        fix = ("lengthen laser.baseline" if d_hi < 1.0 / steps
               else "widen range.near-range.far or lengthen laser.baseline")
        raise RangesimError(f"{implied}: the range spans {span:.3g} px, less than one 1/{steps} px disparity step "
                            f"(structured_light.subpixel_steps; a step is {near * near / (steps * fb):.3g}-"
                            f"{far * far / (steps * fb):.3g} mm of depth here); {fix}", source=source)


def _validate_render(params: dict[str, dict[str, Any]], source) -> None:
    render = params["render"]
    if render["frames"] != "auto":
        _number(params, "render", "frames", source, positive=True, integer=True)
        if render["frames"] < 3:
            raise RangesimError(f"render.frames must be at least 3 or \"auto\", got {render['frames']}",
                                source=source)
    _number(params, "render", "spp", source, positive=True, integer=True)
    _number(params, "render", "max_depth", source, positive=True, integer=True)
    if not 2 <= render["max_depth"] <= MAX_RENDER_DEPTH:
        raise RangesimError(f"render.max_depth must lie in [2, {MAX_RENDER_DEPTH}] (2 = direct light only, 3 = one "
                            f"interreflection), got {render['max_depth']}", source=source)
    _number(params, "render", "exposure_e", source, positive=True)
    if render["exposure_e"] > MAX_EXPOSURE_E:  # saturated anyway; NumPy's Poisson draw refuses such means
        raise RangesimError(f"render.exposure_e must lie in (0, {MAX_EXPOSURE_E:.0e}] electrons, "
                            f"got {render['exposure_e']:g}", source=source)
    if not isinstance(render["image_noise"], bool):
        raise RangesimError(f"render.image_noise must be true or false, got {render['image_noise']!r}",
                            source=source)
    if render["peak"] not in PEAK_FITS:
        raise RangesimError(f"render.peak must be one of {', '.join(PEAK_FITS)}, got {render['peak']!r}",
                            source=source)


def preset_dirs() -> list[Path]:
    """Folders searched for preset names: ``$RANGESIM_SENSORS`` first, then ``sensors/``."""
    dirs = [Path(p) for p in os.environ.get("RANGESIM_SENSORS", "").split(os.pathsep) if p]
    for d in dirs:
        if not d.is_dir() and str(d) not in _WARNED_DIRS:  # a misspelt folder: its presets silently unfound
            import warnings

            _WARNED_DIRS.add(str(d))
            what = "a file, not a folder" if d.exists() else "no such folder"
            warnings.warn(f"RANGESIM_SENSORS: {d}: {what} (its presets are not searched)", stacklevel=2)
    return dirs + [PRESET_DIR]


#: the missing $RANGESIM_SENSORS folders warned about (once per process)
_WARNED_DIRS: set[str] = set()


def preset_names() -> list[str]:
    """Names of the available presets."""
    return sorted({p.stem for d in preset_dirs() if d.is_dir() for p in d.glob("*.toml")})


def load_sensor(spec: "str | Path | Mapping[str, Any] | Sensor") -> Sensor:
    """A :class:`Sensor` from a preset name, a TOML path, or a dict with the TOML's keys.

    Examples
    --------
    >>> sensor = load_sensor("white_scanner")
    >>> quiet = sensor.with_params({"noise.sigma_px": 0.0})
    """
    if isinstance(spec, Sensor):
        return spec
    if isinstance(spec, Mapping):
        return sensor_from_dict(spec, source="dict")
    text = str(spec)
    path = Path(text)
    if path.suffix.lower() == ".toml" or os.sep in text:
        data = read_toml(path)
        data.setdefault("name", path.stem)
        return sensor_from_dict(data, source=str(path))
    for folder in preset_dirs():
        candidate = folder / f"{text}.toml"
        if candidate.is_file():
            data = read_toml(candidate)
            data.setdefault("name", text)
            return sensor_from_dict(data, source=str(candidate))
    raise RangesimError(
        f"unknown sensor preset; available: {', '.join(preset_names()) or '(none found)'}",
        source=text,
    )
