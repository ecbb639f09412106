"""Coordinates stored as float32: a warning when the rounding reaches what a scanner measures."""
from __future__ import annotations

import warnings
from typing import Any

import numpy as np

#: float32 steps (mm) beyond which coordinates lose what a scanner measures: a laser scanner's
#: noise is 0.02-0.1 mm, so steps of 0.01 mm (coordinates past ~130 m) are kept without a word
FLOAT32_STEP_WARN_MM = 0.01


def warn_float32_steps(values: Any, name: str, advice: str, stacklevel: int = 3) -> None:
    """Warn when storing ``values`` (mm) as float32 rounds them to steps over
    :data:`FLOAT32_STEP_WARN_MM` (georeferenced coordinates, hundreds of km in mm, land on a
    lattice of tens of mm). Float32 input is left alone: it is already what it is.

    Parameters
    ----------
    values : array-like
        Coordinates, mm (NaN and infinities ignored).
    name : str
        What they are (a file name), at the start of the message.
    advice : str
        What to do instead, at its end.

    Examples
    --------
    >>> warn_float32_steps(np.array([1.0e3, 2.0e3]), "part.ply", "use .npz")   # no warning
    """
    array = np.asarray(values)
    if array.dtype == np.float32 or array.size == 0 or array.dtype.kind not in "iuf":
        return
    finite = array[np.isfinite(array)]
    largest = float(np.abs(finite).max()) if finite.size else 0.0
    step = float(np.spacing(np.float32(largest)))
    if step > FLOAT32_STEP_WARN_MM:
        warnings.warn(f"{name}: coordinates reach {largest:.6g} mm, where float32 steps by {step:g} mm; {advice}",
                      RuntimeWarning, stacklevel=stacklevel)
