"""Circular arcs: circle hypotheses of the directional Hough transform with partial support."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rangesim.core import params as P
from rangesim.features._circles import _dedupe, _support, circle_hypotheses
from rangesim.features._edge_points import check_range, edge_points


@dataclass(frozen=True)
class Arc:
    """A circular arc.

    Attributes
    ----------
    center : (x, y) float, pixels
    radius : float, pixels
    start, end : float
        Angles of the longest supported run, radians from +x towards +y (image), end > start.
    coverage : float
        Fraction of the whole circumference supported (within 1 px), 0..1.
    votes : int
    residual : float
        RMS distance of the supporting edge pixels, pixels.
    """

    center: tuple[float, float]
    radius: float
    start: float
    end: float
    coverage: float
    votes: int
    residual: float

    @property
    def span(self) -> float:
        """Angle of the longest supported run, radians."""
        return self.end - self.start


#: an arc's run of points must lie this many times farther from their best straight line (RMS,
#: total least squares) than from the arc: a small circle threads a straight edge 2-3 px thick
#: (a jump and its crease side by side) over 60-90 degrees as closely as the line does
LINE_RATIO = 1.5


def _bows(points: np.ndarray, c: np.ndarray, r: float, start: float, end: float) -> bool:
    """Whether the points of the run ``start``..``end`` (radians about ``c``) are an arc rather
    than a straight edge: their RMS distance from their total-least-squares line is at least
    :data:`LINE_RATIO` times their RMS distance from the circle (``c``, ``r``)."""
    d = points - c
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]) - start, 2 * np.pi)
    run = points[ang <= (end - start) + 1e-9]
    if len(run) < 3:
        return False
    arc_rms = float(np.sqrt(np.mean((np.hypot(*(run - c).T) - r) ** 2)))
    centred = run - run.mean(axis=0)
    line_rms = float(np.sqrt(max(np.linalg.eigvalsh(centred.T @ centred / len(run))[0], 0.0)))
    return line_rms >= LINE_RATIO * max(arc_rms, 0.1)


def arcs(
    edge_map: Any,
    radii: tuple[float, float] = (5, 80),
    *,
    min_span_deg: float = 60.0,
    max_coverage: float = 0.5,
    threshold: float = 0.12,
    angle_tol_deg: float = 4.0,
    max_residual: float = 0.8,
    keep: np.ndarray | None = None,
) -> list[Arc]:
    """Arcs: circle hypotheses whose support is partial.

    Same accumulator as :func:`~rangesim.features.circles` with a lower threshold (a
    fraction of 2 pi r, so proportional to r); kept when the longest contiguous supported run
    spans at least ``min_span_deg`` while the total coverage stays below ``max_coverage``
    (above it the hypothesis is a circle), and when the run's points bow: they lie
    :data:`LINE_RATIO` times farther from their best straight line than from the arc (a small
    circle threads a thick straight edge as closely as the line does). As for circles, the
    centre must lie inside the image: the arc of a large rim whose centre the frame cuts off
    is not found.

    Returns
    -------
    list of Arc, longest span first, near-duplicates removed.

    Examples
    --------
    >>> import numpy as np
    >>> import rangesim as rs
    >>> y, x = np.mgrid[0:120, 0:120]          # a thin 120 degree arc, radius 30 px, centre (60.3, 59.6)
    >>> ring = np.abs(np.hypot(x - 60.3, y - 59.6) - 30) < 0.5
    >>> arc = ring & (np.degrees(np.arctan2(y - 59.6, x - 60.3)) % 360 <= 120)
    >>> (found,) = rs.features.arcs(arc, radii=(10, 50))
    >>> round(found.radius), round(float(np.degrees(found.span))), found.coverage < 0.5
    (30, 119, True)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 5.
    .. [2] R. O. Duda, P. E. Hart, "Use of the Hough transformation to detect lines and curves
       in pictures", Communications of the ACM 15(1), 11-15 (1972), doi:10.1145/361237.361242.
    """
    radii = check_range(radii, "radii")
    P.number(min_span_deg, "min_span_deg", 0, 360, what="angle", unit="degrees")
    P.number(max_coverage, "max_coverage", 0, 1, what="share")
    P.number(threshold, "threshold", 0, lo_open=True)
    P.number(angle_tol_deg, "angle_tol_deg", 0, 90, lo_open=True, what="angle", unit="degrees")
    P.number(max_residual, "max_residual", 0, lo_open=True, unit="pixels")
    xy, _ = edge_points(edge_map, keep)
    found = []
    for c, r, votes, _ in circle_hypotheses(edge_map, radii, angle_tol_deg=angle_tol_deg,
                                            threshold=threshold, keep=keep):
        if not radii[0] <= r <= radii[1]:
            continue  # refined out of the radii searched
        on, cov, s, e, rms = _support(xy, c, r)
        if cov < max_coverage and (e - s) >= np.deg2rad(min_span_deg) and rms <= max_residual \
                and _bows(xy[on], c, r, s, e):
            found.append(Arc((float(c[0]), float(c[1])), float(r), s, e, cov, votes, rms))
    # of near-duplicates the one covering more of its circle stays (then the closer fit), so a
    # hypothesis refined 1 px off does not win by a few degrees more of run
    found.sort(key=lambda a: (-a.coverage, a.residual))
    kept = _dedupe(found, lambda k: np.array(k.center), lambda k: k.radius, 2.0)
    return sorted(kept, key=lambda a: -a.span)
