"""Edges on range data and their scores against the exact ground truth: the gradient detector
on the Green Piece at the White Scanner's preset noise (README figure
``edges_green_piece_gradient.png``), and, where the shared data are present, on a recorded
Stanford bunny scan (``edges_bunny_gradient.png``) and an mOSD Kinect frame
(``edges_mosd_normal.png``).

The recorded scans need the shared data (``../shared/data``, or ``$RANGESIM_DATA``); without
them those two figures are skipped.

Run: ``python examples/edges_and_scores.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _gallery import SCENES, keep, need_data, parse_args, rangesim, workdir

import rangesim as rs
from rangesim.viz.edge_overlay import save_edge_overlay


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    # the Python API: scan, detect, score against the truth behind the synthetic scan
    scene = rs.load_scene(SCENES / "green_piece.toml")
    sensor = rs.load_sensor("white_scanner")
    if args.small:
        sensor = sensor.with_params({"camera.width": 160, "camera.height": 150})
    scan = rs.scan(scene, sensor, seed=0)
    truth = rs.ground_truth_edges(scan, scene)
    edges = rs.edges.gradient(scan)
    scores = rs.evaluate.edge_scores(edges, truth, tolerance_px=2)
    print(f"gradient on the Green Piece: precision {scores['precision']:.2f}, recall {scores['recall']:.2f}, "
          f"F1 {scores['f1']:.2f}")
    save_edge_overlay(scan, edges, args.out / "edges_green_piece_gradient.png")
    print(f"wrote {args.out / 'edges_green_piece_gradient.png'}")

    # recorded scans, from the command line (`rangesim detect`)
    data = need_data("stanford-bunny/bun000.ply", "mosd-kinect/test0.pcd")
    if data is None or args.small:  # recorded scans have their own size; --small keeps to the synthetic one
        return
    with workdir() as tmp:
        rangesim("detect", data / "stanford-bunny/bun000.ply", "--method", "gradient", "--out", tmp / "bunny")
        keep(tmp / "bunny" / "gradient.png", args.out, "edges_bunny_gradient.png")
        rangesim("detect", data / "mosd-kinect/test0.pcd", "--method", "normal", "--out", tmp / "mosd")
        keep(tmp / "mosd" / "normal.png", args.out, "edges_mosd_normal.png")


if __name__ == "__main__":
    main()
