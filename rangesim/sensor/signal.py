"""Return signal of the stripe: Lambertian reflection with inverse-square falloff both ways.

signal = albedo * cos(i) * cos(e) * (z_ref / d_L)^2 * (z_ref / d_C)^2

with i the incidence angle of the laser ray on the surface, e the angle between the
surface normal and the direction to the camera, d_L and d_C the distances (mm) to the laser
source and to the camera, and z_ref the sensor's reference distance (mid-range). A white
target (albedo 1) facing both at z_ref returns 1; ``noise.min_signal`` is relative to that.
Grazing surfaces (cos -> 0) therefore drop out, as on real scanners.
"""
from __future__ import annotations

import numpy as np


def return_signal(albedo, normals, points, sources, reference_distance):
    """Relative return signal and the cosine of the laser's incidence angle.

    Parameters
    ----------
    albedo : (N,) float array
        Diffuse reflectance 0..1.
    normals : (N, 3) float array
        Unit surface normals facing the camera, camera frame.
    points, sources : (N, 3) float arrays
        Surface points and laser source positions, camera frame, mm (camera at the origin).
    reference_distance : float
        Distance (mm) at which a white facing target returns 1.

    Returns
    -------
    signal : (N,) float array, 0 where the laser is behind the surface
    cos_incidence : (N,) float array, negative where the laser is behind the surface
    """
    to_laser = sources - points
    d_laser = np.linalg.norm(to_laser, axis=1)
    d_camera = np.linalg.norm(points, axis=1)
    cos_i = np.einsum("ij,ij->i", normals, to_laser) / d_laser
    cos_e = -np.einsum("ij,ij->i", normals, points) / d_camera
    z2 = reference_distance**2
    signal = albedo * np.clip(cos_i, 0, None) * np.clip(cos_e, 0, None) * (z2 / d_laser**2) * (z2 / d_camera**2)
    return signal, cos_i
