"""``python -m rangesim.docs``: rebuild the README's figures (runs ``examples/make_figures.py``).

The example scripts live in the repository's ``examples/`` folder, beside the package (an
editable install or a source checkout); the options are those of ``make_figures.py``:
``--out DIR`` (default ``docs/images/``), ``--small``, ``--only NAME ...``.

This module imports no other part of :mod:`rangesim` (the scripts do, when they run), so it
sits outside the layers of ``pyproject.toml``.
"""
from __future__ import annotations

import runpy
import sys
from pathlib import Path

#: the gallery: examples/ in the checkout this package was imported from
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def main(argv: list[str] | None = None) -> int:
    """Run ``examples/make_figures.py`` with ``argv`` (default ``sys.argv[1:]``); its exit code."""
    script = EXAMPLES / "make_figures.py"
    if not script.is_file():
        print(f"rangesim.docs: error: {script} not found (the examples come with a source checkout)",
              file=sys.stderr)
        return 2
    module = runpy.run_path(str(script), run_name="rangesim_make_figures")
    return module["main"](sys.argv[1:] if argv is None else list(argv))


if __name__ == "__main__":
    sys.exit(main())
