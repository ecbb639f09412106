"""Return signal of the stripe: Lambertian reflection with inverse-square falloff both ways.

signal = albedo * cos(i) * cos(e) * (z_ref / d_L)^2 * (z_ref / d_C)^2

with i the incidence angle of the laser ray on the surface, e the angle between the
surface normal and the direction to the camera, d_L and d_C the distances (mm) to the laser
source and to the camera, and z_ref the sensor's reference distance (mid-range). A white
target (albedo 1) facing both at z_ref returns 1; ``noise.min_signal`` is relative to that.
Grazing surfaces (cos -> 0) therefore drop out, as on real scanners.
"""
from __future__ import annotations

import drjit as dr


def return_signal(albedo, normals, points, sources, reference_distance: float):
    """Relative return signal and the cosine of the laser's incidence angle.

    Parameters
    ----------
    albedo : mi.Float
        Diffuse reflectance 0..1.
    normals : mi.Vector3f
        Unit surface normals facing the camera, camera frame.
    points, sources : mi.Vector3f
        Surface points and laser source positions, camera frame, mm (camera at the origin).
    reference_distance : float
        Distance (mm) at which a white facing target returns 1.

    Returns
    -------
    signal : mi.Float, 0 where the laser is behind the surface
    cos_incidence : mi.Float, negative where the laser is behind the surface
    """
    to_laser = sources - points
    d2_laser = dr.squared_norm(to_laser)
    d2_camera = dr.squared_norm(points)
    cos_i = dr.dot(normals, to_laser) * dr.rsqrt(d2_laser)
    cos_e = -dr.dot(normals, points) * dr.rsqrt(d2_camera)
    z2 = reference_distance**2
    # dr.select, not dr.maximum: LLVM 14's x86 backend cannot lower llvm.maximum
    facing = (cos_i > 0) & (cos_e > 0)
    signal = dr.select(facing, albedo * cos_i * cos_e * (z2 / d2_laser) * (z2 / d2_camera), 0.0)
    return signal, cos_i
