"""Volumes and generalized cylinders (paper, section 6): the Green Piece's part tree with its
Boolean expressions (README figure ``part_tree_green_piece.png``), a deformed ellipsoid after
1, 3 and 5 recursions of the splitting (``gc_recursions.png``, the paper's Fig. 18), its
generalized cylinder (``gc_ellipsoid.png``), and the Renault Piece's heads, neck and bump
(``gc_renault.png``).

Run: ``python examples/volumes_and_cylinders.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _gallery import parse_args, rangesim, workdir

import rangesim as rs
from rangesim.viz.volumes import save_gc_figure, save_gc_recursions
from rangesim.volumes.shapes import deformed_ellipsoid

ABOVE, SIDE = (90, -90), (0, -90)  # (elevation, azimuth) of the second panels


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    with workdir() as tmp:
        rangesim("volumes", "green_piece", "--out", tmp / "tree.json", "--picture", args.out / "part_tree_green_piece.png")

    resolution = 4.0  # mm: axis segments shorter than this are not split further
    ellipsoid, _ = deformed_ellipsoid(subdivisions=3 if args.small else 4)
    save_gc_recursions(ellipsoid, args.out / "gc_recursions.png", resolution)
    gcs = rs.volumes.generalized_cylinders(ellipsoid, resolution)
    n = sum(len(g.sections) for g in gcs)
    save_gc_figure([(f"deformed ellipsoid: GC, {n} sections", gcs, ellipsoid), ("side view", gcs, ellipsoid, SIDE)],
                   args.out / "gc_ellipsoid.png")

    part = rs.cad.renault_piece()
    gcs = rs.volumes.generalized_cylinders(part.mesh, 8.0 if args.small else 3.0, parts=part)
    for g in gcs:
        print(f"{g.name}: {len(g.sections)} sections, {len(g.junctions)} junctions")
    shown = [g for g in gcs if g.name != "base_plate"]  # the plate is drawn as the surface
    save_gc_figure([("Renault Piece: heads, neck, bump", shown, part.mesh), ("from above", shown, part.mesh, ABOVE)],
                   args.out / "gc_renault.png")
    for name in ("gc_recursions.png", "gc_ellipsoid.png", "gc_renault.png"):
        print(f"wrote {args.out / name}")


if __name__ == "__main__":
    main()
