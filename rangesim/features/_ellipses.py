"""Ellipses: model-guided (predicted from the model's 3D circles and the scan's pose, refined on
the edge points that straight lines leave over), or model-free (arcs of smooth edge curves,
fitted and grown: :mod:`._arc_ellipses`)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.core.conics import (
    conic_normal_angle,
    ellipse_from_conic,
    ellipse_params,
    fit_circle,
    fit_conic,
    sampson_distance,
)
from rangesim.core.errors import RangesimError
from rangesim.core.scene_of_scan import check_scene_of_scan
from rangesim.features._arc_ellipses import free_ellipses
from rangesim.features._edge_points import check_range, check_scan_shape, edge_mask, edge_points, point_labels

#: a segment whose points' edge normals turn by more than this (degrees) along it explains no
#: points for :func:`ellipses`: the line finder also draws chords along gently curved edges,
#: 30-55 px long on a clean 120 x 60 px ellipse, and removing their points left none of the
#: large ellipses (semi-major axes 80-190 px) found at most angles. Chosen on such drawn
#: ellipses (7: all found but a 190 x 60 px one at 2 of 5 angles; 10: that one at 1; 5: all
#: but one) and on the machined parts' tuning seeds 0-7 / 20-29 (5 cost cyberware_3030 one
#: false round feature; 7 and 10 none), checked on 8-15 / 30-39 (the same round features)
CURVED_SEGMENT_DEG = 7.0
#: nor a segment whose points bow by more than this (px) from its chord (:func:`_sagitta`):
#: chosen on clean drawn ellipses of semi-axes 80-200 x 30-60 px at five angles (23 -> 37 of
#: 40 found by the default call) and the machined parts' tuning seeds (the same round features); on
#: their check seeds one false round feature more of 74 (inria_laser)
CURVED_SEGMENT_SAGITTA_PX = 0.5
SAGITTA_SIGNIFICANCE = 3.0


@dataclass(frozen=True)
class Ellipse:
    """An ellipse in the image.

    Attributes
    ----------
    center : (x, y) float, pixels
    axes : (a, b) float
        Semi-major and semi-minor axes, pixels.
    orientation : float
        Major-axis direction, radians from +x towards +y, in [-pi/2, pi/2).
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

    if not (hasattr(mesh, "face_adjacency_angles") and hasattr(mesh, "vertices")):
        raise RangesimError(f"mesh_circles: mesh must be a trimesh.Trimesh (load a file with rs.cad.load_model), "
                            f"got {type(mesh).__name__}")
    P.number(crease_deg, "crease_deg", 0, 180, lo_open=True, hi_open=True, what="angle", unit="degrees")
    P.number(max_rel_residual, "max_rel_residual", 0, lo_open=True)
    min_points = P.whole(min_points, "min_points", 3)
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
        loop = V[vs]
        m = loop.mean(0)
        _, sv, vt = np.linalg.svd(loop - m, full_matrices=False)
        normal = vt[2]
        uv = (loop - m) @ vt[:2].T
        c2, r, rms = fit_circle(uv)
        planar = sv[2] / np.sqrt(len(loop))
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

    if getattr(scan, "K", None) is None:
        raise RangesimError("has no camera intrinsics (meta['K']): ellipses predicted from a model need a "
                            "pinhole scan; without a scene, ellipses() finds them from the edges alone", "scan")
    if isinstance(circles3d, (str, bytes)) or not hasattr(circles3d, "__iter__"):
        raise RangesimError(f"circles3d must be a list of Circle3D (a scene's circles), got {type(circles3d).__name__}")
    inv = np.linalg.inv(np.asarray(scan.pose, float)) if world else np.eye(4)
    R, t = inv[:3, :3], inv[:3, 3]
    out = []
    for i, c in enumerate(circles3d):
        _check_circle3d(c, i)
        conic = project_circle(R @ np.asarray(c.center, float) + t, R @ np.asarray(c.normal, float), c.radius, scan.K)
        if conic is not None and ellipse_from_conic(conic) is not None:
            out.append((c.name, conic / (np.sign(conic[0]) * np.linalg.norm(conic))))  # a > 0
    return out


def _check_circle3d(c: Any, index: int) -> None:
    """Refuse a circle that is not a Circle3D-like record with a finite centre, a non-zero
    normal and a positive radius (tuples raised AttributeError; a negative radius was projected)."""
    try:
        center = np.asarray(c.center, dtype=np.float64)
        normal = np.asarray(c.normal, dtype=np.float64)
        radius = float(c.radius)
    except (AttributeError, TypeError, ValueError):
        raise RangesimError(f"circles3d[{index}] must be a Circle3D (name, center, normal, radius), "
                            f"got {type(c).__name__} {c!r:.60}") from None
    if center.shape != (3,) or normal.shape != (3,) or not (np.isfinite(center).all() and np.isfinite(normal).all()):
        raise RangesimError(f"circles3d[{index}] needs a finite (3,) center and normal")
    if not np.linalg.norm(normal) > 0 or not (math.isfinite(radius) and radius > 0):
        raise RangesimError(f"circles3d[{index}] needs a non-zero normal and a positive radius, got radius {radius:g}")


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
    free_support: float = 0.5,
    axes_range: tuple[float, float] = (4.0, 200.0),
    seed: int = 0,
    hypotheses: str | None = None,
) -> list[Ellipse]:
    """Ellipses of an edge map.

    First the edge points explained by straight lines (``explained``: the features whose
    points to remove, anything with ``start``/``end`` or ``center``/``radius``; by default the
    segments of :func:`~rangesim.features.lines` found here) are removed, except where they
    lie in a model-predicted ellipse's band (the model has priority). Circles and arcs are
    not removed by default: a circle is an ellipse, and an arc is often the part of a rim that
    a gap or a junction cut off (measured on the machined parts' tuning seeds, removing them
    cost 0.2 of the rim recall).

    With ``scene`` (a loaded :class:`~rangesim.scene.Scene` or any object with its
    ``objects``, see :func:`_scene_circles`; not a file name, load it with
    :func:`rangesim.load_scene`) and ``scan`` (pose and intrinsics): the model's 3D circles
    (analytic features of built-in parts; for other meshes circles fitted to closed crease
    loops, :func:`mesh_circles`) are projected to predicted image ellipses; each is refined by a
    direct least-squares conic fit (Fitzgibbon) on the remaining edge points within a band
    of ``band_px`` (default ``max(3, 0.15 b)``) px whose edge direction agrees, narrowing the
    band over three passes. Kept when its supporting points cover at least ``min_support``
    of its perimeter (about one point per pixel). The predictions are refined independently,
    so two predicted rims closer than the band may lock onto the one edge the map holds and
    both be returned with the same geometry: a chamfered hole's two circles 1-2 px apart (on
    the flat machined target each truth rim then has its match), or a through-hole's bottom
    rim, partly seen through the hole, beside its top rim (the plate of
    :func:`rangesim.datasets.plate_scene` returns ``loop_1`` and ``loop_2`` alike). Claiming
    each edge point for one prediction was tried and dropped: it lost one of each chamfer pair.

    Without a model (:func:`~._arc_ellipses.free_ellipses`): the edge pixels are linked into
    smooth curves (neighbours, or up to 3 px apart along their tangent, whose normals agree
    within 35 degrees); the pieces of each curve inside square tiles of 16-256 px (two shifts
    each: none and half a tile diagonally), the pairs of the largest pieces that share a tile,
    and the outer outline of each group of edge pixels are fitted by direct least squares; those
    that are good ellipses (after one trimmed refit, RMS Sampson distance <= 0.5 px over at
    least 60 degrees of arc) are grown over the edge points within 3, 2, 1.5 then 1 px whose
    normal agrees within 25 degrees, refitted, and kept when those points cover at least
    ``free_support`` of the perimeter (1 px bins of arc length) with an RMS distance <= 0.8 px.
    Edge points are claimed by one ellipse each (largest coverage first): a candidate whose
    unclaimed points no longer cover ``free_support`` (a near-duplicate, a ghost across two
    rims) is dropped; an accepted ellipse's ``n_points`` counts all its inliers. ``seed`` is not used (the path has no random
    sampling; kept so that callers passing it keep working). ``hypotheses`` (model-free path;
    default "tilings", :data:`~._arc_ellipses.HYPOTHESES`): with "chains" the
    hypotheses come instead from the edge pixels traced into chains and cut into arc pieces at
    corners, inflections and curvature jumps, pieces linked end to end across gaps
    (:mod:`~._ellipse_chains`): 1.3-1.5x faster on the tilted Green Piece and far better on
    large partial ellipses (55 of 80 found against 25 on held-out synthetic maps, precision 0.98
    against 0.56), not the default: on the machined parts' check seeds it lost one rim of 54 on
    white_scanner and added a false one on cyberware_3030 (``benchmarks/bench_hough.py``), and
    on dense random clutter (a mask half set at random) it finds ghost ellipses, tens per
    100 x 100, where the tilings find none. With "outlines" only outlines are fitted (what
    ``cv2.fitEllipse`` on each contour of ``cv2.findContours(..., RETR_LIST)`` sees; checked,
    grown and claimed like the rest): each group's outer outline and the outlines of the
    regions it encloses, with the pixels dilated by 1 px (bridging a broken rim), and the
    outer outlines undilated (keeping apart a rim and a line a pixel or two beside it),
    :data:`~._arc_ellipses.OUTLINE_PASSES`. 3x faster than the tilings (1.4-1.5x
    fitEllipse's CPU time on the tilted Green Piece) with their recall there. It needs
    outlines: it misses an ellipse broken by gaps over 2 px (dashed: 9 of 99 found, the tilings
    93) or whose inside an edge splits in two (neither region is the ellipse), and two crossing
    ellipses' lens can come out as a ghost; on the machined parts it misses some boss and
    cylinder tops the tilings find (hole rims alike on the laser-stripe presets, fewer on the
    block-matched ones).

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
    if hypotheses not in (None, "tilings", "chains", "outlines"):
        raise RangesimError(f"hypotheses must be 'tilings', 'chains' or 'outlines', got {hypotheses!r}")
    if scene is not None and scan is None:
        raise RangesimError("a scene needs its scan (the scan's pose and intrinsics project the scene's "
                            "circles); give both, or no scene for the model-free search")
    if scene is not None and not hasattr(scene, "objects"):
        raise RangesimError(f"scene must be a loaded scene (rangesim.load_scene), not {type(scene).__name__}")
    remove_explained = P.flag(remove_explained, "remove_explained")
    if not isinstance(explained, (tuple, list)):
        raise RangesimError(f"explained must be a tuple of found lines, circles or arcs, not {type(explained).__name__}")
    for k, f in enumerate(explained):  # numbers were silently explained nothing
        if not (hasattr(f, "radius") and hasattr(f, "center")) and not (hasattr(f, "start") and hasattr(f, "end")):
            raise RangesimError(f"explained[{k}] must be a found line, circle or arc (start and end, or centre "
                                f"and radius), got {type(f).__name__} {f!r:.40}")
    P.whole(seed, "seed", 0, none=True)  # not used (no random sampling); kept checked for the callers passing it
    P.number(band_px, "band_px", 0, lo_open=True, unit="pixels", none=True)
    min_points = P.whole(min_points, "min_points", 5)
    P.number(min_support, "min_support", 0, 1, what="share")
    P.number(free_support, "free_support", 0, 1, what="share")
    mask = edge_mask(edge_map)
    if scan is not None:
        check_scan_shape(scan, mask)
    if scene is not None:  # the model's circles are another part's on a scan of something else
        check_scene_of_scan(scan, scene)
    axes_range = check_range(axes_range, "axes_range")
    H, W = mask.shape
    xy, theta, pixels = edge_points(edge_map, return_pixels=True)
    if not remove_explained and (scene is None or scan is None):
        return _free(xy, theta, pixels, point_labels(edge_map, pixels), min_points, free_support, axes_range,
                     hypotheses)
    predictions = []
    if scene is not None and scan is not None:
        predictions = predict_ellipses(scan, _scene_circles(scene))
    # -- remove points explained by lines, circles and arcs (not those a model claims) --
    remove = np.zeros(len(xy), bool)
    if remove_explained:
        if not explained:
            from rangesim.features._lines import lines as find_lines

            explained = tuple(find_lines(edge_map))
        for f in explained:
            if hasattr(f, "radius"):
                remove |= np.abs(np.hypot(*(xy - np.array(f.center)).T) - f.radius) <= 1.0
            elif hasattr(f, "start") and hasattr(f, "end") and not hasattr(f, "radius"):
                a, b = np.array(f.start), np.array(f.end)
                ab = b - a
                t = np.clip((xy - a) @ ab / max(ab @ ab, 1e-12), 0, 1)
                near = np.hypot(*(xy - a - t[:, None] * ab).T) <= 1.0
                # a chord the line finder drew along a gently curved edge (the flat sides of a
                # large ellipse) is no line: its points' normals turn along it
                if _turns(t[near] * np.hypot(*ab), theta[near], ab) > np.radians(CURVED_SEGMENT_DEG):
                    continue
                # or bow away from their chord (a long chord of a very elongated ellipse, whose
                # normals turn by less over it: a 100 px chord where the curvature radius is
                # 800 px turns 7 degrees but bows 1.5 px)
                if _sagitta(xy[near], a, ab) > CURVED_SEGMENT_SAGITTA_PX:
                    continue
                remove |= near
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
    # -- no model: arcs of the remaining points, grown --
    labels = point_labels(edge_map, pixels)
    return _free(xy[keep], theta[keep], pixels[keep], None if labels is None else labels[keep], min_points,
                 free_support, axes_range, hypotheses)


def _sagitta(p: np.ndarray, a: np.ndarray, ab: np.ndarray) -> float:
    """How far (px) the points ``p`` (N, 2) near a segment (start ``a``, vector ``ab``) bow
    from a straight line over their span: a parabola's offset between the span's middle and
    its ends (least squares in the segment's frame), or 0 where that is within
    ``SAGITTA_SIGNIFICANCE`` standard errors of the fit (a digitised or noisy straight edge:
    the standard error of the sagitta of N points spread evenly over the span is
    rms sqrt(180 / N) / 4)."""
    L = float(np.hypot(*ab))
    if len(p) < 5 or L <= 0:
        return 0.0
    d = ab / L
    u = (p - a) @ d
    u = u - u.mean()
    v = (p - a) @ np.array([-d[1], d[0]])
    coef = np.polyfit(u, v, 2)
    sag = abs(coef[0]) * np.ptp(u) ** 2 / 4
    rms = float(np.sqrt(np.mean((np.polyval(coef, u) - v) ** 2)))
    return float(sag) if sag > SAGITTA_SIGNIFICANCE * rms * np.sqrt(180.0 / len(p)) / 4 else 0.0


def _turns(u: np.ndarray, theta: np.ndarray, ab: np.ndarray) -> float:
    """How far (radians) the edge normals ``theta`` (N,) of the points at ``u`` (N,) px along
    a segment of direction ``ab`` turn over its length: the slope of their angle to the
    segment's normal (modulo pi) against ``u``, times the length they span."""
    if len(u) < 5 or np.ptp(u) <= 0:
        return 0.0
    rel = theta - np.arctan2(ab[1], ab[0]) - np.pi / 2
    phi = 0.5 * np.arctan2(np.sin(2 * rel), np.cos(2 * rel))
    slope = np.polyfit(u, phi, 1)[0]
    return float(abs(slope) * np.ptp(u))


def _free(xy: np.ndarray, theta: np.ndarray, pixels: np.ndarray, labels: np.ndarray | None, min_points: int,
          min_support: float, axes_range: tuple[float, float], hypotheses: str | None = None) -> list[Ellipse]:
    """The model-free ellipses (:func:`~._arc_ellipses.free_ellipses`) as Ellipse."""
    found = free_ellipses(xy, theta, min_points=min_points, min_support=min_support, axes_range=axes_range,
                          pixels=pixels, labels=labels, hypotheses=hypotheses)
    if not found:
        return []
    # the accepted conics are real ellipses: their parameters in one compiled call (the rows of
    # ellipse_from_conic)
    c, axes, angle, ok = ellipse_params(np.array([f[0] for f in found]))
    assert ok.all(), "free_ellipses accepted a conic that is no real ellipse"
    return [Ellipse((float(c[k, 0]), float(c[k, 1])), (float(axes[k, 0]), float(axes[k, 1])), float(angle[k]), rms, n)
            for k, (_, _, _, rms, n) in enumerate(found)]
