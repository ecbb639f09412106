"""Pictures of range scans: previews and the shared colours other figures draw with."""
from rangesim.viz.preview import (
    STATUS_COLORS,
    UNKNOWN_STATUS_COLOR,
    depth_limits,
    depth_rgb,
    estimate_normals,
    hillshade,
    save_preview,
    status_color,
    status_colors,
)

__all__ = [
    "STATUS_COLORS",
    "UNKNOWN_STATUS_COLOR",
    "depth_limits",
    "depth_rgb",
    "estimate_normals",
    "hillshade",
    "save_preview",
    "status_color",
    "status_colors",
]
