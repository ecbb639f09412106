"""Rigid transforms: look-at poses (OpenCV camera axes) and Euler rotations."""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from rangesim.core.errors import RangesimError


def look_at(position, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world pose of a camera at ``position`` looking at ``target``.

    The camera frame is OpenCV's: x right, y down (opposite ``up`` as seen in the image),
    z forward.

    Parameters
    ----------
    position, target, up : array_like, shape (3,)
        World coordinates of the camera centre and the point it looks at, and the world
        direction that appears upwards in the image.

    Returns
    -------
    (4, 4) float64 camera-to-world transform.

    Raises
    ------
    ValueError
        If position equals target, or ``up`` is parallel to the viewing direction.
    """
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    norm = np.linalg.norm(forward)
    if not np.isfinite(norm) or norm == 0:
        raise RangesimError("view position and look_at coincide")
    z = forward / norm
    up = np.asarray(up, dtype=np.float64)
    down = -(up - np.dot(up, z) * z)
    if np.linalg.norm(down) < 1e-9 * max(np.linalg.norm(up), 1e-300):
        raise RangesimError("view 'up' is parallel to the viewing direction")
    y = down / np.linalg.norm(down)
    x = np.cross(y, z)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, position
    return pose


#: the largest |R^T R - I| (any element) of a pose's rotation block that :func:`check_pose` takes
#: as a rotation written with a few decimals: 4 decimals leave up to about 2e-4, and the
#: shared data's shapes_pose.json (8 decimals, fitted) 7e-4
POSE_ORTHONORMAL_TOL = 1e-3


def _is_number(v: Any) -> bool:
    try:
        float(v)  # as np.asarray(..., float64) takes it (a numeric string too)
    except (TypeError, ValueError):
        return False
    return True


def check_pose(pose: Any, source: Any = None) -> np.ndarray:
    """``pose`` as a float64 (4, 4) rigid camera-to-world transform, or a one-line refusal.

    A rigid transform has an orthonormal, right-handed rotation block and the bottom row
    0 0 0 1 (anything else would scale or project the rays the scanner casts). A rotation
    block within :data:`POSE_ORTHONORMAL_TOL` of orthonormal (a pose written to 4-6 decimals,
    a calibration's output) is replaced by the nearest rotation (``U V^T`` of its SVD, a
    change of the same order); one farther off is refused with the measured deviation.

    Parameters
    ----------
    pose : array-like, (4, 4)
    source : str or Path, optional
        The file it came from, named in the message.

    Examples
    --------
    >>> check_pose(np.eye(4)).shape
    (4, 4)
    """
    given = pose
    try:
        pose = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError):
        raw = np.asarray(pose, dtype=object)
        if raw.shape == (4, 4):  # the right shape, an entry that is no number: name it
            bad = next((i, j, v) for (i, j), v in np.ndenumerate(raw) if not _is_number(v))
            raise RangesimError(f"pose entries must be numbers, got {bad[2]!r} at row {bad[0]}, column {bad[1]}",
                                source=source) from None
        what = f"a {type(pose).__name__}" if raw.ndim == 0 else f"{raw.shape[0]} rows of unequal or non-numeric entries"
        raise RangesimError(f"pose must be a finite 4x4 camera-to-world matrix of numbers, got {what}",
                            source=source) from None
    if pose.shape != (4, 4):
        got = f"a {type(given).__name__}" if pose.ndim == 0 else f"shape {pose.shape}"
        raise RangesimError(f"pose must be a finite 4x4 camera-to-world matrix, got {got}", source=source)
    if not np.all(np.isfinite(pose)):
        raise RangesimError("pose must be a finite 4x4 camera-to-world matrix (it holds NaN or infinity)",
                            source=source)
    rot = pose[:3, :3]
    off = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if off > POSE_ORTHONORMAL_TOL:
        raise RangesimError(f"pose rotation must be orthonormal: R^T R differs from the identity by up to {off:.3g} "
                            f"(allowed {POSE_ORTHONORMAL_TOL:g}); is the 3x3 block scaled, or not a rotation?",
                            source=source)
    if np.linalg.det(rot) < 0:
        raise RangesimError("pose rotation must be right-handed (its determinant is negative: a mirror)",
                            source=source)
    if not np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-9):
        raise RangesimError(f"pose must be a rigid transform: bottom row 0 0 0 1, got {pose[3].tolist()}",
                            source=source)
    if off > 0:  # the nearest rotation (polar decomposition): a pose written to a few decimals
        u, _, vt = np.linalg.svd(rot)
        pose = pose.copy()
        pose[:3, :3] = u @ vt
    return pose


def object_transform(translate=(0, 0, 0), rotate_deg=(0, 0, 0), scale=1.0) -> np.ndarray:
    """4x4 object-to-world transform: scale, then rotate, then translate.

    ``rotate_deg`` are extrinsic X, Y, Z Euler angles in degrees (rotate about the world
    x axis first, then y, then z), as in ``scipy.spatial.transform.Rotation.from_euler("xyz")``.
    ``scale`` is a scalar or a (3,) per-axis factor.
    """
    m = np.eye(4)
    rot = Rotation.from_euler("xyz", np.asarray(rotate_deg, dtype=np.float64), degrees=True)
    m[:3, :3] = rot.as_matrix() * np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    m[:3, 3] = np.asarray(translate, dtype=np.float64)
    return m


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (N, 3) points."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def circle_basis(normal) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane perpendicular to ``normal`` (right-handed with it)."""
    normal = np.asarray(normal, dtype=np.float64)
    normal = normal / np.linalg.norm(normal)
    helper = np.array([1.0, 0, 0]) if abs(normal[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def project_circle(center, normal, radius: float, K: np.ndarray) -> np.ndarray | None:
    """Image conic of a 3D circle seen by a pinhole camera.

    Parameters
    ----------
    center, normal : (3,) array_like
        Circle centre (mm) and axis in the camera frame (OpenCV axes).
    radius : float
        mm.
    K : (3, 3) intrinsics, pixel (row i, col j) looking along K^-1 (j + 0.5, i + 0.5, 1).

    Returns
    -------
    (6,) conic coefficients (a, b, c, d, e, f) of a x^2 + b x y + c y^2 + d x + e y + f = 0 in
    pixel-centre coordinates (x = column, y = row, integers at pixel centres), or None when
    the circle's plane passes through the camera centre (seen edge-on) or any of the circle
    lies at or behind the camera's plane (z <= 0: its image is then no ellipse, and a circle
    wholly behind the camera would give the conic of its mirror image in front).
    """
    n = np.asarray(normal, dtype=np.float64)
    n_len = float(np.linalg.norm(n))
    if not n_len > 0:
        return None
    # the circle's nearest approach to the plane z = 0: centre z less radius x the in-plane reach along z
    if float(center[2]) - radius * np.sqrt(max(0.0, 1.0 - (n[2] / n_len) ** 2)) <= 0:
        return None
    e1, e2 = circle_basis(normal)
    shift = np.array([[1.0, 0, -0.5], [0, 1.0, -0.5], [0, 0, 1.0]])
    # the circle's plane maps to the image by H (x_img ~ H (cos, sin, 1)); the unit circle
    # diag(1, 1, -1) maps to the conic H^-T diag(1, 1, -1) H^-1
    H = shift @ K @ np.column_stack([radius * e1, radius * e2, np.asarray(center, dtype=np.float64)])
    if abs(np.linalg.det(H)) < 1e-12:
        return None
    Hi = np.linalg.inv(H)
    C = Hi.T @ np.diag([1.0, 1.0, -1.0]) @ Hi
    return np.array([C[0, 0], 2 * C[0, 1], C[1, 1], 2 * C[0, 2], 2 * C[1, 2], C[2, 2]])
