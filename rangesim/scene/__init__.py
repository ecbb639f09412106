"""Scenes: geometry and materials, built into Mitsuba once; ray-cast visibility of points."""
from rangesim.scene.scene import Scene, SceneObject, load_scene
from rangesim.scene.visibility import visible_points, visible_surface_points

__all__ = ["Scene", "SceneObject", "load_scene", "visible_points", "visible_surface_points"]
