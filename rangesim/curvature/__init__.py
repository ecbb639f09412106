"""Curvature on data: per-vertex (meshes) and per-pixel (scans) from one local quadric fit.

Analysis layer: pure NumPy/SciPy over arrays. Sign convention (all functions): curvature is
measured against the normal facing the camera (scans) or pointing outwards (meshes) and is
negative where the surface bends away from it; a sphere of radius r seen from outside has
k1 = k2 = H = -1/r, K = 1/r^2, which the HK map labels a peak (Besl and Jain). Units 1/mm
(K in 1/mm^2). Details in :mod:`rangesim.curvature.quadric`.
"""
from rangesim.curvature.edges import curvature_edges
from rangesim.curvature.grid import curvature_scan
from rangesim.curvature.hk import SURFACE_TYPE_NAMES, SurfaceType, hk_sign_map, surface_type_name
from rangesim.curvature.mesh import curvature_mesh
from rangesim.curvature.quadric import QuadricFit, fit_quadric

__all__ = [
    "fit_quadric", "QuadricFit", "curvature_mesh", "curvature_scan", "hk_sign_map",
    "SurfaceType", "surface_type_name", "SURFACE_TYPE_NAMES", "curvature_edges",
]
