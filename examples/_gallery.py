"""Shared plumbing of the example scripts: the ``--out``/``--small`` options, the shared data
folder, and running a ``rangesim`` command in this process.

Not an example itself; every script in this folder imports it (``python examples/NAME.py``
puts this folder on ``sys.path``).
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

#: the repository root (the scripts use the scene files in scenes/)
ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
#: where the README's figures live
DEFAULT_OUT = ROOT / "docs" / "images"


def parse_args(description: str, argv=None) -> argparse.Namespace:
    """``--out DIR`` (default docs/images/) and ``--small`` (small sizes, for the tests)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"folder for the figures (default: {DEFAULT_OUT.relative_to(ROOT)})")
    parser.add_argument("--small", action="store_true", help="small sizes: seconds, not the README's quality")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def data_dir() -> Path | None:
    """The shared recorded data: ``$RANGESIM_DATA``, else ``../shared/data`` beside the repository."""
    root = Path(os.environ.get("RANGESIM_DATA", ROOT.parent / "shared" / "data"))
    return root if root.is_dir() else None


def need_data(*relative: str) -> Path | None:
    """The shared data folder if it holds every ``relative`` path, else None (with a one-line note)."""
    root = data_dir()
    missing = [r for r in relative if root is None or not (root / r).exists()]
    if missing:
        where = root if root is not None else ROOT.parent / "shared" / "data"
        print(f"skipped: needs the shared data ({', '.join(missing)} under {where}; set RANGESIM_DATA)")
        return None
    return root


def rangesim(*argv: str) -> None:
    """Run one ``rangesim`` command (the CLI's own entry point) and stop on an error."""
    from rangesim.cli.main import main

    argv = [str(a) for a in argv]
    print("$ rangesim " + " ".join(argv), flush=True)
    code = main(argv)
    if code != 0:
        raise SystemExit(f"rangesim {argv[0]} failed with exit code {code}")


@contextmanager
def workdir():
    """A temporary folder for the intermediate files (scans, tables), removed afterwards."""
    path = Path(tempfile.mkdtemp(prefix="rangesim-example-"))
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def keep(source: Path, out: Path, name: str) -> Path:
    """Copy a picture a command wrote into the output folder under its README name."""
    target = Path(out) / name
    shutil.copyfile(source, target)
    print(f"wrote {target}")
    return target


def small_camera(small: bool, width: int = 160, height: int = 150) -> list[str]:
    """``--set`` options shrinking the camera for ``--small`` (none otherwise)."""
    return ["--set", f"camera.width={width}", "--set", f"camera.height={height}"] if small else []


if __name__ == "__main__":  # pragma: no cover
    sys.exit("this is a helper module; run one of the example scripts")
