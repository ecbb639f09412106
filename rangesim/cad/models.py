"""The registry of built-in parametric models, and loading a model by name or mesh path."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import trimesh

from rangesim.cad.meshes import MESH_SUFFIXES, load_mesh
from rangesim.core.errors import RangesimError
from rangesim.core.memory import check_memory

#: the most facets a circle of a built-in model may have (``segments``), a documented limit:
#: memory grows with the square of it (about 8 GB at 960) and time faster
MAX_SEGMENTS = 4096
MAX_DIVISIONS_PER_TURN = 1024
#: the largest magnitude a numeric model parameter may have, mm (or degrees, counts): 100 m. No
#: machined part is larger, and beyond it the float32 meshes the scanner casts rays against lose
#: their sub-millimetre resolution (and the geometry kernel overflows its integer sizes)
MAX_PARAM_MAGNITUDE = 1e5
#: parameters that are not sizes and take any integer
FREE_PARAMS = ("seed",)


def _check_numbers(key: str, value, name: str) -> None:
    """Every number in a parameter value (nested lists and tables too) finite and of sensible size."""
    import math

    if isinstance(value, dict):
        for k, v in value.items():
            _check_numbers(f"{key}.{k}", v, name)
    elif isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            _check_numbers(f"{key}[{k}]", v, name)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        if not math.isfinite(value):
            raise RangesimError(f"--param {key} must be a finite number, got {value!r}", source=name)
        if abs(value) > MAX_PARAM_MAGNITUDE:
            raise RangesimError(f"--param {key} = {value!r} is out of range (at most {MAX_PARAM_MAGNITUDE:g} "
                                "in magnitude: mm, degrees or counts)", source=name)

#: name -> builder returning a built part (see ``rangesim.cad.part``); filled by the model modules
MODELS: dict[str, Callable] = {}


def model_names() -> list[str]:
    """Names of the built-in models."""
    return sorted(MODELS)


def model_memory_estimate(params: dict) -> float:
    """Bytes a built-in model needs with these tessellation parameters (measured on green_piece)."""
    segments = float(params.get("segments", 48))
    segments *= max(1.0, float(params.get("divisions_per_turn", 16)) / 16.0)
    return 300 * 1024**2 + 2.9e6 * segments + 5.6e3 * segments**2


def check_model_params(name: str, params: dict) -> None:
    """Reject empty names, non-finite or huge numbers, and tessellation parameters that are not integers
    in range or would not fit in memory."""
    for key, value in params.items():
        if not str(key).strip():
            raise RangesimError(f"--param needs a parameter name before '=' (got an empty name for {value!r})",
                                source=name)
        if key not in FREE_PARAMS:
            _check_numbers(str(key), value, name)
    for key, low, high in (("segments", 3, MAX_SEGMENTS), ("divisions_per_turn", 1, MAX_DIVISIONS_PER_TURN)):
        if key not in params:
            continue
        value = params[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
            raise RangesimError(f"--param {key} must be an integer, got {value!r}", source=name)
        if not low <= value <= high:
            raise RangesimError(f"--param {key} must lie in {low}..{high}, got {value!r}", source=name)
    if "segments" in params or "divisions_per_turn" in params:
        given = ", ".join(f"{k}={params[k]}" for k in ("segments", "divisions_per_turn") if k in params)
        check_memory(model_memory_estimate(params), f"--param {given}", source=name)


def load_model(name_or_path: str | Path, **params) -> trimesh.Trimesh:
    """The mesh (millimetres) of a built-in model by name, or of a mesh file.

    Parameters
    ----------
    name_or_path : str or Path
        A built-in model name (:func:`model_names`) or a mesh file trimesh reads.
    **params
        Parameters of a built-in model (its parameter table); not allowed for a file.
    """
    name = str(name_or_path)
    if name in MODELS:
        check_model_params(name, params)
        return MODELS[name](**params).mesh
    path = Path(name)
    if path.suffix.lower() in MESH_SUFFIXES:
        if params:
            raise RangesimError("parameters apply to built-in models only", source=path)
        try:
            return load_mesh(path)
        except RangesimError:
            from rangesim.io.mesh_check import diagnose_mesh_file

            problem = diagnose_mesh_file(path) if path.is_file() else None
            if problem is None:
                raise
            raise RangesimError(problem, source=path) from None
    raise RangesimError(
        f"unknown model; built-in models: {', '.join(model_names()) or '(none)'}, or a mesh file",
        source=name,
    )
