"""Helpers shared by the command modules: output checks and write-error reporting."""
from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.atomic import atomic_path
from rangesim.core.errors import RangesimError

#: the lengths ``--units`` accepts for a bare mesh file
MESH_UNITS = ("mm", "cm", "m", "in")


def check_suffix(path: Path, allowed: Sequence[str], what: str) -> None:
    """Reject an output extension before any work is done."""
    if path.suffix.lower() not in allowed:
        found = f"{path.suffix!r} files" if path.suffix else "files without an extension"
        raise RangesimError(
            f"cannot write {what} as {found}; supported: {', '.join(allowed)}", source=path
        )


@contextmanager
def writing(path: Path, tmp: Path | None = None) -> Iterator[None]:
    """Report a failed write against ``path``, not the temporary name the data went to."""
    try:
        yield
    except OSError as exc:
        reason = exc.strerror or str(exc)
        # mkdir under a regular file says "File exists" or "Not a directory": name the culprit
        blocker = next((p for p in path.parents if p.exists()), None)
        if blocker is not None and not blocker.is_dir():
            reason = f"{blocker} is not a directory"
        raise RangesimError(f"cannot write file ({reason})", source=path) from exc
    except RangesimError as exc:
        if tmp is None or str(tmp) not in str(exc):
            raise
        relabelled = RangesimError(str(exc).replace(str(tmp), str(path)))
        relabelled.source = str(path)
        raise relabelled from exc


def mesh_problem(path: Path) -> None:
    """Raise a one-line error naming what is wrong with a broken mesh file (truncated, empty, ...)."""
    from rangesim.io.mesh_check import diagnose_mesh_file

    if path.is_file():
        problem = diagnose_mesh_file(path)
        if problem is not None:
            raise RangesimError(problem, source=path)


def load_scene_arg(source: str, units: str | None = None, option: str = "--units"):
    """A scene from a scene .toml or a bare mesh file (with ``--units``), broken meshes named clearly."""
    from rangesim.cad.meshes import MESH_SUFFIXES
    from rangesim.scene import load_scene
    from rangesim.scene.scene import load_mesh_scene

    path = Path(source)
    is_mesh = path.suffix.lower() in MESH_SUFFIXES
    if units is not None and not is_mesh:
        if path.suffix.lower() != ".toml":
            load_scene(path)  # (no such file, or an unknown type: its own words, not the --units rule's)
        raise RangesimError(f"{option} applies to a bare mesh file; a scene .toml sets its own units "
                            "(units = ...)", source=path)
    if not is_mesh:
        return load_scene(path)
    mesh_problem(path)
    return load_mesh_scene(path, units)


def make_out_dir(path: Path, option: str = "--out") -> None:
    """Create an output folder; when folders above it are new too (a mistyped path), say so once on stderr."""
    import sys

    if not path.exists():
        missing = [p for p in path.parents if not p.exists()]
        with writing(path):
            path.mkdir(parents=True, exist_ok=True)
        if missing:
            print(f"rangesim: note: {option} {path}: created {missing[-1]} and the folders below it",
                  file=sys.stderr)
    elif not path.is_dir():
        raise RangesimError("output must be a directory", source=path)


def positive(name: str, value: float | None, *, allow_zero: bool = False, upper: float | None = None,
             at_most: float | None = None) -> None:
    """Reject a non-finite, negative (or zero) or too large (``>= upper``, ``> at_most``)
    numeric option, naming it."""
    import math

    if value is None:
        return
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        need = "a non-negative" if allow_zero else "a positive"
        raise RangesimError(f"{name} must be {need} number, got {value:g}")
    if upper is not None and value >= upper:
        raise RangesimError(f"{name} must be below {upper:g}, got {value:g}")
    if at_most is not None and value > at_most:
        raise RangesimError(f"{name} must be at most {at_most:g}, got {value:g}")


def build_model(name: str, param_texts: Sequence[str]):
    """A built-in CAD model from its name and ``--param KEY=VALUE`` texts (TOML values)."""
    import tomllib

    from rangesim.cad.models import MODELS, model_names

    if name not in MODELS:
        raise RangesimError(f"unknown model; built-in models: {', '.join(model_names())}", source=name)
    params = {}
    for text in param_texts:
        key, sep, raw = text.partition("=")
        if not sep:
            raise RangesimError(f"--param expects KEY=VALUE, got {text!r}")
        try:
            params[key.strip()] = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError as exc:
            raise RangesimError(f"--param {key}: not a TOML value: {raw!r}") from exc
    import warnings

    from rangesim.cad.models import check_model_params

    check_model_params(name, params)
    try:
        # numeric warnings of a build that then fails are noise before the one-line error
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            part = MODELS[name](**params)
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return part
    except RangesimError:
        raise
    except TypeError as exc:  # an unknown keyword
        raise RangesimError(f"--param: {exc}", source=name) from exc
    except (ValueError, ArithmeticError, IndexError, KeyError) as exc:  # numpy.linalg.LinAlgError included
        given = ", ".join(f"{k}={v!r}" for k, v in params.items())
        raise RangesimError(f"cannot build the model with --param {given} ({type(exc).__name__}: {exc})",
                            source=name) from exc


def write_together(writes: Sequence[tuple[Path, Callable[[Path], Any]]]) -> None:
    """Write several files: all of them, or none (old files stay as they were).

    Each ``write(tmp)`` fills a temporary name beside its ``path``; the renames onto the
    targets happen only once every file is written (the first file last), so a failed write
    or drawing leaves no new file behind. Check the targets first (:func:`check_writable`):
    a rename refused then would leave the files renamed before it.

    Parameters
    ----------
    writes : sequence of (path, write)
        Target and the function that writes the file to the path it is given.
    """
    import warnings

    with ExitStack() as stack:
        for path, write in writes:
            path = Path(path)
            stack.enter_context(writing(path))
            tmp = stack.enter_context(atomic_path(path))
            with writing(path, tmp), warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                write(tmp)
            for w in caught:  # about the file, not its temporary name
                text = str(w.message).replace(str(tmp), str(path)).replace(tmp.name, path.name)
                warnings.warn_explicit(text, w.category, w.filename, w.lineno)


def json_safe(value: Any) -> Any:
    """Plain JSON types: NumPy scalars to Python, non-finite floats to None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(float(value)) else None
    return value


def write_json(data: dict, path: Path) -> None:
    """``data`` as indented JSON at ``path``, written atomically (see :func:`writing`)."""
    with writing(path), atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(json_safe(data), indent=2) + "\n", encoding="utf-8")


def check_writable(path: Path | str, what: str = "file") -> None:
    """Refuse an output path that cannot be written, before any work or any other output.

    The path must not be a directory, the nearest existing folder above it must be a folder,
    and a file must be creatable there (tried with a temporary file that is removed at once:
    as root, ``os.access`` says yes to ``/proc``). Missing folders below it are fine (they are
    created when the file is written).
    """
    import tempfile

    path = Path(path)
    if path.is_dir():
        raise RangesimError(f"cannot write the {what}: a directory of that name exists", source=path)
    blocker = next((p for p in path.parents if p.exists()), None)
    if blocker is None:
        return
    if not blocker.is_dir():
        raise RangesimError(f"cannot write the {what} ({blocker} is not a directory)", source=path)
    try:
        with tempfile.TemporaryFile(dir=blocker, prefix=".rangesim-probe-"):
            pass
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise RangesimError(f"cannot write the {what} (cannot create files in {blocker}: {reason})",
                            source=path) from exc


def same_file(a: Path | str, b: Path | str) -> bool:
    """Whether two paths name one file: the same inode when both exist (hard and symbolic links
    included), else the same absolute path once links in the folders above are resolved."""
    a, b = Path(a), Path(b)
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return a.resolve() == b.resolve()


def check_outputs(outputs: Iterable[tuple[Path | str | None, str]],
                  inputs: Iterable[Path | str | None] = ()) -> None:
    """Refuse, before any work, outputs that cannot be written, that name one file twice or that
    would overwrite one of the command's inputs (``scan --out`` onto its own mesh, ``points
    --out`` onto the model it samples: the input was replaced with exit status 0).

    Parameters
    ----------
    outputs : iterable of (path or None, what)
        The files the command writes and a few words for each (``"scan"``, ``"preview"``);
        ``None`` paths (options not given) are skipped.
    inputs : iterable of path or None
        Files the command reads (scene, meshes it names, scan, pose or .conf files); ``None``
        and names that are no existing file (built-in model names) are skipped.
    """
    outs = [(Path(path), what) for path, what in outputs if path is not None]
    ins = [Path(p) for p in inputs if p is not None and Path(p).is_file()]
    for k, (path, what) in enumerate(outs):
        check_writable(path, what)
        for other, other_what in outs[:k]:
            if same_file(path, other):
                raise RangesimError(f"the {other_what} and the {what} would be the same file; give each its own name",
                                    source=path)
        for source in ins:
            if same_file(path, source):
                raise RangesimError(f"the {what} would overwrite {source}, an input of this command; "
                                    "write it under another name", source=path)


def check_out_files(folder: Path, names: Sequence[str], inputs: Iterable[Path | str | None] = ()) -> None:
    """The files a command writes into ``folder``: :func:`check_outputs` on each (none a
    directory or one of the command's ``inputs``, the folder creatable)."""
    check_outputs([(folder / name, name) for name in names], inputs)


def scene_files(scene: Any) -> list[str]:
    """The files a loaded scene was read from: its scene file (or bare mesh) and every mesh file
    its objects name (built-in models and primitives have none)."""
    files = [str(getattr(scene, "source", ""))]
    files += [str(getattr(obj, "source", "")) for obj in getattr(scene, "objects", ())]
    return [f for f in files if f and Path(f).is_file()]


def check_conf(scan_path: Path | str, conf: str | None) -> None:
    """``--conf`` (a Stanford pose file) goes with Stanford ``.ply`` range grids only."""
    if conf is None:
        return
    if Path(scan_path).suffix.lower() != ".ply":
        raise RangesimError(f"--conf applies to Stanford .ply range grids only (got --conf {conf} with a "
                            f"{Path(scan_path).suffix or 'suffix-less'} file)", source=scan_path)
    if not Path(scan_path).is_file():  # the recording first: a wrong folder misses both
        raise RangesimError("no such file", source=scan_path)
    if not Path(conf).is_file():
        raise RangesimError("no such --conf file", source=conf)


def is_point_list(scan) -> bool:
    """True for a scan read from an unorganized point list (a point .ply: one row of points,
    its unmeasured pixels absent; the readers say so in ``meta["organized"]``), not a grid of
    rows and columns (which may be one row: a scan of camera.height 1)."""
    return scan.meta.get("organized") is False


def require_grid(scan, path: Path | str, needs: str = "the edge detectors need", operators: bool = True) -> None:
    """Refuse a point list where a command needs an organized range image (rows and columns),
    and, for the edge detectors (``operators``), an image under 3 x 3 px."""
    h, w = scan.shape
    if is_point_list(scan):
        raise RangesimError(f"not an organized range image ({w:,} x {h:,} points): {needs} a "
                            "grid of rows and columns (a range-grid .ply, an organized .pcd, .exr, .npz)", source=path)
    if operators and min(h, w) == 1:  # a single row or column: no neighbours across it
        raise RangesimError(f"not an organized range image ({w:,} x {h:,} points): {needs} a "
                            "grid of rows and columns (a range-grid .ply, an organized .pcd, .exr, .npz)", source=path)
    if operators and min(h, w) < 3:  # their 3 x 3 operators have no interior pixel
        raise RangesimError(f"a {w} x {h} px image is too small for the edge detectors (at least 3 x 3)", source=path)
