"""Exact edge ground truth for synthetic scans, from the noise-free geometry behind them.

Only crease visibility casts rays (Mitsuba shadow rays); everything else comes from the scan's own ground-truth images
(``xyz_true``, ``part``, ``face``, ``normal``), its pose and intrinsics, and the scene's
meshes (world mm).

Edge types (:class:`~rangesim.core.constants.EdgeLabel`):

* **jump** -- a depth discontinuity between two 4-neighbour pixels (:func:`jump_edges`), or a
  hit next to a miss; marked on the near (occluding) side.
* **convex / concave crease** -- mesh edges whose dihedral angle exceeds ``crease_deg`` with
  both faces turned towards the camera, projected into the image where visible; plus contact
  creases where two separate surfaces meet (a box standing on a floor), found from pixel
  pairs. Jump wins where both apply.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.conics import ellipse_from_conic
from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.core.geometry import circle_basis, project_circle
from rangesim.core.rangescan import RangeScan
from rangesim.core.scene_of_scan import check_scene_of_scan

#: default jump rule: the 3D step between two neighbours within this angle of the viewing ray
JUMP_ANGLE_DEG = 15.0
#: the least ``spacing_px`` of :func:`ground_truth_features`, pixels
MIN_FEATURE_SPACING_PX = 0.01
#: image-space spacing of the samples along projected crease edges, pixels
SAMPLE_SPACING_PX = 0.25
#: crease samples closer to the camera than this are clipped, mm
NEAR_CLIP_MM = 1e-3


# ---------------------------------------------------------------------------------------
# jump edges
# ---------------------------------------------------------------------------------------
def _pair_jumps(
    p: np.ndarray, q: np.ndarray, both: np.ndarray, cos_max: float, rays: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Jump test for aligned neighbour arrays ``p``, ``q`` (..., 3); returns (jump, p_is_near)."""
    rp = np.linalg.norm(p, axis=-1) if rays is None else None
    rq = np.linalg.norm(q, axis=-1) if rays is None else None
    if rays is None:
        p_near = rp <= rq
        near = np.where(p_near[..., None], p, q)
        ray = near / np.maximum(np.where(p_near, rp, rq), 1e-300)[..., None]  # 0 off the mask
    else:
        # along a given viewing direction, "near" is the smaller coordinate along it
        p_near = np.einsum("...k,...k->...", p - q, rays) <= 0
        ray = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    d = q - p
    along = np.abs(np.einsum("...k,...k->...", d, ray))
    length = np.linalg.norm(d, axis=-1)
    jump = both & (along > cos_max * length) & (length > 0)
    return jump, p_near


def jump_edges(
    xyz: np.ndarray,
    hit: np.ndarray,
    *,
    max_angle_deg: float = JUMP_ANGLE_DEG,
    boundary: bool = True,
    rays: np.ndarray | None = None,
) -> np.ndarray:
    """Jump (depth-discontinuity) edges of an organized point image, near side marked.

    Rule: two 4-neighbour pixels p, q that both hold a point form a jump when the 3D
    segment between their points makes an angle below ``max_angle_deg`` with the viewing
    ray (of the nearer point): ``|(q - p) . r| > cos(max_angle) |q - p|``. A continuous
    surface seen at incidence i gives segments at >= 90 - i degrees from the ray, so with
    the default 15 degrees a surface fires only when seen at more than 75 degrees
    incidence; a step fires when it is deeper than ~1 / tan(15 deg) = 3.7 pixel footprints.
    Exact for planes (never) and boxes (every top-to-floor step), and creases never fire
    (the segment across a crease is no closer to the ray than the steeper face). With
    ``boundary`` a pixel with a point next to one without is a jump too (occluding contour
    against empty space). The pixel of the pair nearer the camera is marked. Image borders
    are not edges.

    Parameters
    ----------
    xyz : (H, W, 3) float
        Points in the camera frame (camera centre at the origin), mm; anything where
        ``hit`` is False (NaN allowed).
    hit : (H, W) bool
        Pixels holding a point (``part >= 0`` for ground truth, ``valid`` for measured data).
    max_angle_deg : float
        Largest angle between the step and the viewing ray that still counts as a jump.
    boundary : bool
        Also mark points next to pixels without a point.
    rays : (H, W, 3) float, optional
        Viewing directions per pixel, for scanners that are not a pinhole at the origin
        (a translating sweep); default the direction from the origin to the point.

    Returns
    -------
    (H, W) bool
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    hit = np.asarray(hit, dtype=bool)
    if xyz.shape[:2] != hit.shape or xyz.shape[-1] != 3:
        raise RangesimError(f"xyz {xyz.shape} and hit {hit.shape} must be (H, W, 3) and (H, W)")
    pts = np.where(hit[..., None], xyz, 0.0)  # NaNs off the mask would poison the arithmetic
    hit = hit & np.all(np.isfinite(pts), axis=-1)
    pts = np.nan_to_num(pts)
    if rays is not None:
        rays = np.asarray(rays, dtype=np.float64)
        if rays.shape != xyz.shape:
            raise RangesimError(f"rays {rays.shape} must have xyz's shape {xyz.shape}")
    max_angle_deg = P.number(max_angle_deg, "max_angle_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    cos_max = float(np.cos(np.radians(max_angle_deg)))
    out = np.zeros(hit.shape, dtype=bool)
    for axis in (0, 1):
        first = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        second = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        hp, hq = hit[first], hit[second]
        ray = None if rays is None else 0.5 * (rays[first] + rays[second])
        jump, p_near = _pair_jumps(pts[first], pts[second], hp & hq, cos_max, ray)
        out[first] |= jump & p_near
        out[second] |= jump & ~p_near
        if boundary:
            out[first] |= hp & ~hq
            out[second] |= hq & ~hp
    return out


# ---------------------------------------------------------------------------------------
# shared helpers
# ---------------------------------------------------------------------------------------
def _camera(scan: RangeScan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(world-to-camera rotation R (3, 3), translation t (3,), K (3, 3)) of a synthetic scan."""
    if not isinstance(scan, RangeScan):
        raise RangesimError(f"ground truth takes a RangeScan (the synthetic scan), got {type(scan).__name__}")
    if scan.xyz_true is None:
        raise RangesimError("ground truth needs a synthetic scan (scan.xyz_true is None)")
    K = scan.K
    if K is None:
        raise RangesimError("ground truth needs the scan's pinhole intrinsics (scan.meta['K'])")
    inv = np.linalg.inv(scan.pose)
    return inv[:3, :3], inv[:3, 3], K


def _project(K: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(N, 2) continuous (u, v) of camera-frame points; pixel (i, j) spans u in [j, j + 1)."""
    uvw = pts @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def _visible(
    scan: RangeScan,
    K: np.ndarray,
    k: int,
    pts: np.ndarray,
    depth_tol_px: float,
    faces: np.ndarray | None = None,
    slack: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which camera-frame points on object ``k`` the scan sees.

    A point is visible when it projects inside the image onto a pixel that hits object
    ``k`` at a true depth within ``depth_tol_px`` pixel footprints (z / fx) of the point's
    own depth, or (``faces``, (N, 2)) whose triangle is one of the point's two faces. With
    ``slack`` any of the 2 x 2 pixels whose centres surround the point will do (a point on
    an occluding contour is seen although half the pixels it may land on see past it).

    Returns (visible (N,) bool, row (N,) int, col (N,) int): the pixel the point lands on,
    clipped into the image (meaningless where not visible).
    """
    h, w = scan.shape
    uv = _project(K, pts)
    front = pts[:, 2] > 0
    tol = depth_tol_px * pts[:, 2] / K[0, 0]

    def test(row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        inside = front & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        row = np.clip(np.nan_to_num(row), 0, h - 1).astype(np.intp)
        col = np.clip(np.nan_to_num(col), 0, w - 1).astype(np.intp)
        same = inside & (scan.part[row, col] == k)
        close = np.abs(scan.xyz_true[row, col, 2].astype(np.float64) - pts[:, 2]) <= tol
        if faces is not None:
            f = scan.face[row, col]
            close |= (f == faces[:, 0]) | (f == faces[:, 1])
        return same & close, row, col

    vis, row, col = test(np.floor(uv[:, 1]), np.floor(uv[:, 0]))
    if slack:
        r0, c0 = np.floor(uv[:, 1] - 0.5), np.floor(uv[:, 0] - 0.5)
        for dr in (0, 1):
            for dc in (0, 1):
                vis |= test(r0 + dr, c0 + dc)[0]
    return vis, row, col


def _clip_near(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clip camera-frame segments to ``z >= NEAR_CLIP_MM``: (kept indices, new a, new b)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    za, zb = a[:, 2], b[:, 2]
    keep = (za >= NEAR_CLIP_MM) | (zb >= NEAR_CLIP_MM)
    crossing = keep & ((za < NEAR_CLIP_MM) | (zb < NEAR_CLIP_MM))
    tc = np.zeros_like(za)
    tc[crossing] = (NEAR_CLIP_MM - za[crossing]) / (zb[crossing] - za[crossing])
    cut = a + tc[:, None] * (b - a)
    a = np.where(((za < NEAR_CLIP_MM) & keep)[:, None], cut, a)
    b = np.where(((zb < NEAR_CLIP_MM) & keep)[:, None], cut, b)
    idx = np.flatnonzero(keep)
    return idx, a[idx], b[idx]


def _perspective_points(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """3D points at image fractions ``s`` of segments a-b (perspective-correct: s -> t)."""
    za, zb = a[:, 2], b[:, 2]
    t = s * za / ((1 - s) * zb + s * za)
    return a + t[:, None] * (b - a)


def _sample_segments(
    K: np.ndarray, a: np.ndarray, b: np.ndarray, shape: tuple[int, int], spacing: float = SAMPLE_SPACING_PX
) -> tuple[np.ndarray, np.ndarray]:
    """Points along camera-frame 3D segments, evenly spaced in the image.

    Each segment is clipped to ``z >= NEAR_CLIP_MM`` and to (a one-pixel margin around)
    the image, then sampled every ``spacing`` pixels of its projection, mapped back to 3D
    with perspective-correct interpolation (image fraction s -> t = s zA / ((1 - s) zB + s zA)).

    Parameters
    ----------
    K : (3, 3) intrinsics
    a, b : (M, 3) float
        Segment ends, camera frame, mm.
    shape : (H, W)

    Returns
    -------
    points : (N, 3) float64
        Samples, camera frame, mm.
    segment : (N,) intp
        Index of the segment each sample belongs to.
    """
    h, w = shape
    idx, a2, b2 = _clip_near(a, b)
    if len(idx) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.intp)
    ua, ub = _project(K, a2), _project(K, b2)
    # Liang-Barsky clip of the image segment to [-1, W + 1] x [-1, H + 1]
    d = ub - ua
    lo, hi = np.zeros(len(idx)), np.ones(len(idx))
    ok = np.ones(len(idx), dtype=bool)
    for p, q in ((-d[:, 0], ua[:, 0] + 1), (d[:, 0], w + 1 - ua[:, 0]),
                 (-d[:, 1], ua[:, 1] + 1), (d[:, 1], h + 1 - ua[:, 1])):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = q / p
        ok &= ~((p == 0) & (q < 0))
        lo = np.where(p < 0, np.maximum(lo, r), lo)
        hi = np.where(p > 0, np.minimum(hi, r), hi)
    ok &= lo <= hi
    idx, lo, hi, a2, b2, d = idx[ok], lo[ok], hi[ok], a2[ok], b2[ok], d[ok]
    length = (hi - lo) * np.linalg.norm(d, axis=1)
    n = np.ceil(length / spacing).astype(np.intp) + 1
    seg = np.repeat(np.arange(len(idx)), n)
    start = np.cumsum(n) - n
    frac = (np.arange(len(seg)) - start[seg]) / np.maximum(n[seg] - 1, 1)
    s = lo[seg] + frac * (hi[seg] - lo[seg])
    return _perspective_points(a2[seg], b2[seg], s), idx[seg]


# ---------------------------------------------------------------------------------------
# creases
# ---------------------------------------------------------------------------------------
def _raster_segments(
    K: np.ndarray, a: np.ndarray, b: np.ndarray, shape: tuple[int, int], *, minor_out: list | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """8-connected rasterisation of projected camera-frame 3D segments.

    Each segment is clipped to ``z >= NEAR_CLIP_MM``, projected, and crossed with the
    centre line of every pixel column (when its image runs more along x than along y) or
    pixel row (otherwise) within its extent: one sample per crossing, at the segment's own
    sub-pixel position there, in the pixel that position falls in. So a line at any angle
    marks exactly one pixel per column (or row), 1 pixel wide on diagonals -- what an edge
    detector gives after non-maximum suppression -- and every marked pixel is one the
    projected edge passes through. The 3D point of each sample comes from
    perspective-correct interpolation (image fraction s -> t = s zA / ((1 - s) zB + s zA)).

    Parameters
    ----------
    K : (3, 3) intrinsics
    a, b : (M, 3) float
        Segment ends, camera frame, mm.
    shape : (H, W)

    Returns
    -------
    points : (N, 3) float64
        Samples on the segments, camera frame, mm.
    segment : (N,) intp
        Index of the segment each sample belongs to.
    row, col : (N,) intp
        The pixel each sample marks (inside the image).

    With ``minor_out`` (a list), two (N,) arrays are appended to it: each sample's
    continuous image coordinate across the line (row for x-major lines, column otherwise,
    pixel (i, j) spanning [i, i + 1)), and whether its line is y-major.
    """
    h, w = shape
    empty = (np.zeros((0, 3)), np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.intp))
    idx, a, b = _clip_near(a, b)
    if len(idx) == 0:
        return empty
    ua, ub = _project(K, a), _project(K, b)
    d = ub - ua
    major = (np.abs(d[:, 1]) > np.abs(d[:, 0])).astype(np.intp)  # 0: x (columns), 1: y (rows)
    minor = 1 - major
    ar = np.arange(len(idx))
    lo = np.minimum(ua[ar, major], ub[ar, major])
    hi = np.maximum(ua[ar, major], ub[ar, major])
    limit = np.where(major == 0, w, h)
    # pixel centres k + 0.5 inside [lo, hi] and inside the image
    first = np.maximum(np.ceil(lo - 0.5), 0)
    last = np.minimum(np.floor(hi - 0.5), limit - 1)
    n = np.maximum(last - first + 1, 0).astype(np.intp)
    if n.sum() == 0:
        return empty
    seg = np.repeat(ar, n)
    start = np.cumsum(n) - n
    k = first[seg] + (np.arange(len(seg)) - start[seg])
    dm = d[seg, major[seg]]
    s = np.clip((k + 0.5 - ua[seg, major[seg]]) / np.where(dm == 0, 1.0, dm), 0.0, 1.0)
    other = ua[seg, minor[seg]] + s * d[seg, minor[seg]]
    pos = np.empty((len(seg), 2))
    pos[np.arange(len(seg)), major[seg]] = k
    pos[np.arange(len(seg)), minor[seg]] = np.floor(other)
    col, row = pos[:, 0], pos[:, 1]
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    pts = _perspective_points(a[seg], b[seg], s)
    if minor_out is not None:
        minor_out += [other[inside], major[seg][inside].astype(bool)]
    return (pts[inside], idx[seg[inside]], row[inside].astype(np.intp), col[inside].astype(np.intp))


def _unoccluded(scene: Any, scan: RangeScan, pts: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """(N,) bool: nothing in ``scene`` lies between the camera and the camera-frame points
    ``pts``, short of ``tol`` (N,) mm in front of each (one Mitsuba shadow ray per point,
    plus one from an eye nudged by a hair, as in :func:`~rangesim.scene.visibility.visible_from`)."""
    from rangesim.core.backend import mitsuba
    from rangesim.scene.visibility import _NUDGE, _blocked

    if len(pts) == 0:
        return np.zeros(0, dtype=bool)
    mi = mitsuba()
    world = pts @ scan.pose[:3, :3].T + scan.pose[:3, 3]
    eye = np.asarray(scan.pose[:3, 3], dtype=np.float64)
    # float32 slack of a hit on the edge's own faces (as visible_from's default)
    magnitude = max(float(np.abs(world).max()), float(np.abs(eye).max()))
    tol = np.maximum(tol, (1.0 + magnitude) * 4.0 * float(mi.math.RayEpsilon))
    mscene = scene.mitsuba_scene().scene
    nudge = _NUDGE * (1.0 + float(np.abs(eye).max())) * 1e-4
    blocked = np.zeros(len(pts), dtype=bool)
    for origin in (eye, eye + nudge):
        blocked |= _blocked(mi, mscene, origin, world, tol)
    return ~blocked


def _mesh_creases(
    scan: RangeScan, scene: Any, k: int, R: np.ndarray, t: np.ndarray, K: np.ndarray,
    crease_deg: float, depth_tol_px: float, out: np.ndarray,
) -> None:
    """Rasterise object ``k``'s visible crease edges into ``out`` (uint8 labels, in place).

    Every crease edge (dihedral above ``crease_deg``, both faces towards the camera) is
    rasterised 8-connected (:func:`_raster_segments`, one sample per pixel column or row it
    crosses, at the edge's own sub-pixel position there). A sample marks its pixel when the
    edge itself is seen there: no surface lies on the ray from the camera to the sample
    more than ``depth_tol_px`` pixel footprints (z / fx) in front of it (a Mitsuba shadow
    ray cast to the sample's own position, not the pixel centre), and the pixel hits
    object ``k``.
    """
    obj = scene.objects[k]
    mesh = obj.mesh
    if len(mesh.faces) < 2 or not np.any(scan.part == k):
        return
    sel = mesh.face_adjacency_angles > np.radians(crease_deg)
    if not np.any(sel):
        return
    pairs = mesh.face_adjacency[sel]
    edges = mesh.face_adjacency_edges[sel]
    convex = mesh.face_adjacency_convex[sel]
    verts = mesh.vertices @ R.T + t  # camera frame
    normals = mesh.face_normals @ R.T
    # a planar face faces the camera (origin) everywhere or nowhere: n . (0 - v0) > 0
    facing = np.einsum("ij,ij->i", normals, -verts[mesh.faces[:, 0]]) > 0
    f0, f1 = facing[pairs[:, 0]], facing[pairs[:, 1]]
    if obj.watertight:
        # both faces seen: a crease; one seen: an occluding contour (the jump rule's job)
        keep = f0 & f1
    else:
        # an open sheet is seen from either side; from its back, convex and concave swap
        keep = f0 == f1
        convex = convex ^ ~f0
    if not np.any(keep):
        return
    pairs, edges, convex = pairs[keep], edges[keep], convex[keep]
    pts, seg, row, col = _raster_segments(K, verts[edges[:, 0]], verts[edges[:, 1]], scan.shape)
    on = scan.part[row, col] == k
    pts, seg, row, col = pts[on], seg[on], row[on], col[on]
    if len(pts) == 0:
        return
    # both faces must be sampled by the scan next to the crease: some pixel of the 3 x 3
    # around the mark hits object k with a true normal within crease_deg / 2 of each face's
    # (a crease bounding a sliver no pixel sees -- a sub-footprint step -- is not in the data)
    h, w = scan.shape
    cos_half = np.cos(np.radians(crease_deg) / 2)
    seen0 = np.zeros(len(pts), dtype=bool)
    seen1 = np.zeros(len(pts), dtype=bool)
    # the scan's normals are turned to face the camera (the visible side): so are the faces'
    # (an open sheet seen from its back; a watertight mesh's kept faces face it already)
    seen_side = np.where(facing[:, None], normals, -normals)
    n0, n1 = seen_side[pairs[seg, 0]], seen_side[pairs[seg, 1]]
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r, c = row + dr, col + dc
            ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
            r, c = np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)
            ok &= scan.part[r, c] == k
            n = np.nan_to_num(scan.normal[r, c].astype(np.float64))
            seen0 |= ok & (np.einsum("ij,ij->i", n, n0) >= cos_half)
            seen1 |= ok & (np.einsum("ij,ij->i", n, n1) >= cos_half)
    both = seen0 & seen1
    pts, seg, row, col = pts[both], seg[both], row[both], col[both]
    if len(pts) == 0:
        return
    vis = _unoccluded(scene, scan, pts, depth_tol_px * pts[:, 2] / K[0, 0])
    label = np.where(convex[seg], EdgeLabel.CONVEX, EdgeLabel.CONCAVE).astype(np.uint8)
    # where convex and concave meet in one pixel, concave wins
    np.maximum.at(out, (row[vis], col[vis]), label[vis])


def _contour_edges(mesh: Any, watertight: bool, verts: np.ndarray, normals: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Occluding-contour edges of a mesh seen from the camera at the origin.

    Returns (edges (M, 2) vertex indices, front (M,) the face on the seen side). A contour
    edge joins a face turned towards the camera and one turned away (where the surface
    folds out of sight); on an open sheet, which is seen from both sides, its boundary
    edges are contours too.
    """
    facing = np.einsum("ij,ij->i", normals, -verts[mesh.faces[:, 0]]) > 0
    pairs = np.asarray(mesh.face_adjacency)
    edges = np.asarray(mesh.face_adjacency_edges)
    if len(pairs):
        flip = facing[pairs[:, 0]] != facing[pairs[:, 1]]
        edges, pairs = edges[flip], pairs[flip]
        front = np.where(facing[pairs[:, 0]], pairs[:, 0], pairs[:, 1])
    else:
        edges, front = np.zeros((0, 2), np.intp), np.zeros(0, np.intp)
    if not watertight:
        import trimesh

        once = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)
        edges = np.concatenate([edges, mesh.edges_sorted[once]])
        front = np.concatenate([front, mesh.edges_face[once]])
    return np.asarray(edges, np.intp), np.asarray(front, np.intp)


def _contour_jumps(
    scan: RangeScan, scene: Any, k: int, R: np.ndarray, t: np.ndarray, K: np.ndarray,
    jump_angle_deg: float, depth_tol_px: float, out: np.ndarray,
) -> None:
    """Mark object ``k``'s visible occluding contours in ``out`` ((H, W) bool, in place).

    Each contour edge (:func:`_contour_edges`) is rasterised like a crease (one sample per
    pixel column or row it crosses) and, at each sample, the two pixels whose centres
    straddle the edge across it are looked at: the *near* one on the side the seen face
    lies (the occluding side) and the *far* one beyond. The near pixel is marked when it
    hits object ``k``, the edge point itself is seen (shadow ray, as creases), and the
    far pixel either sees nothing or sees a surface the jump rule of :func:`jump_edges`
    calls a jump from the near pixel's point (so a box's bottom edge standing on a floor,
    a contour of the box but no step in depth, is not one). So a contour is a line one
    pixel wide on the occluding side, and a steep face seen at grazing incidence, which
    faces the camera, is never filled.
    """
    obj = scene.objects[k]
    mesh = obj.mesh
    if len(mesh.faces) == 0 or not np.any(scan.part == k):
        return
    verts = mesh.vertices @ R.T + t
    normals = mesh.face_normals @ R.T
    edges, front = _contour_edges(mesh, obj.watertight, verts, normals)
    if len(edges) == 0:
        return
    a, b = verts[edges[:, 0]], verts[edges[:, 1]]
    # the seen face's direction into itself, perpendicular to the edge (3D)
    tri = verts[mesh.faces[front]]
    inward = tri.mean(axis=1) - 0.5 * (a + b)
    along = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1, keepdims=True), 1e-300)
    inward -= np.einsum("ij,ij->i", inward, along)[:, None] * along
    inward /= np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-300)
    minor: list = []
    pts, seg, row, col = _raster_segments(K, a, b, scan.shape, minor_out=minor)
    if len(pts) == 0:
        return
    across, y_major = minor
    # which way across the line the seen face lies: a small step into it, projected, less its
    # share along the line (a face seen nearly edge-on, a chamfer beside its foot, projects
    # its step mostly along the line: the image coordinate alone then takes the wrong side)
    eps = (1e-4 * pts[:, 2])[:, None]
    uv0 = _project(K, pts)
    into = _project(K, pts + eps * inward[seg]) - uv0
    line = _project(K, pts + eps * along[seg]) - uv0
    axis = np.where(y_major, 0, 1)  # image coordinate across the line: u (0) or v (1)
    ar = np.arange(len(pts))
    with np.errstate(divide="ignore", invalid="ignore"):
        side = np.sign(into[ar, axis] - line[ar, axis] / line[ar, 1 - axis] * into[ar, 1 - axis])
    side = np.nan_to_num(side)
    base = np.ceil(across - 0.5).astype(np.intp)  # first pixel whose centre lies past the line
    near = np.where(side > 0, base, base - 1)
    far = np.where(side > 0, base - 1, base)
    h, w = scan.shape
    limit = np.where(y_major, w, h)
    ok = (side != 0) & (near >= 0) & (near < limit) & (far >= 0) & (far < limit)
    pts, row, col, near, far, y_major = pts[ok], row[ok], col[ok], near[ok], far[ok], y_major[ok]
    nr, nc = np.where(y_major, row, near), np.where(y_major, near, col)
    fr, fc = np.where(y_major, row, far), np.where(y_major, far, col)
    on = scan.part[nr, nc] == k
    pts, nr, nc, fr, fc = pts[on], nr[on], nc[on], fr[on], fc[on]
    if len(pts) == 0:
        return
    p = scan.xyz_true[nr, nc].astype(np.float64)
    q = np.nan_to_num(scan.xyz_true[fr, fc].astype(np.float64))
    beyond = scan.part[fr, fc] >= 0
    step_jump, p_near = _pair_jumps(p, q, beyond, float(np.cos(np.radians(jump_angle_deg))), None)
    # the occluding side is the nearer one (sliver facets may say otherwise across a line)
    jump = ~beyond | (step_jump & p_near)
    pts, nr, nc = pts[jump], nr[jump], nc[jump]
    seen = _unoccluded(scene, scan, pts, depth_tol_px * pts[:, 2] / K[0, 0])
    out[nr[seen], nc[seen]] = True


def _contact_creases(
    scan: RangeScan, faces_of: list[np.ndarray], K: np.ndarray, crease_deg: float,
    jump_angle_deg: float, out: np.ndarray,
) -> None:
    """Creases where two surfaces that share no mesh edge meet (different objects in contact,
    or separate shells of one mesh), found from 4-neighbour pixel pairs; into ``out``.

    A pair is a contact crease when both pixels hit, their faces share no vertex, the step
    between their true points is no jump, their true normals differ by more than
    ``crease_deg``, and the line where their tangent planes meet passes within the pair's
    own spacing of the pair's midpoint (else it is a small step, not a crease) and, in the
    image, between the two pixel centres (a continuous surface from one ray to the other
    crosses it there). Concave when each point lies in front of the other's tangent plane.
    The pixel whose centre is nearer that image line is marked.
    """
    xyz = scan.xyz_true.astype(np.float64)
    nrm = scan.normal.astype(np.float64)
    part, face = scan.part, scan.face
    hit = (part >= 0) & np.all(np.isfinite(xyz), axis=-1) & np.all(np.isfinite(nrm), axis=-1)
    cos_crease = np.cos(np.radians(crease_deg))
    cos_jump = float(np.cos(np.radians(jump_angle_deg)))
    h, w = scan.shape
    rows, cols = np.indices((h, w))
    for axis in (0, 1):
        first = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        second = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        both = hit[first] & hit[second]
        cand = both & (np.einsum("...k,...k->...", nrm[first], nrm[second]) < cos_crease)
        ip, jp = rows[first][cand], cols[first][cand]
        iq, jq = rows[second][cand], cols[second][cand]
        if len(ip) == 0:
            continue
        kp, kq = part[ip, jp], part[iq, jq]
        fp, fq = face[ip, jp], face[iq, jq]
        # faces of one object sharing a vertex are mesh neighbours: their crease is a mesh edge
        same = kp == kq
        shared = np.zeros(len(ip), dtype=bool)
        for k in np.unique(kp[same]):  # a loop over objects only
            m = same & (kp == k)
            tri_p, tri_q = faces_of[k][fp[m]], faces_of[k][fq[m]]
            shared[m] = np.any(tri_p[:, :, None] == tri_q[:, None, :], axis=(1, 2))
        p, q = xyz[ip, jp], xyz[iq, jq]
        jump, _ = _pair_jumps(p, q, np.ones(len(ip), dtype=bool), cos_jump, None)
        keep = ~shared & ~jump
        if not np.any(keep):
            continue
        ip, jp, iq, jq, p, q = ip[keep], jp[keep], iq[keep], jq[keep], p[keep], q[keep]
        n_p, n_q = nrm[ip, jp], nrm[iq, jq]
        # closest point x to the midpoint m on the planes' intersection line:
        # x = m + a n_p + b n_q with n_p . x = n_p . p and n_q . x = n_q . q
        m = 0.5 * (p + q)
        c = np.einsum("ij,ij->i", n_p, n_q)
        rp = np.einsum("ij,ij->i", n_p, p - m)
        rq = np.einsum("ij,ij->i", n_q, q - m)
        det = np.maximum(1.0 - c * c, 1e-12)  # > 0: the normals differ by > crease_deg
        a = (rp - c * rq) / det
        b = (rq - c * rp) / det
        x = m + a[:, None] * n_p + b[:, None] * n_q
        spacing = np.linalg.norm(q - p, axis=1)
        line = np.cross(n_p, n_q)
        line *= (spacing / np.linalg.norm(line, axis=1))[:, None]
        # the crease line in the image (pixel-centre coordinates): through x0 along e
        x0 = _project(K, x) - 0.5
        e = _project(K, x + line) - 0.5 - x0
        side_p = e[:, 0] * (ip - x0[:, 1]) - e[:, 1] * (jp - x0[:, 0])
        side_q = e[:, 0] * (iq - x0[:, 1]) - e[:, 1] * (jq - x0[:, 0])
        # a continuous surface from p to q crosses the crease between their rays: the line
        # separates the two pixel centres in the image
        eps = 1e-6 * np.linalg.norm(e, axis=1)
        between = side_p * side_q <= eps * eps
        ok = (np.linalg.norm(x - m, axis=1) <= spacing) & between & (x[:, 2] > 0)
        concave = (np.einsum("ij,ij->i", n_p, q - p) + np.einsum("ij,ij->i", n_q, p - q)) > 0
        use_p = np.abs(side_p) <= np.abs(side_q)  # the pixel centre nearer the line
        r = np.where(use_p, ip, iq)[ok]
        cc = np.where(use_p, jp, jq)[ok]
        label = np.where(concave, EdgeLabel.CONCAVE, EdgeLabel.CONVEX).astype(np.uint8)[ok]
        np.maximum.at(out, (r, cc), label)


def ground_truth_edges(
    scan: RangeScan,
    scene: Any,
    crease_deg: float = 20.0,
    *,
    jump_angle_deg: float = JUMP_ANGLE_DEG,
    depth_tol_px: float = 1.0,
    jump_rule: str = "contours",
) -> np.ndarray:
    """Exact edge labels of a synthetic scan from the geometry behind it.

    Jump edges (``jump_rule="contours"``, the default) are the scene's occluding contours:
    mesh edges between a face turned towards the camera and one turned away (and the
    boundary of open sheets), rasterised one pixel wide and marked on the occluding side,
    where the edge itself is seen and the pixel beyond it sees nothing or a surface that
    the jump rule of :func:`jump_edges` (the 3D step within ``jump_angle_deg`` of the
    viewing ray) puts behind it; see ``_contour_jumps``. A face seen at grazing incidence
    still faces the camera, so it is never filled with jumps, and a box standing on a
    floor has no jump along its foot. ``jump_rule="pairs"`` is the former rule: every
    4-neighbour pair :func:`jump_edges` calls a jump, hit-next-to-miss included (it fills
    faces seen beyond 75 degrees). Creases are the mesh edges of each
    object whose dihedral angle (between face normals) exceeds ``crease_deg`` and whose two
    faces both face the camera (one facing away makes it an occluding contour: a jump),
    rasterised 8-connected (one pixel per column or row crossed, 1 px on diagonals) and kept
    where the edge itself is seen: a ray from the camera to the sample's own position meets
    nothing more than ``depth_tol_px`` pixel footprints in front of it, the pixel hits the
    same object, and the scan samples both faces in the 3 x 3 around it (true normals within
    ``crease_deg / 2`` of each face's; a sub-footprint step is not in the data). Convex/concave follows the dihedral sign
    (``face_adjacency_convex``). Surfaces in contact without sharing a mesh edge (a box on
    a floor) get contact creases from pixel pairs (see ``_contact_creases``). Jump wins over
    crease; where convex and concave fall in one pixel, concave wins.

    Parameters
    ----------
    scan : RangeScan
        A synthetic scan (``xyz_true``, ``part``, ``face``, ``normal``, ``pose``, ``meta['K']``).
    scene : Scene or anything :func:`rangesim.load_scene` accepts
        The scene the scan was made of (object order = ``scan.part``), world mm.
    crease_deg : float
        Smallest dihedral angle (degrees between the face normals) that makes a crease.
    jump_angle_deg : float
        The jump rule's angle (see :func:`jump_edges`).
    depth_tol_px : float
        Occluders closer than this to a crease or contour sample (pixel footprints,
        z / fx mm) do not hide it.
    jump_rule : {"contours", "pairs"}
        Occluding contours of the meshes (default), or the pixel-pair rule.

    Returns
    -------
    (H, W) uint8
        :class:`~rangesim.core.constants.EdgeLabel` per pixel: 0 none, 1 jump, 2 convex,
        3 concave.

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120
    >>> scene = rs.datasets.plate_scene()

    >>> truth = rs.ground_truth_edges(scan, scene)
    >>> truth.shape == scan.shape, sorted(int(v) for v in set(truth.ravel()))   # none, jump, convex, concave
    (True, [0, 1, 2, 3])

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    """
    from rangesim.scene.scene import load_scene

    P.number(crease_deg, "crease_deg", 0, 180, lo_open=True, hi_open=True, what="angle", unit="degrees")
    P.number(jump_angle_deg, "jump_angle_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    P.number(depth_tol_px, "depth_tol_px", 0, unit="pixel footprints")
    scene = load_scene(scene)
    R, t, K = _camera(scan)
    check_scene_of_scan(scan, scene, R, t)
    if jump_rule not in ("contours", "pairs"):
        raise RangesimError(f"jump_rule must be 'contours' or 'pairs', got {jump_rule!r}")
    if jump_rule == "pairs":
        hit = (scan.part >= 0) & np.all(np.isfinite(scan.xyz_true), axis=-1)
        jump = jump_edges(scan.xyz_true, hit, max_angle_deg=jump_angle_deg)
    else:
        jump = np.zeros(scan.shape, dtype=bool)
    labels = np.zeros(scan.shape, dtype=np.uint8)
    for k in range(len(scene.objects)):
        _mesh_creases(scan, scene, k, R, t, K, crease_deg, depth_tol_px, labels)
        if jump_rule == "contours":
            _contour_jumps(scan, scene, k, R, t, K, jump_angle_deg, depth_tol_px, jump)
    _contact_creases(scan, [np.asarray(o.mesh.faces) for o in scene.objects], K, crease_deg,
                     jump_angle_deg, labels)
    labels[jump] = EdgeLabel.JUMP
    return labels


# ---------------------------------------------------------------------------------------
# analytic features
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ImageEllipse:
    """A 3D circle's exact perspective image.

    Attributes
    ----------
    name : str
    object : int
        Scene object index.
    center : (2,) float
        Ellipse centre (x = column, y = row), pixels, integers at pixel centres (not the
        projection of the circle's centre).
    axes : (2,) float
        Semi-major and semi-minor axes, pixels.
    angle : float
        Direction of the major axis, radians from +x (columns) towards +y (rows).
    visible : float
        Fraction of the circle (by 3D arc length) the scan sees, 0..1.
    convex : bool
    dihedral_deg : float
    """

    name: str
    object: int
    center: np.ndarray
    axes: np.ndarray
    angle: float
    visible: float
    convex: bool = True
    dihedral_deg: float = 90.0


@dataclass(frozen=True)
class ImageSegment:
    """A 3D segment's image: ``xyxy`` = (x0, y0, x1, y1) in pixels (x = column, y = row,
    integers at pixel centres), clipped to the part in front of the camera; ``visible`` the
    fraction (by image length) the scan sees."""

    name: str
    object: int
    xyxy: np.ndarray
    visible: float
    convex: bool = True
    dihedral_deg: float = 90.0


def ground_truth_features(
    scan: RangeScan, scene: Any, *, depth_tol_px: float = 3.0, spacing_px: float = 0.5
) -> dict[str, list]:
    """The scene's analytic features (circles, segments) projected into a synthetic scan.

    Circles become exact image ellipses (the conic H^-T diag(1, 1, -1) H^-1 with
    H = K' [r e1, r e2, c], K' the intrinsics shifted to pixel-centre coordinates);
    segments become image segments. Visibility: the curve is sampled every ``spacing_px``
    pixels of its image and a sample counts as seen when one of the 2 x 2 pixels around it
    hits the same object within ``depth_tol_px`` pixel footprints of the sample's depth
    (so an edge on an occluding contour counts as seen).

    Parameters
    ----------
    scan : RangeScan
        A synthetic scan of ``scene``.
    scene : Scene or anything :func:`rangesim.load_scene` accepts
        Objects' ``features`` (AnalyticFeatures, world mm, may be None) are used.
    depth_tol_px : float
        How far (pixel footprints, z / fx mm) a hit may lie from a sample's depth and still
        see it, >= 0.
    spacing_px : float
        Spacing of the samples along each curve's image, pixels, >= 0.01.

    Returns
    -------
    dict
        ``{"circles": [ImageEllipse, ...], "segments": [ImageSegment, ...]}``; a circle whose
        image is not an ellipse (it reaches the camera plane) is left out, and so is a
        segment wholly behind the camera. Free-form curves (``features.curves``) are not
        projected.
    """
    from rangesim.scene.scene import load_scene

    P.number(depth_tol_px, "depth_tol_px", 0, unit="pixel footprints")
    # finer than a hundredth of a pixel changes no visibility and costs memory (1e-9: 111 GiB)
    P.number(spacing_px, "spacing_px", MIN_FEATURE_SPACING_PX, unit="pixels")
    scene = load_scene(scene)
    R, t, K = _camera(scan)
    check_scene_of_scan(scan, scene, R, t)
    shift = np.array([[1.0, 0, -0.5], [0, 1.0, -0.5], [0, 0, 1.0]])
    Kc = shift @ K  # x = column, y = row with integers at pixel centres
    circles: list[ImageEllipse] = []
    segments: list[ImageSegment] = []
    for k, obj in enumerate(scene.objects):
        feats = obj.features
        if feats is None:
            continue
        for c in getattr(feats, "circles", []):
            center = R @ np.asarray(c.center, float) + t
            normal = R @ np.asarray(c.normal, float)
            conic = project_circle(center, normal, c.radius, K)
            ell = None if conic is None else ellipse_from_conic(conic)
            if ell is None:
                continue  # seen edge-on, or reaching behind the camera plane
            e1, e2 = circle_basis(normal)
            # sample by 3D angle, dense enough for the image's longest axis
            n = max(64, int(np.ceil(2 * np.pi * ell[1][0] / spacing_px)))
            ang = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
            pts = center + c.radius * (np.cos(ang) * e1 + np.sin(ang) * e2)
            vis, _, _ = _visible(scan, K, k, pts, depth_tol_px, slack=True)
            circles.append(ImageEllipse(c.name, k, ell[0], ell[1], ell[2], float(vis.mean()),
                                        bool(c.convex), float(c.dihedral_deg)))
        segs = list(getattr(feats, "segments", []))
        if not segs:
            continue
        a = np.array([R @ np.asarray(s.start, float) + t for s in segs])
        b = np.array([R @ np.asarray(s.end, float) + t for s in segs])
        front, a_front, b_front = _clip_near(a, b)  # the parts in front of the camera
        for i, aa, bb in zip(front, a_front, b_front):
            s = segs[i]
            ends = _project(Kc, np.stack([aa, bb]))
            pts, _ = _sample_segments(K, aa[None], bb[None], scan.shape, spacing_px)
            if len(pts):
                vis, _, _ = _visible(scan, K, k, pts, depth_tol_px, slack=True)
                # the part outside the image margin was clipped away before sampling
                kept_uv = _project(K, pts[[0, -1]])
                kept = float(np.linalg.norm(kept_uv[1] - kept_uv[0]))
                full = float(np.linalg.norm(ends[1] - ends[0]))
                frac = float(vis.mean()) * (kept / full if full > 0 else 1.0)
            else:
                frac = 0.0
            segments.append(ImageSegment(s.name, k, ends.reshape(-1), min(frac, 1.0),
                                         bool(s.convex), float(s.dihedral_deg)))
    return {"circles": circles, "segments": segments}
