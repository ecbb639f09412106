"""Edge detection on range data (pure NumPy/SciPy over arrays; no Mitsuba, no files)."""
from rangesim.edges.edgemap import EdgeMap

__all__ = ["EdgeMap"]
