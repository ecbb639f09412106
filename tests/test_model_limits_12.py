"""Parameters whose work grows without bound are refused before the work (an independent probe:
a 0.001 mm thread pitch crashed the process in the CSG library, samples_per_mm = 1000 asked for
24 GB, local:100000 hung starting Dask workers)."""
from __future__ import annotations

import pytest

import rangesim as rs
from rangesim.cad._green_piece import MAX_THREAD_VERTICES
from rangesim.cad._renault_piece import MAX_FREEFORM_SAMPLES
from rangesim.cad.models import MODELS
from rangesim.experiments.executors import MAX_LOCAL_WORKERS_PER_CORE, Executor, available_cores


def test_a_thread_too_fine_for_memory_is_refused_naming_it():
    with pytest.raises(rs.RangesimError) as info:
        MODELS["green_piece"](threads=[(0.0, 0.0, 6.0, 0.001)])
    message = str(info.value)
    # 12.7 mm / 0.001 mm x 16 sections per turn, + 2 at the faces, of 48 segments each
    assert "203,202 helix sections" in message
    assert f"{MAX_THREAD_VERTICES:,}" in message and "threads[0] pitch 0.001" in message


def test_the_default_threads_are_far_under_the_thread_limit():
    import math

    sections = sum(math.ceil(12.7 / pitch * 16) + 2 for pitch in (1.75, 1.5, 1.25, 1.0, 0.8, 1.0, 1.5))
    assert sections * 48 < MAX_THREAD_VERTICES / 8


def test_a_freeform_density_too_fine_for_memory_is_refused():
    with pytest.raises(rs.RangesimError, match=r"samples_per_mm 1000 .* more than 200,000"):
        MODELS["renault_piece"](samples_per_mm=1000)
    assert MAX_FREEFORM_SAMPLES == 200_000


def test_local_dask_workers_are_bounded():
    cores = available_cores()
    with pytest.raises(rs.RangesimError, match="worker processes per core"):
        Executor(scheduler=f"local:{MAX_LOCAL_WORKERS_PER_CORE * cores + 1}")
    # within the limit: no more workers than tasks, as the local pool
    assert Executor(scheduler="local:4", max_tasks=1).workers == 1
    assert Executor(scheduler=f"local:{min(3, 8 * cores)}", max_tasks=10).workers == min(3, 8 * cores)


@pytest.mark.parametrize(("body", "words"), [
    ('units = "m"\n[[object]]\nname = "b"\nprimitive = "box"\nsize = [1, 1, 1]\ntranslate = [1e307, 0, 0]\n',
     ["[[object]] 0 (b)", "overflow to infinity"]),
    ('[[object]]\nname = "b"\nprimitive = "box"\nsize = [1e300, 1e300, 1e300]\n', ["[[object]] 0 (b)", "5e+299 mm"]),
    ('[[object]]\nname = "b"\nprimitive = "box"\nsize = [10, 10, 10]\n[view]\nposition = [1e300, 0, 0]\n',
     ["view.position", "1e+300 mm"]),
])
def test_scene_coordinates_beyond_the_world_are_refused(tmp_path, body, words):
    """Finite numbers that overflow once units and scale apply (or that float32 rays cannot
    resolve) were scanned into 'the camera sees no surface' or a view error without a file name."""
    path = tmp_path / "scene.toml"
    path.write_text(body)
    with pytest.raises(rs.RangesimError) as info:
        rs.load_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "1e+09 mm" in message
    for word in words:
        assert word in message, message


@pytest.mark.parametrize(("params", "words"), [
    ({"head_height": 1}, ["right head's rim", "not above the plate's top"]),
    ({"plate_thickness": 100}, ["plate_thickness 100 mm"]),
    ({"plate_thickness": 4}, ["must exceed 5 mm"]),
    ({"head_x": 500}, ["heads", "past the plate"]),
    ({"head_size": [1e-9, 1e-9]}, ["at least 1 mm"]),
])
def test_renault_layouts_whose_sub_parts_are_not_in_the_mesh_are_refused(params, words):
    """The heads buried in the plate (or off it) were listed as features the mesh does not have."""
    with pytest.raises(rs.RangesimError) as info:
        MODELS["renault_piece"](**params)
    for word in words:
        assert word in str(info.value), str(info.value)


def test_params_on_a_primitive_are_refused(tmp_path):
    """A sweep's `object.box.params.thickness` on a primitive box was silently ignored."""
    path = tmp_path / "scene.toml"
    path.write_text('[[object]]\nname = "box"\nprimitive = "box"\nsize = [10, 10, 10]\n[object.params]\nthickness = 3\n')
    with pytest.raises(rs.RangesimError, match=r"\(box\): params apply to a built-in model"):
        rs.load_scene(path)
