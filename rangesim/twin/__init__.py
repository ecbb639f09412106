"""Simulated twins of recorded scans, their calibration, and the comparison of the two.

The package is callable: ``rs.twin(recorded, mesh, sensor)`` is :func:`rangesim.twin.twin`,
while ``rs.twin.compare``, ``rs.twin.calibrate`` and the modules (``rangesim.twin.joint``,
``rangesim.twin.realism``, ...) stay reachable as attributes, so the function does not shadow
its package.
"""
import sys
import types

from rangesim.twin.calibration import calibrate
from rangesim.twin.comparison import compare, compare_scans
from rangesim.twin.joint import calibrate_views
from rangesim.twin.stage import DEFAULT_PARAMS, TwinStage, twin

__all__ = ["DEFAULT_PARAMS", "TwinStage", "calibrate", "calibrate_views", "compare", "compare_scans", "twin"]


class _CallablePackage(types.ModuleType):
    """The package module, callable as :func:`twin` (``rs.twin(...)``)."""

    def __call__(self, *args, **kwargs):
        return twin(*args, **kwargs)


sys.modules[__name__].__class__ = _CallablePackage
