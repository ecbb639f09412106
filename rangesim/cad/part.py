"""Part trees: CSG-like structures of named solids joined by union and difference.

A part is built stepwise from named primitives, as in the paper's Alpha_1 designs: each
leaf is a closed solid (a ``manifold3d.Manifold``) with a function tag (plate, hole,
thread, dent, ...); inner nodes are Boolean operations. Evaluating the tree with
manifold3d gives a closed, valid mesh in which every triangle knows which leaf it came
from (manifold3d keeps each input's ``original_id`` through the Booleans), so scans can
label pixels by sub-part. Every node carries its volume properties.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterator

import manifold3d
import numpy as np
import trimesh

from rangesim.cad.features import AnalyticFeatures

OPERATIONS = ("solid", "union", "difference")


@dataclass
class PartNode:
    """A node of a part tree.

    Attributes
    ----------
    name : str
        Unique within the tree.
    operation : {"solid", "union", "difference"}
        A leaf solid, or a Boolean of the children (difference: the first child minus the
        others).
    function : str
        What the node is for: plate, hole, thread, dent, scratch, neck, head, ...
    children : list of PartNode
    params : dict
        The dimensions that made the node (mm, degrees).
    properties : dict
        Volume properties of the node's own solid: ``volume`` (mm^3), ``area`` (mm^2),
        ``centroid`` (3,), ``inertia`` (3, 3) about the centroid for unit density,
        ``principal_moments`` (3,) ascending and ``principal_axes`` (3, 3) as rows.
    """

    name: str
    operation: str
    function: str
    children: list["PartNode"] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    properties: dict[str, Any] = field(default_factory=dict)
    solid: Any = field(default=None, repr=False)

    def walk(self) -> Iterator["PartNode"]:
        """This node and all below it, depth first."""
        yield self
        for child in self.children:
            yield from child.walk()

    def leaves(self) -> list["PartNode"]:
        return [n for n in self.walk() if n.operation == "solid"]

    def find(self, name: str) -> "PartNode":
        for node in self.walk():
            if node.name == name:
                return node
        raise KeyError(name)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict (numbers as floats and lists)."""
        return {
            "name": self.name,
            "operation": self.operation,
            "function": self.function,
            "params": _jsonable(self.params),
            "properties": _jsonable(self.properties),
            "children": [c.to_dict() for c in self.children],
        }


def solid(name: str, function: str, manifold: manifold3d.Manifold, **params) -> PartNode:
    """A leaf: a closed solid with its own identity (its triangles stay labelled)."""
    return PartNode(name, "solid", function, params=params, solid=manifold.as_original())


def union(name: str, *children: PartNode, function: str = "assembly", **params) -> PartNode:
    return PartNode(name, "union", function, list(children), params)


def difference(name: str, base: PartNode, *cutters: PartNode, function: str = "assembly", **params) -> PartNode:
    return PartNode(name, "difference", function, [base, *cutters], params)


def evaluate(node: PartNode) -> manifold3d.Manifold:
    """Solid of a node (computed bottom-up, cached on the nodes with their properties)."""
    if node.operation == "solid":
        result = node.solid
    else:
        parts = [evaluate(c) for c in node.children]
        if node.operation == "union":
            result = manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add)
        elif node.operation == "difference":
            cut = manifold3d.Manifold.batch_boolean(parts[1:], manifold3d.OpType.Add)
            result = parts[0] - cut
        else:
            raise ValueError(f"unknown operation {node.operation!r}")
        node.solid = result
    if not node.properties:
        node.properties = volume_properties(manifold_to_trimesh(result))
    return result


def manifold_to_trimesh(m: manifold3d.Manifold) -> trimesh.Trimesh:
    mesh = m.to_mesh64()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts), process=False)


def volume_properties(mesh: trimesh.Trimesh) -> dict[str, Any]:
    """Volume, area, centroid, inertia tensor and principal moments/axes (unit density)."""
    inertia = np.asarray(mesh.moment_inertia, dtype=np.float64)
    moments, axes = np.linalg.eigh(inertia)
    return {
        "volume": float(mesh.volume),
        "area": float(mesh.area),
        "centroid": np.asarray(mesh.center_mass, dtype=np.float64),
        "inertia": inertia,
        "principal_moments": moments,
        "principal_axes": axes.T,
    }


@dataclass
class BuiltPart:
    """A built parametric part.

    Attributes
    ----------
    name : str
    mesh : trimesh.Trimesh
        Closed, valid triangle mesh, millimetres.
    tree : PartNode
        The part tree (every node with its volume properties).
    face_labels : (n_faces,) int32
        For each triangle, the index into ``labels`` of the leaf solid it came from.
    labels : list of str
        Leaf names, in tree order.
    features : AnalyticFeatures
        Exact hole rims, straight edges and creases (ground truth for detectors).
    params : dict
        The parameters the part was built with.
    """

    name: str
    mesh: trimesh.Trimesh
    tree: PartNode
    face_labels: np.ndarray
    labels: list[str]
    features: AnalyticFeatures
    params: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """Part tree, labels, features and parameters as a JSON-ready dict."""
        return {
            "name": self.name,
            "params": _jsonable(self.params),
            "tree": self.tree.to_dict(),
            "labels": list(self.labels),
            "faces_per_label": np.bincount(self.face_labels, minlength=len(self.labels)).tolist(),
            "features": self.features.to_dict(),
        }


def build_part(name: str, tree: PartNode, features: AnalyticFeatures, params: dict[str, Any]) -> BuiltPart:
    """Evaluate a part tree into a labelled mesh."""
    result = evaluate(tree)
    mesh_gl = result.to_mesh64()
    vertices = np.asarray(mesh_gl.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(mesh_gl.tri_verts, dtype=np.int64)
    leaves = tree.leaves()
    label_of_id = {leaf.solid.original_id(): k for k, leaf in enumerate(leaves)}
    run_index = np.asarray(mesh_gl.run_index, dtype=np.int64) // 3
    run_ids = np.asarray(mesh_gl.run_original_id, dtype=np.int64)
    face_labels = np.full(len(faces), -1, dtype=np.int32)
    for start, stop, original in zip(run_index[:-1], run_index[1:], run_ids, strict=False):
        face_labels[start:stop] = label_of_id.get(int(original), -1)
    if (face_labels < 0).any():
        raise RuntimeError(f"{name}: {int((face_labels < 0).sum())} triangles lost their sub-part label")
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    return BuiltPart(name, mesh, tree, face_labels, [leaf.name for leaf in leaves], features, params)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
