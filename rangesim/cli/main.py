"""The ``rangesim`` command: scan a scene, list sensor presets, describe a scan file.

A thin layer over the library: every command is one call into :mod:`rangesim`, and every
user error (a :class:`~rangesim.core.errors.RangesimError`, an ``OSError``, Ctrl-C) is
reported as one line ``rangesim: error: <message>`` on stderr, without a traceback
(``RANGESIM_DEBUG=1`` adds one).

Exit codes: 0 success, 2 user error (bad input, bad file, bad option), 1 internal error,
130 interrupted.

Examples
--------
::

    rangesim scan scenes/green_piece.toml --sensor white_scanner --out out/scan.exr \\
        --preview out/scan.png --set noise.sigma_px=0
    rangesim sensors
    rangesim info out/scan.exr
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import time
import tomllib
import traceback
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from rangesim import __version__
from rangesim.cli.common import (
    MESH_UNITS,
    check_outputs,
    check_suffix,
    is_point_list,
    load_scene_arg,
    scene_files,
    write_together,
)
from rangesim.core.constants import Status, status_name
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import check_pose
from rangesim.core.memory import check_memory, format_bytes
from rangesim.core.rangescan import RangeScan
from rangesim.core.signals import signal_handler
from rangesim.io import load_scan, save_scan
from rangesim.sensor import intensity_image, load_sensor, preset_names, scan
from rangesim.sensor._scan import BASE_BYTES, EmptyScanWarning
from rangesim.sensor.bands import RESULT_BYTES_PER_PIXEL
from rangesim.viz import save_preview
from rangesim.viz.intensity import save_intensity_image

PROG = "rangesim"
DEFAULT_SENSOR = "white_scanner"
#: extensions ``save_scan`` writes and ``save_preview`` accepts, checked before any work
SCAN_SUFFIXES = (".exr", ".npz", ".ply", ".pcd")  # .pcd: an organized PCD (rangesim.recorded)
PREVIEW_SUFFIXES = (".png",)

EXIT_OK, EXIT_INTERNAL, EXIT_USER, EXIT_INTERRUPTED = 0, 1, 2, 130
#: the shell's status for a process ended by SIGTERM (128 + 15)
EXIT_TERMINATED = 143


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, a batch system) raised as an interrupt, so every ``finally``
    and atomic write cleans up (temporary files removed, worker pools stopped) as on Ctrl-C."""


def _terminate(signum, frame) -> None:  # noqa: ARG001 -- a signal handler's signature
    raise Terminated()



#: modules adding subcommands: each has ``register(subparsers)`` that sets ``func`` (args -> exit code)
COMMAND_MODULES: tuple[str, ...] = (
    "rangesim.cli.cad_commands", "rangesim.cli.curvature_commands", "rangesim.cli.points_commands",
    "rangesim.cli.edge_commands", "rangesim.cli.feature_commands", "rangesim.cli.volume_commands",
    "rangesim.cli.compare_commands", "rangesim.cli.calibrate_commands", "rangesim.cli.experiment_commands",
    "rangesim.cli.diff_commands",
)


# -- small helpers ----------------------------------------------------------------------
def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _debug() -> bool:
    return os.environ.get("RANGESIM_DEBUG", "") not in ("", "0")


def _printable(text: str) -> str:
    """Control characters and raw bytes of a broken file escaped (\\x1b), never sent to the terminal."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _new_folders(args: argparse.Namespace) -> list[Path]:
    """The ``--out`` path (absolute, ``..`` resolved) and the folders above it that do not exist
    yet, deepest first: a run that fails removes those it left empty (:func:`_remove_empty`).
    Nothing where the path cannot even be looked at (too long a name: the run says so itself)."""
    out = getattr(args, "out", None)
    if not isinstance(out, (str, Path)) or not str(out):
        return []
    try:
        path = Path(os.path.abspath(out))
        return [p for p in (path, *path.parents) if not p.exists() and not p.is_symlink()]
    except (OSError, ValueError):
        return []


def _remove_empty(folders: list[Path]) -> None:
    """Remove the empty folders a failed run made: ``folders`` did not exist before it (the
    output first, then the new folders above it). Inside the output folder, which is the run's
    own, every empty folder goes (dataset's views/); above it only the new folders themselves,
    each if empty (not what another process made in them meanwhile)."""
    for k, top in enumerate(folders):
        try:
            if not top.is_dir() or top.is_symlink():
                continue
            below = os.walk(top, topdown=False) if k == 0 else [(str(top), [], [])]
            for root, _, _ in below:  # (children first: a parent empties as they go)
                try:
                    Path(root).rmdir()
                except OSError:  # not empty
                    pass
        except OSError:
            pass


def _error(message: str) -> None:
    print(f"{PROG}: error: {_printable(_one_line(message))}", file=sys.stderr)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` of the command line: ``rangesim: warning: <message>`` on one line."""
    print(f"{PROG}: warning: {_printable(_one_line(str(message)))}", file=sys.stderr if file is None else file)


def _os_error_message(exc: OSError) -> str:
    """``<file>: <reason>`` for an OSError (``[Errno 13] ...`` reads badly)."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    return f"{exc.filename}: {reason}" if exc.filename else reason


def _parse_setting(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` from ``--set``; VALUE is a TOML value, or a plain string if not one.

    Examples
    --------
    >>> _parse_setting("noise.sigma_px=0"), _parse_setting("laser.sweep=translating")
    (('noise.sigma_px', 0), ('laser.sweep', 'translating'))
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise RangesimError(f"--set expects KEY=VALUE (e.g. noise.sigma_px=0), got {text!r}")
    try:
        document = tomllib.loads(f"value = {raw}")
    except tomllib.TOMLDecodeError:
        return key, raw.strip()  # a bare word such as `translating`
    if set(document) != {"value"}:  # e.g. "1\nother = 2": more than one value
        raise RangesimError(f"--set {key}: not a single value: {raw!r}")
    return key, document["value"]


def _load_pose(path: Path) -> np.ndarray:
    """A 4x4 camera-to-world matrix from ``.npy`` or ``.json`` (nested list, {"pose": ...}, or a
    view {"position", "look_at", "up"} as a scene's [view] table, mm)."""
    if path.is_dir():
        raise RangesimError("is a directory, not a pose file (.json or .npy)", source=path)
    if not path.is_file():
        raise RangesimError("no such pose file", source=path)
    suffix = path.suffix.lower()
    data: Any
    if suffix == ".npy":
        with open(path, "rb") as fh:  # (numpy's own complaint about such a file is pickle advice)
            if fh.read(6) != b"\x93NUMPY":
                raise RangesimError("not a .npy file (no NumPy header): save the pose with np.save, or as .json",
                                    source=path)
        try:
            data = np.load(path, allow_pickle=False)
        except (ValueError, EOFError, SyntaxError, TypeError, OSError) as exc:  # a broken header: SyntaxError
            raise RangesimError(f"cannot read pose ({type(exc).__name__}: {_one_line(exc)[:200]})",
                                source=path) from exc
        except Exception as exc:  # noqa: BLE001 -- tokenize.TokenError and the like from a mangled header
            raise RangesimError(f"not a readable .npy file ({type(exc).__name__})", source=path) from exc
    elif suffix == ".json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise RangesimError(f"invalid JSON: {exc}", source=path) from exc
        if isinstance(data, dict) and "pose" in data:
            data = data["pose"]
        elif isinstance(data, dict):  # the scene's [view] form, mm
            from rangesim.scene.scene import VIEW_KEYS, view_pose

            if "position" not in data or set(data) - VIEW_KEYS:
                raise RangesimError(f"a JSON pose is a 4x4 list, {{\"pose\": 4x4}} or a view {{\"position\": [x, y, z], "
                                    f"\"look_at\": [...], \"up\": [...]}} in mm; got the keys "
                                    f"{', '.join(map(str, data))}", source=path)
            data = view_pose(data, 1.0, path)
    else:
        raise RangesimError("pose must be a .json or .npy file", source=path)
    # scan() checks it too, but without the file's name
    return check_pose(data, source=path)


#: memory (bytes per pixel) the scan writers take beyond the scan: float32 planes of the
#: vector and integer fields (OpenEXR's channels; measured 47 at 3000 x 3000 px)
WRITE_BYTES_PER_PIXEL = 56


def _status_counts(result: RangeScan) -> list[tuple[str, int]]:
    """(name, pixel count) per status: every known code, then any unknown code present."""
    rows = [(status_name(code, result.meta.get("mode")), result.count(code)) for code in Status]
    known = {int(code) for code in Status}
    for code in np.unique(result.status):
        if int(code) not in known:
            rows.append((f"status {int(code)}", result.count(int(code))))
    return rows


def _percent(n: int, total: int) -> str:
    return f"{100.0 * n / max(total, 1):.1f} %"


# -- commands ---------------------------------------------------------------------------
def cmd_scan(args: argparse.Namespace) -> int:
    """``rangesim scan``: scan a scene or mesh, write the scan (and preview), summarise."""
    out = Path(args.out)
    preview = Path(args.preview) if args.preview else None
    # cheap checks first, so a typo fails before the scene is loaded and rendered
    check_suffix(out, SCAN_SUFFIXES, "scans")
    if preview is not None:
        check_suffix(preview, PREVIEW_SUFFIXES, "previews")
    intensity = Path(args.intensity_image) if args.intensity_image else None
    if intensity is not None:
        check_suffix(intensity, PREVIEW_SUFFIXES + (".npy",), "intensity images")
    frames_path = out.with_name(out.stem + ".frames.npz") if args.keep_frames else None
    # every output checked before any work: all of them are written, or none, and no input is overwritten
    outputs = [(out, "scan"), (preview, "preview"), (intensity, "intensity image"), (frames_path, "frames")]
    check_outputs(outputs, [args.scene, args.pose, args.sensor])
    changes = dict(_parse_setting(text) for text in args.set)
    pose = _load_pose(Path(args.pose)) if args.pose else None

    start = time.perf_counter()
    sensor = load_sensor(args.sensor)
    if changes:
        sensor = sensor.with_params(changes)
    if args.keep_frames and sensor.mode != "rendered":
        raise RangesimError("--keep-frames needs the rendered mode (--set mode=rendered, or "
                            "mode = \"rendered\" in the sensor file)", source=sensor.source)
    # the scan runs in bands when it must, but its result and the file's copy of it must fit
    pixels = float(sensor.width) * sensor.height
    per_pixel = pixels * (RESULT_BYTES_PER_PIXEL + WRITE_BYTES_PER_PIXEL)
    check_memory(BASE_BYTES + per_pixel,
                 f"camera.width x camera.height = {sensor.width:,} x {sensor.height:,} px "
                 f"(the scan and its {Path(args.out).suffix or 'output'} file: {format_bytes(per_pixel)}, "
                 f"on the renderer's fixed {format_bytes(BASE_BYTES)})", source=sensor.source)
    scene = load_scene_arg(args.scene, args.units)
    check_outputs(outputs, scene_files(scene))  # the meshes a scene file names
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", EmptyScanWarning)
        if args.keep_frames:
            result, stack = scan(scene, sensor, pose=pose, seed=args.seed, keep_frames=True)
        else:
            result = scan(scene, sensor, pose=pose, seed=args.seed)
    for w in caught:
        if not issubclass(w.category, EmptyScanWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        elif args.keep_empty:
            print(f"{PROG}: warning: {_one_line(str(w.message))}", file=sys.stderr)
        else:
            raise RangesimError(f"{w.message}; nothing written (--keep-empty writes it anyway)", source=args.scene)
    writes = [(out, lambda tmp: save_scan(result, tmp))]
    if preview is not None:
        writes.append((preview, lambda tmp: save_preview(result, tmp)))
    if intensity is not None:
        image = intensity_image(scene, sensor, pose=result.pose, seed=args.seed)
        writes.append((intensity, lambda tmp: save_intensity_image(image, tmp)))
    if frames_path is not None:
        writes.append((frames_path, stack.save))
    write_together(writes)
    elapsed = time.perf_counter() - start

    h, w = result.shape
    total = h * w
    n_valid = int(np.count_nonzero(result.valid))
    invalid = ", ".join(f"{name} {n:,}" for name, n in _status_counts(result)[1:])
    written = ", ".join(str(path) for path, _ in writes)
    print(
        f"Scanned {args.scene} with {sensor.name} (seed {args.seed}): {w} x {h} px (W x H), "
        f"{n_valid:,} valid ({_percent(n_valid, total)}); {invalid}. "
        f"Wrote {written} in {elapsed:.2f} s."
    )
    return EXIT_OK


def cmd_sensors(args: argparse.Namespace) -> int:
    """``rangesim sensors``: the presets, one a line, with their descriptions."""
    names = preset_names()
    if not names:
        print("no sensor presets found")
        return EXIT_OK
    width = max(len(name) for name in names)
    for name in names:
        try:
            description = load_sensor(name).description or "(no description)"
        except RangesimError as exc:  # one broken preset should not hide the others
            description = f"(cannot load: {exc})"
        print(f"{name:<{width}}  {description}")
    return EXIT_OK


def cmd_info(args: argparse.Namespace) -> int:
    """``rangesim info``: size, status counts, depth range, sensor and pose of a scan file."""
    result = load_scan(args.scan_file)
    h, w = result.shape
    total = h * w
    sensor = result.meta.get("sensor") or {}
    # a point list (a point .ply) holds its measured points only: no grid, no unmeasured pixels
    size = (f"{total:,} points (a point list, not an organized range image: unmeasured pixels are not in it)"
            if is_point_list(result) else f"{w:,} x {h:,} px (W x H)")
    lines = [f"{args.scan_file}: {size}, sensor {sensor.get('name', 'unknown')}, seed {result.meta.get('seed', 'unknown')}"]
    counts = _status_counts(result)
    label = max(len(name) for name, _ in counts)
    digits = max(len(f"{n:,}") for _, n in counts)
    lines += [f"  {name:<{label}}  {n:>{digits},}  ({_percent(n, total)})" for name, n in counts]
    finite = np.isfinite(result.depth)
    depth = result.depth[result.valid & finite]
    if depth.size:
        lines.append(f"depth: {depth.min():.3f} .. {depth.max():.3f} mm")
    else:
        lines.append("depth: no valid pixel with a depth")
    holes = int(np.count_nonzero(result.valid & np.isnan(result.depth)))
    if holes:
        # the detectors take them as holes (an edited scan may punch NaN without updating valid)
        lines.append(f"note: {holes:,} pixels marked valid have no depth (NaN); the detectors treat them as invalid")
    infinite = int(np.count_nonzero(result.valid & np.isinf(result.depth)))
    if infinite:
        lines.append(f"note: {infinite:,} pixels marked valid have an infinite depth; the detectors refuse the scan")
    edited = int(np.count_nonzero(result.valid != (result.status == Status.VALID)))
    if edited:
        # the counts above are the status codes'; the detectors and scores use the valid mask
        lines.append(f"note: valid and status disagree at {edited:,} pixels (an edited mask?); the counts above "
                     f"are the status codes', the detectors use the {int(np.count_nonzero(result.valid)):,} valid "
                     "pixels")
    if result.sigma is not None:
        sig = result.sigma[result.valid & np.isfinite(result.sigma)]
        if sig.size:
            p5, p50, p95 = np.percentile(sig, [5, 50, 95])
            lines.append(f"predicted depth std (sigma): median {p50:.4f} mm, 5-95 % {p5:.4f} .. {p95:.4f} mm")
    lines.append("pose (camera-to-world):")
    # rounding first and adding 0.0 turns -0.0 and -1e-17 into a plain 0.0000
    lines += ["  [" + "  ".join(f"{round(v, 4) + 0.0:10.4f}" for v in row) + " ]" for row in result.pose]
    print("\n".join(lines))
    return EXIT_OK


# -- parser and entry point ---------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse with a usage error on one line (``rangesim: error: scan: argument --seed: invalid int
    value: '1e3' (see rangesim scan --help)``), exit code 2, like every other user error."""

    def error(self, message: str) -> NoReturn:
        command = self.prog.removeprefix(PROG).strip()
        _error(f"{command + ': ' if command else ''}{message} (see {self.prog} --help)")
        self.exit(EXIT_USER)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with its three subcommands."""
    parser = _Parser(
        prog=PROG,
        description="Laser-stripe range-scanner simulator on Mitsuba 3.",
        epilog="Set RANGESIM_DEBUG=1 to see tracebacks of internal errors.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("scan", help="scan a scene or mesh file", description=(
        "Scan a scene (.toml) or a mesh file with a sensor and write the range scan."))
    p.add_argument("scene", metavar="SCENE_OR_MESH", help="scene .toml or mesh (.stl, .obj, .ply, ...)")
    p.add_argument("--sensor", default=DEFAULT_SENSOR, metavar="NAME_OR_TOML",
                   help=f"preset name or sensor .toml (default: {DEFAULT_SENSOR})")
    p.add_argument("--out", required=True, metavar="OUT",
                   help=f"scan file ({', '.join(SCAN_SUFFIXES)})")
    p.add_argument("--units", choices=MESH_UNITS, help="length unit of a bare mesh file (default: mm)")
    p.add_argument("--keep-empty", action="store_true",
                   help="write a scan with no (or almost no) valid pixel instead of failing (a warning)")
    p.add_argument("--preview", metavar="PNG", help="also write a preview picture (.png)")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="noise seed (default: 0)")
    p.add_argument("--pose", metavar="POSE", help="4x4 camera-to-world matrix (.json or .npy); "
                   "default: the scene's [view], or a pose framing the scene")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a sensor key, e.g. noise.sigma_px=0 (repeatable; TOML values)")
    p.add_argument("--keep-frames", action="store_true",
                   help="rendered mode: also write the raw frame stack to OUT's stem + .frames.npz")
    p.add_argument("--intensity-image", metavar="PNG_OR_NPY",
                   help="also render the white-light intensity image of the same view (.png or .npy)")
    p.set_defaults(func=cmd_scan)

    p = sub.add_parser("sensors", help="list the sensor presets",
                       description="List the sensor presets with their descriptions.")
    p.set_defaults(func=cmd_sensors)

    p = sub.add_parser("info", help="describe a scan file",
                       description="Print a scan file's size, status counts, depth range, "
                       "sensor and pose.")
    p.add_argument("scan_file", metavar="SCAN_FILE", help="scan file (.exr, .npz)")
    p.set_defaults(func=cmd_info)
    for module in COMMAND_MODULES:
        importlib.import_module(module).register(sub)
    # every command may show progress (rendered tiles, sweeps, comparisons): each takes --quiet,
    # and so does the program (``rangesim --quiet COMMAND``)
    parser.add_argument("--quiet", dest="quiet_all", action="store_true", help="no progress bar or progress lines")
    for command in sub.choices.values():
        try:
            command.add_argument("--quiet", action="store_true", help="no progress bar or progress lines")
        except argparse.ArgumentError:  # the command has its own
            pass
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``rangesim`` command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit code: 0 success, 2 user error, 1 internal error, 130 interrupted (Ctrl-C), 143
        terminated (SIGTERM).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage or the help
        return exc.code if isinstance(exc.code, int) else EXIT_USER
    from rangesim.core import progress

    before = progress._default
    # long work shows progress: a bar on a terminal, log lines in CI logs and nohup files
    quiet = getattr(args, "quiet", False) or getattr(args, "quiet_all", False)
    progress.set_progress("off" if quiet else "log")
    shown = warnings.showwarning
    # a warning is one line like an error (with RANGESIM_DEBUG, Python's own form: file and line)
    if not _debug():
        warnings.showwarning = _show_warning
    new_folders = _new_folders(args)
    code = EXIT_INTERNAL
    try:
        with signal_handler(signal.SIGTERM, _terminate):
            code = args.func(args)
            return code
    except Terminated:
        _error("terminated")
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        _error("interrupted")
        return EXIT_INTERRUPTED
    except (RangesimError, OSError) as exc:
        if _debug():
            traceback.print_exc()
        if isinstance(exc, BrokenPipeError):  # e.g. `rangesim sensors | head -1`
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 -- keeps the exit flush quiet
            return EXIT_INTERNAL
        _error(str(exc) if isinstance(exc, RangesimError) else _os_error_message(exc))
        return EXIT_USER
    except Exception as exc:  # a bug: one line, the traceback on request
        if _debug():
            traceback.print_exc()
        _error(f"internal error ({type(exc).__name__}: {exc}); "
               "run with RANGESIM_DEBUG=1 for a traceback")
        return EXIT_INTERNAL
    finally:
        progress.set_progress(before)
        warnings.showwarning = shown
        if code != EXIT_OK:  # a failed run leaves no empty output folder it made (a write failed, ...)
            _remove_empty(new_folders)


if __name__ == "__main__":
    sys.exit(main())
