"""Curvature maps: Gaussian, mean, maximum and minimum curvature of a Coons patch built from
four wavy boundary curves (README figure ``coons_curvature.png``, the paper's Fig. 11), and the
Besl-Jain HK sign map of a scan computed from the data (printed).

Run: ``python examples/curvature_maps.py [--out DIR] [--small]``
"""
from __future__ import annotations

import numpy as np
from _gallery import SCENES, parse_args, rangesim

import rangesim as rs


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    rangesim("curvature", "--patch", "coons", "--resolution", 60 if args.small else 200,
             "--out", args.out / "coons_curvature.png")

    # curvature on data: a noise-free scan of the Green Piece, one quadric fit per pixel
    sensor = rs.load_sensor("white_scanner").with_params(
        {"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": 0,
         "camera.width": 128, "camera.height": 120})
    scan = rs.scan(rs.load_scene(SCENES / "green_piece.toml"), sensor, seed=0)
    curv = rs.curvature.curvature_scan(scan)
    signs = rs.curvature.hk_sign_map(curv["K"], curv["H"])
    kinds, counts = np.unique(signs[scan.valid], return_counts=True)
    print("HK sign map of the scan: " + ", ".join(
        f"{rs.curvature.surface_type_name(k)} {c}" for k, c in zip(kinds, counts)))


if __name__ == "__main__":
    main()
