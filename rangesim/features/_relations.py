"""Relations between features (the paper's section 5): distances and angles, as a table."""
from __future__ import annotations

import csv
import io
import json
import math
import os
import secrets
from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.features._feature_lists import feature_list
from rangesim.features._lines import segment_pairs

FIELDS = ("relation", "a", "b", "value", "unit")


def _point_segment(p: np.ndarray, segs: list) -> np.ndarray:
    """(N,) distance from a point to each segment, pixels."""
    A = np.array([s.start for s in segs], float)
    B = np.array([s.end for s in segs], float)
    ab = B - A
    t = np.clip(((p - A) * ab).sum(1) / np.maximum((ab ** 2).sum(1), 1e-12), 0, 1)
    return np.linalg.norm(p - (A + t[:, None] * ab), axis=1)


def relations(segments: list = (), circles: list = (), ellipses: list = (), arcs: list = (),
              pairs: bool = True) -> list[dict]:
    """Relations between features, one row per pair.

    Rows (``relation``, ``a``, ``b`` as ``kind:index``, ``value``, ``unit``):
    ``circle_segment_distance`` and ``ellipse_segment_distance`` (minimum distance from the
    centre to the segment, px), ``circle_ellipse_distance``, ``circle_circle_distance``
    (centre distances, px), ``segment_ellipse_angle`` (angle between the segment and the
    ellipse's major axis, degrees in [0, 90]) and, with ``pairs``,
    ``segment_segment_distance`` (px) and ``segment_segment_angle`` (degrees).
    Arcs count as circles (``arc:i``).

    Examples
    --------
    >>> import rangesim as rs
    >>> quiet = {"noise.sigma_px": 0, "noise.speckle_contrast": 0}
    >>> scan = rs.datasets.plate_scan(quiet)   # a plate with a hole, on a table, 128 x 120, noise-free

    >>> edges = rs.edges.gradient(scan)
    >>> rows = rs.features.relations(rs.features.lines(edges, scan), rs.features.circles(edges, radii=(5, 30)))
    >>> rows[0]["relation"], rows[0]["unit"]
    ('circle_segment_distance', 'px')

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    """
    segs = _features(segments, "segments", ("start", "end"))
    circles, arcs = _features(circles, "circles", ("center",)), _features(arcs, "arcs", ("center",))
    ellipses = _features(ellipses, "ellipses", ("center", "orientation"))
    rows: list[dict] = []
    round_ = [("circle", i, c) for i, c in enumerate(circles)] + [("arc", i, a) for i, a in enumerate(arcs)]
    if segs:
        for kind, i, c in round_:
            for j, d in enumerate(_point_segment(np.array(c.center), segs)):
                rows.append(dict(relation="circle_segment_distance", a=f"{kind}:{i}", b=f"segment:{j}", value=float(d), unit="px"))
        for i, e in enumerate(ellipses):
            for j, d in enumerate(_point_segment(np.array(e.center), segs)):
                rows.append(dict(relation="ellipse_segment_distance", a=f"ellipse:{i}", b=f"segment:{j}", value=float(d), unit="px"))
            for j, s in enumerate(segs):
                sa = np.arctan2(s.end[1] - s.start[1], s.end[0] - s.start[0])
                diff = abs(sa - e.orientation) % np.pi
                rows.append(dict(relation="segment_ellipse_angle", a=f"segment:{j}", b=f"ellipse:{i}",
                                 value=float(np.rad2deg(min(diff, np.pi - diff))), unit="deg"))
        if pairs:
            dist, ang = segment_pairs(segs)
            iu, ju = np.triu_indices(len(segs), 1)
            for i, j in zip(iu, ju):
                rows.append(dict(relation="segment_segment_distance", a=f"segment:{i}", b=f"segment:{j}", value=float(dist[i, j]), unit="px"))
                rows.append(dict(relation="segment_segment_angle", a=f"segment:{i}", b=f"segment:{j}", value=float(ang[i, j]), unit="deg"))
    for kind, i, c in round_:
        for k, e in enumerate(ellipses):
            rows.append(dict(relation="circle_ellipse_distance", a=f"{kind}:{i}", b=f"ellipse:{k}",
                             value=float(np.hypot(*(np.array(c.center) - e.center))), unit="px"))
    for x in range(len(round_)):
        for y in range(x + 1, len(round_)):
            (k1, i1, c1), (k2, i2, c2) = round_[x], round_[y]
            rows.append(dict(relation="circle_circle_distance", a=f"{k1}:{i1}", b=f"{k2}:{i2}",
                             value=float(np.hypot(*(np.array(c1.center) - c2.center))), unit="px"))
    return rows


def _features(items, name: str, attrs: tuple[str, ...]) -> list:
    """:func:`~._feature_lists.feature_list` for :func:`relations`."""
    return feature_list(items, name, attrs, "relations")


def _check_rows(rows) -> list[dict]:
    """The rows of :func:`relations`: dicts with exactly :data:`FIELDS`."""
    rows = list(rows)
    for k, row in enumerate(rows):
        if not isinstance(row, dict) or set(row) != set(FIELDS):
            raise RangesimError(f"relations table row {k} must be a dict with the keys {', '.join(FIELDS)}")
    return rows


def relations_to_csv(rows: list[dict], path: str | Path | None = None) -> str:
    """The table as CSV text (written to ``path`` when given, atomically)."""
    rows = _check_rows(rows)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=FIELDS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    text = buf.getvalue()
    if path is not None:
        _write_text(path, text)
    return text


def relations_to_json(rows: list[dict], path: str | Path | None = None) -> str:
    """The table as JSON text (a list of objects), written to ``path`` when given, atomically."""
    # strict JSON: a non-finite value (hand-made features) is null, never a bare NaN; NumPy
    # scalars as Python numbers
    rows = [{k: _json_value(v) for k, v in row.items()} for row in _check_rows(rows)]
    text = json.dumps(rows, indent=1, allow_nan=False)
    if path is not None:
        _write_text(path, text)
    return text


def _json_value(v):
    if isinstance(v, np.generic):
        v = v.item()
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically: to a fresh hidden name beside it, then
    ``os.replace`` onto it (the temporary file is removed on failure); parent directories
    are created. Plain Python, so that this analysis layer does not depend on
    :mod:`rangesim.io` (same scheme as :func:`rangesim.io.atomic.atomic_path`)."""
    path = Path(path)
    if path.is_dir():
        raise RangesimError(f"{path}: is a directory, not a file to write the relations table to")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RangesimError(f"{path}: cannot create its directory ({e.strerror or e})") from None
    while True:
        tmp = path.with_name(f".{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
        if not tmp.exists():
            break
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise RangesimError(f"{path}: cannot write the relations table ({e.strerror or e})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
