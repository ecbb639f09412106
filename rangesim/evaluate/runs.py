"""Running edge detectors on a scan and scoring them against whatever truth the scan has."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rangesim.core.constants import EdgeLabel
from rangesim.core.errors import RangesimError
from rangesim.core.progress import Progress
from rangesim.evaluate._edge_scores import edge_scores
from rangesim.evaluate._visible import visible_truth
from rangesim.evaluate.regions import region_boundaries


@dataclass
class EdgeTruth:
    """Ground-truth edges of a scan.

    Attributes
    ----------
    labels : (H, W) uint8
        EdgeLabel per pixel (region boundaries carry JUMP: their type is unknown).
    kind : str
        ``"geometry"`` (exact, from the scene behind a synthetic scan) or ``"regions"``
        (boundaries between labelled segments of a recorded scan).
    """

    labels: np.ndarray
    kind: str

    @property
    def mask(self) -> np.ndarray:
        return self.labels != EdgeLabel.NONE

    def edge_map(self):
        """The truth as an :class:`~rangesim.edges.edgemap.EdgeMap` for pictures: region
        boundaries with no type (label 0 on the mask, "type unknown"), not as jumps."""
        from rangesim.edges.edgemap import EdgeMap

        labels = self.labels if self.kind == "geometry" else np.zeros_like(self.labels)
        return EdgeMap(self.mask, labels, np.zeros(self.labels.shape, np.float32), method=f"ground truth ({self.kind})")


#: extensions whose reader takes ``sensor=`` (what recorded the file; see :func:`load_scan_with_labels`)
SENSOR_READERS = (".pcd",)


def load_scan_with_labels(path, conf=None, *, sensor=None):
    """A scan file and its per-pixel segment labels if the format has them (PCD ``label``).

    Parameters
    ----------
    path : str or Path
    conf : str or Path, optional
        A Stanford ``.conf`` pose file.
    sensor : str, Path, dict or Sensor, optional
        What recorded the file (a preset name, a sensor TOML, a dict, a Sensor, or
        ``"auto"``), passed to readers that take it (``.pcd``:
        :func:`rangesim.recorded.read_pcd`), so that a structured-light recording gets
        ``meta["sensor"]`` and the detectors' block-matched paths. Any other format with
        ``sensor`` given is refused (a RangesimError naming the file): its scans either
        carry their sensor already (``.exr``, rangesim ``.npz``) or record no such thing.

    Returns
    -------
    scan : RangeScan
    labels : (H, W) int array or None
    """
    from rangesim.io import load_scan

    path = Path(path)
    options = {"conf": conf} if conf else {}
    if path.suffix.lower() in SENSOR_READERS:
        from rangesim.recorded import read_pcd

        if sensor is not None:
            options["sensor"] = sensor
        scan, extras = read_pcd(path, **options)
        return scan, extras.get("label")
    if sensor is not None:
        if not path.is_file():
            return load_scan(path, **options), None  # the reader's "no such file" / "not a file"
        kind = f"{path.suffix!r} files" if path.suffix else "files without an extension"
        given = f"sensor {str(sensor)!r}" if isinstance(sensor, (str, Path)) else "a sensor"
        raise RangesimError(f"{given} applies to recorded {', '.join(SENSOR_READERS)} frames only; {kind} take none "
                            "(they carry their sensor already or record none)", path)
    return load_scan(path, **options), None


def scan_truth(scan, scene: Any = None, segment_labels: np.ndarray | None = None,
               crease_deg: float = 20.0) -> EdgeTruth | None:
    """The best ground truth available for ``scan``, or None.

    A synthetic scan (``xyz_true`` present) with its scene (given, or the scene file named
    in ``scan.meta["scene"]`` if it still exists) gets the exact geometric truth, kept on
    the pixels the scanner measured (an edge inside a laser shadow is nobody's to find); a
    recorded scan with per-pixel segment labels gets their region boundaries.
    """
    if scan.xyz_true is not None:
        if scene is None:
            scene = scene_of_scan(scan)
        if scene is not None:
            from rangesim.scene import load_scene

            # no detector can find an edge where the scanner measured nothing (laser shadow)
            labels = visible_truth(scan, load_scene(scene), crease_deg=crease_deg)
            return EdgeTruth(labels, "geometry")
    if segment_labels is not None:
        boundary = region_boundaries(segment_labels, scan.valid)
        return EdgeTruth(np.where(boundary, np.uint8(EdgeLabel.JUMP), np.uint8(0)), "regions")
    return None


def scene_of_scan(scan):
    """The scene a synthetic scan names in its metadata (``meta["scene"]``, a bare mesh file read
    in ``meta["scene_units"]`` where it was not in mm), loaded; None when the file is gone."""
    source = scan.meta.get("scene")
    if not source or not Path(str(source)).is_file():
        return None
    from rangesim.scene.scene import MESH_SUFFIXES, load_mesh_scene, load_scene

    path = Path(str(source))
    if path.suffix.lower() in MESH_SUFFIXES:
        return load_mesh_scene(path, scan.meta.get("scene_units"))
    return load_scene(path)


def run_detectors(scan, methods, truth: EdgeTruth | None = None, tolerance_px: float = 2.0,
                  params: dict[str, dict] | None = None) -> dict[str, dict[str, Any]]:
    """Run edge detectors on one scan and score them.

    Parameters
    ----------
    scan : RangeScan
    methods : iterable of str
        Names in :data:`rangesim.edges.DETECTORS`.
    truth : EdgeTruth, optional
    tolerance_px : float
        Matching tolerance of the scores, pixels.
    params : dict, optional
        Keyword arguments per method.

    Returns
    -------
    dict
        Per method: ``edge_map``, ``seconds`` and, with a truth, ``scores`` (precision,
        recall, F1, FOM; per label for geometric truth).
    """
    from rangesim.edges import DETECTORS

    results = {}
    methods = list(methods)
    bar = Progress(len(methods), "edge detectors", unit="detector")
    for method in methods:
        start = time.perf_counter()
        edge_map = DETECTORS[method](scan, **(params or {}).get(method, {}))
        entry: dict[str, Any] = {"edge_map": edge_map, "seconds": time.perf_counter() - start}
        if truth is not None:
            labelled = truth.kind == "geometry"
            entry["scores"] = edge_scores(
                edge_map.mask, truth.mask, tolerance_px,
                pred_labels=edge_map.labels if labelled else None,
                gt_labels=truth.labels if labelled else None,
            )
        results[method] = entry
        bar.update()
    bar.close()
    return results
