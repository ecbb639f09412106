"""Ellipses: model-guided (predicted from the model's 3D circles and the scan's pose, refined on
the edge points left over by lines, circles and arcs), or fitted to linked chains (RANSAC)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from rangesim.core.conics import (
    conic_normal_angle,
    ellipse_from_conic,
    fit_circle,
    fit_conic,
    fit_conics_batched,
    fit_conics_grouped,
    real_ellipses,
    sampson_distance,
    sampson_distance_batched,
    sampson_distance_rows,
)
from rangesim.features._edge_points import edge_points


@dataclass(frozen=True)
class Ellipse:
    """An ellipse in the image.

    Attributes
    ----------
    center : (x, y) float, pixels
    axes : (a, b) float
        Semi-major and semi-minor axes, pixels.
    orientation : float
        Major-axis direction, radians from +x towards +y, in (-pi/2, pi/2].
    residual : float
        RMS Sampson distance of the supporting edge pixels, pixels.
    n_points : int
    name : str
        The model circle it was predicted from ("" without a model).
    """

    center: tuple[float, float]
    axes: tuple[float, float]
    orientation: float
    residual: float
    n_points: int
    name: str = ""


def mesh_circles(mesh: Any, crease_deg: float = 30.0, max_rel_residual: float = 0.02,
                 min_points: int = 8) -> list:
    """3D circles fitted to the closed crease loops of a mesh.

    Mesh edges whose dihedral angle exceeds ``crease_deg`` are grouped into connected
    components (graph traversal); components where every vertex has degree 2 are closed
    loops; each loop is fitted with a plane (SVD) and a circle in that plane, and kept when
    the RMS residuals are below ``max_rel_residual`` times the radius.

    Returns
    -------
    list of :class:`~rangesim.cad.features.Circle3D` (world mm, the mesh's frame).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from rangesim.cad.features import Circle3D

    angles = np.asarray(mesh.face_adjacency_angles)
    edges = np.asarray(mesh.face_adjacency_edges)[angles > np.deg2rad(crease_deg)]
    if len(edges) == 0:
        return []
    nv = len(mesh.vertices)
    g = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(nv, nv))
    n_comp, lab = connected_components(g, directed=False)
    deg = np.bincount(edges.ravel(), minlength=nv)
    verts = np.unique(edges)
    out = []
    V = np.asarray(mesh.vertices, float)
    for comp in np.unique(lab[verts]):
        vs = verts[lab[verts] == comp]
        if len(vs) < min_points or np.any(deg[vs] != 2):
            continue
        P = V[vs]
        m = P.mean(0)
        _, sv, vt = np.linalg.svd(P - m, full_matrices=False)
        normal = vt[2]
        uv = (P - m) @ vt[:2].T
        c2, r, rms = fit_circle(uv)
        planar = sv[2] / np.sqrt(len(P))
        if r <= 0 or rms > max_rel_residual * r or planar > max_rel_residual * r:
            continue
        out.append(Circle3D(f"loop_{comp}", m + c2 @ vt[:2], normal, float(r)))
    return out


def predict_ellipses(scan: Any, circles3d: list, world: bool = True) -> list[tuple[str, np.ndarray]]:
    """Predicted image ellipses of 3D circles seen from the scan's pose.

    Parameters
    ----------
    scan : RangeScan
        Needs ``pose`` and ``meta["K"]``.
    circles3d : list of Circle3D
        World mm (camera frame when ``world`` is False).

    Returns
    -------
    list of (name, conic (6,)) in pixel-centre coordinates; circles whose image is not an
    ellipse are left out.
    """
    from rangesim.core.geometry import project_circle

    inv = np.linalg.inv(np.asarray(scan.pose, float)) if world else np.eye(4)
    R, t = inv[:3, :3], inv[:3, 3]
    out = []
    for c in circles3d:
        conic = project_circle(R @ np.asarray(c.center, float) + t, R @ np.asarray(c.normal, float), c.radius, scan.K)
        if conic is not None and ellipse_from_conic(conic) is not None:
            out.append((c.name, conic / (np.sign(conic[0]) * np.linalg.norm(conic))))  # a > 0
    return out


def _scene_circles(scene: Any) -> list:
    """3D circles of a scene's objects (world mm): each object's analytic circles
    (``features.circles``) where it has them, else circles of its mesh's closed crease loops
    (:func:`mesh_circles`; not for planes, boxes or meshes of up to 12 faces).

    ``scene`` is duck-typed so that this layer does not depend on :mod:`rangesim.scene`: a
    :class:`~rangesim.scene.Scene` or anything with ``objects``, each with ``features``
    (or None), ``source`` and ``mesh`` (a trimesh). Scene or mesh files are loaded by the
    caller (:func:`rangesim.load_scene`).
    """
    if not hasattr(scene, "objects"):
        raise TypeError(f"scene must be a loaded scene (with .objects), not {type(scene).__name__}; "
                        "load files and meshes with rangesim.load_scene first")
    circles3d = []
    for obj in scene.objects:
        feats = obj.features
        if feats is not None and getattr(feats, "circles", None):
            circles3d += list(feats.circles)
        elif obj.source not in ("plane", "box") and len(obj.mesh.faces) > 12:
            circles3d += mesh_circles(obj.mesh)
    return circles3d


def _refine(conic: np.ndarray, xy: np.ndarray, theta: np.ndarray, band: float,
            angle_tol_deg: float = 25.0, iterations: int = 3) -> tuple[np.ndarray, np.ndarray] | None:
    """Refit a conic on the edge points within ``band`` px of it whose direction agrees."""
    cos_tol = np.cos(np.deg2rad(angle_tol_deg))
    sel = None
    for k in range(iterations):
        b = band if k == 0 else max(1.0, band / 2 ** k)
        d = sampson_distance(conic, xy)
        agree = np.abs(np.cos(conic_normal_angle(conic, xy) - theta)) >= cos_tol
        sel = np.nonzero((d <= b) & agree)[0]
        if len(sel) < 8:
            return None
        new = fit_conic(xy[sel])
        if new is None or ellipse_from_conic(new) is None:
            return None
        conic = new
    return conic, sel


def _ransac(xy: np.ndarray, rng: np.random.Generator, iters: int = 200, tol: float = 1.0,
            direct_inliers: float = 0.95, local: int = 24, refits: int = 5):
    """Best ellipse (conic, inliers) of points, or None.

    First a direct least-squares fit (Fitzgibbon) of all the points: kept when at least
    ``direct_inliers`` of them lie within ``tol`` px (Sampson distance), then refitted on
    those. Otherwise 6-point RANSAC as the fallback: ``local`` samples stratified along the
    points' order (one point from each sixth of the curve, so every sample spans it), then
    (only if none gives an ellipse) up to ``iters`` in all drawn from the whole set; each
    batch fitted and scored at once; then up to ``refits`` fits on the inliers of the last
    conic, until the inlier set stops changing.
    """
    n = len(xy)
    c = fit_conic(xy)
    if c is not None and ellipse_from_conic(c) is not None:
        inl = np.nonzero(sampson_distance(c, xy) <= tol)[0]
        if len(inl) >= direct_inliers * n:
            c2 = fit_conic(xy[inl]) if len(inl) < n else c
            if c2 is not None and ellipse_from_conic(c2) is not None:
                return c2, np.nonzero(sampson_distance(c2, xy) <= tol)[0]
    if n < 6:
        return None
    idx = _stratified_samples(n, min(local, iters), rng)
    res = _best_sample(xy, idx, tol)
    if res is None and iters > local:
        res = _best_sample(xy, np.argsort(rng.random((iters - local, n)), axis=1)[:, :6], tol)
    if res is None:
        return None
    inl = np.nonzero(sampson_distance(res, xy) <= tol)[0]
    best = None
    for _ in range(max(refits, 1)):
        c = fit_conic(xy[inl])
        if c is None or ellipse_from_conic(c) is None:
            break
        new = np.nonzero(sampson_distance(c, xy) <= tol)[0]
        best = (c, inl)
        if len(new) == len(inl) and np.array_equal(new, inl):
            break
        inl = new
    return best


def _stratified_samples(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """(k, 6) indices: one point drawn from each sixth of the ordered points."""
    bounds = np.linspace(0.0, n, 7)
    return np.minimum((bounds[:-1] + rng.random((k, 6)) * np.diff(bounds)).astype(np.intp), n - 1)


def _best_sample(xy: np.ndarray, idx: np.ndarray, tol: float) -> np.ndarray | None:
    """The conic, among those fitted to each row of samples ``idx``, with most inliers."""
    conics, ok = fit_conics_batched(xy[idx])
    counts = np.where(ok, (sampson_distance_batched(conics, xy) <= tol).sum(1), -1)
    best = None
    for k in np.argsort(-counts, kind="stable"):
        if counts[k] < 0:
            break
        if ellipse_from_conic(conics[k]) is not None:  # real ellipse, not an imaginary one
            best = conics[k]
            break
    return best


def ellipses(
    edge_map: Any,
    scan: Any = None,
    scene: Any = None,
    *,
    explained: tuple = (),
    remove_explained: bool = True,
    band_px: float | None = None,
    min_points: int = 20,
    min_support: float = 0.3,
    axes_range: tuple[float, float] = (4.0, 200.0),
    seed: int = 0,
) -> list[Ellipse]:
    """Ellipses of an edge map.

    First the edge points explained by lines, circles and arcs (``explained``: the features
    to remove; by default found here with :func:`~rangesim.features.lines`,
    :func:`~rangesim.features.circles` and :func:`~rangesim.features.arcs`) are removed,
    except where they lie in a model-predicted ellipse's band (the model has priority).

    With ``scene`` (a loaded :class:`~rangesim.scene.Scene` or any object with its
    ``objects``, see :func:`_scene_circles`; not a file name, load it with
    :func:`rangesim.load_scene`) and ``scan`` (pose and intrinsics): the model's 3D circles
    (analytic features of built-in parts; for other meshes circles fitted to closed crease
    loops, :func:`mesh_circles`) are projected to predicted image ellipses; each is refined by a
    direct least-squares conic fit (Fitzgibbon) on the remaining edge points within a band
    of ``band_px`` (default ``max(3, 0.15 b)``) px whose edge direction agrees, narrowing the
    band over three passes. Kept when its supporting points cover at least ``min_support``
    of its perimeter (about one point per pixel).

    Without a model: ellipses fitted to the connected groups of edge pixels
    (:func:`edge_groups`: 8-connected components after bridging gaps of up to 2 px, no
    thinning or linking) by direct least squares, RANSAC as the fallback.

    Returns
    -------
    list of Ellipse

    Examples
    --------
    >>> import rangesim as rs
    >>> scan = rs.datasets.plate_scan()        # a plate with a hole, on a table, 128 x 120
    >>> scene = rs.datasets.plate_scene()

    >>> found = rs.features.ellipses(rs.edges.gradient(scan), scan, scene)
    >>> len(found) > 0, round(found[0].axes[0])           # the hole's rim seen obliquely, semi-axis in px
    (True, 9)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    .. [2] A. Fitzgibbon, M. Pilu, R. B. Fisher, "Direct least square fitting of ellipses", IEEE
       TPAMI 21(5), 476-480 (1999), doi:10.1109/34.765658.
    """
    mask = np.asarray(getattr(edge_map, "mask", edge_map), bool)
    H, W = mask.shape
    if not remove_explained and (scene is None or scan is None):
        # nothing to remove and no model: groups of the whole mask (edge directions unused)
        return _chain_ellipses(edge_groups(mask, min_points), np.random.default_rng(seed),
                               min_points, axes_range)
    xy, theta = edge_points(edge_map)
    predictions = []
    if scene is not None and scan is not None:
        predictions = predict_ellipses(scan, _scene_circles(scene))
    # -- remove points explained by lines, circles and arcs (not those a model claims) --
    remove = np.zeros(len(xy), bool)
    if remove_explained:
        if not explained:
            from rangesim.features._arcs import arcs as find_arcs
            from rangesim.features._circles import circles as find_circles
            from rangesim.features._lines import lines as find_lines

            explained = (*find_lines(edge_map), *find_circles(edge_map), *find_arcs(edge_map))
        for f in explained:
            if hasattr(f, "radius"):
                remove |= np.abs(np.hypot(*(xy - np.array(f.center)).T) - f.radius) <= 1.0
            elif hasattr(f, "start") and hasattr(f, "end") and not hasattr(f, "radius"):
                a, b = np.array(f.start), np.array(f.end)
                ab = b - a
                t = np.clip((xy - a) @ ab / max(ab @ ab, 1e-12), 0, 1)
                remove |= np.hypot(*(xy - a - t[:, None] * ab).T) <= 1.0
    claimed = np.zeros(len(xy), bool)
    for _, conic in predictions:
        ell = ellipse_from_conic(conic)
        claimed |= sampson_distance(conic, xy) <= (band_px or max(3.0, 0.15 * ell[1][1]))
    keep = ~remove | claimed
    out: list[Ellipse] = []
    if predictions:
        for name, conic in predictions:
            ell = ellipse_from_conic(conic)
            if ell is None:
                continue
            (cx, cy), (a, b) = ell[0], ell[1]
            if not (-a <= cx <= W + a and -a <= cy <= H + a):
                continue
            band = band_px or max(3.0, 0.15 * b)
            res = _refine(conic, xy[keep], theta[keep], band)
            if res is None:
                continue
            c2, sel = res
            e2 = ellipse_from_conic(c2)
            if e2 is None or np.hypot(*(e2[0] - ell[0])) > band or abs(e2[1][0] - a) > band:
                continue
            perim = np.pi * (3 * (e2[1][0] + e2[1][1]) - np.sqrt((3 * e2[1][0] + e2[1][1]) * (e2[1][0] + 3 * e2[1][1])))
            if len(sel) < min_support * perim or len(sel) < min_points:
                continue
            rms = float(np.sqrt(np.mean(sampson_distance(c2, xy[keep][sel]) ** 2)))
            out.append(Ellipse((float(e2[0][0]), float(e2[0][1])), (float(e2[1][0]), float(e2[1][1])),
                               float(e2[2]), rms, len(sel), name))
        return out
    # -- no model: direct fits / RANSAC on connected groups of the remaining points --
    rest = np.zeros_like(mask)
    rest[xy[keep, 1].astype(int), xy[keep, 0].astype(int)] = True
    return _chain_ellipses(edge_groups(rest, min_points), np.random.default_rng(seed),
                           min_points, axes_range)


def edge_groups(mask: np.ndarray, min_points: int = 20, max_gap: int = 1) -> list[np.ndarray]:
    """Edge pixels grouped into connected components: a light stand-in for linking.

    The pixels of ``mask`` are labelled by the 8-connected components of the mask dilated
    with a ``(max_gap + 1)``-square (so pixels up to ``max_gap`` missing pixels apart share a
    group); no thinning, tracing or junction splitting. Each group's points are ordered by
    their angle around the group's centroid, which follows a closed convex curve such as an
    ellipse (the RANSAC fallback draws its samples from windows of that order). A direct
    least-squares conic fit (Fitzgibbon) needs no order at all.

    Parameters
    ----------
    mask : (H, W) bool
    min_points : int
        Groups with fewer pixels are dropped.
    max_gap : int
        Largest number of missing pixels bridged (0: plain 8-connectivity).

    Returns
    -------
    list of (N, 2) float arrays
        (x = column, y = row) of each group's pixels, largest group first.
    """
    mask = np.asarray(mask, bool)
    grown = ndimage.binary_dilation(mask, np.ones((max_gap + 1,) * 2, bool)) if max_gap > 0 else mask
    lab, n = ndimage.label(grown, _EIGHT)
    rows, cols = np.nonzero(mask)
    if n == 0 or len(rows) < min_points:
        return []
    g = lab[rows, cols]
    counts = np.bincount(g, minlength=n + 1)
    order = np.argsort(g, kind="stable")
    ends = np.cumsum(counts)
    xy = np.column_stack([cols, rows]).astype(np.float64)[order]
    out = []
    for k in np.argsort(-counts[1:], kind="stable") + 1:
        if counts[k] < min_points:
            break
        p = xy[ends[k] - counts[k]:ends[k]]
        d = p - p.mean(axis=0)
        out.append(p[np.argsort(np.arctan2(d[:, 1], d[:, 0]), kind="stable")])
    return out


_EIGHT = np.ones((3, 3), bool)


def _chain_ellipses(groups: list[np.ndarray], rng: np.random.Generator, min_points: int,
                    axes_range: tuple[float, float]) -> list[Ellipse]:
    """Ellipses fitted to groups of edge points ((N, 2) x, y arrays, ordered along the
    curve), all groups at once (:func:`_batched_ransac`; :func:`_ransac` per group only for
    the groups where none of the stratified samples gives an ellipse)."""
    out: list[Ellipse] = []
    if not groups:
        return out
    conics, inliers = _batched_ransac(groups, rng)
    for k, p in enumerate(groups):
        if conics[k] is None:
            res = _ransac(p, rng)
            if res is None:
                continue
            conics[k], inliers[k] = res
        c2, inl = conics[k], inliers[k]
        e2 = ellipse_from_conic(c2)
        if e2 is None or len(inl) < min_points or not (axes_range[0] <= e2[1][1] and e2[1][0] <= axes_range[1]):
            continue
        if e2[1][1] / e2[1][0] < 0.2:
            continue
        rms = float(np.sqrt(np.mean(sampson_distance(c2, p[inl]) ** 2)))
        out.append(Ellipse((float(e2[0][0]), float(e2[0][1])), (float(e2[1][0]), float(e2[1][1])),
                           float(e2[2]), rms, len(inl)))
    return out


def _batched_ransac(groups: list[np.ndarray], rng: np.random.Generator, tol: float = 1.0,
                    direct_inliers: float = 0.95, local: int = 24, refits: int = 3):
    """:func:`_ransac` on every group at once: direct fits of all groups in one batch
    (:func:`~rangesim.core.conics.fit_conics_grouped`), kept where ``direct_inliers`` of a
    group's points lie within ``tol`` px; for the others ``local`` stratified 6-point samples
    per group fitted and scored (on up to 64 of the group's points) in one batch, the best real ellipse of each group then refitted
    on its inliers (``refits`` batched passes). Returns per group the conic (None where no
    sample gave an ellipse) and the indices of its inliers."""
    G = len(groups)
    n = np.array([len(p) for p in groups])
    xy = np.concatenate(groups)
    gid = np.repeat(np.arange(G), n)
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    conics, ok = fit_conics_grouped(xy, gid, G)
    ok &= real_ellipses(conics)
    d = sampson_distance_rows(conics[gid], xy)
    inl = (d <= tol) & ok[gid]
    direct = ok & (np.bincount(gid, weights=inl, minlength=G) >= direct_inliers * n)
    # stratified samples for the rest: one point from each sixth of the ordered group
    rest = np.nonzero(~direct & (n >= 6))[0]
    if len(rest):
        bounds = np.linspace(0.0, 1.0, 7)
        u = bounds[:-1] + rng.random((len(rest), local, 6)) * np.diff(bounds)
        idx = start[rest, None, None] + np.minimum((u * n[rest, None, None]).astype(np.intp), n[rest, None, None] - 1)
        sc, sok = fit_conics_batched(xy[idx.reshape(-1, 6)])
        sok &= real_ellipses(sc)
        # score each sample on (up to 64 evenly spaced of) its own group's points
        ns = np.minimum(n[rest], 64)
        sub = np.repeat(start[rest], ns) + (np.arange(ns.sum()) - np.repeat(np.cumsum(ns) - ns, ns)) \
            * np.repeat(n[rest], ns) // np.repeat(ns, ns)
        # every (sample, scoring point) of the same group
        per = np.repeat(ns, local)  # scoring points per sample
        owner = np.repeat(np.arange(len(rest) * local), per)
        first = np.repeat(np.concatenate([[0], np.cumsum(ns)[:-1]]), local)
        pts = sub[np.repeat(first, per) + np.arange(owner.size) - np.repeat(np.cumsum(per) - per, per)]
        hits = sampson_distance_rows(sc[owner], xy[pts]) <= tol
        counts = np.where(sok, np.bincount(owner, weights=hits, minlength=len(rest) * local), -1).reshape(len(rest), local)
        best = np.argmax(counts, axis=1)
        found = counts[np.arange(len(rest)), best] >= 0
        conics[rest[found]] = sc.reshape(len(rest), local, 6)[found, best[found]]
        ok[rest] = found
    ok &= n >= 5
    # refits on the inliers, all groups together (the direct ones start from their direct fit)
    for _ in range(max(refits, 1)):
        inl = (sampson_distance_rows(conics[gid], xy) <= tol) & ok[gid]
        new, nok = fit_conics_grouped(xy[inl], gid[inl], G)
        nok &= real_ellipses(new) & (np.bincount(gid[inl], minlength=G) >= 5)
        conics[nok & ok] = new[nok & ok]
    inl = (sampson_distance_rows(conics[gid], xy) <= tol) & ok[gid]
    out_c = [conics[k] if ok[k] else None for k in range(G)]
    out_i = [np.nonzero(inl[start[k]:start[k] + n[k]])[0] for k in range(G)]
    return out_c, out_i
