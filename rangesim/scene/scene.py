"""Scenes: objects (meshes, primitives) in world coordinates, plus an optional view.

All geometry is converted to millimetres on load; sensors work in millimetres.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import trimesh

from rangesim.core import params as P
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import look_at, object_transform
from rangesim.core.tomlfile import check_keys, read_toml
from rangesim.core.units import UNIT_NAMES, UNITS_MM
from rangesim.scene.materials import check_material
from rangesim.scene.meshes import MESH_SUFFIXES, load_mesh, validate_mesh
from rangesim.scene.primitives import GEOMETRY_KEYS, PRIMITIVE_KEYS, make_primitive

OBJECT_KEYS = {
    "name", "mesh", "model", "primitive", "params", "translate", "rotate_deg", "scale",
    "albedo", "units", "material", "size", "radius", "height", "sections", "subdivisions",
}
VIEW_KEYS = {"position", "look_at", "up"}
SCENE_KEYS = {"units", "object", "view", "name", "description"}


@dataclass
class SceneObject:
    """One object of a scene.

    Attributes
    ----------
    name : str
    mesh : trimesh.Trimesh
        Triangles in world coordinates, millimetres; face order as in the source.
    albedo : float
        Diffuse reflectance at the laser wavelength, 0..1.
    source : str
        Where the geometry came from (file path, primitive or model name).
    material : dict
        Material table for the rendered mode (``albedo`` keeps its meaning for diffuse).
    face_labels : (n_faces,) int32 or None
        Built-in models: the sub-part of each triangle, an index into ``labels``.
    labels : list of str
        Sub-part names (built-in models).
    features : AnalyticFeatures or None
        Built-in models: exact circles and edges, in world coordinates (mm).
    """

    name: str
    mesh: trimesh.Trimesh
    albedo: float = 0.6
    source: str = ""
    material: dict[str, Any] = field(default_factory=dict)
    face_labels: np.ndarray | None = None
    labels: list[str] = field(default_factory=list)
    features: Any = None

    def __post_init__(self) -> None:
        # what load_scene checks in a scene file, for objects built in Python (a NaN albedo
        # scanned to 0 valid pixels, a None mesh or face labels of another length crashed later)
        if not (hasattr(self.mesh, "vertices") and hasattr(self.mesh, "faces")):
            raise RangesimError(f"object {self.name!r}: mesh must be a trimesh.Trimesh, got {type(self.mesh).__name__}")
        albedo = P.number(self.albedo, f"object {self.name!r}: albedo", 0, 1, what="reflectance")
        self.albedo = float(albedo)
        if self.face_labels is not None:
            labels = np.asarray(self.face_labels)
            n_faces = len(self.mesh.faces)
            if labels.shape != (n_faces,) or labels.dtype.kind not in "iu":
                raise RangesimError(f"object {self.name!r}: face_labels must be ({n_faces},) integers, one per "
                                    f"triangle, got {labels.dtype} of shape {labels.shape}")
            # (without label names the labels are not read: Scene.subpart_image)
            if self.labels and labels.size and (labels.min() < 0 or labels.max() >= len(self.labels)):
                raise RangesimError(f"object {self.name!r}: face_labels must index its {len(self.labels)} "
                                    f"labels, got values {int(labels.min())}..{int(labels.max())}")

    @property
    def watertight(self) -> bool:
        """True for a closed, consistently wound mesh (its back faces are never visible).

        Known from validation (``mesh.metadata["rangesim_closed"]``); computed once otherwise.
        """
        from rangesim.cad.meshes import is_closed

        meta = self.mesh.metadata
        if "rangesim_closed" not in meta:
            meta["rangesim_closed"] = is_closed(np.asarray(self.mesh.faces))
        return bool(meta["rangesim_closed"])


@dataclass
class Scene:
    """Objects in world coordinates (mm) and the default view.

    Attributes
    ----------
    objects : list of SceneObject
        Object index in this list is the ``part`` label of scans.
    view : (4, 4) float64 or None
        Default camera-to-world pose; None lets ``scan`` choose one that frames the objects.
    source : str
        The scene file, or a description of where the scene came from.
    source_units : str or None
        The units a bare mesh file ``source`` was read in when not millimetres
        (:func:`load_mesh_scene`); scans record it as ``meta["scene_units"]``, so that the
        scene can be rebuilt from the file for their ground truth.
    """

    objects: list[SceneObject]
    view: np.ndarray | None = None
    source: str = "scene"
    source_units: str | None = None
    _mitsuba: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.objects, SceneObject):
            raise RangesimError("Scene takes a list of SceneObject, got one SceneObject")
        self.objects = list(self.objects)  # (a generator is read once, here)
        if not all(isinstance(o, SceneObject) for o in self.objects):
            raise RangesimError("Scene takes a list of SceneObject")
        if not self.objects:
            raise RangesimError("a scene needs at least one object")
        for obj in self.objects:
            bounds = obj.mesh.bounds  # cached by trimesh: one pass per mesh
            if bounds is None:
                raise RangesimError(f"object {obj.name!r} has no vertices")
            if not np.all(np.isfinite(bounds)):
                raise RangesimError(f"object {obj.name!r} has NaN or infinite vertex coordinates")

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounding box of all objects, mm."""
        corners = np.vstack([o.mesh.bounds for o in self.objects])
        return np.stack([corners.min(axis=0), corners.max(axis=0)])

    @property
    def subpart_names(self) -> list[str]:
        """Global sub-part names ``object/sub-part`` (an object without labels is one sub-part)."""
        names = []
        for obj in self.objects:
            names += [f"{obj.name}/{label}" for label in obj.labels] if obj.labels else [obj.name]
        return names

    def subpart_image(self, part: np.ndarray, face: np.ndarray) -> np.ndarray:
        """Sub-part label of each pixel from a scan's ``part`` and ``face`` images.

        Parameters
        ----------
        part, face : (H, W) int arrays
            Object and triangle index per pixel (-1 for none), as in a RangeScan.

        Returns
        -------
        (H, W) int32 index into :attr:`subpart_names`, -1 where no surface was hit.
        """
        part = np.asarray(part)
        face = np.asarray(face)
        out = np.full(part.shape, -1, dtype=np.int32)
        offset = 0
        for k, obj in enumerate(self.objects):
            here = part == k
            if obj.face_labels is not None and obj.labels:
                out[here] = offset + obj.face_labels[face[here]]
                offset += len(obj.labels)
            else:
                out[here] = offset
                offset += 1
        return out

    def mitsuba_scene(self):
        """The Mitsuba scene of these objects, built once and cached (see ``mitsuba_scene``)."""
        if self._mitsuba is None:
            from rangesim.scene.mitsuba_scene import build_mitsuba_scene

            self._mitsuba = build_mitsuba_scene(self)
        return self._mitsuba

    def framing_pose(self, distance: float, direction=(0.0, -1.0, 1.4)) -> np.ndarray:
        """A pose looking at the centre of the bounding box from ``distance`` mm along ``direction``."""
        centre = self.bounds.mean(axis=0)
        d = np.asarray(direction, dtype=np.float64)
        return look_at(centre + distance * d / np.linalg.norm(d), centre, up=(0, 0, 1))

    @property
    def bounding_radius(self) -> float:
        """Radius (mm) of the sphere around the bounding-box centre enclosing every vertex."""
        centre = self.bounds.mean(axis=0)
        return float(max(np.linalg.norm(o.mesh.vertices - centre, axis=1).max() for o in self.objects))


def load_mesh_scene(path: str | Path, units: str | None = None) -> Scene:
    """A one-object scene of a bare mesh file read in ``units`` (mm, cm, m, in; None: mm).

    Parameters
    ----------
    path : str or Path
        Any mesh file trimesh reads.
    units : str, optional
        The file's units; the scene is in millimetres.
    """
    path = Path(path)
    if units is None or UNITS_MM.get(units) == 1.0:
        return load_scene(path)
    if units not in UNITS_MM:
        raise RangesimError(f"unknown units {units!r}; use one of {UNIT_NAMES}", source=path)
    mesh = load_mesh(path)
    mesh.apply_scale(UNITS_MM[units])
    return Scene([SceneObject(path.stem, mesh, source=str(path))], source=str(path.resolve()), source_units=units)


def load_scene(source) -> Scene:
    """Build a :class:`Scene` from a scene file, a mesh file, a mesh, or a list of meshes.

    Parameters
    ----------
    source : str, Path, trimesh.Trimesh, Scene or list of trimesh.Trimesh
        A ``.toml`` scene file (see the README for its keys), any mesh file trimesh reads
        (one object, millimetres, no view), or meshes already in memory (millimetres).

    Raises
    ------
    RangesimError
        Any problem with the file or its contents, with the file named.
    """
    if isinstance(source, Scene):
        return source
    if isinstance(source, trimesh.Trimesh):
        source = [source]
    if isinstance(source, (list, tuple)):
        return _scene_from_meshes(source)
    if not isinstance(source, (str, os.PathLike)):
        raise RangesimError(f"load_scene takes a Scene, meshes or a file name, got {type(source).__name__}")
    path = Path(source)
    if path.suffix.lower() == ".toml":
        return _scene_from_toml(path)
    if path.suffix.lower() in MESH_SUFFIXES:
        mesh = load_mesh(path)
        return Scene([SceneObject(path.stem, mesh, source=str(path))], source=str(path.resolve()))
    if not path.exists():
        raise RangesimError("no such scene or mesh file", source=path)
    raise RangesimError(
        f"unknown scene file type {path.suffix!r}; use .toml or a mesh ({', '.join(MESH_SUFFIXES)})",
        source=path,
    )


def _scene_from_meshes(meshes: Iterable[trimesh.Trimesh]) -> Scene:
    objects = []
    for k, mesh in enumerate(meshes):
        if not isinstance(mesh, trimesh.Trimesh):
            raise RangesimError(f"scene item {k} is a {type(mesh).__name__}, not a trimesh.Trimesh")
        objects.append(SceneObject(f"object{k}", validate_mesh(mesh, f"mesh {k}"), source="memory"))
    if not objects:
        raise RangesimError("scene has no objects")
    return Scene(objects, source="memory")


def data_dir() -> Path:
    """The shared recorded-data folder: ``$RANGESIM_DATA``, else ``../shared/data`` beside the repository."""
    env = os.environ.get("RANGESIM_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[3] / "shared" / "data"


def expand_data_path(text: str) -> str:
    """Replace a leading ``$RANGESIM_DATA`` (or ``${RANGESIM_DATA}``) by :func:`data_dir`."""
    for token in ("${RANGESIM_DATA}", "$RANGESIM_DATA"):
        if text.startswith(token):
            return str(data_dir()) + text[len(token):]
    return text


def _unit_scale(value: str, where: str, source) -> float:
    if not isinstance(value, str) or value not in UNITS_MM:
        raise RangesimError(
            f"unknown units {value!r} in {where}; use one of {UNIT_NAMES}", source=source
        )
    return UNITS_MM[value]


#: the largest |coordinate| (mm) a scene may hold once units, scales and offsets are applied: the
#: scan casts rays in float32, whose spacing there is 64 mm (a 1e307 m offset overflowed to
#: infinity and the scan said "the camera sees no surface")
MAX_WORLD_MM = 1e9


def _in_world(values: np.ndarray, what: str, source) -> np.ndarray:
    """``values`` (mm) if finite and within :data:`MAX_WORLD_MM`, else a one-line refusal."""
    with np.errstate(over="ignore", invalid="ignore"):
        largest = float(np.max(np.abs(values))) if np.size(values) else 0.0
    if not largest <= MAX_WORLD_MM:  # NaN and infinity too
        shown = "overflow to infinity" if not np.isfinite(largest) else f"reach {largest:.3g} mm"
        raise RangesimError(f"{what}: coordinates {shown}, beyond the {MAX_WORLD_MM:.0e} mm a scene may span",
                            source=source)
    return values


def _numbers(value, what: str, source) -> np.ndarray:
    """``value`` as float64 numbers, or a RangesimError naming ``what`` (a TOML string, table or
    ragged list where numbers belong)."""
    if isinstance(value, (str, dict, bool)) or (isinstance(value, list) and any(isinstance(v, (str, dict, list, bool))
                                                                         for v in value)):
        raise RangesimError(f"{what} must be numbers, got {value!r}", source=source)
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"{what} must be numbers, got {value!r}", source=source) from exc


def _vector(table: dict, key: str, default, where: str, source) -> np.ndarray:
    value = _numbers(table.get(key, default), f"{where}.{key}", source)
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise RangesimError(f"{where}.{key} must be 3 finite numbers", source=source)
    return value


def view_pose(view: dict, scale: float = 1.0, source=None) -> np.ndarray:
    """The camera-to-world pose of a ``[view]`` table: ``position`` (required), ``look_at``
    (default the origin) and ``up`` (default +z), in units of ``scale`` mm; a one-line
    RangesimError naming ``source`` where they are not 3 finite numbers each, lie beyond the
    world, or make no view (``up`` along the viewing direction)."""
    position = _in_world(_vector(view, "position", None, "view", source) * scale, "view.position", source)
    target = _in_world(_vector(view, "look_at", (0, 0, 0), "view", source) * scale, "view.look_at", source)
    up = _vector(view, "up", (0, 0, 1), "view", source)
    try:
        return look_at(position, target, up)
    except ValueError as exc:
        raise RangesimError(str(exc), source=source) from exc


def _scene_from_toml(path: Path) -> Scene:
    data = read_toml(path)
    check_keys(data, SCENE_KEYS, "the scene", path)
    scene_mm = _unit_scale(data.get("units", "mm"), "units", path)
    tables = data.get("object", [])
    if isinstance(tables, dict):
        tables = [tables]
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise RangesimError("'object' must be [[object]] tables", source=path)
    if not tables:
        raise RangesimError("scene has no [[object]] tables", source=path)
    object_names(tables, path)
    objects = [_object_from_table(t, k, scene_mm, path) for k, t in enumerate(tables)]
    view = None
    if "view" in data:
        v = data["view"]
        if not isinstance(v, dict):
            raise RangesimError("'view' must be a [view] table", source=path)
        check_keys(v, VIEW_KEYS, "[view]", path)
        view = view_pose(v, scene_mm, path)
    return Scene(objects, view=view, source=str(path.resolve()))


def object_names(tables: list[dict], path: Path | str) -> list[str]:
    """The names of a scene file's ``[[object]]`` tables (``object<k>`` where a table has
    none), refused when two are the same: sweeps and overrides address objects by name.

    Examples
    --------
    >>> object_names([{"name": "part"}, {}], "scene.toml")
    ['part', 'object1']
    """
    names = [str(t.get("name", f"object{k}")) for k, t in enumerate(tables)]
    seen: dict[str, int] = {}
    for k, name in enumerate(names):
        if name in seen:
            raise RangesimError(f"[[object]] {seen[name]} and {k} are both named {name!r}; object names must "
                                "differ (sweeps and overrides address objects by name)", source=path)
        seen[name] = k
    return names


def _object_from_table(t: dict, k: int, scene_mm: float, path: Path) -> SceneObject:
    where = f"[[object]] {k}"
    check_keys(t, OBJECT_KEYS, where, path)
    name = str(t.get("name", f"object{k}"))
    kinds = [key for key in ("mesh", "model", "primitive") if key in t]
    if len(kinds) != 1:
        raise RangesimError(f"{where} ({name}) needs exactly one of mesh, model, primitive", source=path)
    kind = str(t["primitive"]) if "primitive" in t else kinds[0]
    foreign = sorted(set(t) & GEOMETRY_KEYS - set(PRIMITIVE_KEYS.get(kind, ())))
    # a key of another kind (size on a sphere, radius on a mesh) is a mistake, not a no-op; an
    # unknown primitive gets its own error below
    if foreign and (kind in PRIMITIVE_KEYS or kind in ("mesh", "model")):
        takes = ", ".join(PRIMITIVE_KEYS.get(kind, ())) or "none of them"
        raise RangesimError(f"{where} ({name}): {', '.join(foreign)} does not apply to a {kind} "
                            f"(its geometry keys: {takes})", source=path)
    if "params" in t and "model" not in t:  # a sweep's params.thickness on a box was silently ignored
        raise RangesimError(f"{where} ({name}): params apply to a built-in model (model = ...), not to a {kind}",
                            source=path)
    if "mesh" in t:
        mesh_path = (path.parent / expand_data_path(str(t["mesh"]))).resolve()
        try:
            mesh, origin = load_mesh(mesh_path), str(mesh_path)
        except RangesimError as exc:  # named as the scene names it, in the scene that does
            reason = str(exc).removeprefix(f"{exc.source}: ")
            raise RangesimError(f"{where} ({name}): mesh = {str(t['mesh'])!r} -> {mesh_path}: {reason}",
                                source=path) from None
    elif "model" in t:
        built = _build_model(t, where, path)
        mesh, origin = built.mesh, f"model:{t['model']}"
    else:
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # sizes past the world are refused below
                mesh, origin = make_primitive(str(t["primitive"]), t, source=path), str(t["primitive"])
        except RangesimError as exc:
            raise RangesimError(f"{where} ({name}): {str(exc).removeprefix(f'{path}: ')}", source=path) from None
    # the object's own units, else a model's millimetres (built-in models are made in mm:
    # positions follow the scene's unit, the part does not), else the scene's
    object_mm = _unit_scale(t["units"], where, path) if "units" in t else 1.0 if "model" in t else scene_mm
    scale = _numbers(t.get("scale", 1.0), f"{where}.scale", path)
    if not np.all(np.isfinite(scale)) or np.any(scale <= 0) or scale.shape not in ((), (3,)):
        raise RangesimError(f"{where}.scale must be a positive number or 3 of them", source=path)
    albedo = _numbers(t.get("albedo", 0.6), f"{where}.albedo", path)
    if albedo.shape != ():
        raise RangesimError(f"{where}.albedo must be one number, got {t['albedo']!r}", source=path)
    albedo = float(albedo)
    if not 0.0 <= albedo <= 1.0:
        raise RangesimError(f"{where}.albedo must lie in 0..1, got {albedo}", source=path)
    translate, rotate = _vector(t, "translate", (0, 0, 0), where, path), _vector(t, "rotate_deg", (0, 0, 0), where, path)
    mesh = mesh.copy()
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below, in one line
        matrix = object_transform(translate * scene_mm, rotate, scale * object_mm)
        mesh.apply_transform(matrix)
    _in_world(mesh.vertices, f"{where} ({name}) after units, scale and translate", path)
    material = check_material(t["material"], where, path) if "material" in t else {}
    obj = SceneObject(name, mesh, albedo=albedo, source=origin, material=material)
    if "model" in t:
        obj.face_labels, obj.labels = built.face_labels, list(built.labels)
        if scale.shape == () or np.allclose(scale, scale.flat[0]):  # features survive similarity transforms
            obj.features = built.features.transformed(matrix)
    return obj


def _build_model(t: dict, where: str, path: Path):
    """A built-in parametric model (``model = "green_piece"``, optional ``params`` table)."""
    from rangesim.cad.models import MODELS, check_model_params, model_names

    if not isinstance(t["model"], str) or t["model"] not in MODELS:
        raise RangesimError(
            f"{where}: unknown model {t['model']!r}; built-in models: {', '.join(model_names())}", source=path
        )
    params = t.get("params", {})
    if not isinstance(params, dict):
        raise RangesimError(f"{where}.params must be a table", source=path)
    try:  # the checks rangesim model's --param gets: ranges, integers, the memory estimate
        check_model_params(t["model"], params)
    except RangesimError as exc:
        text = str(exc).removeprefix(f"{t['model']}: ").replace("--param ", "")
        raise RangesimError(f"{where}.params: {text}", source=path) from None
    try:
        return MODELS[t["model"]](**params)
    except RangesimError as exc:
        raise RangesimError(f"{where}: {exc}", source=path) from exc
    except (TypeError, ValueError) as exc:
        raise RangesimError(f"{where}: bad model parameters ({exc})", source=path) from exc
