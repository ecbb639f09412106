"""Experiments at scale: parameter sweeps, synthetic datasets, detectors against SNR.

Orchestration only: every task is one call into the library (``scan``, ground truth,
detectors, scores), run in this process, a local process pool or on Dask
(:mod:`~rangesim.experiments.executors`), resumable (each task's output is written
atomically under a key derived from its parameters) and deterministic (seeds derive from
the sweep seed and the task's parameters).

>>> from rangesim.experiments import run_sweep                      # doctest: +SKIP
>>> run = run_sweep("scenes/snr_sweep.toml", "results/")           # doctest: +SKIP
>>> run.table.groupby("detector")["f1"].median()                   # doctest: +SKIP
"""
from rangesim.experiments.dataset import DatasetRun, make_dataset
from rangesim.experiments.loader import SyntheticDataset
from rangesim.experiments.poses import cap_directions, sample_view
from rangesim.experiments.snr import EdgeSNR, depth_noise, edge_snr
from rangesim.experiments.sweep import SweepRun, run_sweep
from rangesim.experiments.sweep_file import SweepSpec, load_sweep

__all__ = [
    "DatasetRun", "EdgeSNR", "SweepRun", "SweepSpec", "SyntheticDataset", "cap_directions", "depth_noise",
    "edge_snr", "load_sweep", "make_dataset", "run_sweep", "sample_view",
]
