"""Writing an intensity image: 8-bit grey PNG (sRGB-like gamma) or the float array as .npy."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from rangesim.core.errors import RangesimError
from rangesim.io.atomic import atomic_path

#: display gamma of the PNG (radiance ** (1 / gamma) -> grey level)
DISPLAY_GAMMA = 2.2


def save_intensity_image(image: np.ndarray, path: str | Path) -> Path:
    """Write an (H, W) intensity image atomically.

    Parameters
    ----------
    image : (H, W) float array
        Relative radiance (1 = white); NaN is written as black.
    path : str or Path
        ``.png``: grey levels 255 * min(1, radiance) ** (1 / 2.2); ``.npy``: the floats as they are.
    """
    import matplotlib.image as mpimg

    path = Path(path)
    image = np.asarray(image, dtype=np.float32)
    if image.ndim != 2:
        raise RangesimError(f"an intensity image must be 2-D, got shape {image.shape}", source=path)
    suffix = path.suffix.lower()
    if suffix not in (".png", ".npy"):
        raise RangesimError("intensity images are written as .png or .npy", source=path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            if suffix == ".npy":
                np.save(handle, image)
            else:
                grey = np.clip(np.nan_to_num(image, nan=0.0), 0.0, 1.0) ** (1.0 / DISPLAY_GAMMA)
                mpimg.imsave(handle, np.round(grey * 255).astype(np.uint8), cmap="gray", vmin=0, vmax=255,
                             format="png")
    return path
