"""The white-light intensity image of a view, registered with its range image.

Real scanners record a grey-level image with the same camera (the laser off, room light
on), so every range pixel has an intensity. Here Mitsuba's own ``path`` integrator renders
the scene under uniform white room light (a ``constant`` environment of radiance 1) through
a perspective camera with the sensor's intrinsics and pose, so pixel (row i, column j) sees
exactly what range pixel (i, j) sees. An unoccluded white Lambertian surface reads 1; a
diffuse surface reads its albedo times its ambient occlusion, plus interreflections.
"""
from __future__ import annotations

import numpy as np

from rangesim.core.backend import mitsuba
from rangesim.core.errors import RangesimError

#: OpenCV camera axes (x right, y down) -> Mitsuba's (x left, y up), both looking along +z
OPENCV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0, 1.0])


def mitsuba_camera(sensor, pose: np.ndarray, spp: int):
    """A Mitsuba ``perspective`` sensor matching ``sensor``'s pinhole and a camera-to-world pose."""
    mi = mitsuba()
    return mi.load_dict({
        "type": "perspective",
        "fov": float(sensor.params["camera"]["fov_deg"]),
        "fov_axis": "x",
        "near_clip": 1.0,
        "far_clip": 10.0 * float(sensor.params["range"]["far"]),
        "to_world": mi.ScalarTransform4f((np.asarray(pose, float) @ OPENCV_TO_MITSUBA).tolist()),
        "film": {"type": "hdrfilm", "width": sensor.width, "height": sensor.height,
                 "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": int(spp)},
    })


def intensity_image(scene, sensor, pose: np.ndarray | None = None, spp: int = 16, max_depth: int = 3,
                    seed: int = 0) -> np.ndarray:
    """Render the white-light intensity image of a view.

    Parameters
    ----------
    scene, sensor
        Anything :func:`rangesim.load_scene` / :func:`rangesim.load_sensor` accept.
    pose : (4, 4) array, optional
        Camera-to-world; default as in :func:`rangesim.scan`.
    spp : int
        Samples per pixel.
    max_depth : int
        Mitsuba's path depth (2: direct light only).
    seed : int

    Returns
    -------
    (H, W) float32 radiance at the laser's wavelength (red channel), relative to the room
    light: 1 for an unoccluded white Lambertian surface.
    """
    from rangesim.scene import load_scene
    from rangesim.sensor._scan import default_pose
    from rangesim.sensor.config import load_sensor
    from rangesim.sensor.rendered import check_backend

    if isinstance(spp, bool) or int(spp) < 1 or int(max_depth) < 2:
        raise RangesimError(f"intensity_image needs spp >= 1 and max_depth >= 2, got {spp}, {max_depth}")
    check_backend()
    mi = mitsuba()
    scene = load_scene(scene)
    sensor = load_sensor(sensor)
    pose = default_pose(scene, sensor) if pose is None else np.asarray(pose, float)
    integrator = mi.load_dict({"type": "path", "max_depth": int(max_depth)})
    image = mi.render(scene.mitsuba_scene().scene, sensor=mitsuba_camera(sensor, pose, spp),
                      integrator=integrator, seed=int(seed), spp=int(spp))
    return np.asarray(image)[..., 0].astype(np.float32)
