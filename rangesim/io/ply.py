"""PLY point clouds: the valid points of a scan, with normals and intensity.

Binary little-endian, one ``vertex`` element with float32 properties
``x y z nx ny nz intensity`` and no faces, which trimesh, Open3D and MeshLab all read.
Points are in the **camera frame** (OpenCV: x right, y down, z forward, scene units);
the camera-to-world pose is kept in a ``comment pose ...`` header line (16 row-major
float64 values, exact repr) so the cloud can be moved to the world frame later.
This is an export format: it drops the image grid, labels and invalid pixels.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rangesim.core.rangescan import RangeScan, checked_scan

#: vertex layout, in file order
VERTEX_DTYPE = np.dtype(
    [(name, "<f4") for name in ("x", "y", "z", "nx", "ny", "nz", "intensity")]
)


CAMERA_FRAME = "camera frame (x right, y down, z forward)"


def ply_header(n_vertices: int, pose: np.ndarray | None, frame: str = CAMERA_FRAME) -> bytes:
    """ASCII header of a rangesim point-cloud PLY with ``n_vertices`` vertices.

    ``frame`` says which frame the points are in; ``pose`` (4x4, camera-to-world) is
    recorded as a comment when given.
    """
    lines = [
        "ply",
        "format binary_little_endian 1.0",
        f"comment rangesim point cloud, {frame}",
    ]
    if pose is not None:
        pose_text = " ".join(repr(float(v)) for v in np.asarray(pose, dtype=np.float64).ravel())
        lines.append(f"comment pose {pose_text}")
    lines += [
        f"element vertex {n_vertices}",
        *(f"property float {name}" for name in VERTEX_DTYPE.names),
        "end_header",
    ]
    return ("\n".join(lines) + "\n").encode("ascii")


def write_ply(scan: RangeScan, path: str | Path) -> None:
    """Write the valid points of ``scan`` as a binary PLY (directly; not atomic).

    Use :func:`rangesim.io.save_scan` for an atomic write.

    Parameters
    ----------
    scan : RangeScan
        Its ``valid`` pixels become vertices, in row-major pixel order: position
        ``xyz`` and ``normal`` (camera frame) and ``intensity``.
    path : str or Path
        Target file.

    Raises
    ------
    TypeError
        If ``scan`` is not a RangeScan.
    RangesimError
        If a field reassigned since construction fails the constructor's checks.
    """
    scan = checked_scan(scan, path)  # fields may have been reassigned since construction
    mask = scan.valid
    vertices = np.empty(int(np.count_nonzero(mask)), dtype=VERTEX_DTYPE)
    xyz, normal = scan.xyz[mask], scan.normal[mask]
    for i, axis in enumerate("xyz"):
        vertices[axis] = xyz[:, i]
        vertices["n" + axis] = normal[:, i]
    vertices["intensity"] = scan.intensity[mask]
    with open(path, "wb") as fh:
        fh.write(ply_header(len(vertices), scan.pose))
        fh.write(vertices.tobytes())
