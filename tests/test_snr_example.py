"""The README's SNR figure (examples/snr_sweep.py): the sweep it runs is scenes/snr_sweep.toml
with fewer views, every noise level, detector and the full camera kept (issue 20: each example
runs on 2 cores in under a minute; the full sweep takes about 75 s)."""
from __future__ import annotations

import sys
from pathlib import Path

from rangesim.experiments.sweep_file import load_sweep

EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "examples"


def test_figure_sweep_is_the_sweep_file_with_three_views(tmp_path):
    if str(EXAMPLES_DIR) not in sys.path:
        sys.path.insert(0, str(EXAMPLES_DIR))
    import snr_sweep

    full = load_sweep(EXAMPLES_DIR.parent / "scenes" / "snr_sweep.toml")
    figure = load_sweep(snr_sweep.figure_sweep(tmp_path))
    assert figure.views == snr_sweep.FIGURE_VIEWS == 3 and full.views == 5
    assert figure.n_tasks == 24
    for name in ("grid", "fixed", "pose", "detectors", "seed", "tolerance_px", "crease_deg", "snr_window"):
        assert getattr(figure, name) == getattr(full, name), name
    assert [s.label for s in figure.sensors] == [s.label for s in full.sensors]
    assert [(s.label, s.sha1) for s in figure.scenes] == [(s.label, s.sha1) for s in full.scenes]
