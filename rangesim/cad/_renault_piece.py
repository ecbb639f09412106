"""The "Renault Piece" of the founding paper: an automobile part with sculptured freeform
surfaces, from five sub-parts: neck, right head, back bump, left head, base plate.

As in the paper: the right head, left head and back bump have sharp edges (vertical walls
meeting a freeform top), while the base plate and the neck meet in rounded edges: the
neck's top is a cubic B-spline patch whose two outer control rings sit at the plate's top
level, so it leaves the plate tangentially, a cubic B-spline blend. Every freeform top is a
tensor-product B-spline patch (:class:`rangesim.cad.BSplineSurface`). The sub-parts are
joined by manifold3d unions (the heads and the bump reach down into the plate), and two
mounting holes go through the plate.

Coordinates: millimetres, the plate centred on the z axis, its bottom at z = 0, the neck
along x between the heads, the back bump towards +y.
"""
from __future__ import annotations

from typing import Any

import manifold3d
import numpy as np

from rangesim.cad import _layout
from rangesim.cad._layout import positive, tuples, within
from rangesim.cad.features import AnalyticFeatures, Circle3D, Curve3D, Segment3D
from rangesim.cad.freeform import height_patch, surface_solid
from rangesim.cad.models import MAX_PARAM_MAGNITUDE, MAX_SEGMENTS, MODELS
from rangesim.cad.part import BuiltPart, build_part, difference, solid, union
from rangesim.core import params as P
from rangesim.core.errors import RangesimError

DEFAULTS: dict[str, Any] = {
    "plate_length": 150.0,
    "plate_width": 80.0,
    "plate_thickness": 10.0,
    "corner_radius": 12.0,
    "hole_radius": 4.0,
    "hole_x": 66.0,           # holes at (+-hole_x, 0)
    "neck_length": 90.0,      # along x, blend included
    "neck_width": 36.0,
    "neck_height": 22.0,      # above the plate, at its ends
    "neck_waist": 0.75,       # height at the middle relative to the ends
    "head_x": 45.0,           # heads centred at (+-head_x, 0)
    "head_size": (30.0, 44.0),
    "head_height": 38.0,      # rim level of the heads' tops above z = 0
    "bump_size": (44.0, 14.0),
    "bump_y": 29.0,           # back bump centred at (0, bump_y)
    "bump_height": 15.0,
    "samples_per_mm": 0.8,    # tessellation density of the freeform tops
    "segments": 48,
}
#: the most grid points of all freeform tops together (the default part: 4,081; 415,744 at
#: 8 per mm took 12 s and 2 GB, and 1000 per mm asked for 24 GB)
MAX_FREEFORM_SAMPLES = 200_000
#: the smallest side of a head or the bump (mm)
MIN_FREEFORM_MM = 1.0
FLOOR_Z = 5.0  # freeform solids reach down into the plate, so the unions are clean


def renault_piece(**params) -> BuiltPart:
    """Build the Renault Piece.

    Parameters
    ----------
    **params
        Any key of :data:`DEFAULTS` (millimetres).

    Returns
    -------
    BuiltPart
        Mesh, part tree (base_plate minus holes, united with neck, right_head, back_bump,
        left_head), sub-part labels, analytic features (hole rims, plate and head edges,
        the heads' and bump's sharp top rims as curves).

    Examples
    --------
    >>> import rangesim as rs
    >>> part = rs.cad.renault_piece()
    >>> part.mesh.is_watertight, sorted(leaf.name for leaf in part.tree.leaves())[:3]
    (True, ['back_bump', 'base_plate', 'hole_1'])

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 2 (Fig.
       4-6).
    """
    unknown = sorted(set(params) - set(DEFAULTS))
    if unknown:
        raise RangesimError(f"unknown renault_piece parameter(s) {', '.join(unknown)}; known: {', '.join(DEFAULTS)}")
    p = {**DEFAULTS, **params}
    p["segments"] = P.whole(p["segments"], "renault_piece: segments", 3, MAX_SEGMENTS)
    _check_layout(p)
    L, W, T = p["plate_length"], p["plate_width"], p["plate_thickness"]
    r, n_seg = p["corner_radius"], int(p["segments"])
    features = AnalyticFeatures()
    density = p["samples_per_mm"]

    outline = manifold3d.CrossSection.square((L - 2 * r, W - 2 * r), True).offset(r, manifold3d.JoinType.Round, 2.0, 4 * n_seg)
    plate = solid("base_plate", "base", manifold3d.Manifold.extrude(outline, T), length=L, width=W, thickness=T,
                  corner_radius=r)
    features.segments += _plate_edges(L, W, T, r)
    holes = []
    for k, x in enumerate((-p["hole_x"], p["hole_x"]), start=1):
        name = f"hole_{k}"
        hr = p["hole_radius"]
        holes.append(solid(name, "hole", manifold3d.Manifold.cylinder(T + 2, hr, hr, n_seg).translate((x, 0, -1)),
                           x=x, y=0.0, radius=hr))
        for z in (0.0, T):
            features.circles.append(Circle3D(f"{name}_rim_{'top' if z else 'bottom'}", np.array([x, 0, z]),
                                             np.array([0, 0, 1.0]), hr, 90.0, True, name))
    base = difference("base_with_holes", plate, *holes, function="base")

    neck_surface = _neck_surface(p, T)
    neck = solid("neck", "neck", _freeform(neck_surface, p["neck_length"], p["neck_width"], density),
                 length=p["neck_length"], width=p["neck_width"], height=p["neck_height"], blend="cubic B-spline")
    heads = []
    for side, name in ((1, "right_head"), (-1, "left_head")):
        surface = _head_surface(p, side)
        heads.append(solid(name, "head", _freeform(surface, *p["head_size"], density),
                           center=(side * p["head_x"], 0.0), size=p["head_size"]))
        features.segments += _wall_edges(name, surface, T)
        features.curves.append(_rim_curve(name, surface))
    bump_surface = _bump_surface(p)
    bump = solid("back_bump", "bump", _freeform(bump_surface, *p["bump_size"], density),
                 center=(0.0, p["bump_y"]), size=p["bump_size"])
    features.segments += _wall_edges("back_bump", bump_surface, T)
    features.curves.append(_rim_curve("back_bump", bump_surface))

    right, left = heads
    tree = union("renault_piece", neck, right, bump, left, base, function="part")
    return build_part("renault_piece", tree, features, p)


def _check_layout(p: dict) -> None:
    """Sizes that are sizes, the corner radius under half the plate, the holes, the neck, the heads
    and the bump on it and clear of each other (a hole off the plate or under the neck would be
    listed as a rim the mesh does not have, a head over the plate's edge covers edges listed there)."""
    m = "renault_piece"
    sizes = ("plate_length", "plate_width", "plate_thickness", "corner_radius", "hole_radius", "neck_length",
             "neck_width", "neck_height", "neck_waist", "head_height", "bump_height", "samples_per_mm")
    positive(m, **{k: p[k] for k in sizes})
    for key in ("hole_x", "head_x", "bump_y"):  # positions: any finite number
        P.number(p[key], f"{m}: {key}", -MAX_PARAM_MAGNITUDE, MAX_PARAM_MAGNITUDE, what="number", unit="mm")
    for key in ("head_size", "bump_size"):
        (size,) = tuples(m, key, p[key], ("x", "y"), many=False)
        positive(m, **{f"{key} x": size[0], f"{key} y": size[1]})
    grid = [(p["neck_length"], p["neck_width"]), tuple(p["head_size"]), tuple(p["head_size"]), tuple(p["bump_size"])]
    samples = sum(_grid_points(sx, p["samples_per_mm"]) * _grid_points(sy, p["samples_per_mm"]) for sx, sy in grid)
    if samples > MAX_FREEFORM_SAMPLES:
        # the freeform tops are sampled on grids of size x density points per side
        raise RangesimError(f"{m}: samples_per_mm {p['samples_per_mm']:g} samples the freeform tops (neck, heads, "
                            f"bump) at {samples:,} points, more than {MAX_FREEFORM_SAMPLES:,}; use a lower density")
    L, W, r = p["plate_length"], p["plate_width"], p["corner_radius"]
    if r >= min(L, W) / 2:
        raise RangesimError(f"{m}: corner_radius {r:g} mm must be less than half the plate ({min(L, W) / 2:g} mm)")
    within(m, "the hole (hole_x, hole_radius)", float(p["hole_x"]), 0.0, p["hole_radius"], L / 2, W / 2)
    T = p["plate_thickness"]
    if T <= FLOOR_Z:
        raise RangesimError(f"{m}: plate_thickness {T:g} mm must exceed {FLOOR_Z:g} mm (the freeform solids reach "
                            "down to that height inside the plate)")
    # the heads and the bump: on the plate, and their rims above its top (a buried head's walls
    # and rim would be listed as features the mesh does not have)
    (hx, hy), (bx, by) = p["head_size"], p["bump_size"]
    if min(hx, hy, bx, by) < MIN_FREEFORM_MM:  # a patch of a micrometre has no wall or rim to scan
        raise RangesimError(f"{m}: head_size and bump_size must be at least {MIN_FREEFORM_MM:g} mm a side, got "
                            f"{[hx, hy]} and {[bx, by]}")
    gap = _layout.MIN_GAP_MM
    head_x, bump_y, hole_x, hr = (float(p[k]) for k in ("head_x", "bump_y", "hole_x", "hole_radius"))
    nx, ny = float(p["neck_length"]) / 2, float(p["neck_width"]) / 2
    neck = _layout.box(-nx, -ny, nx, ny)
    heads = [_layout.box(side * head_x - hx / 2, -hy / 2, side * head_x + hx / 2, hy / 2) for side in (1, -1)]
    bump = _layout.box(-bx / 2, bump_y - by / 2, bx / 2, bump_y + by / 2)
    holes = [_layout.circle(-hole_x, 0.0, hr), _layout.circle(hole_x, 0.0, hr)]
    # on the plate (its rounded outline), clear of its edges: a sub-part at or over an edge
    # covers the plate's edges listed there
    for what, footprints in (("the heads (head_x, head_size)", heads), ("the bump (bump_y, bump_size)", [bump]),
                             ("the neck (neck_length, neck_width)", [neck]),
                             ("the holes (hole_x, hole_radius)", holes)):
        if min(_layout.clearance_in_rounded_rect(f, L / 2, W / 2, r) for f in footprints) < gap:
            verb = "reach" if len(footprints) > 1 else "reaches"
            raise RangesimError(f"{m}: {what} {verb} past the plate ({L:g} x {W:g} mm, corner_radius {r:g} mm) or "
                                f"within {gap:g} mm of its edge")
    # the holes apart and clear of the freeform sub-parts (which would cover their top rims); the
    # heads, the bump and the neck apart (each would cover the other's walls), except the neck's
    # ends, which run into the heads below their rims
    names = {"hole_1": "hole_1 (hole_x, hole_radius)", "hole_2": "hole_2 (hole_x, hole_radius)",
             "neck": "the neck (neck_length, neck_width)", "right": "the right head (head_x, head_size)",
             "left": "the left head (head_x, head_size)", "bump": "the back bump (bump_y, bump_size)"}
    shapes = {"hole_1": holes[0], "hole_2": holes[1], "neck": neck, "right": heads[0], "left": heads[1],
              "bump": bump}
    for one, other in (("hole_1", "hole_2"), *((h, k) for h in ("hole_1", "hole_2")
                                               for k in ("neck", "right", "left", "bump")),
                       ("right", "left"), ("right", "bump"), ("left", "bump"), ("neck", "bump")):
        _layout.clear(m, names[one], shapes[one], names[other], shapes[other])
    rims = {key: _rim_height(surface) for key, surface in (("right", _head_surface(p, 1)),
                                                            ("left", _head_surface(p, -1)),
                                                            ("bump", _bump_surface(p)))}
    for key, what in (("right", "right head"), ("left", "left head"), ("bump", "bump")):
        rim = rims[key]
        if rim <= T:
            raise RangesimError(f"{m}: the {what}'s rim falls to {rim:g} mm, not above the plate's top "
                                f"(plate_thickness {T:g} mm); raise head_height / bump_height or thin the plate")
    neck_top = float(np.asarray(_neck_surface(p, T).control_points)[..., 2].max())
    for key, head in (("right", heads[0]), ("left", heads[1])):
        if _layout.gap(head, neck) >= 0:
            continue
        # the neck runs into the head: past its walls' corner edges, and below its rim
        for corner in head[1]:
            _layout.clear(m, f"the corner edge at ({corner[0]:g}, {corner[1]:g}) of {names[key]}",
                          _layout.circle(*corner, 0.0), names["neck"], neck)
        rim = rims[key]
        if rim <= neck_top:
            raise RangesimError(f"{m}: the neck (neck_height {p['neck_height']:g} mm) rises to {neck_top:g} mm where "
                                f"it meets the {key} head, whose rim falls to {rim:g} mm: it would break through the "
                                "head's rim; lower the neck or raise head_height")


def _rim_height(surface: Any) -> float:
    """The lowest point of a clamped B-spline patch's border (its control net's border), mm."""
    z = np.asarray(surface.control_points)[..., 2]
    return float(min(z[0].min(), z[-1].min(), z[:, 0].min(), z[:, -1].min()))


def _grid_points(size: float, density: float) -> int:
    """Samples of a freeform top along a side ``size`` mm long at ``density`` per mm (at least 8)."""
    return max(8, int(size * density))


def _freeform(surface, size_x, size_y, density):
    return surface_solid(surface, _grid_points(size_x, density), _grid_points(size_y, density), FLOOR_Z)


def _neck_surface(p, top):
    """Ridge between the heads, saddle-shaped (lower at the waist), blended into the plate."""
    n_u, n_v = 11, 7
    x = np.linspace(-0.5, 0.5, n_u)[:, None] * 2  # -1 .. 1 along the neck
    y = np.linspace(-1, 1, n_v)[None, :]
    height = p["neck_height"] * (p["neck_waist"] + (1 - p["neck_waist"]) * x**2) * (1 - 0.35 * y**2)
    heights = top + np.broadcast_to(height, (n_u, n_v)).copy()
    heights[[0, 1, -2, -1], :] = top  # two rings at the plate's level: tangent, a rounded blend
    heights[:, [0, 1, -2, -1]] = top
    half_l, half_w = p["neck_length"] / 2, p["neck_width"] / 2
    return height_patch((-half_l, half_l), (-half_w, half_w), heights)


def _head_surface(p, side):
    """A sculptured head top: a dome tilted sideways (right) or a saddle (left)."""
    n_u, n_v = 6, 7
    sx, sy = p["head_size"]
    u = np.linspace(-1, 1, n_u)[:, None]
    v = np.linspace(-1, 1, n_v)[None, :]
    if side > 0:
        shape = 7.0 * (1 - 0.6 * u**2) * (1 - 0.5 * v**2) + 3.0 * v
    else:
        shape = 5.0 + 4.0 * u**2 - 5.0 * v**2 - 2.0 * u
    heights = p["head_height"] + shape
    cx = side * p["head_x"]
    return height_patch((cx - sx / 2, cx + sx / 2), (-sy / 2, sy / 2), heights)


def _bump_surface(p):
    n_u, n_v = 7, 5
    sx, sy = p["bump_size"]
    u = np.linspace(-1, 1, n_u)[:, None]
    v = np.linspace(-1, 1, n_v)[None, :]
    heights = p["bump_height"] + 4.0 * (1 - u**2) * (1 - 0.3 * v) + 1.0 * v
    y0 = p["bump_y"]
    return height_patch((-sx / 2, sx / 2), (y0 - sy / 2, y0 + sy / 2), heights)


def _plate_edges(L, W, T, r):
    """The straight parts of the plate's top and bottom outline (convex right angles)."""
    out = []
    for z in (0.0, T):
        level = "top" if z else "bottom"
        for sy in (-1, 1):
            out.append(Segment3D(f"plate_{level}_x_{'neg' if sy < 0 else 'pos'}", np.array([-L / 2 + r, sy * W / 2, z]),
                                 np.array([L / 2 - r, sy * W / 2, z]), 90.0, True, "base_plate"))
        for sx in (-1, 1):
            out.append(Segment3D(f"plate_{level}_y_{'neg' if sx < 0 else 'pos'}", np.array([sx * L / 2, -W / 2 + r, z]),
                                 np.array([sx * L / 2, W / 2 - r, z]), 90.0, True, "base_plate"))
    return out


def _wall_edges(name, surface, plate_top):
    """Vertical corner edges of a walled freeform solid, from the plate up to its top."""
    (u0, u1), (v0, v1) = surface.domain
    out = []
    for k, (u, v) in enumerate(((u0, v0), (u1, v0), (u1, v1), (u0, v1))):
        corner = surface.evaluate(u, v)
        out.append(Segment3D(f"{name}_corner_{k}", np.array([corner[0], corner[1], plate_top]), corner,
                             90.0, True, name))
    return out


def _rim_curve(name, surface, n: int = 33):
    """The sharp rim where the walls meet the freeform top, with its crease angle."""
    (u0, u1), (v0, v1) = surface.domain
    t = np.linspace(0, 1, n)[:-1]
    u = np.concatenate([u0 + (u1 - u0) * t, np.full(n - 1, u1), u1 - (u1 - u0) * t, np.full(n - 1, u0)])
    v = np.concatenate([np.full(n - 1, v0), v0 + (v1 - v0) * t, np.full(n - 1, v1), v1 - (v1 - v0) * t])
    points = surface.evaluate(u, v)
    top_normal = surface.normal(u, v)
    wall = np.zeros_like(points)  # outward wall normals of the rectangular footprint
    wall[:len(t), 1] = -1
    wall[len(t):2 * len(t), 0] = 1
    wall[2 * len(t):3 * len(t), 1] = 1
    wall[3 * len(t):, 0] = -1
    dihedral = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", top_normal, wall), -1, 1)))
    return Curve3D(f"{name}_rim", points, dihedral, True, name)


MODELS["renault_piece"] = renault_piece
