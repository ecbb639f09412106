"""Codes defined once and imported everywhere (status codes, file channel names)."""
from __future__ import annotations

import math
from enum import IntEnum

#: a Gaussian profile's full width at half maximum per standard deviation, 2 sqrt(2 ln 2): the
#: laser sheet's thickness (``laser.stripe_width``) is given as a FWHM
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))


class Status(IntEnum):
    """Per-pixel outcome of a scan, stored in ``RangeScan.status`` (uint8)."""

    VALID = 0
    #: the camera ray hits no surface (within the ray's maximum length)
    MISS = 1
    #: the camera sees the surface but the laser sheet cannot reach it
    SHADOW = 2
    #: the return signal is below the sensor's ``min_signal``
    DROPOUT = 3
    #: the surface lies outside the sensor's working range [near, far], or its measured depth does
    #: (a noisy peak carried past near or far: no measurement)
    OUT_OF_RANGE = 4


#: human-readable names of the status codes, for legends and reports
STATUS_NAMES = {
    Status.VALID: "valid",
    Status.MISS: "no surface",
    Status.SHADOW: "laser shadow",
    Status.DROPOUT: "dropout",
    Status.OUT_OF_RANGE: "out of range",
}


def status_name(code: int, mode: str | None = None) -> str:
    """The name of a status code for a scan of sensor ``mode``: a structured-light scanner's
    shadow is the projector's, not a laser's.

    Examples
    --------
    >>> status_name(Status.SHADOW), status_name(Status.SHADOW, "structured_light")
    ('laser shadow', 'projector shadow')
    """
    if mode == "structured_light" and int(code) == Status.SHADOW:
        return "projector shadow"
    return STATUS_NAMES[Status(int(code))]


class EdgeLabel(IntEnum):
    """Edge types in edge maps and ground truth (``EdgeMap.labels``, uint8)."""

    NONE = 0
    #: depth discontinuity / occluding boundary
    JUMP = 1
    #: crease where the material angle is below 180 degrees (a roof)
    CONVEX = 2
    #: crease where the material angle is above 180 degrees (a valley)
    CONCAVE = 3


EDGE_LABEL_NAMES = {
    EdgeLabel.NONE: "none",
    EdgeLabel.JUMP: "jump",
    EdgeLabel.CONVEX: "convex",
    EdgeLabel.CONCAVE: "concave",
}

#: largest matching distance :func:`rangesim.evaluate.edge_scores` takes, pixels: the candidate
#: pairs grow with its square (about 3 t^2 per predicted pixel; 1000 px took 30 s and 2.3 GB on a 120 x 128 map),
#: and a pixel that far from an edge does not locate it (the BSDS benchmark matches within
#: about 0.75 % of the image diagonal, 5 px at 512^2)
MAX_TOLERANCE_PX = 64.0
