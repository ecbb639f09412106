"""Scenes: geometry and materials, built into Mitsuba once."""
from rangesim.scene.scene import Scene, SceneObject, load_scene

__all__ = ["Scene", "SceneObject", "load_scene"]
