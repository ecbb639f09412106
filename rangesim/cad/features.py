"""Analytic features of a part: exact 3D circles (hole rims) and segments (straight edges),
each a crease with its dihedral angle and convex/concave sign. Ground truth for detectors.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from rangesim.core.geometry import circle_basis


@dataclass(frozen=True)
class Circle3D:
    """A circular edge.

    Attributes
    ----------
    name : str
    center : (3,) float, mm
    normal : (3,) float, unit axis of the circle
    radius : float, mm
    dihedral_deg : float
        Angle between the normals of the two surfaces meeting at the edge, degrees
        (0: smooth, 90: a right-angled edge).
    convex : bool
        True for a convex crease (material angle < 180 degrees), False for concave.
    part : str
        The sub-part the edge belongs to.
    """

    name: str
    center: np.ndarray
    normal: np.ndarray
    radius: float
    dihedral_deg: float = 90.0
    convex: bool = True
    part: str = ""

    def points(self, n: int = 64) -> np.ndarray:
        """(n, 3) points around the circle."""
        e1, e2 = circle_basis(self.normal)
        angle = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
        return np.asarray(self.center) + self.radius * (np.cos(angle) * e1 + np.sin(angle) * e2)


@dataclass(frozen=True)
class Segment3D:
    """A straight edge from ``start`` to ``end`` (mm), with crease angle and sign."""

    name: str
    start: np.ndarray
    end: np.ndarray
    dihedral_deg: float = 90.0
    convex: bool = True
    part: str = ""

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.asarray(self.end) - np.asarray(self.start)))


@dataclass(frozen=True)
class Curve3D:
    """A sharp curved edge (e.g. the rim of a freeform top), as a polyline.

    Attributes
    ----------
    points : (N, 3) float, mm
    dihedral_deg : (N,) float
        Crease angle at each point, degrees.
    convex : bool
    """

    name: str
    points: np.ndarray
    dihedral_deg: np.ndarray
    convex: bool = True
    part: str = ""


@dataclass
class AnalyticFeatures:
    """All analytic features of a part (or of a placed object)."""

    circles: list[Circle3D] = field(default_factory=list)
    segments: list[Segment3D] = field(default_factory=list)
    curves: list[Curve3D] = field(default_factory=list)

    def transformed(self, matrix: np.ndarray) -> "AnalyticFeatures":
        """The features under a 4x4 similarity transform (rotation, uniform scale, translation)."""
        linear = matrix[:3, :3]
        scale = float(np.cbrt(abs(np.linalg.det(linear))))
        rotation = linear / scale

        def point(p):
            return linear @ np.asarray(p, float) + matrix[:3, 3]

        circles = [
            replace(c, center=point(c.center), normal=rotation @ np.asarray(c.normal, float), radius=c.radius * scale)
            for c in self.circles
        ]
        segments = [replace(s, start=point(s.start), end=point(s.end)) for s in self.segments]
        curves = [replace(c, points=np.asarray(c.points, float) @ linear.T + matrix[:3, 3]) for c in self.curves]
        return AnalyticFeatures(circles, segments, curves)

    def to_dict(self) -> dict[str, Any]:
        def clean(obj):
            return {k: (np.asarray(v).tolist() if isinstance(v, (np.ndarray, list, tuple)) else v)
                    for k, v in obj.__dict__.items()}

        return {
            "circles": [clean(c) for c in self.circles],
            "segments": [clean(s) for s in self.segments],
            "curves": [clean(c) for c in self.curves],
        }

    def __len__(self) -> int:
        return len(self.circles) + len(self.segments) + len(self.curves)
