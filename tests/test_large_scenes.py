"""Large scenes: a new image size compiles nothing, mesh validation is cheap and exact, the mesh cache."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import rangesim as rs
from tests.conftest import make_sensor, plane, top_down_pose


def test_a_new_image_size_compiles_no_kernel():
    import drjit as dr

    # one plane seen straight down: no data-dependent kernel (no shared-edge re-cast, no mixed
    # pixels), so any kernel compiled at a new size would be the size's own
    scene = rs.load_scene([plane(z=0.0)])
    sizes = [(160, 120), (170, 128), (180, 136), (200, 150)]

    def run(w, h, seed):
        sensor = make_sensor(**{"camera.width": w, "camera.height": h, "noise.sigma_px": 0.1})
        scan = rs.scan(scene, sensor, pose=top_down_pose(400.0), seed=seed)
        assert scan.meta["recast_rays"] == 0
        return scan

    for k, (w, h) in enumerate(sizes[:2]):
        run(w, h, k)
    flag = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    try:
        for k, (w, h) in enumerate(sizes[2:]):
            scan = run(w, h, k)
            assert scan.shape == (h, w) and scan.valid.mean() > 0.9
        kernels = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, flag)
    missed = [(k.get("size"), k.get("operation_count")) for k in kernels if not k["cache_hit"]]
    assert kernels and not missed, missed


def _open_sphere():
    m = trimesh.creation.icosphere(subdivisions=3)
    return trimesh.Trimesh(m.vertices, m.faces[:-3], process=False)


def _flipped_face():
    m = trimesh.creation.icosphere(subdivisions=2)
    f = m.faces.copy()
    f[5] = f[5, ::-1]
    return trimesh.Trimesh(m.vertices, f, process=False)


@pytest.mark.parametrize("make", [trimesh.creation.box, lambda: trimesh.creation.icosphere(subdivisions=4),
                                  lambda: trimesh.creation.cylinder(radius=3, height=5, sections=40), _open_sphere,
                                  _flipped_face])
def test_closedness_agrees_with_trimesh(make):
    from rangesim.cad.meshes import is_closed

    mesh = make()
    mesh.merge_vertices()
    assert is_closed(mesh.faces) == bool(mesh.is_watertight and mesh.is_winding_consistent)


def test_inside_out_closed_mesh_is_flipped_and_volume_is_exact():
    from rangesim.cad.meshes import signed_volume

    box = trimesh.creation.box(extents=(10, 20, 30))
    inverted = trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False)
    obj = rs.load_scene([inverted]).objects[0]
    assert obj.watertight
    assert signed_volume(obj.mesh.vertices, obj.mesh.faces) == pytest.approx(6000.0)
    # an STL-like soup (no shared vertices) is welded before the check
    soup = trimesh.Trimesh(box.vertices[box.faces].reshape(-1, 3), np.arange(36).reshape(-1, 3), process=False)
    assert rs.load_scene([soup]).objects[0].watertight


def test_mesh_cache_skips_validation_and_follows_the_content(tmp_path, monkeypatch):
    from rangesim.cad import meshes

    path = tmp_path / "part.ply"
    trimesh.creation.icosphere(subdivisions=3, radius=20.0).export(path)
    monkeypatch.setenv(meshes.CACHE_ENV, str(tmp_path / "cache"))
    first = meshes.load_mesh(path)
    assert "rangesim_cache" not in first.metadata and len(list((tmp_path / "cache").glob("*.npz"))) == 1
    second = meshes.load_mesh(path)
    assert second.metadata["rangesim_cache"]
    np.testing.assert_array_equal(second.vertices, first.vertices)
    np.testing.assert_array_equal(second.faces, first.faces)
    assert second.metadata["rangesim_closed"] is True
    # another content is another entry, never the stale one
    trimesh.creation.box(extents=(5, 5, 5)).export(path)
    third = meshes.load_mesh(path)
    assert len(third.faces) == 12 and len(list((tmp_path / "cache").glob("*.npz"))) == 2
    monkeypatch.setenv(meshes.CACHE_ENV, "off")
    assert meshes.mesh_cache_dir() is None
