"""Tensor-product B-spline and NURBS surfaces with exact derivatives, normals and curvatures.

The founding paper (section 4) computes the four curvature maps of a part -- Gaussian,
mean, maximum and minimum -- from the first and second partial derivatives of its
B-spline patches: the derivative of a B-spline is again a B-spline of one degree lower,
so normals and curvatures come exactly out of the control mesh and knot vectors.

One mechanism serves every parametric surface in the package:

* :class:`ParametricSurface` turns a surface's partial derivatives (one method,
  ``_partials``) into points, derivatives, normals, curvatures and meshes;
* :func:`surface_curvatures` is the single fundamental-form computation (also for
  curvature estimated from range data);
* :func:`tessellate_surface` is the single tessellation.

:class:`BSplineSurface` implements ``_partials`` with basis-function derivatives
(``scipy.interpolate.NdBSpline`` with derivative orders ``nu``; the vectorised
de Boor / Cox recursion of Piegl & Tiller algorithm A2.3, :func:`basis_derivatives`, is
kept as the reference and the fallback) and, for NURBS, the quotient rule in homogeneous
coordinates; :class:`rangesim.cad.coons.CoonsPatch` with the
Coons formula.

Curvature sign convention (used everywhere in the package)
-----------------------------------------------------------
The unit normal is ``n = S_u x S_v / |S_u x S_v|`` and the second fundamental form is
``L = S_uu . n``, ``M = S_uv . n``, ``N = S_vv . n``. A normal curvature is **positive
where the surface bends towards n** (seen from the side n points to, the surface is
concave there). Hence a sphere of radius r whose normal points outwards has
``H = k1 = k2 = -1/r`` and ``K = 1/r**2``; flipping the normal (swapping u and v) flips
the signs of H, k1 and k2 but never of K. Always ``k1 >= k2`` (k1 "maximum", k2
"minimum", as signed numbers). Units: 1/length for H, k1, k2 and 1/length**2 for K,
in the length unit of the control points (mm in rangesim).
"""
from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import trimesh
from scipy.interpolate import make_interp_spline, make_lsq_spline

from rangesim.core import params as P
from rangesim.core.errors import RangesimError

try:  # scipy >= 1.12
    from scipy.interpolate import NdBSpline
except ImportError:  # pragma: no cover - older scipy: the hand-written evaluation only
    NdBSpline = None

Partials = dict[tuple[int, int], np.ndarray]

#: the partial-derivative orders curvature needs: S, S_u, S_v, S_uu, S_uv, S_vv
SECOND_ORDER: tuple[tuple[int, int], ...] = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))

#: ``|Su x Sv|`` below this fraction of ``|Su|^2 + |Sv|^2`` is a singular point (a pole,
#: where one tangent is zero up to rounding: cos(pi/2) = 6e-17), not a real surface direction
_SINGULAR = 1e-12
#: the most vertices :func:`tessellate_surface` makes (n_u x n_v, 1000 x 1000): about 0.6 GB and
#: 2 s (100,000 x 100,000 asked for 75 GiB)
MAX_TESSELLATION_VERTICES = 1_000_000


def unit_normals(Su: np.ndarray, Sv: np.ndarray) -> np.ndarray:
    """Unit normals ``Su x Sv / |Su x Sv|``, shape ``(..., 3)``; NaN at singular points.

    A point is singular where ``|Su x Sv| <= 1e-12 (|Su|^2 + |Sv|^2)``: a tangent vanishes
    (sphere poles) or the two are parallel, so no normal is defined.
    """
    cross = np.cross(Su, Sv)
    W = np.linalg.norm(cross, axis=-1, keepdims=True)
    scale = np.sum(Su * Su, axis=-1, keepdims=True) + np.sum(Sv * Sv, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(W > _SINGULAR * scale, cross / W, np.nan)


# -- curvature from the fundamental forms ----------------------------------------------------
def surface_curvatures(
    Su: np.ndarray, Sv: np.ndarray, Suu: np.ndarray, Suv: np.ndarray, Svv: np.ndarray
) -> dict[str, np.ndarray]:
    """Gaussian, mean and principal curvatures from first and second partial derivatives.

    With ``n = Su x Sv / |Su x Sv|``, first fundamental form ``E = Su.Su``, ``F = Su.Sv``,
    ``G = Sv.Sv`` and second ``L = Suu.n``, ``M = Suv.n``, ``N = Svv.n``::

        K = (L N - M^2) / (E G - F^2)
        H = (E N - 2 F M + G L) / (2 (E G - F^2))
        k1, k2 = H +- sqrt(H^2 - K)

    Evaluated through the shape operator in the orthonormal tangent frame
    ``e1 = Su/|Su|``, ``e2 = n x e1``, where it is the symmetric matrix ``[[a, b], [b, c]]``
    with ``a = L/E``, ``b = (E M - F L) / (E W)``, ``c = (E^2 N - 2 E F M + F^2 L) / (E W^2)``,
    ``W = |Su x Sv|``: then ``k1, k2 = (a + c)/2 +- hypot((a - c)/2, b)`` has no
    cancellation at umbilics (sphere, plane), where ``sqrt(H^2 - K)`` would amplify
    rounding to ~1e-8 relative.

    Sign convention: positive where the surface bends towards ``n`` (a sphere with an
    outward normal has ``H = -1/r``); see the module docstring.

    Parameters
    ----------
    Su, Sv : (..., 3) float
        First partial derivatives (length per parameter unit).
    Suu, Suv, Svv : (..., 3) float
        Second partial derivatives.

    Returns
    -------
    dict of str -> (...) float
        ``"K"`` Gaussian (1/length^2), ``"H"`` mean, ``"k1"`` maximum and ``"k2"``
        minimum principal curvature (1/length); ``k1 >= k2``. NaN where the
        parametrisation is singular (``Su x Sv ~ 0``, e.g. at a sphere's pole; see
        :func:`unit_normals`).
    """
    Su, Sv, Suu, Suv, Svv = (np.asarray(a, dtype=np.float64) for a in (Su, Sv, Suu, Suv, Svv))
    n = unit_normals(Su, Sv)
    W = np.linalg.norm(np.cross(Su, Sv), axis=-1)  # = sqrt(E G - F^2), accurately
    with np.errstate(invalid="ignore", divide="ignore"):
        E, F = (np.einsum("...i,...i->...", Su, b) for b in (Su, Sv))
        L, M, N = (np.einsum("...i,...i->...", a, n) for a in (Suu, Suv, Svv))
        a = L / E
        b = (E * M - F * L) / (E * W)
        c = (E * E * N - 2.0 * E * F * M + F * F * L) / (E * W * W)
        H = 0.5 * (a + c)
        root = np.hypot(0.5 * (a - c), b)
        K = a * c - b * b
    return {"K": K, "H": H, "k1": H + root, "k2": H - root}


# -- the shared surface interface --------------------------------------------------------------
class ParametricSurface:
    """A parametric surface ``S(u, v)`` in 3-D: points, derivatives, normals, curvatures, mesh.

    Subclasses provide :attr:`domain` and ``_partials(u, v, orders)``; everything else is
    built on those two. Parameters broadcast like NumPy: scalar ``u, v`` give a (3,) point,
    arrays of shapes that broadcast to ``shape`` give ``shape + (3,)``.
    """

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Parameter domain ``((u0, u1), (v0, v1))``."""
        raise NotImplementedError

    def _partials(self, u: np.ndarray, v: np.ndarray, orders: Iterable[tuple[int, int]]) -> Partials:
        """Partial derivatives at flat parameter arrays (N,): ``{(k, l): (N, 3)}``."""
        raise NotImplementedError

    # -- parameters -------------------------------------------------------------------------
    def _flat_params(self, u, v) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        """Broadcast u, v, check they lie in the domain; flat (N,) copies and the shape."""
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        shape = u.shape
        flat = []
        for name, x, (lo, hi) in (("u", u, self.domain[0]), ("v", v, self.domain[1])):
            x = x.ravel()
            if not np.all(np.isfinite(x)):
                raise RangesimError(f"surface parameter {name} must be finite")
            # a few ulps outside (linspace end points, rounding) is the boundary, not an error
            slack = 1e-9 * max(hi - lo, abs(lo), abs(hi), 1e-300)
            if x.size and (x.min() < lo - slack or x.max() > hi + slack):
                raise RangesimError(
                    f"surface parameter {name} outside the domain [{lo:g}, {hi:g}]: "
                    f"got values in [{x.min():g}, {x.max():g}]"
                )
            flat.append(np.clip(x, lo, hi))
        return flat[0], flat[1], shape

    def _partials_shaped(self, u, v, orders: Iterable[tuple[int, int]]) -> Partials:
        """Checked orders and parameters in, partials shaped like the broadcast ``u, v`` out."""
        checked = []
        for du, dv in orders:
            if int(du) != du or int(dv) != dv or du < 0 or dv < 0:
                raise RangesimError(f"derivative orders must be integers >= 0, got ({du}, {dv})")
            checked.append((int(du), int(dv)))
        orders = tuple(checked)
        fu, fv, shape = self._flat_params(u, v)
        parts = self._partials(fu, fv, orders)
        return {key: parts[key].reshape(shape + (3,)) for key in orders}

    # -- public interface -------------------------------------------------------------------
    def evaluate(self, u, v) -> np.ndarray:
        """Surface points.

        Parameters
        ----------
        u, v : float or array_like
            Parameters inside :attr:`domain`; broadcast against each other.

        Returns
        -------
        (..., 3) float
            ``S(u, v)`` in the control points' unit (mm).
        """
        return self._partials_shaped(u, v, [(0, 0)])[(0, 0)]

    def derivative(self, u, v, du: int = 1, dv: int = 0) -> np.ndarray:
        """Partial derivative ``d^(du+dv) S / du^du dv^dv``.

        Parameters
        ----------
        u, v : float or array_like
            Parameters inside :attr:`domain`; broadcast against each other.
        du, dv : int
            Orders of differentiation in u and v (>= 0; ``(0, 0)`` is the point itself).

        Returns
        -------
        (..., 3) float
            Length per parameter unit to the power ``du + dv``.
        """
        return self._partials_shaped(u, v, [(du, dv)])[(du, dv)]

    def normal(self, u, v) -> np.ndarray:
        """Unit normals ``S_u x S_v / |S_u x S_v|``, shape ``(..., 3)``.

        NaN at singular points (see :func:`unit_normals`).
        """
        p = self._partials_shaped(u, v, [(1, 0), (0, 1)])
        return unit_normals(p[(1, 0)], p[(0, 1)])

    def curvatures(self, u, v) -> dict[str, np.ndarray | float]:
        """Gaussian ``K``, mean ``H``, maximum ``k1`` and minimum ``k2`` curvature.

        Exact, from the first and second fundamental forms (:func:`surface_curvatures`,
        whose sign convention applies: positive where the surface bends towards
        :meth:`normal`).

        Returns
        -------
        dict of str -> float or (...) float
            Shaped like the broadcast ``u, v`` (a float for scalars). K in 1/mm^2, the
            others in 1/mm for a surface in mm.
        """
        p = self._partials_shaped(u, v, SECOND_ORDER[1:])
        out = surface_curvatures(p[(1, 0)], p[(0, 1)], p[(2, 0)], p[(1, 1)], p[(0, 2)])
        return {key: _scalar_if_0d(val) for key, val in out.items()}

    def tessellate(self, n_u: int = 33, n_v: int = 33) -> trimesh.Trimesh:
        """A triangle mesh of the surface with exact normals and curvatures per vertex.

        See :func:`tessellate_surface`.
        """
        return tessellate_surface(self, n_u, n_v)


def _scalar_if_0d(a: np.ndarray) -> np.ndarray | float:
    return float(a) if np.ndim(a) == 0 else a


def tessellate_surface(surface: ParametricSurface, n_u: int = 33, n_v: int = 33) -> trimesh.Trimesh:
    """Triangulate a parametric surface on a regular (u, v) grid.

    Vertex ``i * n_v + j`` lies at ``(u_i, v_j)`` (``n_u`` and ``n_v`` samples spanning
    the domain, ends included). Each grid cell gives two triangles wound so that their
    face normals agree with ``S_u x S_v``.

    Parameters
    ----------
    surface : ParametricSurface
        Any surface of this module's interface (B-spline, NURBS, Coons patch).
    n_u, n_v : int
        Vertices along u and v (>= 2), at most :data:`MAX_TESSELLATION_VERTICES` in all.

    Returns
    -------
    trimesh.Trimesh
        ``process=False`` (vertices stay in grid order, none merged). ``vertex_normals``
        are the exact unit normals (where the parametrisation is singular, e.g. a pole,
        the limit normal to ~1e-7, taken just inside the domain); ``vertex_attributes`` hold the
        exact ``"K", "H", "k1", "k2"`` (NaN where singular) and the parameters ``"u", "v"``.
    """
    sizes = []
    for name, n in (("n_u", n_u), ("n_v", n_v)):
        try:
            sizes.append(P.whole(n, name, 2))
        except RangesimError:
            raise RangesimError(f"tessellation needs {name} >= 2 vertices (a whole number), got {n!r:.60}") from None
    n_u, n_v = sizes
    if n_u * n_v > MAX_TESSELLATION_VERTICES:
        raise RangesimError(f"tessellation of n_u x n_v = {n_u:,} x {n_v:,} vertices is more than the "
                            f"{MAX_TESSELLATION_VERTICES:,} allowed (1000 x 1000, about 0.6 GB of memory); use fewer")
    (u0, u1), (v0, v1) = surface.domain
    uu, vv = np.meshgrid(np.linspace(u0, u1, n_u), np.linspace(v0, v1, n_v), indexing="ij")
    u, v = uu.ravel(), vv.ravel()
    p = surface._partials_shaped(u, v, SECOND_ORDER)
    curv = surface_curvatures(p[(1, 0)], p[(0, 1)], p[(2, 0)], p[(1, 1)], p[(0, 2)])

    i, j = np.meshgrid(np.arange(n_u - 1), np.arange(n_v - 1), indexing="ij")
    a = (i * n_v + j).ravel()          # (u_i, v_j)
    b = a + n_v                        # (u_i+1, v_j)
    c = b + 1                          # (u_i+1, v_j+1)
    d = a + 1                          # (u_i, v_j+1)
    # (b - a) x (c - a) ~ du dv S_u x S_v: the winding follows the surface normal
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])

    mesh = trimesh.Trimesh(p[(0, 0)], faces, process=False, validate=False)
    normals = unit_normals(p[(1, 0)], p[(0, 1)])
    bad = ~np.all(np.isfinite(normals), axis=1)
    if bad.any():
        # singular points (poles): the limit normal, from a point 1e-7 of the domain inwards
        step = 1e-7
        nudged_u = u[bad] + step * (0.5 * (u0 + u1) - u[bad])
        nudged_v = v[bad] + step * (0.5 * (v0 + v1) - v[bad])
        normals[bad] = surface.normal(nudged_u, nudged_v)
        still = ~np.all(np.isfinite(normals), axis=1)
        normals[still] = mesh.vertex_normals[still]  # truly degenerate: the mesh's own normal
    mesh.vertex_normals = normals
    mesh.vertex_attributes.update({**curv, "u": u, "v": v})
    return mesh


# -- B-spline basis functions -------------------------------------------------------------------
def validate_knots(knots, n_ctrl: int, degree: int, name: str = "knots") -> np.ndarray:
    """Check a knot vector for ``n_ctrl`` control points of ``degree``; return it as float.

    Requirements: 1-D, finite, non-decreasing, ``len == n_ctrl + degree + 1``, no knot
    repeated more than ``degree + 1`` times, and a non-empty domain
    ``knots[degree] < knots[n_ctrl]``. Clamped and unclamped vectors are both accepted.

    Raises
    ------
    RangesimError
        Naming what is wrong (a ``ValueError`` subclass).
    """
    if int(degree) != degree or degree < 1:
        raise RangesimError(f"{name}: degree must be an integer >= 1, got {degree!r}")
    degree = int(degree)
    if n_ctrl < degree + 1:
        raise RangesimError(
            f"{name}: degree {degree} needs at least {degree + 1} control points, got {n_ctrl}"
        )
    t = np.asarray(knots, dtype=np.float64)
    if t.ndim != 1:
        raise RangesimError(f"{name}: knot vector must be 1-D, got shape {t.shape}")
    if t.size != n_ctrl + degree + 1:
        raise RangesimError(
            f"{name}: knot vector needs n + degree + 1 = {n_ctrl} + {degree} + 1 = "
            f"{n_ctrl + degree + 1} values, got {t.size}"
        )
    if not np.all(np.isfinite(t)):
        raise RangesimError(f"{name}: knots must be finite")
    steps = np.diff(t)
    if np.any(steps < 0):
        k = int(np.argmax(steps < 0))
        raise RangesimError(
            f"{name}: knots must be non-decreasing, but knot {k + 1} ({t[k + 1]:g}) "
            f"< knot {k} ({t[k]:g})"
        )
    _, counts = np.unique(t, return_counts=True)
    if counts.max() > degree + 1:
        raise RangesimError(
            f"{name}: a knot is repeated {counts.max()} times; at most degree + 1 = {degree + 1}"
        )
    if not t[degree] < t[n_ctrl]:
        raise RangesimError(
            f"{name}: empty domain: knot[degree] = {t[degree]:g} must be < knot[n] = {t[n_ctrl]:g}"
        )
    return t


def find_spans(knots: np.ndarray, degree: int, x: np.ndarray) -> np.ndarray:
    """Knot span index ``i`` with ``knots[i] <= x < knots[i+1]`` for each x, shape (N,) int.

    Only non-empty spans inside the domain ``[knots[p], knots[n]]`` are returned; the
    domain's right end belongs to the last non-empty span (the basis is right-continuous
    everywhere else).
    """
    n = knots.size - degree - 1
    candidates = np.arange(degree, n)
    spans = candidates[knots[candidates] < knots[candidates + 1]]
    pos = np.searchsorted(knots[spans], x, side="right") - 1
    return spans[np.clip(pos, 0, spans.size - 1)]


def basis_derivatives(
    knots: np.ndarray, degree: int, span: np.ndarray, x: np.ndarray, nder: int
) -> np.ndarray:
    """Non-zero B-spline basis functions and their derivatives, vectorised over points.

    Piegl & Tiller's algorithm A2.3 with every scalar replaced by an (N,) array: loops
    run over the degree and the derivative order only, never over points. Derivatives
    follow from the recursion ``N'_{i,p} = p/(t_{i+p}-t_i) N_{i,p-1} -
    p/(t_{i+p+1}-t_{i+1}) N_{i+1,p-1}`` -- the derivative of a B-spline is a B-spline of
    one degree lower (the paper's section 4).

    Parameters
    ----------
    knots : (n + p + 1,) float
        Validated knot vector.
    degree : int
        Degree p.
    span : (N,) int
        Knot spans from :func:`find_spans`.
    x : (N,) float
        Parameters.
    nder : int
        Highest derivative order wanted (orders above p are zero).

    Returns
    -------
    (nder + 1, N, p + 1) float
        ``out[k, m, r]`` is the k-th derivative of basis function ``span[m] - p + r`` at
        ``x[m]``.
    """
    p, npts = degree, x.size
    left = np.empty((p + 1, npts))
    right = np.empty((p + 1, npts))
    # ndu: upper triangle basis functions of rising degree, lower triangle knot differences
    ndu = np.empty((p + 1, p + 1, npts))
    ndu[0, 0] = 1.0
    for j in range(1, p + 1):
        left[j] = x - knots[span + 1 - j]
        right[j] = knots[span + j] - x
        saved = np.zeros(npts)
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved

    ders = np.zeros((nder + 1, npts, p + 1))
    ders[0] = ndu[:, p].T
    top = min(nder, p)
    for r in range(p + 1):
        a = np.zeros((2, top + 1, npts))
        a[0, 0] = 1.0
        s1, s2 = 0, 1
        for k in range(1, top + 1):
            d = np.zeros(npts)
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d += a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d += a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d += a[s2, k] * ndu[r, pk]
            ders[k, :, r] = d
            s1, s2 = s2, s1
    for k in range(1, top + 1):
        ders[k] *= math.perm(p, k)  # p! / (p - k)!
    return ders


# -- exact conic building blocks ---------------------------------------------------------------
def circular_arc(start: float, end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact rational quadratic NURBS of the unit-circle arc from ``start`` to ``end`` (radians).

    The arc is split into equal segments of at most 90 degrees; each is a rational Bezier
    with middle weight ``cos(half segment angle)`` (Piegl & Tiller A7.1), so every point
    lies on the circle to rounding.

    Returns
    -------
    points : (n, 2) float
        Control points (cos, sin) of the unit circle.
    weights : (n,) float
    knots : (n + 3,) float
        Clamped, on [0, 1]; parameter is not proportional to angle except at knots.
    """
    sweep = end - start
    if not (np.isfinite(sweep) and 0.0 < abs(sweep) <= 2.0 * math.pi + 1e-12):
        raise RangesimError(f"arc angle must be in (0, 2 pi] radians, got {sweep!r}")
    segments = max(1, math.ceil(abs(sweep) / (math.pi / 2.0) - 1e-9))
    half = sweep / segments / 2.0
    ends = start + 2.0 * half * np.arange(segments + 1)
    mids = ends[:-1] + half
    points = np.empty((2 * segments + 1, 2))
    weights = np.empty(2 * segments + 1)
    points[0::2] = np.stack([np.cos(ends), np.sin(ends)], 1)
    # the middle control point is the tangent lines' intersection at distance 1/cos(half)
    points[1::2] = np.stack([np.cos(mids), np.sin(mids)], 1) / math.cos(half)
    weights[0::2] = 1.0
    weights[1::2] = math.cos(half)
    inner = np.repeat(np.arange(1, segments) / segments, 2)
    knots = np.concatenate([[0.0] * 3, inner, [1.0] * 3])
    return points, weights, knots


def _rational_partials(hom: Partials, orders: list[tuple[int, int]]) -> Partials:
    """Quotient rule: partials of ``S = A / w`` from those of the homogeneous ``(A, w)``.

    ``S^(k,l) = (A^(k,l) - sum_{(i,j) != (0,0), i<=k, j<=l} C(k,i) C(l,j) w^(i,j) S^(k-i,l-j)) / w``
    (Piegl & Tiller eq. 4.20); ``orders`` sorted so lower partials come first.
    """
    w = hom[(0, 0)][:, 3]
    out: Partials = {}
    for k, l in orders:
        acc = hom[(k, l)][:, :3].copy()
        for i in range(k + 1):
            for j in range(l + 1):
                if i or j:
                    acc -= math.comb(k, i) * math.comb(l, j) * hom[(i, j)][:, 3:4] * out[(k - i, l - j)]
        out[(k, l)] = acc / w[:, None]
    return out


# -- constructor helpers ------------------------------------------------------------------------
def _bezier_knots(degree: int) -> np.ndarray:
    return np.concatenate([np.zeros(degree + 1), np.ones(degree + 1)])


def _as_vector(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise RangesimError(f"{name} must be a finite 3-vector, got {x!r}")
    return a


def _positive(x: float, name: str) -> float:
    x = float(x)
    if not (np.isfinite(x) and x > 0):
        raise RangesimError(f"{name} must be > 0, got {x!r}")
    return x


def _grid_parameters(points: np.ndarray, axis: int, method: str) -> np.ndarray:
    """Parameters in [0, 1] of the grid lines along ``axis``: uniform or averaged chord length."""
    m = points.shape[axis]
    if method == "uniform":
        return np.linspace(0.0, 1.0, m)
    if method != "chord":
        raise RangesimError(f"parameters must be 'chord' or 'uniform', got {method!r}")
    chords = np.linalg.norm(np.diff(points, axis=axis), axis=-1)         # along axis, per line
    lengths = chords.sum(axis=axis, keepdims=True)
    if np.any(lengths == 0):
        raise RangesimError("from_grid: a grid line has all its points equal; use parameters='uniform'")
    cum = np.concatenate([np.zeros_like(lengths), np.cumsum(chords / lengths, axis=axis)], axis=axis)
    # averaged over the lines (Piegl & Tiller 9.2.5): one parameter set for the whole grid
    params = cum.mean(axis=1 - axis)
    params[0], params[-1] = 0.0, 1.0
    if np.any(np.diff(params) <= 0):
        raise RangesimError(
            "from_grid: repeated grid points give equal parameters; use parameters='uniform'"
        )
    return params


def _lsq_knots(params: np.ndarray, n_ctrl: int, degree: int) -> np.ndarray:
    """Clamped knots for a least-squares fit, interior knots averaged from the data (P&T 9.69)."""
    m = params.size
    d = m / (n_ctrl - degree)
    j = np.arange(1, n_ctrl - degree)
    i = np.floor(j * d).astype(int)
    alpha = j * d - i
    inner = (1 - alpha) * params[i - 1] + alpha * params[i]
    return np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])


# -- B-spline surfaces --------------------------------------------------------------------------
class BSplineSurface(ParametricSurface):
    """A tensor-product B-spline surface, optionally rational (NURBS).

    ``S(u, v) = sum_ij N_i,p(u) N_j,q(v) w_ij P_ij / sum_ij N_i,p(u) N_j,q(v) w_ij``

    Parameters
    ----------
    control_points : (n_u, n_v, 3) float
        Control mesh ``P_ij`` (mm).
    knots_u : (n_u + degree_u + 1,) float
        Non-decreasing knot vector in u, clamped or not (see :func:`validate_knots`).
    knots_v : (n_v + degree_v + 1,) float
        Knot vector in v.
    degree_u, degree_v : int
        Polynomial degrees p, q >= 1 (order = degree + 1).
    weights : (n_u, n_v) float, optional
        Positive NURBS weights; None for a polynomial (non-rational) B-spline.

    Notes
    -----
    The domain is ``[knots_u[p], knots_u[n_u]] x [knots_v[q], knots_v[n_v]]``. All
    evaluation is vectorised over points: per point, the ``(p+1) x (q+1)`` window of
    homogeneous control points is gathered and contracted with the basis-function
    derivatives. Rational derivatives use the quotient rule on the homogeneous surface
    ``A = sum N N w P`` and ``w = sum N N w`` (Piegl & Tiller eq. 4.20). Curvature signs:
    see the module docstring (sphere with outward normal: ``H = -1/r``).

    Examples
    --------
    >>> from rangesim.cad import BSplineSurface
    >>> sphere = BSplineSurface.sphere_patch(50.0)             # exact (rational) sphere patch, r = 50 mm
    >>> c = sphere.curvatures(0.3, 0.6)
    >>> round(c["K"] * 2500, 9), round(c["H"] * 50, 9)        # K = 1/r^2, H = -1/r (outward normal)
    (1.0, -1.0)

    References
    ----------
    .. [1] "CAD Based 3-D Models for Computer Vision", the founding paper of this package
       (``../shared/reference/cad-based-3d-models-for-computer-vision.txt``), section 4
       (B-spline curvatures, Fig. 11).
    .. [2] L. Piegl, W. Tiller, "The NURBS Book", 2nd ed., Springer (1997),
       doi:10.1007/978-3-642-59223-2.
    """

    def __init__(self, control_points, knots_u, knots_v, degree_u: int, degree_v: int, weights=None):
        ctrl = np.array(control_points, dtype=np.float64)
        if ctrl.ndim != 3 or ctrl.shape[2] != 3:
            raise RangesimError(f"control_points must have shape (n_u, n_v, 3), got {ctrl.shape}")
        if not np.all(np.isfinite(ctrl)):
            raise RangesimError("control_points must be finite")
        n_u, n_v, _ = ctrl.shape
        self.knots_u = validate_knots(knots_u, n_u, degree_u, "knots_u")
        self.knots_v = validate_knots(knots_v, n_v, degree_v, "knots_v")
        self.degree_u, self.degree_v = int(degree_u), int(degree_v)
        if weights is None:
            w = None
        else:
            w = np.array(weights, dtype=np.float64)
            if w.shape != (n_u, n_v):
                raise RangesimError(
                    f"weights must have shape {(n_u, n_v)} like the control mesh, got {w.shape}"
                )
            if not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise RangesimError("NURBS weights must be finite and > 0")
        self.control_points = ctrl
        self.weights = w
        for a in (self.control_points, self.knots_u, self.knots_v) + ((w,) if w is not None else ()):
            a.setflags(write=False)  # the surface is a value: callers cannot change it under us
        # homogeneous control net (w P, w): the rational case is a polynomial one in 4-D
        self._net = ctrl if w is None else np.concatenate([ctrl * w[..., None], w[..., None]], axis=2)
        self._spline = None if NdBSpline is None else NdBSpline(
            (self.knots_u, self.knots_v), self._net, (self.degree_u, self.degree_v))

    # -- properties ---------------------------------------------------------------------------
    @property
    def rational(self) -> bool:
        """True for a NURBS surface (weights given)."""
        return self.weights is not None

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Parameter domain ``((u0, u1), (v0, v1))`` = ``((t_u[p], t_u[n_u]), (t_v[q], t_v[n_v]))``."""
        n_u, n_v = self.control_points.shape[:2]
        return (
            (float(self.knots_u[self.degree_u]), float(self.knots_u[n_u])),
            (float(self.knots_v[self.degree_v]), float(self.knots_v[n_v])),
        )

    def __repr__(self) -> str:
        n_u, n_v = self.control_points.shape[:2]
        kind = "NURBS" if self.rational else "B-spline"
        degrees = f"degrees ({self.degree_u}, {self.degree_v})"
        return f"BSplineSurface({kind}, {n_u} x {n_v} control points, {degrees})"

    # -- evaluation ---------------------------------------------------------------------------
    def _homogeneous_partials(
        self, u: np.ndarray, v: np.ndarray, orders: set[tuple[int, int]]
    ) -> Partials:
        """Partials of the (homogeneous, if rational) surface at flat u, v: ``{(k, l): (N, D)}``.

        Through ``scipy.interpolate.NdBSpline`` (one call per order, ``nu=(k, l)``): the
        same values as :meth:`_homogeneous_partials_by_hand` to ~1e-15 relative (~1e-13
        for high orders of a degree-5 patch), and faster in every case measured, although
        each order recomputes the basis (``benchmarks/bench_bspline.py``, 2 CPU cores,
        1e5 points, hand -> scipy: bicubic 12 x 10 points 60 -> 17 ms, S_u and S_v
        143 -> 38 ms, curvatures 141 -> 104 ms; NURBS sphere points 37 -> 12 ms,
        curvatures 141 -> 103 ms; 100 points 2-4x faster too). Without NdBSpline
        (scipy < 1.12) the hand-written evaluation.
        """
        if self._spline is None:
            return self._homogeneous_partials_by_hand(u, v, orders)
        xi = np.stack([u, v], axis=-1)
        # u, v are clipped to the domain, so extrapolation never happens; scipy returns
        # zeros for orders above the degree and puts the domain's right end in the last
        # non-empty span, as find_spans does
        return {(k, l): self._spline(xi, nu=(k, l)) for k, l in orders}

    def _homogeneous_partials_by_hand(
        self, u: np.ndarray, v: np.ndarray, orders: set[tuple[int, int]]
    ) -> Partials:
        """:meth:`_homogeneous_partials` from :func:`basis_derivatives` (P&T A2.3), the reference.

        Computes the basis derivatives once for every order; kept as the fallback for
        scipy < 1.12 and as the reference the tests and the benchmark compare with.
        """
        p, q = self.degree_u, self.degree_v
        su = find_spans(self.knots_u, p, u)
        sv = find_spans(self.knots_v, q, v)
        bu = basis_derivatives(self.knots_u, p, su, u, max(k for k, _ in orders))
        bv = basis_derivatives(self.knots_v, q, sv, v, max(l for _, l in orders))
        # the (p+1) x (q+1) window of control points each point depends on: (N, p+1, q+1, D)
        iu = (su - p)[:, None] + np.arange(p + 1)
        iv = (sv - q)[:, None] + np.arange(q + 1)
        window = self._net[iu[:, :, None], iv[:, None, :]]
        return {
            (k, l): np.einsum("ni,nj,nijd->nd", bu[k], bv[l], window, optimize=True) for k, l in orders
        }

    def _partials(self, u: np.ndarray, v: np.ndarray, orders: Iterable[tuple[int, int]]) -> Partials:
        orders = set(orders)
        if not self.rational:
            return self._homogeneous_partials(u, v, orders)
        # the quotient rule needs every lower partial: all (i, j) <= (k, l)
        needed = {(i, j) for k, l in orders for i in range(k + 1) for j in range(l + 1)}
        hom = self._homogeneous_partials(u, v, needed)
        return _rational_partials(hom, sorted(needed))

    # -- constructors ---------------------------------------------------------------------------
    @classmethod
    def plane(cls, origin=(0.0, 0.0, 0.0), u_vector=(1.0, 0.0, 0.0), v_vector=(0.0, 1.0, 0.0),
              degree_u: int = 1, degree_v: int = 1) -> BSplineSurface:
        """The parallelogram ``S(u, v) = origin + u u_vector + v v_vector``, u, v in [0, 1].

        A Bezier patch of the given degrees (control points on the Greville abscissae
        ``i / p``, so the parametrisation stays linear): higher degrees exercise the
        general code with an exactly flat surface (``K = H = 0``). Normal:
        ``u_vector x v_vector`` direction (+z by default).
        """
        o = _as_vector(origin, "origin")
        a, b = _as_vector(u_vector, "u_vector"), _as_vector(v_vector, "v_vector")
        if np.linalg.norm(np.cross(a, b)) == 0:
            raise RangesimError("plane: u_vector and v_vector must not be parallel")
        gu = np.linspace(0.0, 1.0, int(degree_u) + 1)
        gv = np.linspace(0.0, 1.0, int(degree_v) + 1)
        ctrl = o + gu[:, None, None] * a + gv[None, :, None] * b
        return cls(ctrl, _bezier_knots(degree_u), _bezier_knots(degree_v), degree_u, degree_v)

    @classmethod
    def cylinder_patch(cls, radius: float, height: float, angle: float = math.pi / 2) -> BSplineSurface:
        """Exact NURBS patch of a cylinder: a rational quadratic arc extruded along +z.

        ``S(u, v)`` runs over the arc ``(r cos a, r sin a, 0)``, ``a`` from 0 to ``angle``
        (radians, up to 2 pi) with u in [0, 1] (not proportional to angle), and along
        ``z = v * height``, v in [0, 1] (degree 1). The normal ``S_u x S_v`` points
        outwards, so ``k1 = 0``, ``k2 = -1/r``, ``H = -1/(2r)``, ``K = 0``.
        """
        radius, height = _positive(radius, "radius"), _positive(height, "height")
        arc, w, knots = circular_arc(0.0, float(angle))
        ctrl = np.zeros((len(arc), 2, 3))
        ctrl[:, :, :2] = radius * arc[:, None, :]
        ctrl[:, 1, 2] = height
        weights = np.repeat(w[:, None], 2, axis=1)
        return cls(ctrl, knots, _bezier_knots(1), 2, 1, weights)

    @classmethod
    def sphere_patch(cls, radius: float, longitude: tuple[float, float] = (0.0, math.pi / 2),
                     latitude: tuple[float, float] = (-math.pi / 4, math.pi / 4)) -> BSplineSurface:
        """Exact NURBS patch of a sphere centred at the origin: a revolved rational quadratic arc.

        u runs east along ``longitude`` (radians, about +z), v north along ``latitude``
        (radians, within [-pi/2, pi/2]); both parameters on [0, 1]. East x north points
        outwards, so ``H = k1 = k2 = -1/r`` and ``K = 1/r^2``. The whole sphere is
        ``longitude=(0, 2 pi), latitude=(-pi/2, pi/2)``; its poles are singular points of
        the parametrisation (normals and curvatures NaN there).
        """
        radius = _positive(radius, "radius")
        lat0, lat1 = (float(a) for a in latitude)
        if not (-math.pi / 2 - 1e-12 <= lat0 < lat1 <= math.pi / 2 + 1e-12):
            raise RangesimError(f"latitude must satisfy -pi/2 <= start < end <= pi/2, got {latitude!r}")
        lon0, lon1 = (float(a) for a in longitude)
        if not lon0 < lon1:
            raise RangesimError(f"longitude must satisfy start < end, got {longitude!r}")
        around, w_around, k_around = circular_arc(lon0, lon1)     # (cos, sin) of longitude
        meridian, w_mer, k_mer = circular_arc(lat0, lat1)          # (cos, sin) of latitude
        # a tensor product of two rational curves is their product:
        # x = cos(lat) cos(lon), y = cos(lat) sin(lon), z = sin(lat)
        ctrl = np.empty((len(around), len(meridian), 3))
        ctrl[..., 0] = around[:, None, 0] * meridian[None, :, 0]
        ctrl[..., 1] = around[:, None, 1] * meridian[None, :, 0]
        ctrl[..., 2] = meridian[None, :, 1]
        return cls(radius * ctrl, k_around, k_mer, 2, 2, w_around[:, None] * w_mer[None, :])

    @classmethod
    def from_grid(cls, points, degree_u: int = 3, degree_v: int = 3, *, parameters: str = "chord",
                  n_control: tuple[int, int] | None = None) -> BSplineSurface:
        """A B-spline surface through (or fitted to) a grid of points.

        Interpolation is separable for tensor products: a spline through each grid column
        along u, then splines through the resulting coefficients along v
        (``scipy.interpolate.make_interp_spline``, not-a-knot ends). With ``n_control`` the
        same two passes are least-squares fits (``make_lsq_spline``) with fewer control
        points, for smoothing dense or noisy grids.

        Parameters
        ----------
        points : (m_u, m_v, 3) float
            Grid of points (mm); ``points[i, j]`` is the sample at ``(u_i, v_j)``.
        degree_u, degree_v : int
            Degrees (>= 1, and < the grid size in that direction).
        parameters : {"chord", "uniform"}
            Parameter values of the grid lines on [0, 1]: averaged chord length (default,
            follows the point spacing) or uniform.
        n_control : (int, int), optional
            Control points per direction for a least-squares fit; default interpolation.

        Returns
        -------
        BSplineSurface
            Non-rational, clamped, domain [0, 1] x [0, 1].
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 3 or pts.shape[2] != 3:
            raise RangesimError(f"from_grid: points must have shape (m_u, m_v, 3), got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise RangesimError("from_grid: points must be finite")
        degrees = (int(degree_u), int(degree_v))
        for axis, (m, k) in enumerate(zip(pts.shape[:2], degrees, strict=True)):
            if k < 1 or m < k + 1:
                raise RangesimError(
                    f"from_grid: degree {k} along {'uv'[axis]} must be >= 1 and needs at least "
                    f"{k + 1} points, got {m}"
                )
        params = [_grid_parameters(pts, axis, parameters) for axis in (0, 1)]
        coeffs, knots = pts, []
        for axis in (0, 1):
            k = degrees[axis]
            if n_control is None:
                spline = make_interp_spline(params[axis], coeffs, k=k, axis=axis)
            else:
                n = int(n_control[axis])
                if not k + 1 <= n <= pts.shape[axis]:
                    raise RangesimError(
                        f"from_grid: n_control along {'uv'[axis]} must be in "
                        f"[{k + 1}, {pts.shape[axis]}], got {n}"
                    )
                knots_lsq = _lsq_knots(params[axis], n, k)
                spline = make_lsq_spline(params[axis], coeffs, knots_lsq, k=k, axis=axis)
            coeffs = np.moveaxis(spline.c, 0, axis)  # scipy puts the spline axis first
            knots.append(spline.t)
        return cls(coeffs, knots[0], knots[1], *degrees)
