"""The registry of built-in parametric models, and loading a model by name or mesh path."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import trimesh

from rangesim.cad.meshes import MESH_SUFFIXES, load_mesh
from rangesim.core.errors import RangesimError

#: name -> builder returning a built part (see ``rangesim.cad.part``); filled by the model modules
MODELS: dict[str, Callable] = {}


def model_names() -> list[str]:
    """Names of the built-in models."""
    return sorted(MODELS)


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
        return MODELS[name](**params).mesh
    path = Path(name)
    if path.suffix.lower() in MESH_SUFFIXES:
        if params:
            raise RangesimError("parameters apply to built-in models only", source=path)
        return load_mesh(path)
    raise RangesimError(
        f"unknown model; built-in models: {', '.join(model_names()) or '(none)'}, or a mesh file",
        source=name,
    )
