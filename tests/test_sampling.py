"""Surface points at a resolution (paper, section 3): units, the sampler's guarantees,
single-view visibility, files, the preview and the ``points`` command.

The guarantees, for resolution ``h``:
(a) every sample's nearest *other* sample is within ``h * sqrt(3)`` (and no two samples
    coincide, so (a) is not met by duplicates);
(b) every sample lies on the mesh;
(c) every point of the surface is within ``h * sqrt(3)`` of a sample (checked on random
    surface points); with ``ends="triangle"`` also every triangle wider than ``h`` in
    its projection plane has a sample on it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import rangesim.cli.main as cli
from rangesim.cad.sampling import ENDS, MERGE_FRACTION, SurfacePoints, surface_points
from rangesim.core.errors import RangesimError
from rangesim.core.units import UNITS_MM, parse_length
from rangesim.scene.visibility import visible_from, visible_points, visible_surface_points

SQRT3 = math.sqrt(3.0)


# -- meshes -----------------------------------------------------------------------------
def _rotated(mesh: trimesh.Trimesh, seed: int) -> trimesh.Trimesh:
    """A copy turned and moved off the grid, so no face is axis-aligned by luck."""
    rng = np.random.default_rng(seed)
    out = mesh.copy()
    out.apply_transform(trimesh.transformations.random_rotation_matrix(rng.random(3)))
    out.apply_translation(rng.uniform(-5, 5, 3))
    return out


def _box() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=[10.0, 6.0, 4.0])
    box.apply_translation([0.3, 0.1, 0.7])
    return box


def _slivers() -> trimesh.Trimesh:
    """A fan of 120 long thin triangles (20 mm x 0.17 mm), tilted, plus a 300-sided tube."""
    ang = np.linspace(0.0, np.pi / 3, 121)
    verts = np.r_[[[0.0, 0.0, 0.0]], np.c_[20 * np.cos(ang), 20 * np.sin(ang), np.zeros(121)]]
    faces = np.c_[np.zeros(120, int), np.arange(1, 121), np.arange(2, 122)]
    fan = trimesh.Trimesh(verts, faces, process=False)
    fan.apply_transform(trimesh.transformations.rotation_matrix(np.radians(50), [1, 1, 0]))
    tube = trimesh.creation.cylinder(radius=3.0, height=20.0, sections=300)
    tube.apply_translation([0.0, 0.0, 30.0])
    return trimesh.util.concatenate([fan, tube])


def _tiny() -> trimesh.Trimesh:
    """A sphere of ~0.6 mm triangles (sampled at 2 mm: every triangle is tiny)."""
    return trimesh.creation.icosphere(subdivisions=5, radius=10.0)


CASES = {
    "box": (_box, 0.5),
    "rotated box": (lambda: _rotated(_box(), 1), 0.7),
    "icosphere": (lambda: trimesh.creation.icosphere(subdivisions=3, radius=10.0), 1.0),
    "rotated icosphere": (lambda: _rotated(trimesh.creation.icosphere(subdivisions=2, radius=10.0), 2), 0.6),
    "slivers": (_slivers, 0.5),
    "tiny triangles": (_tiny, 2.0),
}


def _barycentric_on_face(mesh, samples):
    """(max distance to the own face's plane, min barycentric coordinate), for (b)."""
    tri = mesh.triangles[samples.face_index]
    normal = mesh.face_normals[samples.face_index]
    plane = np.abs(np.einsum("ij,ij->i", samples.points - tri[:, 0], normal))
    bary = trimesh.triangles.points_to_barycentric(tri, samples.points)
    return plane.max(), bary.min()


# -- units --------------------------------------------------------------------------------
@pytest.mark.parametrize("text, mm", [
    ("0.2in", 5.08), ("5mm", 5.0), ("0.5 cm", 5.0), ("1e-3m", 1.0), ('0.2"', 5.08),
    ("2 inch", 50.8), ("7", 7.0), (".5IN", 12.7), (3, 3.0), (2.5, 2.5),
])
def test_parse_length(text, mm):
    assert parse_length(text) == pytest.approx(mm, rel=1e-12)


def test_parse_length_default_unit_and_table():
    assert parse_length(2, default_unit="cm") == 20.0
    assert parse_length("2", default_unit="in") == pytest.approx(50.8)
    assert UNITS_MM["in"] == UNITS_MM["inch"] == 25.4 and UNITS_MM["m"] == 1000.0


@pytest.mark.parametrize("bad", ["abc", "", "5 km", "2em", "1.2.3", "nan", "inf", "1e400", float("nan"), None, True])
def test_parse_length_rejects_bad_values(bad):
    with pytest.raises(RangesimError):
        parse_length(bad)


@pytest.mark.parametrize("bad", ["-1mm", "0", 0.0, -2])
def test_parse_length_positive(bad):
    parse_length(bad)  # a length, just not a positive one
    with pytest.raises(RangesimError, match="resolution must be positive"):
        parse_length(bad, positive=True, what="resolution")


# -- the sampler's guarantees ------------------------------------------------------------------
@pytest.mark.parametrize("ends", ENDS)
@pytest.mark.parametrize("name", list(CASES))
def test_guarantees(name, ends):
    build, h = CASES[name]
    check_guarantees(build(), h, ends)


@pytest.mark.parametrize("model", ["green_piece", "renault_piece"])
def test_guarantees_on_the_papers_parts(model):
    from rangesim.cad import load_model

    check_guarantees(load_model(model), parse_length("0.2in"), "triangle")


def check_guarantees(mesh, h, ends):
    samples = surface_points(mesh, h, ends=ends)
    n = len(samples)
    assert n > 50
    assert samples.points.shape == (n, 3) and samples.normals.shape == (n, 3)
    assert samples.face_index.shape == (n,) and samples.face_index.dtype == np.int64
    assert samples.resolution == h
    tree = cKDTree(samples.points)

    # (a) each sample's nearest other sample is within h*sqrt(3), and not a duplicate
    nearest = tree.query(samples.points, k=2)[0][:, 1]
    assert nearest.max() <= h * SQRT3, f"a sample is {nearest.max() / h:.3f} h from the others"
    assert nearest.min() > MERGE_FRACTION * h

    # (b) on the surface: in its own triangle's plane and inside it, and near the mesh
    scale = float(np.abs(mesh.vertices).max())
    plane, bary = _barycentric_on_face(mesh, samples)
    assert plane < 1e-12 * scale and bary > -1e-6  # barycentrics of slivers are ill-conditioned
    some = np.random.default_rng(0).choice(n, min(n, 1500), replace=False)  # trimesh is slow
    _, dist, _ = trimesh.proximity.closest_point(mesh, samples.points[some])
    assert dist.max() < 1e-9 * scale

    # (c) every surface point is within h*sqrt(3) of a sample
    probe, _ = trimesh.sample.sample_surface(mesh, 20_000, seed=0)
    gap = tree.query(probe)[0].max()
    assert gap <= h * SQRT3, f"a surface point is {gap / h:.3f} h from every sample"

    # unit normals
    assert np.allclose(np.linalg.norm(samples.normals, axis=1), 1.0)


def test_per_triangle_ends_every_wide_triangle_has_samples():
    """(c), per polygon: a triangle wider than h in its projection plane gets a sample on it."""
    mesh, h = _slivers(), 0.5
    samples = surface_points(mesh, h, ends="triangle")
    tri = mesh.triangles
    axis = np.argmax(np.abs(mesh.face_normals), axis=1)
    keep = np.ones((len(tri), 3), dtype=bool)
    keep[np.arange(len(tri)), axis] = False
    extent = np.ptp(tri, axis=1)[keep].reshape(-1, 2).max(axis=1)
    wide = np.flatnonzero(extent > h)
    assert len(wide) > 100
    # a sample on a shared edge is listed under one of the two faces: look for a sample
    # of the triangle or of an edge neighbour lying on it (in its plane, barycentric >= 0)
    neighbours = [[f] for f in range(len(tri))]
    for f, g in mesh.face_adjacency:
        neighbours[f].append(g)
        neighbours[g].append(f)
    order = np.argsort(samples.face_index, kind="stable")
    by_face = np.split(order, np.searchsorted(samples.face_index[order], np.arange(1, len(tri))))
    for f in wide:
        point = samples.points[np.concatenate([by_face[g] for g in neighbours[f]])]
        bary = trimesh.triangles.points_to_barycentric(np.repeat(tri[f][None], len(point), 0), point)
        off_plane = np.abs((point - tri[f, 0]) @ mesh.face_normals[f])
        assert np.any((bary.min(axis=1) > -1e-9) & (off_plane < 1e-9)), f"triangle {f} has no sample"


def test_point_count_follows_resolution_not_tessellation():
    """A fine mesh gives about one sample per h^2 of area, like a coarse one of the same shape."""
    h = 2.0
    area = 4 * np.pi * 10.0**2
    coarse = surface_points(trimesh.creation.icosphere(subdivisions=3, radius=10.0), h, ends="thin")
    fine = surface_points(_tiny(), h, ends="thin")
    assert 0.5 * area / h**2 < len(fine) < 1.5 * area / h**2
    assert len(fine) == pytest.approx(len(coarse), rel=0.25)
    # the paper's per-polygon ends: several times more points on the fine mesh
    assert len(surface_points(_tiny(), h, ends="triangle")) > 2 * len(surface_points(_tiny(), h, ends="surface"))


def test_thin_ends_on_a_surface_folded_finer_than_h():
    """A sawtooth with folds 0.1 h apart (flanks 76 degrees steep, so every fold is a seam
    between two projection sides) keeps about one end per (h/2)-voxel, not one per fold."""
    h = 1.0
    x = np.arange(0.0, 20.01, 0.1) + 0.013
    z = np.where(np.arange(len(x)) % 2 == 0, 0.0, 0.4) + 0.013
    verts = np.concatenate([np.c_[x, np.full_like(x, y), z] for y in (0.07, 10.07)])
    n = len(x)
    i = np.arange(n - 1)
    saw = trimesh.Trimesh(verts, np.r_[np.c_[i, i + 1, i + n], np.c_[i + 1, i + n + 1, i + n]], process=False)
    counts = {}
    probe, _ = trimesh.sample.sample_surface(saw, 20_000, seed=0)
    for ends in ENDS:
        samples = surface_points(saw, h, ends=ends)
        counts[ends] = len(samples)
        tree = cKDTree(samples.points)
        assert tree.query(samples.points, k=2)[0][:, 1].max() <= h * SQRT3
        assert tree.query(probe)[0].max() <= h * SQRT3
    # 10 lines y = 1..10 cross 200 flanks: ~2000 ends; thinned: at most one per (h/2)-voxel,
    # 40 along each line and 2 layers across the 0.4 mm height
    assert counts["triangle"] > counts["surface"] > 2 * counts["thin"]
    assert counts["thin"] <= 11 * 40 * 2


def test_grid_is_global():
    """Moving a mesh by whole grid steps moves its samples with it: the grid is fixed in space."""
    mesh, h = _rotated(trimesh.creation.icosphere(subdivisions=2, radius=10.0), 5), 0.8
    shift = np.array([3, -2, 5]) * h
    moved = mesh.copy()
    moved.apply_translation(shift)
    a, b = surface_points(mesh, h), surface_points(moved, h)
    assert len(a) == len(b)
    dist, _ = cKDTree(b.points).query(a.points + shift)
    assert dist.max() < 1e-9


def test_grid_nodes_on_a_face():
    """On an axis-aligned face the samples are the grid nodes plus the points on its border."""
    square = trimesh.Trimesh([[0.3, 0.3, 1.0], [4.7, 0.3, 1.0], [4.7, 3.6, 1.0], [0.3, 3.6, 1.0]],
                             [[0, 1, 2], [0, 2, 3]], process=False)
    pts = surface_points(square, 1.0, ends="surface").points
    assert np.allclose(pts[:, 2], 1.0, rtol=0, atol=1e-12)
    eps = 1e-9
    interior = (pts[:, 0] > 0.3 + eps) & (pts[:, 0] < 4.7 - eps) & (pts[:, 1] > 0.3 + eps) & (pts[:, 1] < 3.6 - eps)
    nodes = {(x, y) for x in range(1, 5) for y in range(1, 4)}
    assert {tuple(p) for p in np.round(pts[interior, :2], 9)} == nodes and interior.sum() == len(nodes)
    # border: the line crossings (x = 1..4 twice, y = 1..3 twice) and no crossing of the
    # inner diagonal (the lines run on from one triangle into the other)
    assert (~interior).sum() == 2 * 4 + 2 * 3


def test_resolution_strings_and_bad_values():
    mesh = _box()
    assert len(surface_points(mesh, "0.02in")) == len(surface_points(mesh, 0.508))
    for bad in ("-1mm", "abc", 0, float("inf")):
        with pytest.raises(RangesimError, match="resolution"):
            surface_points(mesh, bad)
    with pytest.raises(RangesimError, match="too fine"):
        surface_points(mesh, 1e-4)
    with pytest.raises(RangesimError, match="ends must be one of"):
        surface_points(mesh, 1.0, ends="all")


def test_normals_smooth_and_flat():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    smooth = surface_points(sphere, 1.0)
    radial = smooth.points / np.linalg.norm(smooth.points, axis=1, keepdims=True)
    # interpolated vertex normals follow the sphere better than the facets do
    flat = surface_points(sphere, 1.0, smooth=False)
    assert np.allclose(flat.normals, sphere.face_normals[flat.face_index])
    flat_err = np.einsum("ij,ij->i", flat.normals, radial).min()
    smooth_err = np.einsum("ij,ij->i", smooth.normals, radial).min()
    assert smooth_err > flat_err > 0.98
    # a box: flat normals are exact, smooth ones blend across the sharp edges
    box = _box()
    assert np.allclose(np.abs(surface_points(box, 1.0, smooth=False).normals).max(axis=1), 1.0)
    assert np.abs(surface_points(box, 1.0).normals).max(axis=1).min() < 0.9


def test_small_isolated_parts_get_a_sample():
    """A triangle far smaller than h, between the grid lines and far from the rest, is not lost."""
    big = trimesh.creation.icosphere(subdivisions=2, radius=10.0)
    speck = trimesh.Trimesh([[30.2, 30.2, 30.2], [30.25, 30.2, 30.2], [30.2, 30.25, 30.2]], [[0, 1, 2]])
    mesh = trimesh.util.concatenate([big, speck])
    samples = surface_points(mesh, 1.0)
    assert np.count_nonzero(samples.face_index == len(mesh.faces) - 1) == 1


# -- one view ------------------------------------------------------------------------------
def test_single_view_keeps_the_front_half_of_a_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=20.0)
    eye = np.array([0.0, 0.0, 400.0])
    every = surface_points(sphere, 1.5)
    seen = visible_surface_points(sphere, 1.5, eye)
    mask = visible_from(sphere, every.points, eye, normals=every.normals)
    assert np.array_equal(seen.points, every.points[mask])
    to_eye = eye - every.points
    cos = np.einsum("ij,ij->i", every.normals, to_eye) / np.linalg.norm(to_eye, axis=1)
    assert not np.any(mask & (cos <= 0))                      # nothing from the back
    assert np.all(mask[cos > 0.05])                           # all of the front (away from the rim)
    assert 0.4 < mask.mean() < 0.5                            # the eye sees less than a half
    # without normals the rays alone find the back hidden behind the front
    rays_only = visible_from(sphere, every.points, eye)
    # (away from the rim, where smooth normals and facets disagree by a few degrees)
    assert np.array_equal(rays_only[np.abs(cos) > 0.1], cos[np.abs(cos) > 0.1] > 0)


def test_single_view_drops_a_sphere_hidden_behind_a_box():
    small = trimesh.creation.icosphere(subdivisions=2, radius=3.0)
    small.apply_translation([0.0, 0.0, -40.0])
    box = trimesh.creation.box(extents=[30.0, 30.0, 10.0])
    eye = [0.0, 0.0, 300.0]
    samples = surface_points(small, 0.5)
    assert len(visible_points(samples, [small, box], eye)) == 0
    alone = visible_points(samples, small, eye)
    assert 0.3 * len(samples) < len(alone) < 0.5 * len(samples)
    # moved out from behind the box it is seen again
    side = small.copy()
    side.apply_translation([40.0, 0.0, 0.0])
    side_samples = surface_points(side, 0.5)
    assert len(visible_points(side_samples, [side, box], eye)) == len(visible_points(side_samples, side, eye))


def test_visible_from_checks_viewpoint():
    with pytest.raises(RangesimError, match="viewpoint"):
        visible_from(_box(), np.zeros((2, 3)), [0.0, 1.0])
    with pytest.raises(RangesimError, match="viewpoint"):
        visible_surface_points(_box(), 1.0, [0.0, 1.0])


def test_sampling_is_pure_geometry():
    """Visibility is the scene layer's: cad.surface_points names the replacement for ``view``."""
    with pytest.raises(RangesimError, match="visible_surface_points"):
        surface_points(_box(), 1.0, view=[0.0, 0.0, 100.0])
    box, eye = _box(), [10.0, -20.0, 30.0]
    seen = visible_surface_points(box, 1.0, eye, smooth=False, ends="surface")
    every = surface_points(box, 1.0, smooth=False, ends="surface")
    assert np.array_equal(seen.points, visible_points(every, box, eye).points)
    assert 0 < len(seen) < len(every)


# -- files and pictures -----------------------------------------------------------------------
def test_save_ply_with_normals_readable_by_trimesh(tmp_path):
    samples = surface_points(trimesh.creation.icosphere(subdivisions=2, radius=10.0), 1.0)
    path = samples.save(tmp_path / "sub" / "points.ply")
    cloud = trimesh.load(path)
    assert len(cloud.vertices) == len(samples)
    assert np.allclose(cloud.vertices, samples.points, atol=1e-5)
    raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    normals = np.c_[raw["nx"], raw["ny"], raw["nz"]]
    assert np.allclose(normals, samples.normals, atol=1e-6)
    assert list(tmp_path.joinpath("sub").iterdir()) == [path]  # no temporary file left


def test_save_npz_is_exact_and_other_suffixes_fail(tmp_path):
    samples = surface_points(_box(), 1.0)
    path = samples.save(tmp_path / "points.npz")
    with np.load(path) as data:
        back = SurfacePoints(data["points"], data["normals"], data["face_index"], float(data["resolution"]))
    assert np.array_equal(back.points, samples.points) and np.array_equal(back.face_index, samples.face_index)
    with pytest.raises(RangesimError, match=r"\.ply, \.npz"):
        samples.save(tmp_path / "points.xyz")


def test_points_preview_png(tmp_path):
    from rangesim.viz.points import save_points_preview

    samples = surface_points(_box(), 1.0, smooth=False)
    path = save_points_preview(samples.points, samples.normals, tmp_path / "pts.png", normal_length=1.0)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    save_points_preview(samples.points, None, tmp_path / "bare.png")
    with pytest.raises(RangesimError, match="png"):
        save_points_preview(samples.points, samples.normals, tmp_path / "pts.jpg")


# -- the command ----------------------------------------------------------------------------
@pytest.fixture
def points_cli(monkeypatch):
    monkeypatch.setattr(cli, "COMMAND_MODULES", ("rangesim.cli.points_commands",))
    return cli.main


def test_cli_points_with_a_mesh_file(points_cli, tmp_path, capsys):
    mesh_path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=2, radius=10.0).export(mesh_path)
    out, png = tmp_path / "out" / "pts.ply", tmp_path / "out" / "pts.png"
    code = points_cli(["points", str(mesh_path), "--resolution", "0.05in", "--out", str(out),
                       "--preview", str(png)])
    assert code == 0, capsys.readouterr().err
    summary = capsys.readouterr().out
    assert "1.27 mm" in summary and str(out) in summary
    every = len(trimesh.load(out).vertices)
    assert png.stat().st_size > 0

    front = tmp_path / "front.npz"
    assert points_cli(["points", str(mesh_path), "--resolution=1.27", "--out", str(front),
                       "--view", "0,0,10in", "--flat"]) == 0
    with np.load(front) as data:
        assert 0.3 * every < len(data["points"]) < 0.55 * every
        assert np.all(data["normals"][:, 2] > 0)


@pytest.mark.parametrize("args, message", [
    (["--resolution=-1mm"], "resolution must be positive"),
    (["--resolution", "abc"], "resolution must be a number"),
    (["--resolution", "1", "--view", "1,2"], "X,Y,Z"),
])
def test_cli_points_bad_input(points_cli, tmp_path, capsys, args, message):
    mesh_path = tmp_path / "box.stl"
    _box().export(mesh_path)
    out = tmp_path / "pts.ply"
    assert points_cli(["points", str(mesh_path), *args, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_cli_points_checks_suffixes_first(points_cli, tmp_path, capsys):
    # the mesh does not exist: the bad suffix is reported before the mesh is looked at
    assert points_cli(["points", str(tmp_path / "missing.stl"), "--resolution", "1",
                       "--out", str(tmp_path / "pts.txt")]) == 2
    assert "cannot write surface points as '.txt' files" in capsys.readouterr().err


def test_cli_points_errors_are_rangesim_errors(tmp_path):
    """The command raises RangesimError (the CLI turns it into exit code 2)."""
    import argparse

    from rangesim.cli.points_commands import register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    mesh_path = tmp_path / "box.stl"
    _box().export(mesh_path)
    for bad in ("-1mm", "abc"):
        args = parser.parse_args(["points", str(mesh_path), f"--resolution={bad}", "--out", str(tmp_path / "p.ply")])
        with pytest.raises(RangesimError):
            args.func(args)
