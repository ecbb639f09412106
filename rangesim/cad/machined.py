"""Procedural machined-style parts with their exact features: a benchmark nobody tuned to.

:func:`machined_design` draws a random but seeded layout on a plate: through- and blind
holes of several radii, a step, a slot, bosses, a wedge, standing and lying cylinders, and
a plain, chamfered or filleted plate outline. :func:`machined_part` builds it as a part
tree of named solids (manifold3d Booleans, like :func:`~rangesim.cad.green_piece`), so the
mesh is closed and valid, and records every feature exactly: hole, boss and cylinder rims
as :class:`~rangesim.cad.features.Circle3D`, straight creases as
:class:`~rangesim.cad.features.Segment3D`, each with its dihedral angle and sign. One
exception: a lying cylinder's end circles are listed whole, though its axis lies 0.5 r above
the plate's top, so their lowest third (120 degrees) is inside the plate and no edge of the
mesh; the scorers' visibility tests leave that arc out (it is never seen), so such a circle
is never 80 % visible and the benchmark never counts it as a rim to find.

Coordinates: millimetres, the plate centred on the z axis, its bottom at z = 0, its top at
z = thickness; a step lowers the top at the +x end.

Feature names are ``KIND_K_WHERE`` (``through_hole_2_top``, ``boss_1_foot``,
``plate_top_y+``); :func:`feature_type` strips the index (``through_hole_top``), the unit a
benchmark reports per type.
"""
from __future__ import annotations

import math
import re
from typing import Any

import manifold3d
import numpy as np

from rangesim.cad import _layout
from rangesim.cad.features import AnalyticFeatures, Circle3D, Segment3D
from rangesim.cad.models import MAX_PARAM_MAGNITUDE, MAX_SEGMENTS, MODELS
from rangesim.cad.part import BuiltPart, build_part, difference, solid, union
from rangesim.core import params as P
from rangesim.core.errors import RangesimError

__all__ = ["machined_design", "machined_part", "feature_type", "HOLE_RADII", "ROUND_TYPES"]

#: hole radii drawn from, mm
HOLE_RADII = (2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
#: circle feature types (:func:`feature_type` of a circle's name)
ROUND_TYPES = ("through_hole_top", "through_hole_bottom", "blind_hole_top", "blind_hole_floor",
               "boss_top", "boss_foot", "cylinder_top", "cylinder_foot", "lying_cylinder_end")
#: solids added on top sink this far into the plate, so unions never meet face to face, mm
_SINK_MM = 1.0
#: clearance kept between features and to the plate's outline, mm
_CLEARANCE_MM = 3.0
#: a lying cylinder's axis lies this many radii above the plate top (it overhangs)
_LYING_AXIS = 0.5


def feature_type(name: str) -> str:
    """The type of a machined part's feature from its name: the index removed.

    Examples
    --------
    >>> feature_type("through_hole_3_top"), feature_type("lying_cylinder_1_end_b"), feature_type("plate_top_y+")
    ('through_hole_top', 'lying_cylinder_end', 'plate_top_y+')
    """
    kind = re.sub(r"_\d+_", "_", name, count=1)
    return re.sub(r"_end_[ab]$", "_end", kind)


# ---------------------------------------------------------------------------------------
# the random layout
# ---------------------------------------------------------------------------------------
class _Layout:
    """Axis-aligned rectangles already taken on the plate top (x0, y0, x1, y1), mm."""

    def __init__(self, x0: float, y0: float, x1: float, y1: float):
        self.bounds = (x0, y0, x1, y1)
        self.taken: list[tuple[float, float, float, float]] = []

    def place(self, rng: np.random.Generator, half_x: float, half_y: float, tries: int = 60):
        """Centre (x, y) of a free (2 half_x) x (2 half_y) rectangle, or None."""
        x0, y0, x1, y1 = self.bounds
        c = _CLEARANCE_MM
        if x1 - x0 < 2 * (half_x + c) or y1 - y0 < 2 * (half_y + c):
            return None
        for _ in range(tries):
            x = float(rng.uniform(x0 + half_x + c, x1 - half_x - c))
            y = float(rng.uniform(y0 + half_y + c, y1 - half_y - c))
            box = (x - half_x - c, y - half_y - c, x + half_x + c, y + half_y + c)
            if all(box[2] <= t[0] or box[0] >= t[2] or box[3] <= t[1] or box[1] >= t[3] for t in self.taken):
                self.taken.append(box)
                return round(x, 2), round(y, 2)
        return None


def machined_design(seed: int) -> dict[str, Any]:
    """A random machined-part layout, the same for the same seed.

    Parameters
    ----------
    seed : int
        Seed of :func:`numpy.random.default_rng`.

    Returns
    -------
    dict
        The keyword arguments of :func:`machined_part` (mm, degrees): ``length``,
        ``width``, ``thickness``, ``outline`` ("plain", "chamfer" or "fillet") and
        ``outline_size``, ``step`` (width, depth) or None, ``slot`` (x, y, length, width,
        depth, along) or None, ``holes`` [(x, y, radius, depth or None for through); three
        values (x, y, radius) are a through hole too], ``bosses`` and ``cylinders`` [(x, y,
        radius, height)], ``wedge`` (x, y, length, width, height) or None (rising towards
        +x), ``lying`` [(x, y, radius, length, along)].

    Examples
    --------
    >>> d = machined_design(7)
    >>> d == machined_design(7), len(d["holes"]) >= 2
    (True, True)
    """
    rng = np.random.default_rng(int(seed))
    L = float(np.round(rng.uniform(90, 140), 1))
    W = float(np.round(rng.uniform(65, 100), 1))
    T = float(np.round(rng.uniform(10, 16), 1))
    has_step = bool(rng.random() < 0.5)
    outline = str(rng.choice(["plain", "fillet"] if has_step else ["plain", "chamfer", "fillet"]))
    outline_size = {"plain": 0.0, "chamfer": float(np.round(rng.uniform(1.5, 3.0), 1)),
                    "fillet": float(np.round(rng.uniform(4.0, 10.0), 1))}[outline]
    step = None
    x_end = L / 2
    if has_step:
        step = (float(np.round(rng.uniform(0.18, 0.3) * L, 1)), float(np.round(rng.uniform(0.3, 0.6) * T, 1)))
        x_end = L / 2 - step[0]
    margin = outline_size
    layout = _Layout(-L / 2 + margin, -W / 2 + margin, x_end, W / 2 - margin)
    design: dict[str, Any] = {"length": L, "width": W, "thickness": T, "outline": outline,
                              "outline_size": outline_size, "step": step, "slot": None, "holes": [],
                              "bosses": [], "cylinders": [], "wedge": None, "lying": []}
    # the larger items first, so they find room
    if rng.random() < 0.5:
        along = str(rng.choice(["x", "y"]))
        length, width = float(np.round(rng.uniform(20, 40), 1)), float(np.round(rng.uniform(5, 10), 1))
        half = (length / 2, width / 2) if along == "x" else (width / 2, length / 2)
        at = layout.place(rng, *half)
        if at:
            design["slot"] = (*at, length, width, float(np.round(rng.uniform(0.25, 0.5) * T, 1)), along)
    if rng.random() < 0.5:
        length, width = float(np.round(rng.uniform(18, 30), 1)), float(np.round(rng.uniform(12, 22), 1))
        # 25-40 degree ramps: its toe is a crease above the truth's 20 degrees
        height = float(np.round(length * math.tan(math.radians(rng.uniform(25, 40))), 1))
        at = layout.place(rng, length / 2, width / 2)
        if at:
            design["wedge"] = (*at, length, width, height)
    if rng.random() < 0.4:
        along = str(rng.choice(["x", "y"]))
        radius, length = float(np.round(rng.uniform(4, 8), 1)), float(np.round(rng.uniform(25, 40), 1))
        half = (length / 2, radius) if along == "x" else (radius, length / 2)
        at = layout.place(rng, *half)
        if at:
            design["lying"].append((*at, radius, length, along))
    for key, count, radius_range, height_range in (("cylinders", int(rng.random() < 0.5), (5, 9), (15, 30)),
                                                   ("bosses", int(rng.integers(0, 3)), (4, 10), (3, 8))):
        for _ in range(count):
            radius = float(np.round(rng.uniform(*radius_range), 1))
            at = layout.place(rng, radius, radius)
            if at:
                design[key].append((*at, radius, float(np.round(rng.uniform(*height_range), 1))))
    for _ in range(int(rng.integers(2, 7))):
        radius = float(rng.choice(HOLE_RADII))
        at = layout.place(rng, radius, radius)
        if at:
            blind = bool(rng.random() < 0.4)
            depth = float(np.round(rng.uniform(0.3, 0.7) * T, 1)) if blind else None
            design["holes"].append((*at, radius, depth))
    return design


# ---------------------------------------------------------------------------------------
# building
# ---------------------------------------------------------------------------------------
def machined_part(seed: int = 0, *, segments: int = 64, **design: Any) -> BuiltPart:
    """Build a machined part: :func:`machined_design` of ``seed``, with any key replaced.

    Parameters
    ----------
    seed : int
        Layout seed (:func:`machined_design`).
    segments : int
        Facets of a full circle (3..4096).
    **design
        Keys of :func:`machined_design`'s dict, replacing the drawn ones (mm).

    Returns
    -------
    BuiltPart
        Closed mesh (mm), part tree (``plate`` plus ``additions`` minus ``cuts``),
        per-triangle sub-part labels, and exact features: circles (:data:`ROUND_TYPES`) and
        straight creases; ``params`` holds the full design and the seed.

    Raises
    ------
    RangesimError
        An unknown key, dimensions that are not finite and positive, ``segments`` out of range,
        or an override whose listed features the mesh would not have: a feature off the
        plate's flat top (past its outline or its chamfer or fillet, or into the step), two
        features closer than 0.5 mm (one cuts or covers the other's rims), an ``outline``
        not "plain", "chamfer" or "fillet", an ``outline_size`` over 0.49 x the plate (its
        thickness too for a chamfer), a step on a chamfered plate or no wider than its fillet.

    Examples
    --------
    >>> part = machined_part(3)
    >>> part.mesh.is_watertight, len(part.features.circles) > 0
    (True, True)
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RangesimError(f"machined_part: seed must be a whole number >= 0, got {seed!r}")
    base = machined_design(seed)
    unknown = sorted(set(design) - set(base))
    if unknown:
        raise RangesimError(f"unknown machined_part parameter(s) {', '.join(unknown)}; known: seed, segments, "
                            f"{', '.join(base)}")
    segments = P.whole(segments, "machined_part: segments", 3, MAX_SEGMENTS)
    p = {**base, **design}
    if isinstance(design.get("holes"), (list, tuple)):
        # (x, y, radius) is a through hole: TOML (the CLI's --param) has no None for the depth
        p["holes"] = [(*h, None) if isinstance(h, (list, tuple)) and len(h) == 3 else h for h in design["holes"]]
    for key in ("length", "width", "thickness"):
        P.number(p[key], f"machined_part: {key}", 0, MAX_PARAM_MAGNITUDE, lo_open=True, what="positive number",
                 unit="mm")
    L, W, T = (float(p[k]) for k in ("length", "width", "thickness"))
    if design:  # the random layouts hold by construction; a user's override is checked
        _check_design(p, L, W, T)
    n = int(segments)
    feats = AnalyticFeatures()
    plate = solid("plate", "plate", _plate_solid(L, W, T, p["outline"], float(p["outline_size"]), n),
                  length=L, width=W, thickness=T, outline=p["outline"])
    feats.segments += _plate_edges(L, W, T, p["outline"], float(p["outline_size"]), p["step"])
    additions, cuts = [], []
    top = T
    if p["step"]:
        s, d = (float(v) for v in p["step"])
        cuts.append(solid("step", "step", manifold3d.Manifold.cube((s + 1, W + 2, d + 1)).translate(
            (L / 2 - s, -W / 2 - 1, T - d)), width=s, depth=d))
    if p["slot"]:
        x, y, length, width, depth, along = p["slot"]
        sx, sy = (length, width) if along == "x" else (width, length)
        cuts.append(solid("slot", "slot", manifold3d.Manifold.cube((sx, sy, depth + 1)).translate(
            (x - sx / 2, y - sy / 2, top - depth)), x=x, y=y, length=length, width=width, depth=depth))
        feats.segments += _pocket_edges("slot_1", x, y, sx, sy, top, depth)
    for k, (x, y, r, depth) in enumerate(p["holes"], start=1):
        kind = "through_hole" if depth is None else "blind_hole"
        z0 = -1.0 if depth is None else top - float(depth)
        cyl = manifold3d.Manifold.cylinder(top + 1 - z0, r, r, n).translate((x, y, z0))
        cuts.append(solid(f"{kind}_{k}", "hole", cyl, x=x, y=y, radius=r, depth=depth))
        up = np.array([0, 0, 1.0])
        feats.circles.append(Circle3D(f"{kind}_{k}_top", np.array([x, y, top]), up, r, 90.0, True, f"{kind}_{k}"))
        if depth is None:
            feats.circles.append(Circle3D(f"{kind}_{k}_bottom", np.array([x, y, 0.0]), up, r, 90.0, True,
                                          f"{kind}_{k}"))
        else:
            feats.circles.append(Circle3D(f"{kind}_{k}_floor", np.array([x, y, top - float(depth)]), up, r, 90.0,
                                          False, f"{kind}_{k}"))
    for kind, items in (("boss", p["bosses"]), ("cylinder", p["cylinders"])):
        for k, (x, y, r, h) in enumerate(items, start=1):
            cyl = manifold3d.Manifold.cylinder(h + _SINK_MM, r, r, n).translate((x, y, top - _SINK_MM))
            additions.append(solid(f"{kind}_{k}", kind, cyl, x=x, y=y, radius=r, height=h))
            up = np.array([0, 0, 1.0])
            feats.circles.append(Circle3D(f"{kind}_{k}_top", np.array([x, y, top + h]), up, r, 90.0, True,
                                          f"{kind}_{k}"))
            feats.circles.append(Circle3D(f"{kind}_{k}_foot", np.array([x, y, top]), up, r, 90.0, False,
                                          f"{kind}_{k}"))
    if p["wedge"]:
        x, y, length, width, height = p["wedge"]
        additions.append(solid("wedge_1", "wedge", _wedge_solid(x, y, length, width, height, top),
                               x=x, y=y, length=length, width=width, height=height))
        feats.segments += _wedge_edges("wedge_1", x, y, length, width, height, top)
    for k, (x, y, r, length, along) in enumerate(p["lying"], start=1):
        name = f"lying_cylinder_{k}"
        axis = np.array([1.0, 0, 0]) if along == "x" else np.array([0, 1.0, 0])
        cyl = manifold3d.Manifold.cylinder(length, r, r, n, True)
        cyl = cyl.rotate((0, 90, 0) if along == "x" else (90, 0, 0)).translate((x, y, top + _LYING_AXIS * r))
        additions.append(solid(name, "lying_cylinder", cyl, x=x, y=y, radius=r, length=length, along=along))
        centre = np.array([x, y, top + _LYING_AXIS * r])
        for end, sign in (("a", -1), ("b", 1)):
            feats.circles.append(Circle3D(f"{name}_end_{end}", centre + sign * length / 2 * axis, axis, r, 90.0,
                                          True, name))
        # where it enters the plate top: concave creases, the normals 120 degrees apart
        off = r * math.sqrt(1 - _LYING_AXIS**2)
        side = np.array([0, 1.0, 0]) if along == "x" else np.array([1.0, 0, 0])
        for tag, sign in (("left", -1), ("right", 1)):
            a = centre + sign * off * side - _LYING_AXIS * r * np.array([0, 0, 1.0])
            feats.segments.append(Segment3D(f"{name}_foot_{tag}", a - length / 2 * axis, a + length / 2 * axis,
                                            math.degrees(math.acos(-_LYING_AXIS)), False, name))
    body = union("body", plate, *additions, function="part") if additions else plate
    tree = difference("machined_part", body, *cuts, function="part") if cuts else body
    return build_part("machined_part", tree, feats, {**p, "seed": int(seed), "segments": n})


#: the largest chamfer or fillet, relative to the plate (its thickness for a chamfer, its smaller
#: side for both): the outline keeps a flat top and straight sides between its corners
_MAX_OUTLINE_FRACTION = 0.49
#: the outlines a plate may have
OUTLINES = ("plain", "chamfer", "fillet")


def _check_design(p: dict[str, Any], L: float, W: float, T: float) -> None:
    """Refuse, in one line naming the feature, an override whose listed features the mesh would
    not have: a feature off the plate's flat top (past its outline, chamfer or fillet, or into the
    step), two features that overlap (one cuts or covers the other's rims), a chamfer or fillet
    too large for the plate, or a size that is not positive (a raw LinAlgError or a degenerate
    mesh before); a blind hole must end inside the plate, a step and a slot cut less than its
    thickness."""
    def fail(what: str, text: str) -> None:
        raise RangesimError(f"machined_part: {what} {text}")

    def numbers(what: str, value: Any, n: int, size: int | None = None) -> list[float]:
        size = n if size is None else size
        try:
            if isinstance(value, (str, bytes, dict)) or len(value) != size:
                raise TypeError
            vals = [float(v) for v in value[:n]]
        except (TypeError, ValueError, IndexError):
            fail(what, f"must be {size} values, got {value!r:.80}")
        if any(isinstance(v, (bool, np.bool_)) for v in value[:n]) or not all(math.isfinite(v) for v in vals):
            fail(what, f"must be {n} finite numbers, got {value!r:.80}")
        return vals

    def items(key: str) -> list:
        value = p[key]
        if not isinstance(value, (list, tuple)):
            fail(key, f"must be a list, got {value!r:.80}")
        return list(value)

    def positive(what: str, **values: float) -> None:
        for key, v in values.items():
            if v <= 0:
                fail(what, f"{key} must be positive, got {v:g}")

    outline = P.choice(p["outline"], "machined_part: outline", OUTLINES)
    size = float(P.number(p["outline_size"], "machined_part: outline_size", 0, what="number", unit="mm"))
    limit = _MAX_OUTLINE_FRACTION * min(L, W, T if outline == "chamfer" else math.inf)
    if outline != "plain" and size > limit:
        fail(f"outline_size {size:g} mm", f"is too large for a {outline}: at most {_MAX_OUTLINE_FRACTION:g} x the "
             f"plate's {'thickness and ' if outline == 'chamfer' else ''}smaller side, {limit:g} mm")
    chamfer = size if outline == "chamfer" else 0.0
    fillet = size if outline == "fillet" else 0.0
    x_end = L / 2
    if p["step"]:
        s, d = numbers("step", p["step"], 2)
        positive("step", width=s, depth=d)
        if s >= L or d >= T:
            fail("step", f"({s:g} x {d:g} mm) must be narrower than the plate and shallower than its {T:g} mm")
        if chamfer:
            fail("step", "cannot be cut into a chamfered plate (outline 'chamfer'); use 'plain' or 'fillet'")
        if not fillet < s < L - fillet:
            fail("step", f"width {s:g} mm must exceed the fillet's {fillet:g} mm and leave more than it of the plate")
        x_end = L / 2 - s
    gap = _layout.MIN_GAP_MM
    shapes: list[tuple[str, tuple]] = []

    def place(what: str, shape: tuple, x: float, y: float, rx: float, ry: float) -> None:
        """The footprint on the flat top: inside the outline less its chamfer or fillet, left of the step."""
        if _layout.clearance_in_rounded_rect(shape, L / 2 - chamfer, W / 2 - chamfer, fillet) < gap:
            edge = f"{gap:g} mm inside its {f'{size:g} mm {outline}' if chamfer or fillet else 'edges'}"
            fail(what, f"at ({x:g}, {y:g}) reaching {rx:g} x {ry:g} mm does not lie on the {L:g} x {W:g} mm "
                 f"plate's flat top ({edge})")
        if p["step"] and _layout.reach_x(shape)[1] > x_end - gap:
            fail(what, f"at ({x:g}, {y:g}) reaching {rx:g} x {ry:g} mm runs into the step: it must end {gap:g} mm "
                 f"before x = {x_end:g} mm")
        shapes.append((what, shape))

    def rect(what: str, x: float, y: float, hx: float, hy: float) -> None:
        place(what, _layout.box(x - hx, y - hy, x + hx, y + hy), x, y, hx, hy)

    if p["slot"]:
        x, y, length, width, depth = numbers("slot", p["slot"], 5, 6)
        positive("slot", length=length, width=width, depth=depth)
        along = p["slot"][5]
        if along not in ("x", "y"):
            fail("slot", f"runs along 'x' or 'y', got {along!r}")
        if depth >= T:
            fail("slot", f"depth {depth:g} mm must be under the plate's {T:g} mm")
        rect("slot", x, y, *((length / 2, width / 2) if along == "x" else (width / 2, length / 2)))
    for k, hole in enumerate(items("holes"), start=1):
        if not isinstance(hole, (list, tuple)) or len(hole) != 4:  # (three values were made four above)
            fail(f"hole {k}", f"must be (x, y, radius[, depth or None]), got {hole!r:.80}")
        x, y, r = numbers(f"hole {k}", hole, 3, 4)
        depth = hole[3]
        positive(f"hole {k}", radius=r)
        try:
            P.number(depth, "depth", 0, T, lo_open=True, hi_open=True, none=True)
        except RangesimError:
            fail(f"hole {k}", f"depth {depth!r} must lie in 0..{T:g} mm (None: through)")
        place(f"hole {k}", _layout.circle(x, y, r), x, y, r, r)
    sunk = [] if T > _SINK_MM else [what for what in ("bosses", "cylinders", "lying") if p[what]] + (
        ["wedge"] if p["wedge"] else [])
    if sunk:
        fail(f"thickness {T:g} mm", f"must exceed {_SINK_MM:g} mm, the depth {', '.join(sunk)} sink into the plate")
    for kind, key in (("boss", "bosses"), ("cylinder", "cylinders")):
        for k, item in enumerate(items(key), start=1):
            x, y, r, h = numbers(f"{kind} {k}", item, 4)
            positive(f"{kind} {k}", radius=r, height=h)
            place(f"{kind} {k}", _layout.circle(x, y, r), x, y, r, r)
    if p["wedge"]:
        x, y, length, width, height = numbers("wedge", p["wedge"], 5)
        positive("wedge", length=length, width=width, height=height)
        rect("wedge", x, y, length / 2, width / 2)
    for k, item in enumerate(items("lying"), start=1):
        x, y, r, length = numbers(f"lying cylinder {k}", item, 4, 5)
        along = item[4]
        positive(f"lying cylinder {k}", radius=r, length=length)
        if along not in ("x", "y"):
            fail(f"lying cylinder {k}", f"lies along 'x' or 'y', got {along!r}")
        if _LYING_AXIS * r >= T:  # it would reach through the plate's bottom
            fail(f"lying cylinder {k}", f"radius {r:g} mm must be under {1 / _LYING_AXIS:g} x the plate's {T:g} mm")
        rect(f"lying cylinder {k}", x, y, *((length / 2, r) if along == "x" else (r, length / 2)))
    _layout.apart("machined_part", shapes)


def _plate_solid(L: float, W: float, T: float, outline: str, size: float, n: int) -> manifold3d.Manifold:
    """The plate: a box, with its top edges chamfered (45 deg, ``size`` mm) or its vertical
    corners filleted (radius ``size``)."""
    if outline == "plain" or size <= 0:
        return manifold3d.Manifold.cube((L, W, T)).translate((-L / 2, -W / 2, 0))
    if outline == "fillet":
        r = size  # at most 0.49 min(L, W): checked with the design
        section = manifold3d.CrossSection.square((L - 2 * r, W - 2 * r), True).offset(
            r, manifold3d.JoinType.Round, 2.0, n)
        return manifold3d.Manifold.extrude(section, T)
    if outline == "chamfer":
        c = size  # at most 0.49 min(L, W, T): checked with the design
        low = manifold3d.Manifold.cube((L, W, T - c)).translate((-L / 2, -W / 2, 0))
        # a frustum whose sides move in by c over its height c: 45 degree faces
        cap = manifold3d.Manifold.extrude(manifold3d.CrossSection.square((L, W), True), c, 0, 0.0,
                                          ((L - 2 * c) / L, (W - 2 * c) / W)).translate((0, 0, T - c))
        return low + cap
    raise RangesimError(f"machined_part: outline must be plain, chamfer or fillet, got {outline!r}")


def _seg(name: str, a, b, dihedral: float = 90.0, convex: bool = True, part: str = "plate") -> Segment3D:
    return Segment3D(name, np.asarray(a, float), np.asarray(b, float), float(dihedral), bool(convex), part)


def _plate_edges(L: float, W: float, T: float, outline: str, size: float, step) -> list[Segment3D]:
    """Straight creases of the plate outline and of its step (fillet arcs are not straight)."""
    r = size if outline == "fillet" else 0.0
    c = size if outline == "chamfer" else 0.0
    xa, xb, ya, yb = -L / 2, L / 2, -W / 2, W / 2
    xs, low = (xb - float(step[0]), T - float(step[1])) if step else (xb, T)
    out = []
    for y, tag in ((ya, "y-"), (yb, "y+")):
        inner = y + (c if y < 0 else -c)
        if c:
            out += [_seg(f"plate_top_{tag}", (xa + c, inner, T), (xb - c, inner, T), 45.0),
                    _seg(f"plate_chamfer_{tag}", (xa, y, T - c), (xb, y, T - c), 45.0)]
        else:
            out.append(_seg(f"plate_top_{tag}", (xa + r, y, T), (xs if step else xb - r, y, T)))
            if step:
                out.append(_seg(f"plate_step_top_{tag}", (xs, y, low), (xb - r, y, low)))
                out.append(_seg(f"plate_riser_{tag}", (xs, y, low), (xs, y, T)))
        out.append(_seg(f"plate_bottom_{tag}", (xa + r, y, 0), (xb - r, y, 0)))
    for x, tag, h in ((xa, "x-", T), (xb, "x+", low)):
        if c:
            out += [_seg(f"plate_top_{tag}", (x + (c if x < 0 else -c), ya + c, T), (x + (c if x < 0 else -c), yb - c, T),
                         45.0),
                    _seg(f"plate_chamfer_{tag}", (x, ya, T - c), (x, yb, T - c), 45.0)]
        else:
            out.append(_seg(f"plate_top_{tag}", (x, ya + r, h), (x, yb - r, h)))
        out.append(_seg(f"plate_bottom_{tag}", (x, ya + r, 0), (x, yb - r, 0)))
        if not r:
            for y, ytag in ((ya, "y-"), (yb, "y+")):
                out.append(_seg(f"plate_corner_{tag}{ytag}", (x, y, 0), (x, y, h - c)))
    if step:
        out += [_seg("plate_step_edge", (xs, ya, T), (xs, yb, T)),
                _seg("plate_step_foot", (xs, ya, low), (xs, yb, low), 90.0, False)]
    return out


def _pocket_edges(name: str, x: float, y: float, sx: float, sy: float, top: float, depth: float) -> list[Segment3D]:
    """Rim (convex), floor (concave) and inner corner (concave) creases of a rectangular pocket."""
    x0, x1, y0, y1, z = x - sx / 2, x + sx / 2, y - sy / 2, y + sy / 2, top - depth
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    out = []
    for i in range(4):
        (ax, ay), (bx, by) = corners[i], corners[(i + 1) % 4]
        out.append(_seg(f"{name}_rim_{i}", (ax, ay, top), (bx, by, top), part=name))
        out.append(_seg(f"{name}_floor_{i}", (ax, ay, z), (bx, by, z), 90.0, False, name))
        out.append(_seg(f"{name}_corner_{i}", (ax, ay, z), (ax, ay, top), 90.0, False, name))
    return out


def _wedge_solid(x: float, y: float, length: float, width: float, height: float, top: float) -> manifold3d.Manifold:
    """A ramp rising towards +x from the plate top to ``height``, its back face vertical."""
    x0, x1 = x - length / 2, x + length / 2
    # the x-z profile, sunk below the top so the union does not meet face to face
    profile = [[x0, top], [x1, top + height], [x1, top - _SINK_MM], [x0, top - _SINK_MM]]
    prism = manifold3d.Manifold.extrude(manifold3d.CrossSection([profile[::-1]]), width)
    # extruded along z: turn so the profile's second axis is z and the extrusion runs along y
    return prism.rotate((90, 0, 0)).translate((0, y + width / 2, 0))


def _wedge_edges(name: str, x: float, y: float, length: float, width: float, height: float,
                 top: float) -> list[Segment3D]:
    """Crest, toe, side and foot creases of the ramp."""
    x0, x1, ya, yb = x - length / 2, x + length / 2, y - width / 2, y + width / 2
    slope = math.degrees(math.atan2(height, length))
    out = [_seg(f"{name}_crest", (x1, ya, top + height), (x1, yb, top + height), 90.0 + slope, True, name),
           _seg(f"{name}_toe", (x0, ya, top), (x0, yb, top), slope, False, name),
           _seg(f"{name}_back_foot", (x1, ya, top), (x1, yb, top), 90.0, False, name),
           _seg(f"{name}_back_y-", (x1, ya, top), (x1, ya, top + height), 90.0, True, name),
           _seg(f"{name}_back_y+", (x1, yb, top), (x1, yb, top + height), 90.0, True, name)]
    for yy, tag in ((ya, "y-"), (yb, "y+")):
        out.append(_seg(f"{name}_side_{tag}", (x0, yy, top), (x1, yy, top + height), 90.0, True, name))
        out.append(_seg(f"{name}_foot_{tag}", (x0, yy, top), (x1, yy, top), 90.0, False, name))
    return out


MODELS["machined_part"] = machined_part
