"""Scenes for experiment tasks: a scene file with per-object overrides, cached per process.

Object overrides (``object.<name>.<key>`` in a sweep) replace keys of that ``[[object]]``
table of the scene file (``translate``, ``rotate_deg``, ``albedo``, ``params.thickness``,
...). The changed table is written to a temporary scene file (mesh paths made absolute)
and loaded with :func:`rangesim.load_scene`, so it is validated exactly like a scene file.
"""
from __future__ import annotations

import json
import math
import tempfile
from collections import OrderedDict
from pathlib import Path
from typing import Any

from rangesim.core.errors import RangesimError
from rangesim.core.tomlfile import read_toml

#: scenes kept per process (a worker of a sweep over a few scenes builds each once)
CACHE_SIZE = 4
_CACHE: "OrderedDict[str, Any]" = OrderedDict()


def toml_value(value: Any) -> str:
    """One TOML value (numbers, booleans, strings, arrays, inline tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def dump_scene_toml(data: dict[str, Any]) -> str:
    """A scene dict (as read from a scene file) back as TOML text."""
    lines = []
    for key, value in data.items():
        if key not in ("object", "view"):
            lines.append(f"{json.dumps(key)} = {toml_value(value)}")
    for table in data.get("object", []):
        lines.append("\n[[object]]")
        lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in table.items()]
    if "view" in data:
        lines.append("\n[view]")
        lines += [f"{json.dumps(k)} = {toml_value(v)}" for k, v in data["view"].items()]
    return "\n".join(lines) + "\n"


def _mesh_files(path: Path) -> list[Path]:
    """The mesh files a scene ``.toml``'s ``[[object]]`` tables name, resolved, in order; none
    for another file or a TOML the scene loader will refuse (it names the problem)."""
    from rangesim.scene.scene import expand_data_path

    if path.suffix.lower() != ".toml":
        return []
    try:
        tables = read_toml(path).get("object", [])
    except RangesimError:
        return []
    tables = [tables] if isinstance(tables, dict) else tables
    return [(path.parent / expand_data_path(str(t["mesh"]))).resolve() for t in tables
            if isinstance(t, dict) and "mesh" in t]


def scene_digest(path: str | Path) -> str:
    """SHA-1 (hex) of what a scene file makes: the file's bytes and, for a scene ``.toml``, the
    bytes of every mesh file its ``[[object]]`` tables name (in order), so that results keyed on
    it are not reused after a mesh changes under an unchanged scene file. A file that names no
    mesh (models, primitives, a bare mesh file) digests as its own bytes alone.

    Parameters
    ----------
    path : str or Path
        Scene ``.toml`` or mesh file.
    """
    import hashlib

    path = Path(path)
    own = hashlib.sha1(path.read_bytes()).hexdigest()
    meshes = _mesh_files(path)
    if not meshes:
        return own
    combined = hashlib.sha1(own.encode())
    for mesh in meshes:
        combined.update(hashlib.sha1(mesh.read_bytes()).hexdigest().encode() if mesh.is_file() else b"missing")
    return combined.hexdigest()


def _file_stamps(path: Path) -> list[tuple[str, int, int]]:
    """(path, mtime ns, size) of a scene file and of every mesh file its objects name, cheaply
    (no file is read but the scene's TOML); missing files stamp as (path, 0, -1)."""
    def stamp(p: Path) -> tuple[str, int, int]:
        try:
            st = p.stat()
            return str(p), st.st_mtime_ns, st.st_size
        except OSError:
            return str(p), 0, -1

    return [stamp(p) for p in (path, *_mesh_files(path))]


def apply_object_overrides(path: str | Path, overrides: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The scene file's data with object keys replaced and mesh paths made absolute.

    Parameters
    ----------
    path : str or Path
        Scene ``.toml``.
    overrides : dict
        ``{object name: {key: value}}``; a key ``params.thickness`` sets one entry of the
        object's ``params`` table (likewise ``material.<key>``).

    Raises
    ------
    RangesimError
        An object name the scene does not have.
    """
    from rangesim.scene.scene import expand_data_path, object_names

    path = Path(path)
    data = read_toml(path)
    tables = data.get("object", [])
    tables = [tables] if isinstance(tables, dict) else list(tables)
    by_name = dict(zip(object_names(tables, path), tables))
    for name, changes in overrides.items():
        if name not in by_name:
            raise RangesimError(f"no object {name!r} in the scene (it has {', '.join(by_name)})", source=path)
        table = by_name[name]
        for key, value in changes.items():
            head, _, sub = key.partition(".")
            if sub:
                inner = table.setdefault(head, {})
                if not isinstance(inner, dict):
                    raise RangesimError(f"object {name}: {head} is not a table", source=path)
                inner[sub] = value
            else:
                table[key] = value
    for table in tables:
        if "mesh" in table:
            table["mesh"] = str((path.parent / expand_data_path(str(table["mesh"]))).resolve())
    data["object"] = tables
    return data


def load_task_scene(path: str | Path, overrides: dict[str, dict[str, Any]] | None = None):
    """The scene of a task, built once per process and kept (up to :data:`CACHE_SIZE`).

    Parameters
    ----------
    path : str or Path
        Scene ``.toml``.
    overrides : dict, optional
        Object overrides (see :func:`apply_object_overrides`).

    Returns
    -------
    Scene
        Its ``source`` is the scene file, with `` (object overrides ...)`` appended when
        there are any.
    """
    from rangesim.scene import load_scene

    given, path = Path(path), Path(path).resolve()
    overrides = overrides or {}
    # keyed on the scene file and every mesh it names (path, mtime, size): a mesh changed under
    # an unchanged scene file gets new task keys (scene_digest), and must not be served its old
    # geometry by a long-lived process (a notebook's workers=0 run, a Dask cluster's workers)
    cache_key = json.dumps([_file_stamps(path), overrides], sort_keys=True, default=str)
    if cache_key in _CACHE:
        _CACHE.move_to_end(cache_key)
        return _CACHE[cache_key]
    if not overrides:
        try:
            scene = load_scene(path)
        except RangesimError as exc:  # named as the user gave it (resolved only for the cache)
            if str(given) == str(path) or str(path) not in str(exc):
                raise
            raise RangesimError(str(exc).replace(str(path), str(given))) from None
    else:
        data = apply_object_overrides(path, overrides)
        with tempfile.TemporaryDirectory(prefix="rangesim-scene-") as tmp:
            tmp_path = Path(tmp) / path.name
            tmp_path.write_text(dump_scene_toml(data), encoding="utf-8")
            try:
                scene = load_scene(tmp_path)
            except RangesimError as exc:
                shown = ", ".join(f"object.{n}.{k} = {v!r}" for n, c in overrides.items() for k, v in c.items())
                raise RangesimError(f"with {shown}: {str(exc).replace(str(tmp_path), '').lstrip(': ')}",
                                    source=path) from exc
        scene.source = f"{path} (object overrides {json.dumps(overrides, sort_keys=True)})"
    _CACHE[cache_key] = scene
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return scene
