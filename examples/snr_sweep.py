"""An SNR sweep: the Green Piece with ``white_scanner`` at stripe-peak noise from 0 to 3.2 px,
five views per level, all five edge detectors scored against the exact ground truth
(``scenes/snr_sweep.toml``, 40 scans, about 50 s on 2 cores; README figure
``snr_sweep_f1.png``), and the picture of the SNR definitions (``snr_definition.png``).

``--small`` sweeps a 128 x 120 camera at three noise levels, one view each, two detectors.

Run: ``python examples/snr_sweep.py [--out DIR] [--small]``
"""
from __future__ import annotations

from _common import SCENES, keep, parse_args, rangesim, workdir

from rangesim.viz.sweep_plots import plot_snr_definition

SMALL_SWEEP = f"""
scenes = ["{(SCENES / 'green_piece.toml').as_posix()}"]
sensors = ["white_scanner"]
views = 1
seed = 0
detectors = ["gradient", "normal"]
[set]
"noise.speckle_contrast" = 0
"camera.width" = 128
"camera.height" = 120
[pose]
cap_deg = 20
distance = [320, 380]
[grid]
"noise.sigma_px" = [0, 0.2, 1.6]
"""


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv)
    plot_snr_definition(args.out / "snr_definition.png")
    print(f"wrote {args.out / 'snr_definition.png'}")
    with workdir() as tmp:
        if args.small:
            sweep = tmp / "small_sweep.toml"
            sweep.write_text(SMALL_SWEEP)
            workers = ["--workers", "0"]  # in this process: no pool to start for three scans
        else:
            sweep, workers = SCENES / "snr_sweep.toml", []
        rangesim("sweep", sweep, "--out", tmp / "snr", "--quiet", *workers)
        keep(tmp / "snr" / "plots" / "f1_vs_snr.png", args.out, "snr_sweep_f1.png")


if __name__ == "__main__":
    main()
