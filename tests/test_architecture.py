"""The package's shape: no function shadows its module, the README's import paths work."""
from __future__ import annotations

import importlib
import pkgutil
import types

import pytest

import rangesim as rs

PACKAGES = ["cad", "cli", "core", "curvature", "edges", "evaluate", "experiments", "features", "io", "recorded",
            "scene", "sensor", "twin", "viz", "volumes"]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_public_name_shadows_a_module(package):
    pkg = importlib.import_module(f"rangesim.{package}")
    for info in pkgutil.iter_modules(pkg.__path__):
        attr = getattr(pkg, info.name, None)
        assert attr is None or isinstance(attr, types.ModuleType), f"rangesim.{package}.{info.name} is a {attr!r}"
        assert isinstance(importlib.import_module(f"rangesim.{package}.{info.name}"), types.ModuleType)


def test_twin_is_a_callable_package():
    assert callable(rs.twin) and isinstance(rs.twin, types.ModuleType)
    assert rs.twin.compare is importlib.import_module("rangesim.twin.comparison").compare
    assert rs.twin.twin is importlib.import_module("rangesim.twin.stage").twin


def test_readme_api_paths():
    for name in ("load_scene", "load_sensor", "scan", "load_scan", "save_scan", "twin", "calibrate",
                 "ground_truth_edges", "intensity_image", "__version__"):
        assert hasattr(rs, name), name
    from rangesim.edges import DETECTORS, estimate_depth_noise, gradient, link  # noqa: F401
    from rangesim.experiments import SyntheticDataset, make_dataset, run_sweep  # noqa: F401
    from rangesim.features import circles, ellipses, lines  # noqa: F401
    assert callable(rs.cad.green_piece) and callable(rs.evaluate.edge_scores) and callable(rs.volumes.generalized_cylinders)
    assert rs.__version__ == importlib.import_module("rangesim.core.version").__version__
