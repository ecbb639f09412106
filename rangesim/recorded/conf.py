"""Stanford ``.conf`` files: the poses of the scans of a range-scan data set.

A line ``bmesh FILE tx ty tz qx qy qz qw`` (metres, scalar-last quaternion) places scan
``FILE``: a scan point maps into the common frame as ``p_world = R(q)^T p + t`` (checked
against ``bun_zipper.ply`` in the data README), so the scan's pose (sensor-to-world, mm)
is ``[[R(q)^T, 1000 t], [0, 1]]``. Every recorded-data reader takes ``conf=`` and sets
the pose through :func:`apply_conf`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan
from rangesim.recorded.common import check_file

__all__ = ["apply_conf", "conf_pose", "read_conf"]

#: .conf translations are in metres; scans are in millimetres
METRES_TO_MM = 1000.0


#: the farthest a scan may sit from the world origin (mm): a kilometre
MAX_TRANSLATION_MM = 1e6


def read_conf(conf: str | Path) -> dict[str, np.ndarray]:
    """All ``bmesh`` poses of a Stanford ``.conf`` file.

    Parameters
    ----------
    conf : str or Path
        Lines ``bmesh FILE tx ty tz qx qy qz qw`` (metres, scalar-last quaternion);
        other lines (``camera ...``) are ignored.

    Returns
    -------
    dict
        Scan file name (as written) -> (4, 4) float64 sensor-to-world pose in mm:
        ``p_world = R(q)^T p + t``.

    Raises
    ------
    RangesimError
        A missing file or a malformed ``bmesh`` line (wrong count, NaN, zero quaternion).
    """
    conf = check_file(conf)
    try:
        text = conf.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise RangesimError(f"cannot read file ({exc.strerror or exc})", conf) from exc
    poses: dict[str, np.ndarray] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if not words or words[0] != "bmesh":
            continue
        try:
            values = np.array([float(w) for w in words[2:]], dtype=np.float64)
        except ValueError:
            values = np.empty(0)
        if len(words) != 9 or values.size != 7 or not np.isfinite(values).all():
            raise RangesimError(f"line {number}: expected 'bmesh FILE tx ty tz qx qy qz qw' (7 finite numbers)", conf)
        t, q = values[:3], values[3:]
        if np.linalg.norm(q) < 1e-12:
            raise RangesimError(f"line {number}: the quaternion is zero", conf)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat(q).inv().as_matrix()
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below
            pose[:3, 3] = t * METRES_TO_MM
        if not np.isfinite(pose).all() or np.abs(pose[:3, 3]).max() > MAX_TRANSLATION_MM:
            raise RangesimError(f"line {number}: the translation is out of range (at most "
                                f"{MAX_TRANSLATION_MM / METRES_TO_MM:g} m)", conf)
        if words[1] in poses and not np.allclose(poses[words[1]], pose):  # which one is meant?
            raise RangesimError(f"line {number}: a second bmesh line for {words[1]} with another pose", conf)
        poses[words[1]] = pose
    return poses


def conf_pose(conf: str | Path, name: str) -> np.ndarray:
    """The pose of scan file ``name`` in a Stanford ``.conf`` (see :func:`read_conf`).

    The ``bmesh`` FILE is matched by file name (directories ignored), exactly first, then
    case-insensitively.

    Raises
    ------
    RangesimError
        If the conf has no line for ``name``.
    """
    poses = read_conf(conf)
    by_name = {Path(key).name: pose for key, pose in poses.items()}
    if name in by_name:
        return by_name[name].copy()
    folded = {key.lower(): pose for key, pose in by_name.items()}
    if name.lower() in folded:
        return folded[name.lower()].copy()
    listed = ", ".join(sorted(by_name)) or "none"
    raise RangesimError(f"no 'bmesh {name}' line (it has: {listed})", conf)


def apply_conf(scan: RangeScan, conf: str | Path | None, path: Path) -> RangeScan:
    """Set ``scan.pose`` from a Stanford ``.conf`` entry for ``path``'s file name (if given)."""
    if conf is not None:
        scan.pose = conf_pose(conf, path.name)
        scan.meta["pose_source"] = {"conf": Path(conf).name}
    return scan
