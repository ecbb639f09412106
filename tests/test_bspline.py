"""B-spline / NURBS surfaces, Coons patches and their curvatures against closed forms.

Sign convention under test: n = S_u x S_v / |S_u x S_v|, curvature positive where the
surface bends towards n -- so the outward-normal sphere has H = k1 = k2 = -1/r.
"""
from __future__ import annotations

import argparse
import copy
import math

import numpy as np
import pytest
from matplotlib.image import imread
from scipy.interpolate import BSpline

from rangesim.cad.bspline import (
    BSplineSurface,
    basis_derivatives,
    circular_arc,
    find_spans,
    surface_curvatures,
)
from rangesim.cad.coons import coons_patch
from rangesim.cli import curvature_commands
from rangesim.core.errors import RangesimError
from rangesim.viz.curvature_maps import save_curvature_maps

RNG = np.random.default_rng(7)
UV = (RNG.uniform(0, 1, (4, 5)), RNG.uniform(0, 1, (4, 5)))  # interior and generic


def grid(n=9):
    return np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")


def fd_check(surface, u, v, orders, h=1e-5, rtol=1e-6):
    """Each partial against a central difference of the next-lower partial."""
    scale = np.abs(surface.derivative(u, v, 0, 0)).max() + 1.0
    for du, dv in orders:
        lower, step = ((du - 1, dv), (h, 0)) if du else ((du, dv - 1), (0, h))
        fd = (surface.derivative(u + step[0], v + step[1], *lower)
              - surface.derivative(u - step[0], v - step[1], *lower)) / (2 * h)
        np.testing.assert_allclose(surface.derivative(u, v, du, dv), fd, rtol=rtol, atol=rtol * scale,
                                   err_msg=f"partial ({du}, {dv})")


# -- basis functions and polynomial surfaces ----------------------------------------------------
def test_basis_derivatives_match_scipy_unclamped():
    t = np.array([-0.2, -0.1, 0.0, 0.1, 0.3, 0.5, 0.8, 1.0, 1.1, 1.3, 1.4])
    p, n = 3, 7
    x = np.linspace(t[p], t[n], 23)  # the domain [0.1, 1.0], both ends included
    span = find_spans(t, p, x)
    ders = basis_derivatives(t, p, span, x, 4)
    for k in range(5):
        dense = np.zeros((x.size, n))
        np.put_along_axis(dense, (span - p)[:, None] + np.arange(p + 1), ders[k], axis=1)
        ref = BSpline(t, np.eye(n), p).derivative(k)(x) if k <= p else 0.0
        np.testing.assert_allclose(dense, ref, atol=1e-12 * 10**k)


def test_bicubic_reproduces_polynomial_surface_and_its_derivatives():
    # a Bezier patch with x = u, y = v (Greville points) and z = f(u, v) = u^3 - 2 u v^2 + v
    # in Bernstein form: f's control values are its blossom at (0..0,1..1) = polar form
    def blossom_u3(i):  # u^3 at Greville points of a cubic: u1 u2 u3 with i ones
        return 1.0 if i == 3 else 0.0

    def blossom_v2(j):  # v^2 in cubic Bernstein: j(j-1) / 6
        return j * (j - 1) / 6.0

    ctrl = np.empty((4, 4, 3))
    for i in range(4):
        for j in range(4):
            ctrl[i, j] = (i / 3, j / 3, blossom_u3(i) - 2 * (i / 3) * blossom_v2(j) + j / 3)
    knots = [0, 0, 0, 0, 1, 1, 1, 1]
    s = BSplineSurface(ctrl, knots, knots, 3, 3)
    u, v = UV
    f = {
        (0, 0): u**3 - 2 * u * v**2 + v, (1, 0): 3 * u**2 - 2 * v**2, (0, 1): -4 * u * v + 1,
        (2, 0): 6 * u, (1, 1): -4 * v, (0, 2): -4 * u, (3, 0): 6 + 0 * u, (2, 1): 0 * u,
        (1, 2): -4 + 0 * u, (4, 0): 0 * u,
    }
    for (du, dv), z in f.items():
        d = s.derivative(u, v, du, dv)
        np.testing.assert_allclose(d[..., 2], z, atol=1e-12, err_msg=f"({du}, {dv})")
    np.testing.assert_allclose(s.derivative(u, v, 1, 0)[..., :2],
                               np.broadcast_to([1.0, 0.0], u.shape + (2,)), atol=1e-12)


def test_evaluate_broadcasts_and_scalars():
    s = BSplineSurface.sphere_patch(3.0)
    assert s.evaluate(0.5, 0.5).shape == (3,)
    assert s.evaluate(np.zeros(4), 0.5).shape == (4, 3)
    assert s.evaluate(np.zeros((2, 1)), np.zeros(3)).shape == (2, 3, 3)
    assert isinstance(s.curvatures(0.2, 0.3)["K"], float)
    assert s.curvatures(*UV)["H"].shape == UV[0].shape
    with pytest.raises(RangesimError, match="outside the domain"):
        s.evaluate(1.5, 0.5)


def test_scipy_evaluation_matches_the_hand_written_basis():
    """NdBSpline (the default) and the P&T A2.3 basis agree: interior knots, ends, high orders."""
    surfaces = [
        BSplineSurface(RNG.normal(size=(7, 6, 3)) * 10, [0, 0, 0, 0, 0.2, 0.5, 0.5, 1, 1, 1, 1],
                       [0, 0, 0, 0.3, 0.3, 0.3, 1, 1, 1], 3, 2),                     # double / triple knots
        BSplineSurface(RNG.normal(size=(6, 5, 3)), np.sort(RNG.uniform(-1, 2, 10)),
                       np.sort(RNG.uniform(-1, 2, 7)), 3, 1),                         # unclamped
        BSplineSurface.sphere_patch(20.0, (0.0, 2 * math.pi), (-math.pi / 2, math.pi / 2)),  # NURBS
        BSplineSurface.plane(degree_u=5, degree_v=4),
    ]
    for s in surfaces:
        assert s._spline is not None
        hand = copy.copy(s)
        hand._spline = None
        (u0, u1), (v0, v1) = s.domain
        knots_u = s.knots_u[(s.knots_u >= u0) & (s.knots_u <= u1)]
        u = np.r_[RNG.uniform(u0, u1, 200), knots_u, u0, u1]
        v = np.r_[RNG.uniform(v0, v1, 200), np.full(knots_u.size, v1), v1, v0]
        orders = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (3, 1), (2, 3), (6, 0)]
        fast, ref = s._partials_shaped(u, v, orders), hand._partials_shaped(u, v, orders)
        for key in orders:
            scale = np.abs(ref[key]).max() + 1.0
            np.testing.assert_allclose(fast[key], ref[key], rtol=0, atol=1e-12 * scale, err_msg=str(key))
        for a, b in zip(s.curvatures(u, v).values(), hand.curvatures(u, v).values(), strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-12)


# -- exact conics: NURBS sphere and cylinder ---------------------------------------------------
def test_circular_arc_is_exact():
    for start, end in [(0.0, 0.3), (0.2, 2.0), (-1.0, 2 * math.pi - 1.0)]:
        pts, w, knots = circular_arc(start, end)
        curve = BSpline(knots, np.column_stack([pts * w[:, None], w]), 2)(np.linspace(0, 1, 101))
        xy = curve[:, :2] / curve[:, 2:]
        np.testing.assert_allclose(np.hypot(*xy.T), 1.0, atol=1e-14)
        np.testing.assert_allclose(xy[[0, -1]], [[math.cos(start), math.sin(start)],
                                                 [math.cos(end), math.sin(end)]], atol=1e-14)


@pytest.mark.parametrize("lon, lat", [((0.0, math.pi / 2), (-math.pi / 4, math.pi / 4)),
                                      ((0.3, 4.0), (-1.2, 1.4))])
def test_sphere_patch_points_and_curvatures(lon, lat):
    r = 7.5
    s = BSplineSurface.sphere_patch(r, lon, lat)
    u, v = grid(13)
    p = s.evaluate(u, v)
    np.testing.assert_allclose(np.linalg.norm(p, axis=-1), r, rtol=0, atol=1e-12 * r)
    # outward unit normal: the point direction
    np.testing.assert_allclose(s.normal(u, v), p / r, atol=1e-12)
    c = s.curvatures(u, v)
    np.testing.assert_allclose(c["K"], 1 / r**2, rtol=1e-9)
    np.testing.assert_allclose(c["H"], -1 / r, rtol=1e-9)
    np.testing.assert_allclose(c["k1"], -1 / r, rtol=1e-9)
    np.testing.assert_allclose(c["k2"], -1 / r, rtol=1e-9)
    assert np.all(c["k1"] >= c["k2"])


def test_sphere_derivatives_match_finite_differences():
    fd_check(BSplineSurface.sphere_patch(2.0, (0.1, 3.0), (-1.0, 1.2)), *UV,
             [(1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (2, 1), (1, 2)], rtol=2e-6)


def test_cylinder_patch_curvatures():
    r, h = 4.0, 10.0
    s = BSplineSurface.cylinder_patch(r, h, 3 * math.pi / 2)
    u, v = grid(11)
    p = s.evaluate(u, v)
    np.testing.assert_allclose(np.hypot(p[..., 0], p[..., 1]), r, atol=1e-12)
    np.testing.assert_allclose(p[..., 2], v * h, atol=1e-12)
    c = s.curvatures(u, v)
    np.testing.assert_allclose(c["K"], 0.0, atol=1e-12)
    np.testing.assert_allclose(c["H"], -1 / (2 * r), rtol=1e-9)
    np.testing.assert_allclose(c["k1"], 0.0, atol=1e-12)
    np.testing.assert_allclose(c["k2"], -1 / r, rtol=1e-9)


def test_saddle_curvature_closed_form():
    # z = (x^2 - y^2) / (2R) as a biquadratic Bezier: K = -1/R^2, k = +-1/R at the origin
    surface = curvature_commands._saddle()
    c = surface.curvatures(0.5, 0.5)
    R = 50.0
    assert c["K"] == pytest.approx(-1 / R**2, rel=1e-12)
    assert c["H"] == pytest.approx(0.0, abs=1e-15)
    assert (c["k1"], c["k2"]) == pytest.approx((1 / R, -1 / R), rel=1e-12)
    # everywhere: the Monge-patch formulas for z = f(x, y)
    u, v = grid(7)
    x, y = (u - 0.5) * 100, (v - 0.5) * 100
    fx, fy, fxx, fyy = x / R, -y / R, 1 / R, -1 / R
    w = 1 + fx**2 + fy**2
    c = surface.curvatures(u, v)
    np.testing.assert_allclose(c["K"], fxx * fyy / w**2, rtol=1e-10)
    H = ((1 + fy**2) * fxx + (1 + fx**2) * fyy) / (2 * w**1.5)
    np.testing.assert_allclose(c["H"], H, rtol=1e-9, atol=1e-16)


@pytest.mark.parametrize("degrees", [(1, 1), (3, 2)])
def test_plane_is_flat(degrees):
    s = BSplineSurface.plane((1, 2, 3), (2, 0, 0), (0.5, 3, 0), *degrees)
    u, v = grid(6)
    np.testing.assert_allclose(s.evaluate(u, v), np.array([1, 2, 3]) + u[..., None] * [2, 0, 0]
                               + v[..., None] * [0.5, 3, 0], atol=1e-13)
    for key, val in s.curvatures(u, v).items():
        np.testing.assert_allclose(val, 0.0, atol=1e-14, err_msg=key)
    np.testing.assert_allclose(s.normal(u, v), np.broadcast_to([0, 0, 1.0], u.shape + (3,)), atol=1e-14)


def test_surface_curvatures_orders_principal_curvatures():
    Su, Sv = RNG.normal(size=(50, 3)), RNG.normal(size=(50, 3))
    c = surface_curvatures(Su, Sv, *RNG.normal(size=(3, 50, 3)))
    assert np.all(c["k1"] >= c["k2"])
    np.testing.assert_allclose(c["k1"] * c["k2"], c["K"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose((c["k1"] + c["k2"]) / 2, c["H"], rtol=1e-12)
    # the textbook formulas
    Suu, Suv, Svv = RNG.normal(size=(3, 50, 3))
    c = surface_curvatures(Su, Sv, Suu, Suv, Svv)
    n = np.cross(Su, Sv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    E, F, G = (np.sum(a * b, axis=1) for a, b in ((Su, Su), (Su, Sv), (Sv, Sv)))
    L, M, N = (np.sum(a * n, axis=1) for a in (Suu, Suv, Svv))
    np.testing.assert_allclose(c["K"], (L * N - M**2) / (E * G - F**2), rtol=1e-8)
    np.testing.assert_allclose(c["H"], (E * N - 2 * F * M + G * L) / (2 * (E * G - F**2)), rtol=1e-8)


def test_nurbs_derivatives_match_finite_differences():
    ctrl = RNG.normal(size=(5, 4, 3))
    w = RNG.uniform(0.5, 2.0, size=(5, 4))
    s = BSplineSurface(ctrl, [0, 0, 0, 0.4, 0.7, 1, 1, 1], [0, 0, 0, 0, 1, 1, 1, 1], 2, 3, w)
    fd_check(s, *UV, [(1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (2, 2)], rtol=1e-5)


def test_from_grid_interpolates_and_reproduces_cubics():
    gu, gv = np.linspace(0, 1, 7), np.linspace(0, 1, 9)
    x, y = np.meshgrid(gu * 40, gv * 30, indexing="ij")
    z = 0.001 * x**3 - 0.002 * x * y**2 + 0.1 * y
    s = BSplineSurface.from_grid(np.stack([x, y, z], -1), parameters="uniform")
    np.testing.assert_allclose(s.evaluate(*np.meshgrid(gu, gv, indexing="ij")), np.stack([x, y, z], -1),
                               atol=1e-10)
    u, v = UV
    p = s.evaluate(u, v)  # cubic in x and y: reproduced exactly between the samples too
    np.testing.assert_allclose(p[..., 2], 0.001 * p[..., 0] ** 3 - 0.002 * p[..., 0] * p[..., 1] ** 2
                               + 0.1 * p[..., 1], atol=1e-10)
    # a least-squares fit with fewer control points reproduces it too
    lsq = BSplineSurface.from_grid(np.stack([x, y, z], -1), n_control=(5, 6), parameters="uniform")
    assert lsq.control_points.shape == (5, 6, 3)
    at_samples = lsq.evaluate(*np.meshgrid(gu, gv, indexing="ij"))
    np.testing.assert_allclose(at_samples, np.stack([x, y, z], -1), atol=1e-9)  # cubics: in the space


# -- validation ------------------------------------------------------------------------------------
@pytest.mark.parametrize("knots, message", [
    ([0, 0, 0, 1, 1], "needs n \\+ degree \\+ 1 = 4 \\+ 2 \\+ 1 = 7"),
    ([0, 0, 0, 0.6, 0.5, 1, 1], "non-decreasing"),
    ([0, 0, 0, 0, 1, 1, 1], "repeated 4 times"),
    ([0, 0, 1, 1, 1, 2, 2], "empty domain"),
    ([0, 0, 0, np.nan, 1, 1, 1], "finite"),
])
def test_knot_validation(knots, message):
    ctrl = np.zeros((4, 3, 3))
    with pytest.raises(RangesimError, match=message):
        BSplineSurface(ctrl, knots, [0, 0, 0.5, 1, 1], 2, 1)


def test_other_validation():
    ctrl = np.zeros((3, 2, 3))
    ku, kv = [0, 0, 0, 1, 1, 1], [0, 0, 1, 1]
    with pytest.raises(ValueError, match="shape"):
        BSplineSurface(np.zeros((3, 2)), ku, kv, 2, 1)
    with pytest.raises(ValueError, match="weights"):
        BSplineSurface(ctrl, ku, kv, 2, 1, weights=np.ones((2, 3)))
    with pytest.raises(ValueError, match="> 0"):
        BSplineSurface(ctrl, ku, kv, 2, 1, weights=-np.ones((3, 2)))
    with pytest.raises(ValueError, match="at least 4 control points"):
        BSplineSurface(ctrl, [0, 0, 0, 0, 1, 1, 1], kv, 3, 1)


# -- Coons patches ----------------------------------------------------------------------------------
def test_coons_patch_interpolates_spline_boundaries_exactly():
    def spline(points):
        return BSpline(np.r_[0, 0, 0, 0, 0.5, 1, 1, 1, 1], np.asarray(points, float), 3)

    corners = np.array([[[0, 0, 0], [0, 10, 1]], [[10, 0, 2], [12, 11, -1]]], float)
    wiggle = RNG.normal(size=(4, 3, 3))

    def side(a, b, k):  # a cubic spline from corner a to corner b with random inner points
        return spline(np.vstack([a, a + (b - a) * [[0.25], [0.5], [0.75]] + wiggle[k], b]))

    c0, c1 = side(corners[0, 0], corners[1, 0], 0), side(corners[0, 1], corners[1, 1], 1)
    d0, d1 = side(corners[0, 0], corners[0, 1], 2), side(corners[1, 0], corners[1, 1], 3)
    patch = coons_patch(c0, c1, d0, d1)
    s = np.linspace(0, 1, 17)
    for (u, v), curve in (((s, 0.0), c0), ((s, 1.0), c1), ((0.0, s), d0), ((1.0, s), d1)):
        np.testing.assert_allclose(patch.evaluate(u, v), curve(s), atol=1e-13)
    np.testing.assert_allclose(patch.derivative(s, 0.0, 2, 0), c0.derivative(2)(s), atol=1e-12)
    fd_check(patch, *UV, [(1, 0), (0, 1), (2, 0), (1, 1), (0, 2)], rtol=1e-5)


def test_coons_patch_of_straight_boundaries_is_bilinear():
    P = np.array([[[0, 0, 0], [1, 9, 2]], [[10, 1, 1], [12, 11, 5]]], float)  # a twisted quad

    def line(a, b):
        return lambda t: a + np.multiply.outer(t, b - a)

    patch = coons_patch(line(P[0, 0], P[1, 0]), line(P[0, 1], P[1, 1]),
                        np.vstack([P[0, 0], P[0, 1]]), np.linspace(P[1, 0], P[1, 1], 5))
    u, v = UV
    bilinear = ((1 - u) * (1 - v))[..., None] * P[0, 0] + (u * (1 - v))[..., None] * P[1, 0] \
        + ((1 - u) * v)[..., None] * P[0, 1] + (u * v)[..., None] * P[1, 1]
    np.testing.assert_allclose(patch.evaluate(u, v), bilinear, atol=1e-12)
    twist = P[1, 1] - P[1, 0] - P[0, 1] + P[0, 0]
    np.testing.assert_allclose(patch.derivative(u, v, 1, 1), np.broadcast_to(twist, u.shape + (3,)),
                               atol=1e-12)
    np.testing.assert_allclose(patch.derivative(u, v, 2, 0), 0.0, atol=1e-9)  # spline-fit rounding


def test_planar_coons_patch_from_mixed_curve_kinds_is_flat():
    flat = coons_patch(np.array([[0, 0, 0], [5, 0, 0]]), np.array([[0, 5, 0], [5, 5, 0]]),
                       lambda t: np.array([0, 5 * t, 0]), lambda t: np.array([5, 5 * t, 0]))
    c = flat.curvatures(*grid(5))
    for val in c.values():
        np.testing.assert_allclose(val, 0.0, atol=1e-14)


def test_coons_corner_mismatch_is_reported():
    a = np.array([[0, 0, 0], [1, 0, 0]], float)
    with pytest.raises(RangesimError, match=r"corner S\(1,1\)"):
        coons_patch(a, a + [0, 1, 0], np.array([[0, 0, 0], [0, 1, 0]]),
                    np.array([[1, 0, 0], [1, 1, 0.5]]))
    with pytest.raises(RangesimError, match="point array"):
        coons_patch(np.zeros((4, 2)), a, a, a)


# -- tessellation ------------------------------------------------------------------------------------
@pytest.mark.parametrize("make", [lambda: BSplineSurface.sphere_patch(5.0, (0, 2.0), (-0.5, 1.0)),
                                  curvature_commands._wavy_coons])
def test_tessellation_carries_exact_normals_and_curvatures(make):
    surface = make()
    mesh = surface.tessellate(12, 9)
    assert mesh.vertices.shape == (108, 3) and mesh.faces.shape == (2 * 11 * 8, 3)
    attrs = mesh.vertex_attributes
    u, v = attrs["u"], attrs["v"]
    np.testing.assert_allclose(mesh.vertices, surface.evaluate(u, v), atol=1e-12)
    np.testing.assert_allclose(mesh.vertex_normals, surface.normal(u, v), atol=1e-12)
    c = surface.curvatures(u, v)
    for key in ("K", "H", "k1", "k2"):
        np.testing.assert_allclose(attrs[key], c[key], rtol=1e-12, atol=1e-15)
    # winding: every face normal agrees with the exact normals at its corners
    corner_normals = mesh.vertex_normals[mesh.faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", mesh.face_normals, corner_normals) > 0.9)


def test_tessellation_of_full_sphere_handles_poles():
    sphere = BSplineSurface.sphere_patch(1.0, (0, 2 * math.pi), (-math.pi / 2, math.pi / 2))
    mesh = sphere.tessellate(9, 7)
    assert np.all(np.isfinite(mesh.vertex_normals))
    assert np.isnan(mesh.vertex_attributes["K"][0])  # the south pole is singular
    # every copy of each pole gets the limit normal
    south, north = mesh.vertex_normals[::7], mesh.vertex_normals[6::7]
    np.testing.assert_allclose(south, np.broadcast_to([0, 0, -1.0], (9, 3)), atol=1e-6)
    np.testing.assert_allclose(north, np.broadcast_to([0, 0, 1.0], (9, 3)), atol=1e-6)


# -- picture and command ------------------------------------------------------------------------------
def test_curvature_maps_png(tmp_path):
    out = save_curvature_maps(curvature_commands._wavy_coons(), tmp_path / "maps.png",
                              resolution=40, dpi=50)
    image = imread(out)
    assert out.stat().st_size > 0 and image.shape[:2] == (430, 500)
    assert image[..., :3].std() > 0.05  # not uniform
    h, w = image.shape[:2]
    for rows in (slice(0, h // 2), slice(h // 2, h)):
        for cols in (slice(0, w // 2), slice(w // 2, w)):
            assert image[rows, cols, :3].std() > 0.05  # one drawn panel in each quarter
    assert not list(tmp_path.glob(".*"))  # the atomic write left no temporary file
    with pytest.raises(RangesimError, match=r"\.png"):
        save_curvature_maps(BSplineSurface.plane(), tmp_path / "maps.jpg")


def _run_cli(argv):
    parser = argparse.ArgumentParser()
    curvature_commands.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_curvature_command(tmp_path, capsys):
    out = tmp_path / "maps.png"
    assert _run_cli(["curvature", "--patch", "saddle", "--resolution", "30", "--out", str(out)]) == 0
    assert out.stat().st_size > 0
    assert "saddle" in capsys.readouterr().out
    with pytest.raises(RangesimError, match="cannot write curvature maps as '.pdf' files"):
        _run_cli(["curvature", "--out", str(tmp_path / "maps.pdf")])
    with pytest.raises(RangesimError, match="resolution"):
        _run_cli(["curvature", "--resolution", "1", "--out", str(out)])


def test_curvature_command_through_main(tmp_path, monkeypatch, capsys):
    import rangesim.cli.main as cli

    monkeypatch.setattr(cli, "COMMAND_MODULES", ("rangesim.cli.curvature_commands",))
    assert cli.main(["curvature", "--resolution", "20", "--out", str(tmp_path / "m.png")]) == 0
    assert cli.main(["curvature", "--out", str(tmp_path / "m.txt")]) == 2
    assert "cannot write curvature maps" in capsys.readouterr().err
