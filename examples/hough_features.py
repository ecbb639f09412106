"""Hough features on an edge map: lines cut into segments, circles, arcs and model-guided
ellipses on the noise-free Green Piece, with their relations (figure ``features_green_piece.png``,
the paper's Fig. 16; the CSV and JSON the command writes are kept in a temporary folder).

Run: ``python examples/hough_features.py [--out DIR] [--small]``
"""
from __future__ import annotations

import json

from _gallery import SCENES, keep, parse_args, rangesim, small_camera, workdir


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    quiet = ["--set", "noise.sigma_px=0", "--set", "noise.speckle_contrast=0", "--set", "noise.quantization_px=0"]
    with workdir() as tmp:
        rangesim("scan", SCENES / "green_piece.toml", "--sensor", "white_scanner", "--out", tmp / "green.exr",
                 *quiet, *small_camera(args.small))
        rangesim("features", tmp / "green.exr", "--edges", "gradient", "--out", tmp / "features",
                 *(["--rmin", "2", "--rmax", "30"] if args.small else []))
        found = json.loads((tmp / "features" / "features.json").read_text())
        print("found: " + ", ".join(f"{len(v)} {k}" for k, v in found.items() if isinstance(v, list)))
        keep(tmp / "features" / "features.png", args.out, "features_green_piece.png")


if __name__ == "__main__":
    main()
