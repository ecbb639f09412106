"""The MSU / White Scanner range-image text format (``.msu``, or gzipped ``.msu.gz``).

Layout: a three-line header giving the number of rows and columns (the wording varied
between files, so the first two integers in those lines are taken as rows, then
columns), then four whitespace-separated images of rows x columns numbers, each in row
order: a flag (1 = valid), X, Y and Z. Coordinates are in the scanner's own frame
(``meta["frame"] == "scanner"``, z the range axis, ``depth`` = Z); their unit is not in
the file: millimetres unless the caller says otherwise (``units=``).
"""
from __future__ import annotations

import gzip
import io
import re
import zlib
from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.io.atomic import atomic_path
from rangesim.recorded.common import check_file, grid_scan, read_bytes, recorded_meta, unit_scale
from rangesim.recorded.conf import apply_conf
from rangesim.recorded.text import parse_numbers

__all__ = ["read_msu", "write_msu"]

HEADER_LINES = 3
GZIP_MAGIC = b"\x1f\x8b"
# a whole integer, not part of a decimal number or a word ("480x512" counts as two)
_INTEGER = re.compile(r"(?<![\w.])[-+]?\d+(?![\w.])")  # signed: "-5 rows" is no size
#: write_msu's third header line: "flag X Y Z images, row order, <unit> (written by rangesim)"
_WRITTEN_UNITS = re.compile(r"row order, (\S+) \(written by rangesim\)")
_TIMES = re.compile(r"(?<=\d)[xX*]\s*(?=\d)")
_NOT_FINITE = re.compile(r"\b(nan|inf|infinity)\b", re.IGNORECASE)


def read_msu(path: str | Path, *, units: str | None = None, conf: str | Path | None = None) -> RangeScan:
    """Read an MSU range image (plain or gzipped, recognised by content; a name ending ``.gz``
    must hold gzip data).

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Unit of X, Y, Z in the file (``"mm"``, ``"in"``, ...); the scan is in mm. Default: the
        unit :func:`write_msu` named in the header, else millimetres (the format has none).
    conf : str or Path, optional
        A Stanford ``.conf`` whose ``bmesh`` line for this file sets ``pose``.

    Returns
    -------
    RangeScan
        rows x columns; valid where the flag is 1 and X, Y, Z are finite.
        ``meta["msu_header"]`` keeps the three header lines.

    Raises
    ------
    RangesimError
        A missing or corrupt file, a header without two positive integers or with NaN,
        or a value count other than 4 x rows x columns.
    """
    path = check_file(path)
    if units is not None:
        unit_scale(units, path)  # a bad unit before the file is read
    raw = read_bytes(path)
    if Path(path).name.lower().endswith(".gz") and not raw.startswith(GZIP_MAGIC):
        raise RangesimError("not a gzip file (the name ends .gz, the content has no gzip signature)", path)
    if raw.startswith(GZIP_MAGIC):
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise RangesimError(f"corrupt gzip data ({exc})", path) from None
    head = raw[:4096]
    if b"\0" in head or sum(b < 9 or 13 < b < 32 for b in head) > 0.05 * len(head):
        raise RangesimError("not an MSU range image (binary data where its text should be)", path)
    parts = raw.split(b"\n", HEADER_LINES)
    if len(parts) <= HEADER_LINES:
        raise RangesimError(f"truncated: fewer than {HEADER_LINES} header lines", path)
    header = [line.decode("ascii", errors="replace").strip() for line in parts[:HEADER_LINES]]
    text = " ".join(header)
    if _NOT_FINITE.search(text):
        raise RangesimError(f"NaN or infinity in the header {text!r}", path)
    sizes = [int(v) for v in _INTEGER.findall(_TIMES.sub(" ", text))[:2]]
    if len(sizes) < 2 or min(sizes) <= 0:
        raise RangesimError(f"the header does not give two positive integers (rows, columns): {text!r}", path)
    rows, cols = sizes
    cells = rows * cols
    values = parse_numbers(parts[HEADER_LINES], path, "MSU image data")
    if values.size != 4 * cells:
        raise RangesimError(
            f"expected 4 images of {rows} x {cols} = {4 * cells} numbers after the header, found {values.size}"
            + (" (truncated)" if values.size < 4 * cells else ""),
            path,
        )
    if units is None:  # the unit write_msu names in its third line, else the format's millimetres
        written = _WRITTEN_UNITS.search(header[2])
        units = written.group(1) if written else "mm"
    scale = unit_scale(units, path)
    images = values.reshape(4, rows, cols)
    flags = images[0]
    odd = ~np.isin(flags, (0, 1))
    if odd.any():  # a flag of 2 or 0.5 is no flag: a misread or another layout, not "no surface"
        r, c = np.argwhere(odd)[0]
        raise RangesimError(f"the flag image must hold 0 or 1; {int(odd.sum()):,} values do not (row {r}, "
                            f"column {c}: {flags[r, c]:g})", path)
    xyz = np.moveaxis(images[1:], 0, -1) * scale  # float64: grid_scan checks the range, then stores float32
    meta = recorded_meta("msu", path, "scanner", organized=True, msu_header=header, msu_units=units)
    scan = grid_scan(xyz, meta, valid=flags == 1)
    return apply_conf(scan, conf, path)


def write_msu(scan: RangeScan, path: str | Path, *, units: str = "mm") -> Path:
    """Write ``scan`` as an MSU range image, atomically; gzipped when the name ends ``.gz``.

    The flag image is ``scan.valid``; X, Y, Z are ``scan.xyz`` (0 where invalid) in
    ``units``, printed with enough digits that millimetre float32 values read back
    exactly.

    Parameters
    ----------
    scan : RangeScan
    path : str or Path
        ``.msu`` or ``.msu.gz``.
    units : str
        Unit of the file's X, Y, Z.

    Returns
    -------
    Path
        The path written.
    """
    path = Path(path)
    scale = unit_scale(units, path)
    rows, cols = scan.shape
    valid = scan.valid
    out = io.StringIO()
    out.write(f"{rows} rows\n{cols} columns\nflag X Y Z images, row order, {units} (written by rangesim)\n")
    np.savetxt(out, valid.astype(np.int64), fmt="%d")
    exact = scale == 1.0
    for axis in range(3):
        image = np.where(valid, scan.xyz[..., axis], np.float32(0)).astype(np.float64) / scale
        np.savetxt(out, image, fmt="%.9g" if exact else "%.17g")
    data = out.getvalue().encode("ascii")
    if path.name.lower().endswith(".gz"):
        data = gzip.compress(data, mtime=0)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path
