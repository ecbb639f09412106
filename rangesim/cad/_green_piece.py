"""The "Green Piece" of the founding paper: a machined plate with holes, a dent, surface
scratches and seven threads of different radii and pitches.

Built stepwise as the paper's Alpha_1 design: the plate and its holes, then the dent, then
the scratches, then the threads, each step a Boolean difference of named solids
(manifold3d), so the result is a closed, valid mesh whose triangles know their sub-part.

Each thread is a tapped hole whose wall is a helical ridge: a circular section of radius
r_major - depth/2, offset depth/2 from the axis and twisted through 360 degrees per pitch
as it is extruded, so the wall radius runs between the minor and major radius once per
turn (the paper's "two surfaces filled between two twisted curves"). Thread depth is
0.6 x pitch, close to ISO's 0.54 x pitch.

Coordinates: millimetres, the plate centred on the z axis, its bottom at z = 0 and its top
at z = thickness.
"""
from __future__ import annotations

import math
from typing import Any

import manifold3d
import numpy as np

from rangesim.cad import _layout
from rangesim.cad._layout import positive, tuples, within
from rangesim.cad.features import AnalyticFeatures, Circle3D, Segment3D
from rangesim.cad.models import MAX_DIVISIONS_PER_TURN, MAX_SEGMENTS, MODELS
from rangesim.cad.part import BuiltPart, build_part, difference, solid
from rangesim.core import params as P
from rangesim.core.errors import RangesimError

#: default dimensions (mm, degrees): a plausible 4 x 3 x 0.5 inch part
DEFAULTS: dict[str, Any] = {
    "length": 101.6,
    "width": 76.2,
    "thickness": 12.7,
    # plain through holes: (x, y, radius)
    "holes": [(-42.0, -30.0, 3.2), (42.0, -30.0, 3.2), (-42.0, 30.0, 3.2), (42.0, 30.0, 3.2)],
    # spherical dent: centre (x, y), sphere radius, depth
    "dent": (-26.0, 16.0, 30.0, 3.0),
    # scratches: start (x, y), angle (deg), length, width, depth
    "scratches": [
        (15.0, 14.0, 10.0, 25.0, 0.6, 0.4),
        (16.0, 22.0, -5.0, 20.0, 0.5, 0.3),
        (14.0, 30.0, -20.0, 18.0, 0.4, 0.25),
    ],
    # threads (tapped holes): (x, y, major radius, pitch); the centre one first
    "threads": [
        (0.0, 0.0, 6.0, 1.75),
        (-30.0, -20.0, 5.0, 1.5),
        (-12.0, -20.0, 4.0, 1.25),
        (8.0, -20.0, 3.0, 1.0),
        (26.0, -20.0, 2.5, 0.8),
        (0.0, 22.0, 3.5, 1.0),
        (22.0, 2.0, 4.5, 1.5),
    ],
    "segments": 48,  # facets of a circle
    "divisions_per_turn": 16,  # sections of a thread per turn of its helix
}
THREAD_DEPTH_PER_PITCH = 0.6
#: the most vertices of all thread cutters together (the default part: 7 threads, 1,228 sections
#: of 48 segments, 59,000); the CSG work grows with them (1.77 million: 31 s and 4.7 GB)
MAX_THREAD_VERTICES = 500_000


def green_piece(**params) -> BuiltPart:
    """Build the Green Piece.

    Parameters
    ----------
    **params
        Any key of :data:`DEFAULTS` (millimetres, degrees): ``length``, ``width``,
        ``thickness``; ``holes`` [(x, y, r)]; ``dent`` (x, y, sphere radius, depth), or ``[]`` / False for none;
        ``scratches`` [(x, y, angle_deg, length, width, depth)]; ``threads``
        [(x, y, major radius, pitch)]; ``segments``; ``divisions_per_turn``.

    Returns
    -------
    BuiltPart
        Mesh, part tree (plate_and_holes -> with_dent -> with_scratches -> green_piece),
        per-triangle sub-part labels, analytic features.

    Examples
    --------
    >>> part = green_piece(thickness=10.0)
    >>> part.mesh.is_watertight
    True
    """
    unknown = sorted(set(params) - set(DEFAULTS))
    if unknown:
        raise RangesimError(f"unknown green_piece parameter(s) {', '.join(unknown)}; known: {', '.join(DEFAULTS)}")
    p = {**DEFAULTS, **params}
    positive("green_piece", length=p["length"], width=p["width"], thickness=p["thickness"])
    L, W, T = float(p["length"]), float(p["width"]), float(p["thickness"])
    p.update(_checked_layout(p, L, W, T))
    n_seg = int(p["segments"])
    features = AnalyticFeatures()

    plate = solid("plate", "plate", manifold3d.Manifold.cube((L, W, T), False).translate((-L / 2, -W / 2, 0)),
                  length=L, width=W, thickness=T)
    features.segments += _box_edges(L, W, T)

    holes = []
    for k, (x, y, r) in enumerate(p["holes"], start=1):
        name = f"hole_{k}"
        cyl = manifold3d.Manifold.cylinder(T + 2, r, r, n_seg).translate((x, y, -1))
        holes.append(solid(name, "hole", cyl, x=x, y=y, radius=r))
        for z in (0.0, T):
            features.circles.append(Circle3D(f"{name}_rim_{'top' if z else 'bottom'}", np.array([x, y, z]),
                                             np.array([0, 0, 1.0]), r, 90.0, True, name))
    step1 = difference("plate_and_holes", plate, *holes, function="plate")

    step2 = step1
    if p["dent"] is not None:  # (dent = [] or false: a plate without it)
        x, y, radius, depth = (float(v) for v in p["dent"])
        sphere = manifold3d.Manifold.sphere(radius, 4 * n_seg).translate((x, y, T + radius - depth))
        dent = solid("dent", "dent", sphere, x=x, y=y, sphere_radius=radius, depth=depth)
        rim = math.sqrt(radius**2 - (radius - depth) ** 2)
        features.circles.append(Circle3D("dent_rim", np.array([x, y, T]), np.array([0, 0, 1.0]), rim,
                                         math.degrees(math.asin(rim / radius)), True, "dent"))
        step2 = difference("with_dent", step1, dent, function="plate")

    scratches = []
    for k, (x, y, angle, length, width, depth) in enumerate(p["scratches"], start=1):
        name = f"scratch_{k}"
        groove = (
            manifold3d.Manifold.cube((length, width, 2 * depth), True)
            .rotate((0, 0, angle))
            .translate(_along((x, y), angle, length / 2) + (T,))
        )
        scratches.append(solid(name, "scratch", groove, x=x, y=y, angle_deg=angle, length=length,
                               width=width, depth=depth))
        features.segments += _groove_edges(name, (x, y), angle, length, width, depth, T)
    step3 = difference("with_scratches", step2, *scratches, function="plate")

    threads = []
    for k, (x, y, r_major, pitch) in enumerate(p["threads"], start=1):
        name = f"thread_{k}"
        cutter, rims = _thread_cutter(name, x, y, r_major, pitch, T, n_seg, int(p["divisions_per_turn"]))
        threads.append(solid(name, "thread", cutter, x=x, y=y, major_radius=r_major, pitch=pitch,
                             depth=THREAD_DEPTH_PER_PITCH * pitch))
        features.circles += rims
    tree = difference("green_piece", step3, *threads, function="part")
    return build_part("green_piece", tree, features, p)


def _checked_layout(p: dict, L: float, W: float, T: float) -> dict:
    """The holes, dent, scratches and threads as tuples of numbers, each on the plate (a feature
    off it would be listed as a rim the mesh does not have)."""
    m = "green_piece"
    segments = P.whole(p["segments"], f"{m}: segments", 3, MAX_SEGMENTS)
    per_turn = P.whole(p["divisions_per_turn"], f"{m}: divisions_per_turn", 1, MAX_DIVISIONS_PER_TURN)
    holes = tuples(m, "holes", p["holes"], ("x", "y", "radius"))
    for k, (x, y, r) in enumerate(holes, start=1):
        positive(m, **{f"holes[{k - 1}] radius": r})
        within(m, f"holes[{k - 1}]", x, y, r, L / 2, W / 2)
    dent = None
    if p["dent"] is not False and p["dent"] is not None and not (isinstance(p["dent"], (list, tuple)) and not p["dent"]):
        (dent,) = tuples(m, "dent", p["dent"], ("x", "y", "sphere radius", "depth"), many=False)
        x, y, radius, depth = dent
        positive(m, **{"dent sphere radius": radius, "dent depth": depth})
        if depth >= min(2 * radius, T):
            raise RangesimError(f"{m}: dent depth {depth:g} mm must be less than the sphere's diameter and the "
                                f"thickness {T:g} mm")
        # its widest section below the top: the rim, or the sphere's equator when deeper than its radius
        dent_reach = radius if depth > radius else math.sqrt(radius**2 - (radius - depth) ** 2)
        within(m, "dent", x, y, dent_reach, L / 2, W / 2)
    scratches = tuples(m, "scratches", p["scratches"], ("x", "y", "angle_deg", "length", "width", "depth"))
    for k, (x, y, angle, length, width, depth) in enumerate(scratches, start=1):
        positive(m, **{f"scratches[{k - 1}] length": length, f"scratches[{k - 1}] width": width,
                       f"scratches[{k - 1}] depth": depth})
        if depth >= T:
            raise RangesimError(f"{m}: scratches[{k - 1}] depth {depth:g} mm must be less than the thickness {T:g} mm")
        for end in ((x, y), _along((x, y), angle, length)):
            within(m, f"scratches[{k - 1}]", *end, width / 2, L / 2, W / 2)
    threads = tuples(m, "threads", p["threads"], ("x", "y", "major radius", "pitch"))
    for k, (x, y, r_major, pitch) in enumerate(threads, start=1):
        positive(m, **{f"threads[{k - 1}] major radius": r_major, f"threads[{k - 1}] pitch": pitch})
        within(m, f"threads[{k - 1}]", x, y, r_major, L / 2, W / 2)
    # each thread is a helix of sections every 1 / divisions_per_turn of a turn through the
    # plate, each a circle of `segments` vertices: a fine pitch makes millions of them (a
    # 0.001 mm pitch: 200,000 sections, and the CSG library crashed the process at ~3 GB)
    sections = [_thread_sections(T, pitch, per_turn) + 2 for (_, _, _, pitch) in threads]
    vertices = sum(sections) * float(segments)
    if vertices > MAX_THREAD_VERTICES:
        finest = min(range(len(threads)), key=lambda k: threads[k][3])
        raise RangesimError(
            f"{m}: the threads would need {vertices:,.0f} vertices (at most {MAX_THREAD_VERTICES:,}): "
            f"{sum(sections):,} helix sections (thickness / pitch x divisions_per_turn; threads[{finest}] pitch "
            f"{threads[finest][3]:g} mm alone {sections[finest]:,}) of {segments} segments; use a coarser "
            "pitch or fewer divisions_per_turn or segments")
    # a hole, thread, dent or scratch overlapping another cuts away (or swallows) its rims
    footprints = [(f"holes[{k}]", _layout.circle(x, y, r)) for k, (x, y, r) in enumerate(holes)]
    footprints += [(f"threads[{k}]", _layout.circle(x, y, r)) for k, (x, y, r, _) in enumerate(threads)]
    if dent is not None:
        footprints.append(("dent", _layout.circle(dent[0], dent[1], dent_reach)))
    for k, (x, y, angle, length, width, _) in enumerate(scratches):
        a = math.radians(angle)
        along, across = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)]) * width / 2
        start, end = np.array([x, y]), np.array([x, y]) + length * along
        footprints.append((f"scratches[{k}]", _layout.polygon([start - across, end - across, end + across,
                                                                start + across])))
    _layout.apart(m, footprints)
    return {"holes": holes, "dent": dent, "scratches": scratches, "threads": threads, "segments": segments,
            "divisions_per_turn": per_turn}


def _along(start, angle_deg, distance) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return (start[0] + distance * math.cos(a), start[1] + distance * math.sin(a))


def _box_edges(L, W, T) -> list[Segment3D]:
    corners = np.array([[sx * L / 2, sy * W / 2, sz * T] for sz in (0, 1) for sy in (-1, 1) for sx in (-1, 1)])
    pairs = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
    return [Segment3D(f"plate_edge_{k}", corners[a], corners[b], 90.0, True, "plate") for k, (a, b) in enumerate(pairs)]


def _groove_edges(name, start, angle, length, width, depth, top) -> list[Segment3D]:
    """Rims (convex) and bottom lines (concave) of a straight groove cut into the top face."""
    a = math.radians(angle)
    along = np.array([math.cos(a), math.sin(a), 0.0])
    across = np.array([-math.sin(a), math.cos(a), 0.0])
    s = np.array([start[0], start[1], top])
    out = []
    for side in (-1, 1):
        offset = side * width / 2 * across
        out.append(Segment3D(f"{name}_rim_{'left' if side < 0 else 'right'}", s + offset,
                             s + offset + length * along, 90.0, True, name))
        low = offset - depth * np.array([0, 0, 1.0])
        out.append(Segment3D(f"{name}_floor_{'left' if side < 0 else 'right'}", s + low,
                             s + low + length * along, 90.0, False, name))
    for end in (0.0, length):
        centre = s + end * along
        out.append(Segment3D(f"{name}_end_{'start' if end == 0 else 'end'}", centre - width / 2 * across,
                             centre + width / 2 * across, 90.0, True, name))
    return out


def _thread_sections(top: float, pitch: float, per_turn: float) -> int:
    """Helix sections of a thread through a plate ``top`` mm thick (one per 1 / per_turn turn)."""
    return max(1, int(math.ceil(top / pitch * per_turn)))


def _thread_cutter(name, x, y, r_major, pitch, top, n_seg, per_turn):
    """The helical cutter of a tapped hole and its rim circles at the top and bottom faces."""
    depth = THREAD_DEPTH_PER_PITCH * pitch
    if depth >= r_major:
        raise RangesimError(f"green_piece {name}: pitch {pitch} too coarse for radius {r_major}")
    radius, offset = r_major - depth / 2, depth / 2
    # sections every `step` mm, with the bottom and top faces exactly on sections, so the rims
    # there are the (exact) rotated section and not an interpolation between two of them
    n_inside = _thread_sections(top, pitch, per_turn)
    step = top / n_inside
    height = top + 2 * step
    section = manifold3d.CrossSection.circle(radius, n_seg).translate((offset, 0))
    cutter = manifold3d.Manifold.extrude(section, height, n_inside + 1, 360.0 * height / pitch)
    cutter = cutter.translate((x, y, -step))
    rims = []
    for z, where in ((0.0, "bottom"), (top, "top")):
        phase = math.radians(360.0 * (z + step) / pitch)  # the section's rotation at that height
        centre = np.array([x + offset * math.cos(phase), y + offset * math.sin(phase), z])
        rims.append(Circle3D(f"{name}_rim_{where}", centre, np.array([0, 0, 1.0]), radius, 90.0, True, name))
    return cutter, rims


MODELS["green_piece"] = green_piece
