"""The geometric and the rendered (path-traced) modes side by side: the Green Piece with
``white_scanner``, both noise-free, and rendered minus geometric depth (README figure
``green_piece_modes.png``; also the white-light image ``green_piece_white_light.png``).

The rendered mode needs libLLVM 19 on the CPU (``apt-get install libllvm19``); without it this
script says so and skips.

Run: ``python examples/scan_modes.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _gallery import SCENES, parse_args, rangesim, small_camera, workdir

from rangesim.core.errors import RangesimError
from rangesim.sensor import rendered

#: noise off in both modes, so the difference is the physics the rules cannot see (the rendered
#: frames' image noise too: a render key, set on the rendered scan only)
QUIET = ["--set", "noise.sigma_px=0", "--set", "noise.quantization_px=0", "--set", "noise.speckle_contrast=0"]
RENDERED = ["--set", "mode=rendered", "--set", "render.image_noise=false"]


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    try:
        rendered.check_backend()
    except RangesimError as exc:
        print(f"skipped: the rendered mode is not available here ({exc})")
        return
    scene = SCENES / "green_piece.toml"
    small = small_camera(args.small, 128, 120)
    rendered_small = ["--set", "render.spp=1"] if args.small else []
    with workdir() as tmp:
        rangesim("scan", scene, "--sensor", "white_scanner", "--out", tmp / "geo.exr", *QUIET, *small)
        rangesim("scan", scene, "--sensor", "white_scanner", "--out", tmp / "ren.exr", *QUIET, *small, *RENDERED,
                 *rendered_small, "--intensity-image", args.out / "green_piece_white_light.png")
        rangesim("diff", tmp / "geo.exr", tmp / "ren.exr", "--labels", "geometric", "rendered", "--limit", "0.5",
                 "--out", args.out / "green_piece_modes.png")


if __name__ == "__main__":
    main()
