"""An SNR sweep: the Green Piece with ``white_scanner`` at stripe-peak noise from 0 to 3.2 px,
all five edge detectors scored against the exact ground truth (README figure
``snr_sweep_f1.png``), and the picture of the SNR definitions (``snr_definition.png``).

The sweep is ``scenes/snr_sweep.toml`` with three views per noise level instead of five
(24 scans, about 45 s on 2 idle cores, where the file's 40 take 75 s): each scan costs about
3.4 s of one core (the five detectors 2.3 s, the ground truth 0.5 s, the scan 0.3 s, the SNR
0.07 s), so the views are what an example can spare. The eight noise levels, the full camera
and every detector stay; the median line and the band are then over three views.

``--small`` sweeps a 128 x 120 camera at three noise levels, one view each, two detectors.

Run: ``python examples/snr_sweep.py [--out DIR] [--small]``
"""
from __future__ import annotations

import re
import shutil

from _gallery import SCENES, keep, parse_args, rangesim, workdir

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
#: views per noise level in the README figure (the sweep file has 5)
FIGURE_VIEWS = 3


def figure_sweep(folder, views: int = FIGURE_VIEWS):
    """``scenes/snr_sweep.toml`` with ``views`` views per level, written into ``folder`` with
    the scene file it names (so the figure's panel keeps its short title); returns its path."""
    text = (SCENES / "snr_sweep.toml").read_text()
    text, n_views = re.subn(r"(?m)^views\s*=\s*\d+", f"views = {int(views)}", text)
    scenes = re.findall(r'(?m)^scenes\s*=\s*\[(.*)\]', text)
    if n_views != 1 or len(scenes) != 1:
        raise SystemExit("scenes/snr_sweep.toml changed shape: update examples/snr_sweep.py")
    for name in re.findall(r'"([^"]+)"', scenes[0]):
        shutil.copyfile(SCENES / name, folder / name)
    path = folder / "snr_sweep.toml"
    path.write_text(text)
    return path


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
            sweep, workers = figure_sweep(tmp), []
        rangesim("sweep", sweep, "--out", tmp / "snr", "--quiet", *workers)
        keep(tmp / "snr" / "plots" / "f1_vs_snr.png", args.out, "snr_sweep_f1.png")


if __name__ == "__main__":
    main()
