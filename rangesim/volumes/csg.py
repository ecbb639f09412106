"""The CSG-like volumetric model of a part (section 6 of the paper): the sub-parts of the CAD
design linked by Boolean expressions, each with its volume properties and functional
information, without performing the set operations again."""
from __future__ import annotations

from typing import Any

from rangesim.cad.part import PartNode, _jsonable

_OP = {"union": " + ", "difference": " - "}

def boolean_expression(node: PartNode, expand: bool = True) -> str:
    """The node's solid as a Boolean expression ("+" union, "-" difference).

    Parameters
    ----------
    node : PartNode
    expand : bool
        True: in terms of leaf solids, nested in parentheses; False: of the direct children.

    Examples
    --------
    ``green_piece = ((((plate - hole_1 - ...) - dent) - scratch_1 - ...) - thread_1 - ...)``
    """
    def expr(n: PartNode, top: bool) -> str:
        if n.operation == "solid" or (not expand and not top):
            return n.name
        return "(" + _OP[n.operation].join(expr(c, False) for c in n.children) + ")"

    return f"{node.name} = {expr(node, True)}"


def volumetric_model(tree: PartNode) -> dict[str, Any]:
    """JSON-ready CSG-like tree.

    Every node: ``name``, ``operation``, ``function`` (the functional tag), ``role`` (adds or
    removes material in its parent), ``params``, ``properties`` (volume mm^3, area mm^2,
    centroid (3,), inertia (3, 3), principal moments (3,) ascending, principal axes (3, 3)
    rows, plus ``radii_of_gyration`` (3,) mm), and for inner nodes ``expression`` (of the
    children) and ``expanded`` (of the leaves).

    Examples
    --------
    >>> import rangesim as rs
    >>> from rangesim.volumes.csg import volumetric_model
    >>> model = volumetric_model(rs.cad.green_piece().tree)
    >>> model["expanded"][:40], model["operation"]
    ('green_piece = ((((plate - hole_1 - hole_', 'difference')

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 6.
    """
    def visit(node: PartNode, role: str) -> dict[str, Any]:
        props = dict(node.properties)
        vol = float(props.get("volume", 0.0))
        if vol > 0 and "principal_moments" in props:
            props["radii_of_gyration"] = [max(float(m), 0.0) ** 0.5 / vol ** 0.5 for m in props["principal_moments"]]
        out = {"name": node.name, "operation": node.operation, "function": node.function, "role": role,
               "params": _jsonable(node.params), "properties": _jsonable(props)}
        if node.operation != "solid":
            out["expression"] = boolean_expression(node, expand=False)
            out["expanded"] = boolean_expression(node, expand=True)
            roles = ["adds material"] * len(node.children)
            if node.operation == "difference":
                roles = ["base"] + ["removes material"] * (len(node.children) - 1)
            out["children"] = [visit(c, r) for c, r in zip(node.children, roles)]
        return out

    return visit(tree, "part")
