"""The example gallery (examples/): every script runs with ``--small`` and writes its figures.

Each script runs in this process (``examples/make_figures.py`` loads it and calls its
``main``), on small sizes, into a temporary folder. The rendered-mode example is skipped
without libLLVM 19 (as tests/test_rendered.py is), the twin example without the shared data.
"""
from __future__ import annotations

import importlib.util
import re
import struct
import sys
from pathlib import Path

import pytest

from rangesim.core.errors import RangesimError

EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "examples"


def _make_figures():
    if str(EXAMPLES_DIR) not in sys.path:
        sys.path.insert(0, str(EXAMPLES_DIR))
    spec = importlib.util.spec_from_file_location("rangesim_make_figures", EXAMPLES_DIR / "make_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


make_figures = _make_figures()

#: what each script writes with --small (the recorded-data edge figures are full-size only)
SMALL = {name: figures for name, figures in make_figures.EXAMPLES.items()}
SMALL["edges_and_scores"] = ("edges_green_piece_gradient.png",)
SMALL["twin_of_a_recording"] = ("compare_mosd_test31.png",)


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; fails on anything that is not a PNG."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path.name} is not a PNG"
    return struct.unpack(">II", head[16:24])


def test_every_script_is_listed_and_every_readme_figure_has_a_script():
    scripts = {p.stem for p in EXAMPLES_DIR.glob("*.py")} - {"_gallery", "make_figures"}
    assert scripts == set(make_figures.EXAMPLES)
    readme = (EXAMPLES_DIR.parent / "README.md").read_text(encoding="utf-8")
    made = {f for figures in make_figures.EXAMPLES.values() for f in figures}
    linked = set(re.findall(r"\]\(docs/images/([\w.-]+\.png)\)", readme))
    assert len(linked) >= 16
    assert linked <= made, f"README figures without a script: {sorted(linked - made)}"


@pytest.mark.parametrize("name", list(SMALL))
def test_example_writes_its_figures(name, tmp_path, monkeypatch):
    if name == "scan_modes":
        from rangesim.sensor import rendered

        try:
            rendered.check_backend()
        except RangesimError as exc:  # .ci/run installs Debian's libllvm19
            pytest.skip(str(exc))
    if name == "twin_of_a_recording":
        data = make_figures.load("_gallery").need_data("mosd-kinect/test31.pcd")
        if data is None:
            pytest.skip("shared data not found (set RANGESIM_DATA)")
    monkeypatch.chdir(tmp_path)  # nothing may land in the working directory
    make_figures.run(name, tmp_path / "out", small=True)
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == sorted(SMALL[name])
    for figure in SMALL[name]:
        width, height = png_size(tmp_path / "out" / figure)
        assert width >= 100 and height >= 100, (figure, width, height)
    assert list(tmp_path.iterdir()) == [tmp_path / "out"]
