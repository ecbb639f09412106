"""Sensors: optics and noise (config), and the scanner implementations behind ``scan()``."""
from rangesim.sensor._scan import default_pose, scan
from rangesim.sensor.config import Sensor, load_sensor, preset_names
from rangesim.sensor.intensity import intensity_image

__all__ = ["Sensor", "load_sensor", "preset_names", "scan", "default_pose", "intensity_image"]
