"""A bounded, seeded fuzz pass over every reader (issue 16): random bytes, randomly truncated and
corrupted copies of the shared data files and of files rangesim writes. Every read must end in a
clean RangesimError or a correct read, never another exception or a hang."""
from __future__ import annotations

import signal
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.errors import RangesimError
from rangesim.core.rangescan import RangeScan

#: seconds any one read may take before it counts as a hang
PER_READ_S = 8
#: the whole fuzz pass stops drawing new cases after this many seconds
BUDGET_S = 16.0

#: shared data files fuzzed (relative to the data folder), the small ones of each kind
DATA_FILES = [
    "stanford-bunny/bun000.ply",
    "stanford-bunny/bun.conf",
    "stanford-bunny/reconstruction/bun_zipper_res4.ply",
    "mosd-kinect/test0.pcd",
    "pcl-organized/milk_cartoon_all_small_clorox.pcd",
    "machined-targets/st_4_40k_occ.ply",
    "machined-targets/shapes_pose.json",
    "machined-targets/FlatTargetv3_stats.yml",
]


def _read_scan(path: Path):
    scan = rs.load_scan(path)
    assert isinstance(scan, RangeScan)
    h, w = scan.shape
    assert scan.depth.shape == (h, w) and scan.status.shape == (h, w) and scan.xyz.shape == (h, w, 3)
    return scan


def _read_mesh(path: Path):
    from rangesim.cad.models import load_model

    mesh = load_model(path)
    assert len(mesh.faces) > 0 and np.isfinite(mesh.vertices).all()
    return mesh


def _read_conf(path: Path):
    from rangesim.recorded.conf import read_conf

    poses = read_conf(path)
    assert all(np.asarray(p).shape == (4, 4) for p in poses.values())
    return poses


def _read_yml(path: Path):
    from rangesim.recorded.features_yml import parse_block_yaml

    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        return None  # not text: the readers of .yml files decode first (tested below by read_features_yml)
    return parse_block_yaml(text)


def _read_features_yml(path: Path):
    from rangesim.recorded.features_yml import read_features_yml

    return read_features_yml(path, sharp_only=False)


def _read_pose(path: Path):
    from rangesim.cli.main import _load_pose

    pose = _load_pose(path)
    assert pose.shape == (4, 4)
    return pose


#: suffix -> readers of files with it
READERS = {
    ".exr": [_read_scan], ".npz": [_read_scan], ".ply": [_read_scan, _read_mesh], ".pcd": [_read_scan],
    ".msu": [_read_scan], ".xyz": [_read_scan], ".stl": [_read_mesh], ".obj": [_read_mesh], ".off": [_read_mesh],
    ".glb": [_read_mesh], ".conf": [_read_conf], ".yml": [_read_yml, _read_features_yml], ".json": [_read_pose],
    ".npy": [_read_pose],
}


class Hang(Exception):
    pass


@contextmanager
def _deadline(seconds: int):
    def on_alarm(signum, frame):
        raise Hang(f"read took more than {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _check(reader, path: Path, label: str) -> None:
    try:
        with _deadline(PER_READ_S), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reader(path)
    except RangesimError as exc:
        message = str(exc)
        assert message and "\n" not in message, (label, message)
    except Hang as exc:
        pytest.fail(f"{label}: {reader.__name__} hangs: {exc}")
    except Exception as exc:  # noqa: BLE001 -- the point of the test
        pytest.fail(f"{label}: {reader.__name__} raised {type(exc).__name__}: {exc}")


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> list[Path]:
    """Small files of every kind rangesim writes, to truncate and corrupt."""
    import trimesh

    from rangesim.recorded.msu import write_msu

    d = tmp_path_factory.mktemp("fuzz_written")
    sensor = rs.load_sensor({
        "name": "fuzz", "camera": {"width": 24, "height": 16, "fov_deg": 40.0}, "laser": {"baseline": 150.0},
        "range": {"near": 100.0, "far": 1000.0},
    })
    box = trimesh.creation.box(extents=(80.0, 60.0, 40.0))
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
    pose[2, 3] = 400.0
    scan = rs.scan([box], sensor, pose=pose)
    files = []
    for suffix in (".exr", ".npz", ".ply", ".pcd"):
        path = d / f"scan{suffix}"
        rs.save_scan(scan, path)
        files.append(path)
    files.append(write_msu(scan, d / "scan.msu"))
    points = scan.xyz[scan.valid]
    (d / "scan.xyz").write_text("".join(f"{x:.3f} {y:.3f} {z:.3f}\n" for x, y, z in points))
    files.append(d / "scan.xyz")
    for suffix in (".stl", ".obj", ".off", ".glb"):
        path = d / f"box{suffix}"
        data = box.export(file_type=suffix[1:])
        path.write_bytes(data if isinstance(data, bytes) else data.encode())
        files.append(path)
    np.save(d / "pose.npy", pose)
    files.append(d / "pose.npy")
    return files


def _variants(raw: bytes, rng: np.random.Generator, n: int):
    """Truncations at random points (most in the first kilobytes, where headers are), and byte flips."""
    size = len(raw)
    for k in range(n):
        if k % 3 == 2 and size:
            data = bytearray(raw)
            at = rng.integers(0, size, size=max(1, min(64, size // 100)))
            data_arr = np.frombuffer(bytes(data), np.uint8).copy()
            data_arr[at] = rng.integers(0, 256, size=len(at), dtype=np.uint8)
            yield f"flip{k}", data_arr.tobytes()
        else:
            cut = int(rng.integers(0, min(size, 4096))) if k % 3 == 0 else int(rng.integers(0, max(size, 1)))
            yield f"cut{k}@{cut}", raw[:cut]


def test_random_bytes_to_every_reader(tmp_path):
    rng = np.random.default_rng(16)
    start = time.perf_counter()
    for suffix, readers in READERS.items():
        for k in range(15):
            if time.perf_counter() - start > BUDGET_S / 4:
                return
            n = int(rng.choice([0, 1, 7, 84, 300, 5000]))
            data = rng.integers(0, 256, size=n, dtype=np.uint8).tobytes()
            if k % 5 == 4:  # text-like garbage: digits, spaces, newlines, a header word
                data = b"ply\nformat ascii 1.0\n" if suffix == ".ply" else b""
                data += bytes(rng.choice(list(b"0123456789 .-e\nnan"), size=400))
            path = tmp_path / f"random{k}{suffix}"
            path.write_bytes(data)
            for reader in readers:
                _check(reader, path, f"{path.name} ({n} random bytes)")


def test_truncated_and_corrupted_written_files(written, tmp_path):
    rng = np.random.default_rng(1616)
    start = time.perf_counter()
    for source in written:
        raw = source.read_bytes()
        for label, data in _variants(raw, rng, 18):
            if time.perf_counter() - start > BUDGET_S / 4:
                return
            path = tmp_path / f"{label}_{source.name}"
            path.write_bytes(data)
            for reader in READERS[source.suffix]:
                _check(reader, path, f"{source.name} {label}")


def test_truncated_and_corrupted_shared_data(data_dir, tmp_path):
    rng = np.random.default_rng(161616)
    start = time.perf_counter()
    for rel in DATA_FILES:
        source = data_dir / rel
        if not source.is_file():
            continue
        raw = source.read_bytes()
        for label, data in _variants(raw, rng, 12):
            if time.perf_counter() - start > BUDGET_S / 2:
                return
            # keep the file's name (the yml reader looks for a sibling by name), in a folder per variant
            folder = tmp_path / f"{source.stem}_{label.replace('@', '_')}"
            folder.mkdir()
            path = folder / source.name
            path.write_bytes(data)
            readers = READERS[source.suffix]
            if source.name.endswith("_stats.yml"):
                readers = [_read_yml]
            for reader in readers:
                _check(reader, path, f"{rel} {label}")
