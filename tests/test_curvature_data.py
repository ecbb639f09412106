"""Curvature on data: the shared quadric fit, meshes, scans, HK sign map, curvature edges.

Sign convention under test: curvature is negative where the surface bends away from its
normal (outward on meshes, towards the camera on scans), so convex caps are HK "peaks".
"""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import box, make_sensor, plane, top_down_pose
from scipy.ndimage import binary_erosion
from scipy.spatial.transform import Rotation

import rangesim as rs
from rangesim.core.geometry import look_at
from rangesim.curvature import (
    SURFACE_TYPE_NAMES,
    SurfaceType,
    curvature_edges,
    curvature_mesh,
    curvature_scan,
    fit_quadric,
    hk_sign_map,
    surface_type_name,
)
from rangesim.curvature.quadric import monge_curvature


# --------------------------------------------------------------------------- helpers
def grid_mesh(f, n: int = 41, half: float = 20.0) -> trimesh.Trimesh:
    """Height field z = f(x, y) on [-half, half]^2 as a mesh with +z (upward) normals."""
    x = np.linspace(-half, half, n)
    X, Y = np.meshgrid(x, x, indexing="xy")
    V = np.stack([X.ravel(), Y.ravel(), f(X, Y).ravel()], axis=-1)
    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    F = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])
    return trimesh.Trimesh(V, F, process=False)


def cylinder_side_mesh(r: float, h: float) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A closed cylinder (axis z) refined so its side has interior vertices, all on the surface.

    Returns the mesh and a mask of side vertices at least 10 mm from the caps.
    """
    mesh = trimesh.creation.cylinder(radius=r, height=h, sections=96).subdivide_to_size(
        max_edge=3.0, max_iter=20)
    v = mesh.vertices.copy()
    rad = np.hypot(v[:, 0], v[:, 1])
    side = (np.abs(v[:, 2]) < h / 2 - 1e-9) & (rad > 1e-9)
    v[side, :2] *= (r / rad[side])[:, None]  # chord midpoints back onto the cylinder
    return trimesh.Trimesh(v, mesh.faces, process=False), side & (np.abs(v[:, 2]) < h / 2 - 10)


def interior(mask: np.ndarray, pixels: int = 3) -> np.ndarray:
    """Pixels of ``mask`` at least ``pixels`` away from its border."""
    return binary_erosion(mask, iterations=pixels)


SPHERE_R = 60.0
CYL_R = 30.0


@pytest.fixture(scope="module")
def sphere_scan():
    """A sphere of radius 60 mm, top 340 mm from a top-down camera, no noise."""
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=SPHERE_R)
    return rs.scan([sphere], make_sensor(), pose=top_down_pose(400.0))


@pytest.fixture(scope="module")
def cylinder_scan():
    """A cylinder (r 30 mm, axis along world y) lying on a plane, seen from 400 mm above."""
    cyl = trimesh.creation.cylinder(radius=CYL_R, height=200.0, sections=256)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    cyl.apply_translation([0, 0, CYL_R])
    return rs.scan([plane(), cyl], make_sensor(), pose=top_down_pose(400.0))


# --------------------------------------------------------------------------- the shared fit
def test_fit_recovers_a_tilted_quadric_exactly():
    rng = np.random.default_rng(1)
    rot = Rotation.from_euler("xyz", [30, -20, 50], degrees=True).as_matrix()
    a, b, c = 0.03, 0.01, -0.02  # h = a x^2 + b xy + c y^2 in the rotated frame, 1/mm
    uv = rng.uniform(-3, 3, size=(2, 40, 2))  # two centres' neighbourhoods
    h = a * uv[..., 0] ** 2 + b * uv[..., 0] * uv[..., 1] + c * uv[..., 1] ** 2
    local = np.concatenate([uv, h[..., None]], axis=-1)
    centres = np.array([[10.0, 0, 300], [-5.0, 2, 250]])
    pts = centres[:, None] + local @ rot.T  # rot columns = frame axes in the world
    normal = rot[:, 2]
    fit = fit_quadric(centres, pts, normals=np.tile(normal, (2, 1)))  # the exact frame
    hess = np.array([[2 * a, b], [b, 2 * c]])
    k2, k1 = np.linalg.eigvalsh(hess)
    np.testing.assert_allclose(fit.k1, k1, rtol=1e-9)
    np.testing.assert_allclose(fit.k2, k2, rtol=1e-9)
    np.testing.assert_allclose(fit.K, k1 * k2, rtol=1e-9)
    np.testing.assert_allclose(fit.H, (k1 + k2) / 2, rtol=1e-9)
    np.testing.assert_allclose(fit.normal, [normal, normal], atol=1e-9)
    vecs = np.linalg.eigh(hess)[1]  # principal directions in the frame, columns (k2, k1)
    dir1 = rot[:, :2] @ vecs[:, 1]
    assert np.allclose(np.abs(fit.dir1 @ dir1), 1, atol=1e-9)
    assert np.allclose(np.einsum("ni,ni->n", fit.dir1, fit.dir2), 0, atol=1e-12)
    np.testing.assert_allclose(np.cross(fit.dir1, fit.dir2), fit.normal, atol=1e-12)
    # a PCA frame is slightly tilted, so the quadric is only approximately one in it
    pca = fit_quadric(centres, pts, orient=normal)
    np.testing.assert_allclose(pca.k1, k1, rtol=2e-3)
    np.testing.assert_allclose(pca.k2, k2, rtol=2e-3)
    # the same surface seen with the opposite normal flips every curvature's sign
    flipped = fit_quadric(centres, pts, normals=np.tile(-normal, (2, 1)))
    np.testing.assert_allclose(flipped.H, -fit.H, rtol=1e-9)
    np.testing.assert_allclose(flipped.K, fit.K, rtol=1e-9)


def test_monge_curvature_with_slopes():
    """k1, k2 and dir1 solve II v = k I v for Monge patches with slope (d, e != 0)."""
    rng = np.random.default_rng(2)
    coeffs = rng.normal(0, [0.05, 0.05, 0.05, 0.8, 0.8, 1.0], size=(50, 6))
    geo = monge_curvature(coeffs)
    a, b, c, d, e = coeffs[:, :5].T
    w = np.sqrt(1 + d * d + e * e)
    first = np.stack([np.stack([1 + d * d, d * e], -1), np.stack([d * e, 1 + e * e], -1)], -2)
    second = np.stack([np.stack([2 * a, b], -1), np.stack([b, 2 * c], -1)], -2) / w[:, None, None]
    shape_op = np.linalg.solve(first, second)
    eig = np.sort(np.linalg.eigvals(shape_op).real, axis=1)
    np.testing.assert_allclose(geo["k1"], eig[:, 1], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(geo["k2"], eig[:, 0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(geo["K"], np.linalg.det(shape_op), rtol=1e-9, atol=1e-15)
    # dir1 = v_x S_x + v_y S_y with S v = k1 v
    v = geo["dir1"][:, :2]  # S_x = (1, 0, d), S_y = (0, 1, e): the tangent coordinates
    np.testing.assert_allclose(np.einsum("nij,nj->ni", shape_op, v), geo["k1"][:, None] * v,
                               atol=1e-10)
    np.testing.assert_allclose(np.einsum("ni,ni->n", geo["dir1"], geo["normal"]), 0, atol=1e-12)
    # the same numbers as the CAD layer's fundamental-form code, where it is present
    bspline = pytest.importorskip("rangesim.cad.bspline")
    if not hasattr(bspline, "surface_curvatures"):
        pytest.skip("rangesim.cad.bspline.surface_curvatures not available")
    zero, one = np.zeros_like(d), np.ones_like(d)
    cad = bspline.surface_curvatures(
        np.stack([one, zero, d], -1), np.stack([zero, one, e], -1),
        np.stack([zero, zero, 2 * a], -1), np.stack([zero, zero, b], -1),
        np.stack([zero, zero, 2 * c], -1))
    for key in ("K", "H", "k1", "k2"):
        np.testing.assert_allclose(geo[key], cad[key], rtol=1e-9, atol=1e-15)


def test_fit_rejects_degenerate_and_sparse_neighbourhoods():
    line = np.stack([np.linspace(-2, 2, 9), np.zeros(9), np.zeros(9) + 100], -1)
    cross = np.concatenate([line, line[:, [1, 0, 2]]])
    grid = np.stack(np.meshgrid(np.arange(-2, 3.0), np.arange(-2, 3.0)), -1).reshape(-1, 2)
    ok_pts = np.concatenate([grid, 100 + 0.01 * (grid ** 2).sum(1, keepdims=True)], -1)
    pts = np.full((3, 25, 3), np.nan)
    pts[0, :18], pts[1, :18], pts[2] = np.r_[line, line], cross, ok_pts
    fit = fit_quadric(np.array([[0, 0, 100.0]] * 3), pts)
    assert fit.ok.tolist() == [False, False, True]
    assert np.isnan(fit.K[:2]).all() and np.isfinite(fit.K[2])
    assert not fit_quadric(ok_pts[12][None], ok_pts[None], min_points=26).ok[0]


# --------------------------------------------------------------------------- meshes
@pytest.mark.parametrize("subdivisions", [4, 5])
def test_mesh_sphere(subdivisions):
    r = 50.0
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=r)
    for cur in (curvature_mesh(mesh, rings=2), curvature_mesh(mesh, radius=6.0)):
        np.testing.assert_allclose(cur["K"] * r * r, 1.0, rtol=0.02)
        np.testing.assert_allclose(cur["H"] * r, -1.0, rtol=0.02)  # convex: H < 0
        assert np.all(cur["k1"] >= cur["k2"])
        assert np.min(np.einsum("ij,ij->i", cur["normal"], mesh.vertices / r)) > 0.999
        assert np.all(hk_sign_map(cur["K"], cur["H"]) == SurfaceType.PEAK)
    inside = mesh.copy()
    inside.invert()  # normals inwards: the hollow seen from inside is a pit
    cur = curvature_mesh(inside)
    assert np.all(hk_sign_map(cur["K"], cur["H"]) == SurfaceType.PIT)


def test_mesh_cylinder_side():
    r = 20.0
    mesh, side = cylinder_side_mesh(r, 100.0)
    cur = curvature_mesh(mesh, rings=2)
    assert side.sum() > 1000
    np.testing.assert_allclose(cur["K"][side] * r * r, 0.0, atol=1e-3)
    np.testing.assert_allclose(cur["H"][side] * 2 * r, -1.0, rtol=0.01)
    np.testing.assert_allclose(cur["k1"][side] * r, 0.0, atol=1e-3)
    np.testing.assert_allclose(cur["k2"][side] * r, -1.0, rtol=0.01)
    # the zero-curvature direction is the axis
    assert np.all(np.abs(cur["dir1"][side, 2]) > 0.999)
    labels = hk_sign_map(cur["K"][side], cur["H"][side], eps_K=1e-5, eps_H=1e-3)
    assert np.all(labels == SurfaceType.RIDGE)


def test_mesh_plane_and_saddles():
    flat = curvature_mesh(grid_mesh(lambda x, y: 0 * x))
    np.testing.assert_allclose(flat["K"], 0.0, atol=1e-12)
    np.testing.assert_allclose(flat["H"], 0.0, atol=1e-12)
    np.testing.assert_allclose(flat["normal"], np.tile([0, 0, 1.0], (41 * 41, 1)), atol=1e-12)
    assert np.all(hk_sign_map(flat["K"], flat["H"]) == SurfaceType.FLAT)
    # z = a x^2 + c y^2 with a c < 0; at the centre K = 4ac, H = a + c (upward normal)
    for (a, c), kind in (((0.02, -0.01), SurfaceType.SADDLE_VALLEY),
                         ((-0.02, 0.01), SurfaceType.SADDLE_RIDGE),
                         ((0.01, -0.01), SurfaceType.MINIMAL)):
        mesh = grid_mesh(lambda x, y, a=a, c=c: a * x ** 2 + c * y ** 2)
        cur = curvature_mesh(mesh)
        centre = np.argmin(np.linalg.norm(mesh.vertices[:, :2], axis=1))
        assert cur["K"][centre] == pytest.approx(4 * a * c, rel=1e-6)
        assert cur["H"][centre] == pytest.approx(a + c, abs=1e-9)
        labels = hk_sign_map(cur["K"], cur["H"], eps_K=1e-6, eps_H=1e-3)
        assert labels[centre] == kind
        if kind != SurfaceType.MINIMAL:  # H keeps its sign over the whole patch
            assert np.all(labels == kind)


# --------------------------------------------------------------------------- scans
def test_scan_sphere(sphere_scan):
    scan = sphere_scan
    cur = curvature_scan(scan, window=5)
    facing = interior(scan.valid & (-scan.normal[..., 2] > 0.8))  # within ~37 deg of the view
    assert facing.sum() > 1000
    K = cur["K"][facing] * SPHERE_R ** 2
    assert np.median(K) == pytest.approx(1.0, rel=0.01)
    assert np.all(np.abs(K - 1) < 0.05)
    np.testing.assert_allclose(cur["H"][facing] * SPHERE_R, -1.0, atol=0.03)
    # fitted normals face the camera and match the true ones
    cosang = np.einsum("ijk,ijk->ij", cur["normal"], scan.normal)[facing]
    assert np.degrees(np.arccos(np.clip(cosang, -1, 1))).max() < 1.0
    assert np.all(hk_sign_map(cur["K"], cur["H"])[facing] == SurfaceType.PEAK)
    # invalid pixels carry NaN, and the output shapes follow the image
    assert cur["K"].shape == scan.depth.shape and cur["normal"].shape == scan.xyz.shape
    assert np.isnan(cur["K"][~scan.valid]).all()
    assert (hk_sign_map(cur["K"], cur["H"])[~scan.valid] == SurfaceType.UNDEFINED).all()


def test_scan_cylinder_on_plane(cylinder_scan):
    scan = cylinder_scan
    cur = curvature_scan(scan)
    cyl = interior(scan.valid & (scan.part == 1) & (-scan.normal[..., 2] > 0.8))
    floor = interior(scan.valid & (scan.part == 0), 4)
    assert cyl.sum() > 500 and floor.sum() > 5000
    np.testing.assert_allclose(cur["k1"][cyl] * CYL_R, 0.0, atol=0.005)
    np.testing.assert_allclose(cur["k2"][cyl] * CYL_R, -1.0, atol=0.03)
    np.testing.assert_allclose(cur["K"][cyl] * CYL_R ** 2, 0.0, atol=0.005)
    # k1 (zero) runs along the axis: world y, which is the camera's -y
    assert np.all(np.abs(cur["dir1"][cyl][:, 1]) > 0.999)
    for key in ("k1", "k2"):
        assert np.abs(cur[key][floor]).max() < 1e-4
    labels = hk_sign_map(cur["K"], cur["H"], eps_K=1e-4, eps_H=2e-3)
    assert np.all(labels[cyl] == SurfaceType.RIDGE)
    assert np.all(labels[floor] == SurfaceType.FLAT)


def test_scan_tilted_plane_and_bare_array():
    pose = look_at((0, -250, 300), (0, 0, 0), up=(0, 0, 1))
    scan = rs.scan([plane()], make_sensor(), pose=pose)
    cur = curvature_scan(scan)
    inner = interior(scan.valid)
    assert inner.sum() > 10000
    for key in ("k1", "k2"):
        assert np.abs(cur[key][inner]).max() < 1e-4
    normal_cam = pose[:3, :3].T @ [0, 0, 1.0]
    np.testing.assert_allclose(cur["normal"][inner], np.broadcast_to(normal_cam, (inner.sum(), 3)),
                               atol=1e-4)
    # a bare (H, W, 3) array with NaN holes gives the same maps as the RangeScan
    bare = curvature_scan(np.where(scan.valid[..., None], scan.xyz, np.nan))
    for key in ("K", "H", "k1", "k2", "normal"):
        np.testing.assert_array_equal(bare[key], cur[key])


def test_scan_hole(sphere_scan):
    scan = sphere_scan
    hole = np.zeros_like(scan.valid)
    hole[55:65, 75:85] = True
    assert scan.valid[hole].all()
    holed = rs.RangeScan(**{**scan.__dict__, "valid": scan.valid & ~hole})
    cur = curvature_scan(holed, window=5)
    assert np.isnan(cur["K"][hole]).all() and np.isnan(cur["normal"][hole]).all()
    ring = np.zeros_like(hole)
    ring[53:67, 73:87] = True
    ring &= ~hole  # the two pixels around the hole: their windows reach into it
    assert np.all(cur["n_points"][ring] < 25) and np.all(cur["n_points"][ring] >= 15)
    np.testing.assert_allclose(cur["K"][ring] * SPHERE_R ** 2, 1.0, atol=0.1)
    # a stricter minimum turns the one-sided fits off, never the full ones
    strict = curvature_scan(holed, window=5, min_points=20)
    assert np.isnan(strict["K"][55:65, 74]).all() and np.isfinite(strict["K"][60, 71])


def test_scan_arguments():
    grid = np.zeros((10, 10, 3))
    with pytest.raises(ValueError):
        curvature_scan(grid, window=4)
    with pytest.raises(ValueError):
        curvature_scan(np.zeros((10, 10)))


# --------------------------------------------------------------------------- HK map, edges
def test_hk_sign_map_all_types():
    K = np.array([1, 1, 1, 0, 0, 0, -1, -1, -1, np.nan, 0.0]) * 1e-3
    H = np.array([-1, 0, 1, -1, 0, 1, -1, 0, 1, 0, np.nan]) * 1e-1
    labels = hk_sign_map(K, H, eps_K=1e-4, eps_H=1e-2)
    assert labels.dtype == np.uint8
    expected = [SurfaceType.PEAK, SurfaceType.IMPOSSIBLE, SurfaceType.PIT, SurfaceType.RIDGE,
                SurfaceType.FLAT, SurfaceType.VALLEY, SurfaceType.SADDLE_RIDGE,
                SurfaceType.MINIMAL, SurfaceType.SADDLE_VALLEY, SurfaceType.UNDEFINED,
                SurfaceType.UNDEFINED]
    assert labels.tolist() == [int(e) for e in expected]
    assert [surface_type_name(x) for x in labels[:9]] == [
        "peak", "impossible", "pit", "ridge", "flat", "valley", "saddle ridge",
        "minimal surface", "saddle valley"]
    assert set(SURFACE_TYPE_NAMES) == {int(t) for t in SurfaceType}
    # with eps_K >= eps_H^2 the impossible type cannot appear for real surfaces (H^2 >= K)
    rng = np.random.default_rng(0)
    k1, k2 = rng.normal(0, 0.01, (2, 10000))
    assert not np.any(hk_sign_map(k1 * k2, (k1 + k2) / 2) == SurfaceType.IMPOSSIBLE)
    with pytest.raises(ValueError):
        hk_sign_map(np.zeros(3), np.zeros(4))


def test_curvature_edges_rule():
    k1 = np.array([0.5, 0.5, -0.5, 0.05, np.nan, 0.5])
    k2 = np.array([0.5, 0.05, -0.6, 0.05, 0.5, -0.5])
    assert curvature_edges(k1, k2, 0.1).tolist() == [True, False, True, False, False, True]
    assert curvature_edges(k1.reshape(2, 3), k2.reshape(2, 3), 0.1).shape == (2, 3)
    # per-vertex: a cube's flat faces and straight edges have no edge points
    cube = trimesh.creation.box(extents=(40, 40, 40)).subdivide_to_size(4.0)
    cur = curvature_mesh(cube, rings=1)
    edges = curvature_edges(cur["k1"], cur["k2"], 0.02)
    assert np.all(np.abs(cube.vertices[edges]).min(axis=1) > 19.9)  # only at the 8 corners


def test_curvature_edges_on_a_box_scan():
    """Both |k| large only near the box's vertices: faces and straight creases drop out."""
    half = 40.0
    eye = np.array([1.0, 0.8, 1.2])
    pose = look_at(400 * eye / np.linalg.norm(eye), (0, 0, 0), up=(0, 0, 1))
    scan = rs.scan([box([-half] * 3, [half] * 3)], make_sensor(), pose=pose)
    cur = curvature_scan(scan)
    edges = curvature_edges(cur["k1"], cur["k2"], 0.1)
    world = scan.xyz[edges].astype(float) @ pose[:3, :3].T + pose[:3, 3]
    corners = np.array([[x, y, z] for x in (-half, half) for y in (-half, half)
                        for z in (-half, half)])
    dist = np.linalg.norm(world[:, None] - corners[None], axis=2)
    assert edges.sum() >= 3
    assert dist.min(axis=1).max() < 6.0  # every edge point within ~3 pixels of a box vertex
    assert (dist.argmin(axis=1) == 7).any()  # the vertex facing the camera, (40, 40, 40)
    # face pixels farther than 10 mm (the window's reach on the oblique top) from every
    # crease: no edge point, curvature ~ 0
    pts = scan.xyz_true.astype(float) @ pose[:3, :3].T + pose[:3, 3]
    faces = scan.valid & ((np.abs(pts) > half - 10).sum(axis=2) == 1)
    assert faces.sum() > 1500 and not edges[faces].any()
    assert np.abs(cur["k2"][faces]).max() < 1e-3


def test_cholesky_solve_matches_lapack_and_refuses_degenerate_systems():
    """The quadric fits' compiled 6 x 6 solve: LAPACK's solution and det(A) / prod(diag A) on
    well-conditioned Gram matrices; ratio 0 (refused) for a rank-deficient one, an
    indefinite one and one holding NaN."""
    import numpy as np

    from rangesim.curvature.quadric import _cholesky_solve
    rng = np.random.default_rng(7)
    M = rng.standard_normal((50, 12, 6))
    A = np.einsum("nki,nkj->nij", M, M)              # Gram matrices: positive definite
    b = rng.standard_normal((50, 6))
    low = rng.standard_normal((3, 6))
    A[0] = low.T @ low                               # rank 3
    A[1] = np.diag([1.0, 2.0, -1.0, 3.0, 1.0, 1.0])  # indefinite
    A[2, 3, 4] = A[2, 4, 3] = np.nan
    sol, ratio = _cholesky_solve(A, b)
    good = slice(3, None)
    ref = np.linalg.solve(A[good], b[good][..., None])[..., 0]
    assert np.allclose(sol[good], ref, rtol=1e-9, atol=1e-12)
    hadamard = np.linalg.det(A[good]) / np.prod(np.diagonal(A[good], axis1=1, axis2=2), axis=1)
    assert np.allclose(ratio[good], hadamard, rtol=1e-9)
    assert np.all((ratio[good] > 0) & (ratio[good] <= 1 + 1e-12))
    assert ratio[0] < 1e-10 and ratio[1] == 0.0 and ratio[2] == 0.0
