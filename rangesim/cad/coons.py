"""Bilinearly blended Coons patches: a surface spanned by four boundary curves.

The founding paper's curvature maps (Fig. 11) are those of a Coons patch. Given curves
``c0(s) = S(s, 0)``, ``c1(s) = S(s, 1)``, ``d0(t) = S(0, t)``, ``d1(t) = S(1, t)`` with
matching corners, the patch is::

    S(s, t) = (1-t) c0(s) + t c1(s) + (1-s) d0(t) + s d1(t)
              - [(1-s)(1-t) P00 + s(1-t) P10 + (1-s) t P01 + s t P11]

Its partial derivatives are finite formulas in the curves' derivatives, so points,
normals and curvatures are exact in terms of the curves. Curves that are not
differentiable objects (point arrays, plain functions) are first turned into
interpolating cubic B-spline curves; the patch is then exact for those splines.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from scipy.interpolate import BSpline, make_interp_spline

from rangesim.cad.bspline import ParametricSurface, Partials
from rangesim.core import params as P
from rangesim.core.errors import RangesimError

#: corner name -> (c-curve, its parameter, d-curve, its parameter)
_CORNERS = {
    "S(0,0)": ("c0", 0.0, "d0", 0.0),
    "S(1,0)": ("c0", 1.0, "d1", 0.0),
    "S(0,1)": ("c1", 0.0, "d0", 1.0),
    "S(1,1)": ("c1", 1.0, "d1", 1.0),
}


class BoundaryCurve:
    """A curve ``t in [0, 1] -> (N, 3)`` with exact derivatives of any order.

    Parameters
    ----------
    curve : (m, 3) array_like, differentiable callable, or callable
        * points ``(m, 3)`` (m >= 2): the interpolating cubic B-spline (not-a-knot;
          lower degree for m < 4) with point i at ``t = i / (m - 1)``;
        * an object with ``__call__(t)`` and ``derivative(nu)`` returning such an object
          (``scipy.interpolate.BSpline``, ``PPoly``): used as it is, exactly;
        * any other callable ``t -> (3,)`` or ``(N,) -> (N, 3)``: sampled at ``samples``
          uniform parameters and interpolated as for points.
    name : str
        For error messages (``"c0"``...).
    samples : int
        Samples taken from a plain callable.
    """

    def __init__(self, curve: Any, name: str = "curve", samples: int = 101):
        self.name = name
        if callable(curve) and callable(getattr(curve, "derivative", None)):
            self.spline = curve
        elif callable(curve):
            self.spline = _interpolate(_sample(curve, name, samples), name)
        else:
            self.spline = _interpolate(curve, name)
        self._derivatives: dict[int, Any] = {0: self.spline}
        self(np.array([0.0, 1.0]))  # a curve of the wrong shape fails here, not in the middle of a map

    def __call__(self, t: np.ndarray, nu: int = 0) -> np.ndarray:
        """The curve (``nu = 0``) or its ``nu``-th derivative at ``t`` (N,): (N, 3) float."""
        t = np.asarray(t, dtype=np.float64)
        if isinstance(self.spline, BSpline) and nu > self.spline.k:
            return np.zeros(t.shape + (3,))  # scipy refuses derivatives above the degree
        if nu not in self._derivatives:
            self._derivatives[nu] = self.spline.derivative(nu)
        out = np.asarray(self._derivatives[nu](t), dtype=np.float64)
        if out.shape != t.shape + (3,):
            raise RangesimError(
                f"Coons boundary {self.name} must map N parameters to (N, 3) points, "
                f"got shape {out.shape}"
            )
        return out


def _sample(curve: Callable, name: str, samples: int) -> np.ndarray:
    """Sample a plain callable at uniform t; vectorised if it can be, one call per t if not."""
    if int(samples) != samples or samples < 2:
        raise RangesimError(f"Coons boundary {name}: samples must be an integer >= 2, got {samples!r}")
    t = np.linspace(0.0, 1.0, int(samples))
    try:
        pts = np.asarray(curve(t), dtype=np.float64)
    except Exception:  # noqa: BLE001 -- a scalar-only function; its own errors show below
        pts = None
    if pts is None or pts.shape != (t.size, 3):
        pts = np.array([np.asarray(curve(ti), dtype=np.float64) for ti in t])  # construction only
    return pts


def _interpolate(points: Any, name: str) -> BSpline:
    """Interpolating cubic B-spline (lower degree for fewer than 4 points) on uniform t in [0, 1]."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 2:
        raise RangesimError(
            f"Coons boundary {name} must be a callable or an (m, 3) point array with m >= 2, "
            f"got shape {pts.shape}"
        )
    if not np.all(np.isfinite(pts)):
        raise RangesimError(f"Coons boundary {name} has non-finite points")
    t = np.linspace(0.0, 1.0, pts.shape[0])
    return make_interp_spline(t, pts, k=min(3, pts.shape[0] - 1))


def _linear(x: np.ndarray, rising: bool, order: int) -> np.ndarray | None:
    """``order``-th derivative of the blend ``x`` (rising) or ``1 - x``; None where it is zero."""
    if order == 0:
        return x if rising else 1.0 - x
    if order == 1:
        return np.full_like(x, 1.0 if rising else -1.0)
    return None


class CoonsPatch(ParametricSurface):
    """A bilinearly blended Coons patch on the domain ``[0, 1] x [0, 1]`` (u = s, v = t).

    Build with :func:`coons_patch`. Same interface as
    :class:`~rangesim.cad.bspline.BSplineSurface`: ``evaluate``, ``derivative`` (any
    order the curves provide), ``normal``, ``curvatures`` (same sign convention:
    positive where the surface bends towards ``S_s x S_t``) and ``tessellate``.

    Attributes
    ----------
    curves : dict of str -> BoundaryCurve
        ``"c0", "c1", "d0", "d1"``.
    corners : (2, 2, 3) float
        ``corners[a, b] = S(a, b)``, each the mean of the two curves meeting there.
    """

    def __init__(self, curves: dict[str, BoundaryCurve], corners: np.ndarray):
        self.curves = curves
        self.corners = corners

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """``((0, 1), (0, 1))``."""
        return (0.0, 1.0), (0.0, 1.0)

    def __repr__(self) -> str:
        kinds = ", ".join(f"{k}={type(c.spline).__name__}" for k, c in self.curves.items())
        return f"CoonsPatch({kinds})"

    def _partials(self, u: np.ndarray, v: np.ndarray, orders: Iterable[tuple[int, int]]) -> Partials:
        c = self.curves
        out: Partials = {}
        for k, l in orders:
            acc = np.zeros(u.shape + (3,))
            # ruled surfaces between opposite curves, then the bilinear corner correction
            for curve, blend in ((c["c0"], _linear(v, False, l)), (c["c1"], _linear(v, True, l))):
                if blend is not None:
                    acc += blend[:, None] * curve(u, k)
            for curve, blend in ((c["d0"], _linear(u, False, k)), (c["d1"], _linear(u, True, k))):
                if blend is not None:
                    acc += blend[:, None] * curve(v, l)
            for a in (0, 1):
                for b in (0, 1):
                    fu, fv = _linear(u, bool(a), k), _linear(v, bool(b), l)
                    if fu is not None and fv is not None:
                        acc -= (fu * fv)[:, None] * self.corners[a, b]
            out[(k, l)] = acc
        return out


def coons_patch(
    c0: Any, c1: Any, d0: Any, d1: Any, *, samples: int = 101, tol: float = 1e-6
) -> CoonsPatch:
    """The bilinear Coons patch through four boundary curves.

    Parameters
    ----------
    c0, c1 : curve
        ``S(s, 0)`` and ``S(s, 1)``, s in [0, 1]: each an ``(m, 3)`` point array, a
        differentiable callable (``scipy.interpolate.BSpline``...) or a plain callable
        (see :class:`BoundaryCurve`), in mm.
    d0, d1 : curve
        ``S(0, t)`` and ``S(1, t)``, t in [0, 1].
    samples : int
        Samples taken from plain callables before interpolating them.
    tol : float
        Allowed corner mismatch, relative to the size of the corners' bounding box
        (absolute when the corners coincide).

    Returns
    -------
    CoonsPatch
        Interpolates the four (spline) curves exactly; reproduces a bilinear patch
        exactly when the boundaries are straight and uniformly parametrised.

    Raises
    ------
    RangesimError
        If a curve has the wrong shape, or two curves meeting at a corner disagree.

    Examples
    --------
    >>> import numpy as np
    >>> from rangesim.cad import coons_patch
    >>> t = np.linspace(0, 1, 11)[:, None]
    >>> line = lambda a, b: a + t * (np.asarray(b, float) - a)      # straight boundaries: a flat square
    >>> patch = coons_patch(line(np.zeros(3), [100, 0, 0]), line(np.array([0, 100.0, 0]), [100, 100, 0]),
    ...                     line(np.zeros(3), [0, 100, 0]), line(np.array([100.0, 0, 0]), [100, 100, 0]))
    >>> np.round(patch.evaluate(0.5, 0.5), 6).tolist(), round(abs(patch.curvatures(0.3, 0.7)["K"]), 9)
    ([50.0, 50.0, 0.0], 0.0)

    References
    ----------
    .. [1] S. A. Coons, "Surfaces for computer-aided design of space forms", MIT Project MAC,
       MAC-TR-41 (1967).
    """
    tol = P.number(tol, "coons_patch: tol", 0, what="number", unit="relative corner mismatch")
    curves = {
        name: BoundaryCurve(curve, name, samples)
        for name, curve in (("c0", c0), ("c1", c1), ("d0", d0), ("d1", d1))
    }
    ends = {name: curve(np.array([0.0, 1.0])) for name, curve in curves.items()}
    pairs = {
        corner: (ends[cn][int(cp)], ends[dn][int(dp)]) for corner, (cn, cp, dn, dp) in _CORNERS.items()
    }
    all_corners = np.array([p for pair in pairs.values() for p in pair])
    scale = float(np.linalg.norm(np.ptp(all_corners, axis=0))) or 1.0
    for corner, (p, q) in pairs.items():
        gap = float(np.linalg.norm(p - q))
        if not gap <= tol * scale:  # also catches NaN
            cn, cp, dn, dp = _CORNERS[corner]
            raise RangesimError(
                f"Coons boundary curves disagree at corner {corner}: "
                f"{cn}({cp:g}) = {np.round(p, 6).tolist()} "
                f"but {dn}({dp:g}) = {np.round(q, 6).tolist()}, {gap:.3g} apart "
                f"(tolerance {tol * scale:.3g})"
            )
    corners = np.empty((2, 2, 3))
    for corner, (p, q) in pairs.items():
        a, b = int(corner[2]), int(corner[4])
        corners[a, b] = 0.5 * (p + q)  # the mean splits any tolerated mismatch evenly
    return CoonsPatch(curves, corners)
