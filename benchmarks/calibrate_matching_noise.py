#!/usr/bin/env python
"""Calibrate the block matcher's predicted noise law on scans of tilted planes.

The structured-light presets state the disparity error of their matcher as
(``rangesim.sensor.matching_noise``)::

    sigma_d = sqrt(s0^2 + (a s)^2 + (c s^2)^2)  px,   s = window x disparity gradient

(s0 ``structured_light.match_sigma_px``, a ``slant_linear``, c ``slant_quadratic``). This
script measures it: a large plane, tilted by 5-74 degrees about the camera's x axis, its y
axis and their diagonal, is scanned at two distances per preset with the preset's own noise;
on the central valid pixels the disparity error f |b| (1 / z - 1 / z_true) has a std (clipped at
4 std: chance matches left out) and the plane a disparity gradient g (uniform on a plane). The law is
fitted to those std by least squares on their logarithms. Nothing here looks at the parts
the detectors are benchmarked on, nor at recordings: the law predicts the simulator's own
matcher (``scan.sigma``), which the detectors' thresholds read.

Usage::

    python benchmarks/calibrate_matching_noise.py [--sensors kinect_v1,structured_light_bench]
                                                  [--seed 0] [--json OUT.json]

Prints each plane's measured and predicted std (the preset's constants and the fit), and the
fitted constants per preset.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import trimesh
from scipy.optimize import least_squares

import rangesim as rs
from rangesim.core.geometry import look_at
from rangesim.sensor.matching_noise import matching_sigma_px
from rangesim.twin.realism import clipped_std

HERE = Path(__file__).resolve().parent
#: 5 degrees, not 0: a plane square to the camera has one disparity, so one sub-pixel phase
TILTS_DEG = (5, 15, 30, 45, 55, 62, 68, 74)
#: tilt axes in the camera frame of a camera looking down at the plane (x, y, their diagonal)
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "xy": (math.sqrt(0.5), math.sqrt(0.5), 0.0)}


def distances(sensor) -> tuple[float, float]:
    """Two viewing distances per preset: a quarter and three quarters into its working range, mm."""
    near, far = sensor.params["range"]["near"], sensor.params["range"]["far"]
    return near + 0.25 * (far - near), near + 0.75 * (far - near)


def plane_error_std(sensor, tilt_deg: float, axis, distance: float, seed: int) -> tuple[float, float, int]:
    """(g, std of the disparity error px, valid pixels) of one tilted plane."""
    size = 20.0 * distance
    sheet = trimesh.Trimesh(np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float) * [size / 2, size / 2, 1],
                            np.array([[0, 1, 2], [0, 2, 3]]), process=False)
    sheet.apply_transform(trimesh.transformations.rotation_matrix(math.radians(tilt_deg), axis))
    pose = look_at((0, 0, distance), (0, 0, 0), up=(0, 1, 0))
    scan = rs.scan([sheet], sensor, pose=pose, seed=seed)
    fb = sensor.focal_px * abs(sensor.params["laser"]["baseline"])
    h, w = scan.shape
    rows, cols = np.mgrid[:h, :w]
    centre = (np.abs(rows - h / 2) < h / 4) & (np.abs(cols - w / 2) < w / 4) & scan.valid
    z, z_true = scan.depth[centre].astype(np.float64), scan.xyz_true[..., 2][centre].astype(np.float64)
    error = fb / z - fb / z_true
    # the plane's disparity gradient, b |n_xy| / |n . X| (uniform: n . X is the plane's offset)
    normal = scan.normal[centre].astype(np.float64)
    points = scan.xyz_true[centre].astype(np.float64)
    g = np.median(abs(sensor.params["laser"]["baseline"]) * np.hypot(normal[:, 0], normal[:, 1])
                  / np.abs(np.einsum("ik,ik->i", normal, points)))
    return float(g), clipped_std(error), int(centre.sum())


def fit_law(s: np.ndarray, sigma: np.ndarray) -> tuple[float, float, float]:
    """s0, a, c of sqrt(s0^2 + (a s)^2 + (c s^2)^2) fitted to ``sigma`` in log space."""
    def residual(p):
        s0, a, c = np.abs(p)
        return np.log(np.sqrt(s0**2 + (a * s) ** 2 + (c * s * s) ** 2)) - np.log(sigma)

    fit = least_squares(residual, x0=[0.08, 0.09, 0.036])
    return tuple(float(v) for v in np.abs(fit.x))


def calibrate(name: str, seed: int) -> dict:
    sensor = rs.load_sensor(name)
    sl = sensor.params["structured_light"]
    window = int(sl["window"])
    rows = []
    for distance in distances(sensor):
        for axis_name, axis in AXES.items():
            for tilt in TILTS_DEG:
                g, std, n = plane_error_std(sensor, tilt, axis, distance, seed)
                if n < 2000:
                    continue  # too few matched pixels for a std (a dropout-limited tilt)
                rows.append({"distance_mm": round(distance, 1), "axis": axis_name, "tilt_deg": tilt,
                             "s_px": window * g, "std_px": std, "n": n})
    s = np.array([r["s_px"] for r in rows])
    sigma = np.array([r["std_px"] for r in rows])
    s0, a, c = fit_law(s, sigma)
    preset = (sl["match_sigma_px"], sl["slant_linear"], sl["slant_quadratic"])
    for r in rows:
        r["preset_law_px"] = float(matching_sigma_px(np.array(r["s_px"] / window), window, *preset))
        r["fitted_law_px"] = float(matching_sigma_px(np.array(r["s_px"] / window), window, s0, a, c))
    return {"sensor": name, "seed": seed, "preset": dict(zip(("s0", "a", "c"), preset)),
            "fit": {"s0": round(s0, 4), "a": round(a, 4), "c": round(c, 4)}, "planes": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensors", default="kinect_v1,structured_light_bench")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    out = []
    for name in args.sensors.split(","):
        res = calibrate(name, args.seed)
        out.append(res)
        print(f"\n{name}: preset s0 {res['preset']['s0']}, a {res['preset']['a']}, c {res['preset']['c']}"
              f" -> fitted s0 {res['fit']['s0']}, a {res['fit']['a']}, c {res['fit']['c']}\n")
        print("| distance mm | axis | tilt deg | s px | measured std px | preset law | fitted law |")
        print("|---|---|---|---|---|---|---|")
        for r in res["planes"]:
            print(f"| {r['distance_mm']:.0f} | {r['axis']} | {r['tilt_deg']} | {r['s_px']:.2f} | {r['std_px']:.3f} | "
                  f"{r['preset_law_px']:.3f} | {r['fitted_law_px']:.3f} |")
        worst = max(abs(r["fitted_law_px"] / r["std_px"] - 1) for r in res["planes"])
        print(f"\nfitted law within {100 * worst:.0f} % of every plane")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
