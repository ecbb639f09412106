"""The docstring examples: every ``>>>`` in the package runs (doctest, NumPy-style sections).

Collected per module (every module whose source holds ``>>>``) and run from the repository
root (the examples read ``scenes/...``). A module listed in :data:`KNOWN_BROKEN` is expected
to fail until its owner fixes the example.
"""
from __future__ import annotations

import doctest
import importlib
import pkgutil
from pathlib import Path

import pytest

import rangesim

ROOT = Path(__file__).resolve().parents[1]

#: module -> why its examples fail today (others own these modules; remove the entry when fixed)
KNOWN_BROKEN: dict[str, str] = {}


def _modules_with_examples() -> list[str]:
    names = ["rangesim"]
    for info in pkgutil.walk_packages(rangesim.__path__, "rangesim."):
        path = Path(importlib.util.find_spec(info.name).origin)
        if ">>>" in path.read_text(encoding="utf-8"):
            names.append(info.name)
    return sorted(n for n in names if n != "rangesim" or ">>>" in Path(rangesim.__file__).read_text())


MODULES = _modules_with_examples()


def test_the_examples_cover_the_readme_api():
    for name in ("rangesim.edges._gradient", "rangesim.features._circles", "rangesim.evaluate._edge_scores",
                 "rangesim.curvature.hk", "rangesim.volumes.gc", "rangesim.cad.bspline",
                 "rangesim.cad.machined", "rangesim.evaluate._visible"):
        assert name in MODULES, name


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, monkeypatch):
    monkeypatch.chdir(ROOT)
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(module, name) if t.examples]
    assert tests, f"{name} mentions >>> but doctest finds no example"
    for test in tests:
        runner.run(test, out=lambda text: print(text, end=""))
    results = runner.summarize(verbose=False)
    if name in KNOWN_BROKEN:
        if results.failed:
            pytest.xfail(KNOWN_BROKEN[name])
        pytest.fail(f"{name}'s examples pass now: remove it from KNOWN_BROKEN")
    assert results.failed == 0, f"{results.failed} of {results.attempted} examples failed in {name} (see stdout)"
