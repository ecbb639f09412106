"""Scan a part and look at it: the Green Piece with the White Scanner, the Renault Piece with
the INRIA laser range finder (README figures ``green_piece_scan.png``, ``renault_piece_scan.png``).

Run: ``python examples/scan_a_part.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _gallery import SCENES, parse_args, rangesim, small_camera, workdir

import rangesim as rs
from rangesim.viz import save_preview


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    with workdir() as tmp:
        # the Python API: scene, sensor, scan, picture
        scene = rs.load_scene(SCENES / "green_piece.toml")
        sensor = rs.load_sensor("white_scanner")
        if args.small:
            sensor = sensor.with_params({"camera.width": 160, "camera.height": 150})
        scan = rs.scan(scene, sensor, seed=0)
        print(f"green piece: {scan.shape[1]} x {scan.shape[0]} px, {scan.valid.mean():.1%} valid, "
              f"{scan.count(rs.Status.SHADOW):,} px laser shadow")
        scan.save(tmp / "green.exr")
        save_preview(scan, args.out / "green_piece_scan.png")
        print(f"wrote {args.out / 'green_piece_scan.png'}")

        # the same from the command line
        rangesim("scan", SCENES / "renault_piece.toml", "--sensor", "inria_laser", "--out", tmp / "renault.exr",
                 "--preview", args.out / "renault_piece_scan.png", *small_camera(args.small))


if __name__ == "__main__":
    main()
