"""Whether a scene is the one a synthetic scan was made from (before truth is drawn from it).

Duck-typed over the scene (``scene.objects[k].mesh``: ``vertices``, ``faces``,
``face_normals``), so that every layer that takes a scan and a scene (the ground truth, the
model-guided feature finders) can refuse another scene with the same test.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan

#: a scan's true hits must lie on the scene faces they name within this many mm plus this
#: share of their depth (float32 hits lie within ~1e-4 mm at 1 m; a scene moved by 0.1 mm misses)
FACE_TOL_MM, FACE_TOL_REL = 0.01, 1e-4
#: ... on at least this share of the hit pixels (the scene that made the scan: all of them)
MIN_ON_FACE = 0.9


def check_scene_of_scan(scan: RangeScan, scene: Any, R: np.ndarray | None = None, t: np.ndarray | None = None) -> None:
    """Refuse a scene that is not the one a synthetic scan was made from, before any truth is drawn.

    Every hit pixel names its object (``scan.part``) and triangle (``scan.face``); both must
    exist in ``scene``, and the pixel's noise-free point (``xyz_true``, camera frame, taken to
    the world by the pose) must lie on that triangle's plane within :data:`FACE_TOL_MM` +
    :data:`FACE_TOL_REL` x depth on at least :data:`MIN_ON_FACE` of the hit pixels. A scene
    with other faces or another placement drew truth for another object (its scores were
    meaningless, and a face index past its mesh raised IndexError).

    Parameters
    ----------
    scan : RangeScan
        Synthetic scan (``part``, ``face``, ``xyz_true``).
    scene : Scene
    R, t : (3, 3), (3,) arrays, optional
        World-to-camera rotation and translation of the scan's pose (default: from
        ``scan.pose``).

    A scan without ``part`` or ``xyz_true`` (a recorded one) has nothing to check.
    """
    if getattr(scan, "part", None) is None or getattr(scan, "xyz_true", None) is None:
        return
    if R is None or t is None:
        inv = np.linalg.inv(np.asarray(scan.pose, dtype=np.float64))
        R, t = inv[:3, :3], inv[:3, 3]
    part, face = np.asarray(scan.part), np.asarray(scan.face)
    n_objects = len(scene.objects)
    if part.max(initial=-1) >= n_objects:
        raise RangesimError(f"the scan hits object index {int(part.max())} (at least {int(part.max()) + 1} objects) "
                            f"but the scene has {n_objects} object{'s' if n_objects != 1 else ''}: give the scene "
                            "the scan was made from")
    truth = np.asarray(scan.xyz_true, dtype=np.float64)
    hit = (part >= 0) & np.isfinite(truth).all(axis=-1)
    if not hit.any():
        return
    hits = truth[hit]
    world = (hits - t) @ R  # camera -> world: x_w = R^T (x_c - t)
    k_hit, f_hit = part[hit], face[hit]
    on_face = np.zeros(k_hit.size, dtype=bool)
    for k in np.unique(k_hit):
        mesh = scene.objects[int(k)].mesh
        mine = k_hit == k
        f = f_hit[mine]
        n_faces = len(mesh.faces)
        if f.min() < 0 or f.max() >= n_faces:
            raise RangesimError(f"scan hits triangle {int(f.max() if f.max() >= n_faces else f.min())} of object "
                                f"{int(k)}, whose mesh in this scene has {n_faces:,}: give the scene the scan was "
                                "made from")
        normals = np.asarray(mesh.face_normals, dtype=np.float64)[f]
        corner = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)[f, 0]]
        off = np.abs(np.einsum("nk,nk->n", world[mine] - corner, normals))
        # plus float32's rounding of world coordinates far from the origin (Mitsuba's vertices)
        tol = FACE_TOL_MM + FACE_TOL_REL * np.abs(hits[mine, 2]) + 1e-6 * np.abs(world[mine]).max(axis=1)
        on_face[mine] = off <= tol
    share = float(np.count_nonzero(on_face)) / on_face.size
    if share < MIN_ON_FACE:
        raise RangesimError(f"the scene is not the one this scan was made from: {100 * share:.1f} % of the scan's "
                            f"true hits lie on the scene triangles they name (at least {100 * MIN_ON_FACE:.0f} % "
                            "needed)")
