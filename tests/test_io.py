"""Round trips and failure modes of rangesim.io (scan files)."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import trimesh

import rangesim as rs
import rangesim.io as rio
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import OPTIONAL_PIXEL_FIELDS, PIXEL_FIELDS, RangeScan
from rangesim.io.exr import channel_names
from rangesim.io.ply import VERTEX_DTYPE

H, W = 7, 9


def make_scan(with_truth: bool = True) -> RangeScan:
    """A 7x9 scan exercising every value class the writers must keep exact."""
    rng = np.random.default_rng(1234)
    status = (np.arange(H * W) % 5).astype(np.uint8).reshape(H, W)  # codes 0..4
    valid = status == Status.VALID
    hit = status != Status.MISS
    xyz = rng.normal(size=(H, W, 3)).astype(np.float32) * 100 + np.float32(500)
    xyz[~valid] = np.nan
    normal = rng.normal(size=(H, W, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal[~hit] = np.nan
    part = np.where(hit, np.arange(H * W).reshape(H, W) % 3, -1).astype(np.int32)
    face = np.where(hit, rng.integers(0, 5000, size=(H, W)), -1).astype(np.int32)
    face[0, 1] = 1_000_000
    face[1, 2] = 2**24  # the largest integer float32 stores exactly
    intensity = np.where(hit, rng.random((H, W)), 0).astype(np.float32)
    intensity[2, 3] = np.float32(1e-30)  # tiny but non-zero must survive
    truth = rng.normal(size=(H, W, 3)).astype(np.float32) if with_truth else None
    if truth is not None:
        truth[~hit] = np.nan
    angle = 0.3
    pose = np.array(
        [
            [np.cos(angle), -np.sin(angle), 0.0, 0.1],
            [np.sin(angle), np.cos(angle), 0.0, -123.456789012345],
            [0.0, 0.0, 1.0, 1 / 3],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    meta = {
        "sensor": {"name": "test-sensor", "baseline": 120.5, "noise": {"sigma": 0.02}},
        "seed": 7,
        "K": [[600.0, 0.0, 4.5], [0.0, 600.0, 3.5], [0.0, 0.0, 1.0]],
        "laser_origin": [120.5, 0.0, 0.0],
        "tags": ["a", "b", None, True],
        "note": "unicode ok: µm ±",
    }
    return RangeScan(
        depth=xyz[..., 2].copy(), xyz=xyz, valid=valid, normal=normal,
        intensity=intensity, part=part, face=face, status=status,
        pose=pose, meta=meta, xyz_true=truth,
    )


def assert_scans_equal(a: RangeScan, b: RangeScan) -> None:
    for name, dtype, _ in PIXEL_FIELDS + OPTIONAL_PIXEL_FIELDS:
        va, vb = getattr(a, name), getattr(b, name)
        if va is None:
            assert vb is None, name
            continue
        assert vb.dtype == np.dtype(dtype), name
        assert np.array_equal(va, vb, equal_nan=va.dtype.kind == "f"), name
    assert b.pose.dtype == np.float64
    assert np.array_equal(a.pose, b.pose)
    assert a.meta == b.meta


def no_temp_files(directory: Path) -> bool:
    return not [p for p in directory.iterdir() if ".tmp-" in p.name]


# -- exact round trips -----------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".exr", ".npz", ".EXR", ".Npz"])
@pytest.mark.parametrize("with_truth", [True, False])
def test_round_trip_is_exact(tmp_path, suffix, with_truth):
    scan = make_scan(with_truth)
    path = rio.save_scan(scan, tmp_path / f"scan{suffix}")
    assert path == tmp_path / f"scan{suffix}" and path.is_file()
    assert_scans_equal(scan, rio.load_scan(path))
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_exr_channels_and_header(tmp_path):
    import OpenEXR

    scan = make_scan()
    path = rio.save_scan(scan, tmp_path / "scan.exr")
    with OpenEXR.File(str(path), separate_channels=True) as exr:  # channels die on close
        header = dict(exr.header())
        channels = {name: ch.pixels for name, ch in exr.channels().items()}
    expected = {"depth", "valid", "intensity", "part", "face", "status"}
    expected |= {f"{f}.{a}" for f in ("xyz", "normal", "xyz_true") for a in "XYZ"}
    assert set(channels) == expected
    assert all(px.dtype == np.float32 and px.shape == (H, W) for px in channels.values())
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    assert {"rangesim_meta", "rangesim_pose", "rangesim_format_version"} <= set(header)
    assert channel_names("normal") == ("normal.X", "normal.Y", "normal.Z")


def test_meta_numpy_values_become_plain_json(tmp_path):
    scan = make_scan()
    scan.meta = {"K": np.eye(3) * 2.5, "seed": np.int64(3), "gain": np.float32(0.5)}
    for suffix in (".exr", ".npz"):
        back = rio.load_scan(rio.save_scan(scan, tmp_path / f"s{suffix}"))
        assert back.meta == {"K": (np.eye(3) * 2.5).tolist(), "seed": 3, "gain": 0.5}
        assert type(back.meta["seed"]) is int


def test_exr_refuses_inexact_face_index(tmp_path):
    scan = make_scan()
    scan.face[3, 3] = 2**24 + 1
    with pytest.raises(RangesimError, match="16777217") as err:
        rio.save_scan(scan, tmp_path / "big.exr")
    assert str(err.value).startswith(str(tmp_path / "big.exr") + ": RangeScan.face value")
    assert err.value.source == str(tmp_path / "big.exr")
    assert list(tmp_path.iterdir()) == []
    # npz stores int32 natively, so the same scan is fine there
    assert_scans_equal(scan, rio.load_scan(rio.save_scan(scan, tmp_path / "big.npz")))


def test_scan_save_method(tmp_path):
    scan = make_scan()
    path = scan.save(tmp_path / "nested" / "dir" / "scan.npz")
    assert path.is_file()
    assert_scans_equal(scan, rio.load_scan(path))


# -- PLY -------------------------------------------------------------------------------------
def test_ply_has_valid_points_with_normals(tmp_path):
    scan = make_scan()
    path = rio.save_scan(scan, tmp_path / "cloud.ply")
    n = int(scan.valid.sum())
    assert 0 < n < H * W

    raw = path.read_bytes()
    head, body = raw.split(b"end_header\n", 1)
    assert b"format binary_little_endian 1.0" in head
    assert f"element vertex {n}".encode() in head
    assert b"element face" not in head
    pose_line = next(l for l in head.decode().splitlines() if l.startswith("comment pose "))
    pose = np.array([float(v) for v in pose_line.split()[2:]]).reshape(4, 4)
    assert np.array_equal(pose, scan.pose)
    verts = np.frombuffer(body, dtype=VERTEX_DTYPE)
    assert len(verts) == n
    assert np.array_equal(np.stack([verts[a] for a in "xyz"], -1), scan.xyz[scan.valid])
    assert np.array_equal(np.stack([verts[a] for a in ("nx", "ny", "nz")], -1),
                          scan.normal[scan.valid])
    assert np.array_equal(verts["intensity"], scan.intensity[scan.valid])

    cloud = trimesh.load(path)
    assert isinstance(cloud, trimesh.PointCloud)
    assert np.array_equal(np.asarray(cloud.vertices), scan.points("camera"))
    ply_raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    assert {"nx", "ny", "nz", "intensity"} <= set(ply_raw.dtype.names)


# -- atomic writes ---------------------------------------------------------------------------
def test_atomic_path_keeps_suffix_and_cleans_up(tmp_path):
    target = tmp_path / "sub" / "image.png"
    with rio.atomic_path(target) as tmp:
        assert tmp.parent == target.parent and tmp.suffix == ".png"
        assert tmp.name.startswith(".image.tmp-")
        tmp.write_bytes(b"data")
    assert target.read_bytes() == b"data" and no_temp_files(target.parent)

    with pytest.raises(KeyError):
        with rio.atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise KeyError("boom")
    assert target.read_bytes() == b"data"  # the old file is untouched
    assert sorted(p.name for p in target.parent.iterdir()) == ["image.png"]


@pytest.mark.parametrize("suffix", [".exr", ".npz", ".ply"])
def test_failed_write_leaves_nothing(tmp_path, monkeypatch, suffix):
    def half_write(scan, path):
        Path(path).write_bytes(b"partial")
        raise RuntimeError("disk full")

    monkeypatch.setitem(rio._WRITERS, suffix, half_write)
    with pytest.raises(RuntimeError, match="disk full"):
        rio.save_scan(make_scan(), tmp_path / f"scan{suffix}")
    assert list(tmp_path.iterdir()) == []


# -- bad files -------------------------------------------------------------------------------
def test_unknown_extension(tmp_path):
    with pytest.raises(RangesimError, match=r"scan\.txt.*\.exr, \.npz, \.pcd, \.ply"):
        rio.save_scan(make_scan(), tmp_path / "scan.txt")
    (tmp_path / "data.abc").write_text("1 2 3\n")
    with pytest.raises(RangesimError, match=r"data\.abc.*\.exr, .*\.npz"):
        rio.load_scan(tmp_path / "data.abc")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.abc"]


@pytest.mark.parametrize("suffix", [".exr", ".npz"])
def test_missing_file(tmp_path, suffix):
    with pytest.raises(RangesimError, match=rf"absent{suffix}: no such file"):
        rio.load_scan(tmp_path / f"absent{suffix}")


@pytest.mark.parametrize("suffix", [".exr", ".npz"])
def test_garbage_and_truncated_files(tmp_path, suffix):
    garbage = tmp_path / f"garbage{suffix}"
    garbage.write_bytes(b"this is not a scan file at all\n" * 10)
    with pytest.raises(RangesimError, match=f"garbage{suffix}"):
        rio.load_scan(garbage)

    good = rio.save_scan(make_scan(), tmp_path / f"good{suffix}")
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(RangesimError, match=f"cut{suffix}"):
        rio.load_scan(cut)


def test_exr_without_rangesim_channels(tmp_path):
    import OpenEXR

    path = tmp_path / "photo.exr"
    rgb = {c: np.zeros((4, 5), np.float32) for c in "RGB"}
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, rgb) as exr:
        exr.write(str(path))
    with pytest.raises(RangesimError, match="photo.exr: not a rangesim scan: missing channel depth"):
        rio.load_scan(path)


def test_npz_without_rangesim_arrays(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, depth=np.zeros((2, 2), np.float32))
    with pytest.raises(RangesimError, match="other.npz: not a rangesim scan: missing array xyz"):
        rio.load_scan(path)


def test_register_reader(tmp_path, monkeypatch):
    monkeypatch.setattr(rio, "_READERS", dict(rio._READERS))
    scan = make_scan()
    seen = {}

    def fake_reader(path, *, scale=1.0):
        seen["args"] = (path, scale)
        return copy.deepcopy(scan)

    rio.register_reader(["pcd", ".MSU"], fake_reader)
    (tmp_path / "a.PCD").write_text("x")
    (tmp_path / "b.msu").write_text("x")
    assert rio.load_scan(tmp_path / "a.PCD", scale=2.0) is not scan
    assert seen["args"] == (tmp_path / "a.PCD", 2.0)
    rio.load_scan(tmp_path / "b.msu")
    assert seen["args"] == (tmp_path / "b.msu", 1.0)


def test_ply_readable_by_open3d(tmp_path):
    o3d = pytest.importorskip("open3d")  # optional ("bench" extra)
    scan = make_scan()
    path = rio.save_scan(scan, tmp_path / "cloud.ply")
    cloud = o3d.t.io.read_point_cloud(str(path))
    assert np.array_equal(cloud.point.positions.numpy(), scan.xyz[scan.valid])
    assert np.array_equal(cloud.point.normals.numpy(), scan.normal[scan.valid])
    assert np.array_equal(cloud.point.intensity.numpy()[:, 0], scan.intensity[scan.valid])


def test_run_timings_stay_out_of_scan_files():
    # the rendered mode's stage timings and kernel-cache counts vary per run: files stay byte-identical
    import json

    from rangesim.io.exr import encode_meta

    text = encode_meta({"seed": 3, "seconds": {"paths": 0.1}, "kernels": {"first_tile": 2}, "frames": 9})
    assert json.loads(text) == {"seed": 3, "frames": 9}


def test_atomic_writes_keep_long_names_permissions_and_links(tmp_path):
    # a file system's 255-byte names failed on the temporary's 14 extra bytes; a replaced 0600
    # file came back 0644; a symlink was replaced by a file and its target never updated
    import os

    from rangesim.core.atomic import atomic_path

    long = tmp_path / ("a" * 246 + ".txt")
    with atomic_path(long) as tmp:
        tmp.write_text("one")
    assert long.read_text() == "one"
    os.chmod(long, 0o600)
    with atomic_path(long) as tmp:
        tmp.write_text("two")
    assert long.read_text() == "two" and os.stat(long).st_mode & 0o777 == 0o600
    target = tmp_path / "runs" / "42.txt"
    target.parent.mkdir()
    target.write_text("old")
    link = tmp_path / "latest.txt"
    link.symlink_to(Path("runs") / "42.txt")
    with atomic_path(link) as tmp:
        tmp.write_text("new")
    assert link.is_symlink() and target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.rglob("*") if p.name.startswith(".")) == []  # no temporaries left


def test_atomic_write_errors_name_the_final_file(tmp_path):
    """An OSError on the temporary name (a read-only folder) names the file the user asked for
    ("out/sweep.json: Read-only file system", not ".sweep.tmp-....json"), and leaves nothing."""
    from rangesim.core.atomic import atomic_path

    with pytest.raises(PermissionError) as info:
        with atomic_path(tmp_path / "sweep.json") as tmp:
            raise PermissionError(13, "Permission denied", str(tmp))
    assert info.value.filename == str(tmp_path / "sweep.json") and info.value.strerror == "Permission denied"
    assert list(tmp_path.iterdir()) == []


def test_exr_write_failure_is_one_line_naming_the_file(tmp_path, monkeypatch):
    """A full disk made OpenEXR raise a bare RuntimeError naming the temporary file (an 'internal
    error' on the CLI); it is now a RangesimError naming the file asked for, and nothing is left."""
    import OpenEXR

    import rangesim.io.exr as exr_module

    class FullDisk:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, name):
            open(name, "wb").write(b"partial")
            raise RuntimeError(f'Failed to write pixel data to image file "{name}". No space left on device.')

    monkeypatch.setattr(exr_module.OpenEXR, "File", FullDisk)
    assert OpenEXR.File is FullDisk
    target = tmp_path / "scan.exr"
    with pytest.raises(rs.RangesimError) as info:
        rs.datasets.plate_scan().save(target)
    assert str(info.value) == f"{target}: cannot write file (No space left on device)"
    assert list(tmp_path.iterdir()) == []
