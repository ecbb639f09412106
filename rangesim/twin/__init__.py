"""Simulated twins of recorded scans, their calibration, and the comparison of the two."""
from rangesim.twin.stage import DEFAULT_PARAMS, TwinStage, twin
from rangesim.twin.calibrate import calibrate
from rangesim.twin.compare import compare, compare_scans

__all__ = ["DEFAULT_PARAMS", "TwinStage", "calibrate", "compare", "compare_scans", "twin"]
