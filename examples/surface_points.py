"""Surface points at a resolution (paper, section 3): the Green Piece sampled every 0.2 inch,
with normals interpolated from the vertices and the
segment ends thinned to the resolution (README figure ``green_piece_points.png``, the
paper's Fig. 10).

Run: ``python examples/surface_points.py [--out DIR] [--small]``
"""
from __future__ import annotations

import numpy as np
from _gallery import parse_args, rangesim, workdir

import rangesim as rs


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    resolution = "0.5in" if args.small else "0.2in"
    with workdir() as tmp:
        rangesim("points", "green_piece", "--resolution", resolution, "--ends", "thin",
                 "--out", tmp / "points.ply", "--preview", args.out / "green_piece_points.png")

    # the same in Python, with the guarantee the sampler gives: neighbours within spacing * sqrt(3)
    part = rs.cad.green_piece()
    spacing = rs.core.units.parse_length(resolution)
    samples = rs.cad.surface_points(part.mesh, spacing, ends="thin")
    from scipy.spatial import cKDTree

    gap = cKDTree(samples.points).query(samples.points, k=2)[0][:, 1].max()
    print(f"{len(samples):,} points at {spacing:.2f} mm; largest nearest-neighbour gap {gap:.2f} mm "
          f"<= {spacing * np.sqrt(3):.2f} mm")


if __name__ == "__main__":
    main()
