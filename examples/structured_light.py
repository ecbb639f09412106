"""The structured-light mode (a Kinect-type sensor): the Green Piece seen by
``structured_light_bench``, depth by block matching of a projected dot pattern (README figure
``structured_light_green_piece.png``).

Run: ``python examples/structured_light.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _gallery import SCENES, parse_args, rangesim, small_camera, workdir


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    with workdir() as tmp:
        rangesim("scan", SCENES / "green_piece.toml", "--sensor", "structured_light_bench", "--out", tmp / "sl.exr",
                 "--preview", args.out / "structured_light_green_piece.png", *small_camera(args.small, 160, 120))


if __name__ == "__main__":
    main()
