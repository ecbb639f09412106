"""Readers for recorded range data: Cyberware PLY + .conf, PCD, MSU, point lists, LZF."""
from __future__ import annotations

import gzip
import struct
import warnings

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import rangesim as rs
import rangesim.recorded as rec
from rangesim.core.constants import Status
from rangesim.core.errors import RangesimError
from rangesim.recorded.lzf import LZFError, lzf_decompress, lzf_store


def expect_error(path, pattern, call=None, **kwargs):
    """``call(path)`` (default rs.load_scan) raises a one-line RangesimError naming the file."""
    with pytest.raises(RangesimError, match=pattern) as info:
        (call or rs.load_scan)(path, **kwargs)
    message = str(info.value)
    assert "\n" not in message and path.name in message
    return message


def small_scan(h=3, w=4, seed=0):
    """A recorded-like scan with a few invalid pixels (mm)."""
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-500, 500, (h, w, 3)).astype(np.float32)
    xyz[..., 2] += 1000
    valid = rng.random((h, w)) > 0.25
    valid[0, 0], valid[-1, -1] = False, True
    xyz[~valid] = np.nan
    return rec.grid_scan(xyz, {"units": "mm"})


# -- Stanford bunny (shared data) --------------------------------------------------------------
def test_bunny_range_grid(data_dir):
    scan = rs.load_scan(data_dir / "stanford-bunny" / "bun000.ply")
    assert scan.shape == (400, 512)
    assert scan.valid.sum() == scan.meta["vertex_count"] == 40256  # every vertex sits in one cell
    assert 30_000 <= scan.valid.sum() <= 41_000
    assert set(np.unique(scan.status)) == {Status.VALID, Status.MISS}
    assert np.isnan(scan.xyz[~scan.valid]).all() and np.isfinite(scan.xyz[scan.valid]).all()
    assert np.array_equal(scan.depth[scan.valid], scan.xyz[..., 2][scan.valid])
    assert scan.xyz_true is None and scan.K is None and (scan.part == -1).all()
    assert scan.meta["frame"] == "scanner" and scan.meta["units"] == "mm"
    scanner = scan.meta["scanner"]
    assert scanner["echo_lgincr"] == 0.0005 and scanner["echo_frames"] == 512 and scanner["num_rows"] == 400
    # along a row, neighbouring cells step 0.5 mm in x (the sweep), y nearly constant
    row = scan.xyz[200]
    cols = np.flatnonzero(scan.valid[200])
    step = np.diff(row[cols], axis=0)[np.diff(cols) == 1]
    assert np.median(step[:, 0]) == pytest.approx(0.5, abs=0.01)
    assert abs(np.median(step[:, 1])) < 0.05
    assert 20 < np.nanmedian(scan.depth) < 80  # metres converted to mm


def test_bunny_conf_pose_puts_scans_on_the_mesh(data_dir):
    bunny = data_dir / "stanford-bunny"
    mesh = trimesh.load(bunny / "reconstruction" / "bun_zipper.ply", process=False)
    tree = cKDTree(np.asarray(mesh.vertices) * 1000.0)  # metres -> mm
    scan = rs.load_scan(bunny / "bun045.ply", conf=bunny / "bun.conf")
    assert scan.meta["pose_source"] == {"conf": "bun.conf"}
    assert np.median(tree.query(scan.points("world"))[0]) < 2.0
    assert np.median(tree.query(scan.points())[0]) > 10.0  # the pose matters
    assert np.allclose(rs.load_scan(bunny / "bun000.ply", conf=bunny / "bun.conf").pose, np.eye(4))


def test_conf_errors(data_dir, tmp_path):
    bunny = data_dir / "stanford-bunny"
    bad = tmp_path / "bad.conf"
    bad.write_text("bmesh bun000.ply 0 0 nan 0 0 0 1\n")
    with pytest.raises(RangesimError, match=r"bad\.conf: line 1: expected 'bmesh FILE tx ty tz qx qy qz qw'"):
        rs.load_scan(bunny / "bun000.ply", conf=bad)
    other = tmp_path / "other.conf"
    other.write_text("camera 0 0 0 0 0 0 1\nbmesh x.ply 0 0 0 0 0 0 1\n")
    with pytest.raises(RangesimError, match=r"other\.conf: no 'bmesh bun000\.ply' line \(it has: x\.ply\)"):
        rs.load_scan(bunny / "bun000.ply", conf=other)
    with pytest.raises(RangesimError, match=r"absent\.conf: no such file"):
        rs.load_scan(bunny / "bun000.ply", conf=tmp_path / "absent.conf")


# -- Cyberware PLY (synthetic) ---------------------------------------------------------------
def cyberware_text(
    rows=2, cols=3, grid=("1 0", "0", "1 1", "0", "1 2", "0"), vertices=None, extra_header=(), cells=None
):
    vertices = vertices or ["0.001 0.002 0.05", "0.0015 0.002 0.051", "0.002 0.0027 0.052"]
    lines = [
        "ply", "format ascii 1.0", "obj_info is_cyberware_data 1",
        f"obj_info num_cols {cols}", f"obj_info num_rows {rows}", "obj_info echo_lgincr 0.000500",
        *extra_header,
        f"element vertex {len(vertices)}", "property float x", "property float y", "property float z",
        f"element range_grid {cells or len(grid)}", "property list uchar int vertex_indices", "end_header",
        *vertices, *grid,
    ]
    return "\r\n".join(lines) + "\r\n"


def test_cyberware_small_grid(tmp_path):
    path = tmp_path / "tiny.ply"
    path.write_text(cyberware_text())
    scan = rs.load_scan(path)
    assert scan.shape == (2, 3)
    assert scan.valid.tolist() == [[True, False, True], [False, True, False]]
    assert np.allclose(scan.xyz[0, 0], [1.0, 2.0, 50.0]) and np.allclose(scan.xyz[1, 1], [2.0, 2.7, 52.0])
    assert scan.meta["scanner"]["echo_lgincr"] == 0.0005
    assert rec.read_cyberware_ply(path).valid.sum() == 3


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"rows": 3}, r"range_grid has 6 cells but num_rows x num_cols = 3 x 3 = 9"),
        ({"grid": ("1 0", "0", "1 1", "0", "1 7", "0")}, r"line 5: vertex index 7 out of range"),
        ({"grid": ("1 0", "0", "2 1", "0", "1 2", "0")}, r"line 3: declares 2 vertex indices but holds 1"),
        ({"grid": ("1 0", "0", "1 1", "0", "1 2"), "cells": 6}, r"range_grid data: expected 6 lines, the file has 5"),
        ({"extra_header": ("obj_info echo_frames nan",)}, r"obj_info echo_frames is 'nan', not a finite number"),
        ({"vertices": ["0.001 0.002", "0.1 0.1 0.1", "0.2 0.2 0.2"]}, r"vertex data: expected 3 lines of 3 numbers"),
        ({"vertices": ["0.001 0.002 x", "0.1 0.1 0.1", "0.2 0.2 0.2"]}, r"vertex data: expected whitespace-separated"),
    ],
)
def test_cyberware_bad_files(tmp_path, kwargs, pattern):
    path = tmp_path / "broken.ply"
    text = cyberware_text(**{k: v for k, v in kwargs.items() if k != "rows"})
    if "rows" in kwargs:
        text = text.replace("obj_info num_rows 2", f"obj_info num_rows {kwargs['rows']}")
    path.write_text(text)
    expect_error(path, pattern)


def test_ply_header_errors(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_text(cyberware_text().replace("element vertex 3", "element vertex nan"))
    expect_error(path, r"element vertex count 'nan' is not a non-negative integer")
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\n")
    expect_error(path, r"no end_header")
    path.write_bytes(b"\x00garbage")
    expect_error(path, r"not a PLY file")
    # a comment that mentions end_header does not end the header
    text = cyberware_text().replace("format ascii 1.0\r\n", "format ascii 1.0\r\ncomment written before end_header\r\n", 1)
    assert "comment written" in text
    path.write_bytes(text.encode())
    assert rs.load_scan(path).shape == (2, 3)


# -- point lists -------------------------------------------------------------------------------
def test_rangesim_ply_export_reads_back_as_point_list(tmp_path):
    scan = small_scan()
    scan.pose = np.array([[0, -1, 0, 10.5], [1, 0, 0, -3.0], [0, 0, 1, 7.25], [0, 0, 0, 1]], float)
    back = rs.load_scan(rs.save_scan(scan, tmp_path / "cloud.ply"))
    assert back.shape == (1, scan.valid.sum()) and back.valid.all()
    assert np.array_equal(back.xyz[0], scan.xyz[scan.valid]) and np.array_equal(back.pose, scan.pose)
    assert back.meta["organized"] is False and back.meta["frame"] == "file"


def test_xyz_text_as_other_tools_write_it(tmp_path):
    """XYZ files as CloudCompare, spreadsheets and scripts export them: commas or semicolons
    between columns, a first line of column names; a decimal comma, a word among the numbers
    and a ragged line are refused naming the file's line; a point list under 2 mm across is
    named as probably metres (it read as mm)."""
    pts = np.random.default_rng(0).uniform(0, 100, (20, 3))
    plain = tmp_path / "plain.xyz"
    np.savetxt(plain, pts)
    want = rs.load_scan(plain).xyz
    for name, text in (("comma.xyz", "\n".join(",".join(map(str, p.tolist())) for p in pts)),
                       ("semi.xyz", "\n".join("; ".join(map(str, p.tolist())) for p in pts)),
                       ("header.xyz", "x y z\n" + "\n".join(" ".join(map(str, p.tolist())) for p in pts)),
                       ("cc.xyz", "//X,Y,Z,R,G,B\n" + "\n".join(",".join(map(str, [*p.tolist(), 1, 2, 3])) for p in pts)),
                       ("units.xyz", "x[mm] y[mm] z[mm]\n" + "\n".join(" ".join(map(str, p.tolist())) for p in pts)),
                       ("trailing.xyz", "\n".join(",".join(map(str, p.tolist())) + "," for p in pts)),
                       ("decimal.xyz", "\n".join(";".join(str(v).replace(".", ",") for v in p.tolist()) for p in pts))):
        (tmp_path / name).write_text(text)
        np.testing.assert_array_equal(rs.load_scan(tmp_path / name).xyz, want, err_msg=name)
    bad = tmp_path / "bad.xyz"
    for text, words in (("1,5 2,5 3,5\n", r"line 1: a column holds spaces .*decimal commas"),
                        ("# c\n1 2 3\n4 5 x\n", r"line 3: not numbers: '4 5 x'"),
                        ("1 2 3\n\n4 5\n", r"line 1 has 3, line 3 has 2")):
        bad.write_text(text)
        expect_error(bad, words)
    metres = tmp_path / "metres.xyz"
    np.savetxt(metres, pts / 1000)
    with pytest.warns(UserWarning, match=r"span 0\.0\d+ mm at most \(written in metres\? pass units='m'\)"):
        rs.load_scan(metres)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_allclose(rs.load_scan(metres, units="m").xyz, want, rtol=1e-6)


def test_a_pcd_written_in_millimetres_is_named(tmp_path):
    """PCD coordinates are metres: a frame written in mm reads 1000x too far (a plate at
    0.3 m as 300 m) and gets a warning saying so; the same frame in metres is quiet."""
    metres = tmp_path / "m.pcd"
    rs.datasets.plate_scan().save(metres)
    scan, _ = rec.read_pcd(metres)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec.read_pcd(metres)
    scan.xyz = scan.xyz * 1000
    millimetres = tmp_path / "mm.pcd"
    rec.write_pcd(scan, millimetres)
    with pytest.warns(UserWarning, match=r"mm.pcd: its points lie \d+ m from the sensor \(median\); PCD coordinates "
                                         r"are metres: was the file written in millimetres\?"):
        rec.read_pcd(millimetres)


def test_xyz_and_npz_point_lists(tmp_path):
    xyz = tmp_path / "pts.xyz"
    xyz.write_text("# x y z r g b\n1 2 3 0 0 0\n4 5 6 1 1 1\n\nnan 0 0 2 2 2\n")
    scan = rs.load_scan(xyz)
    assert scan.shape == (1, 3) and scan.valid.tolist() == [[True, True, False]]
    assert np.array_equal(scan.xyz[0, :2], [[1, 2, 3], [4, 5, 6]]) and scan.meta["xyz_columns"] == 6
    assert np.array_equal(rs.load_scan(xyz, units="cm").xyz[0, 1], [40, 50, 60])
    xyz.write_text("1 2 3\n4 5\n")
    expect_error(xyz, r"XYZ data: every line needs the same number")
    xyz.write_text("1 2 3\n4 5\n6 7 8 9\n")  # 9 numbers: once read as (1,2,3), (4,5,6), (7,8,9)
    expect_error(xyz, r"line 1 has 3, line 2 has 2")

    npz = tmp_path / "pts.npz"
    points = np.arange(12, dtype=np.float64).reshape(4, 3)
    np.savez(npz, points=points, normals=np.tile([0.0, 0.0, 1.0], (4, 1)))
    scan = rs.load_scan(npz)
    assert np.array_equal(scan.xyz[0], points) and np.array_equal(scan.normal[0, :, 2], np.ones(4))
    np.savez(npz, points=np.zeros((4, 2)))
    expect_error(npz, r"'points' array of shape \(N, 3\)")
    # a rangesim scan .npz still goes to the exact scan reader
    full = small_scan()
    assert np.array_equal(rs.load_scan(rs.save_scan(full, tmp_path / "scan.npz")).valid, full.valid)


def test_mesh_ply_is_not_a_scan(tmp_path):
    path = tmp_path / "box.ply"
    trimesh.creation.box().export(path)
    expect_error(path, r"a mesh with 12 faces, not a scan")


# -- PCD -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("shape", [(3, 4), (1, 7)])
def test_pcd_round_trip(tmp_path, data, shape):
    scan = small_scan(*shape, seed=1)
    rng = np.random.default_rng(2)
    extras = {
        "label": rng.integers(0, 40, shape).astype(np.uint32),
        "rgba": rng.integers(0, 2**32, shape, dtype=np.uint32),
        "hist": rng.normal(size=shape + (3,)).astype(np.float32),
        "flag": rng.integers(-5, 5, shape).astype(np.int16),
    }
    exact = rec.write_pcd(scan, tmp_path / "exact.pcd", data=data, extras=extras, precision="float64")
    back, back_extras = rec.read_pcd(exact)
    assert back.shape == shape and back.meta["organized"] == (shape[0] > 1)
    assert np.array_equal(back.valid, scan.valid)
    assert np.array_equal(back.xyz, scan.xyz, equal_nan=True)  # float64 metres: exact
    assert back.meta["pcd_fields"] == ["x", "y", "z", "label", "rgba", "hist", "flag"]
    for name, value in extras.items():
        assert back_extras[name].dtype == value.dtype and np.array_equal(back_extras[name], value)
    # PCD floats are 4 or 8 bytes: float16 is written as F 4 (it once wrote F 2, which no reader takes)
    half = rng.normal(size=shape).astype(np.float16)
    back_half = rec.read_pcd(rec.write_pcd(scan, tmp_path / "half.pcd", data=data, extras={"h": half}))[1]["h"]
    assert back_half.dtype == np.float32 and np.array_equal(back_half, half.astype(np.float32))
    single = rec.read_pcd(rec.write_pcd(scan, tmp_path / "single.pcd", data=data))[0]
    ulp = np.spacing(np.abs(scan.xyz[scan.valid]))
    assert (np.abs(single.xyz[scan.valid] - scan.xyz[scan.valid]) <= ulp).all()  # float32 metres


def test_pcd_hand_written_ascii_and_binary(tmp_path):
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\n"
        "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA {}\n"
    )
    ascii_pcd = tmp_path / "a.pcd"
    ascii_pcd.write_text(header.format("ascii") + "0.001 0.002 0.5 7\nnan nan nan 0\n-0.25 0 1 65535\n")
    scan, extras = rec.read_pcd(ascii_pcd)
    assert scan.valid.tolist() == [[True, False, True]]
    assert np.allclose(scan.xyz[0, [0, 2]], [[1, 2, 500], [-250, 0, 1000]])
    assert extras["label"].tolist() == [[7, 0, 65535]] and extras["label"].dtype == np.uint16
    ascii_pcd.write_text(header.format("ascii") + "0.001 0.002 0.5 7\nnan nan nan 0\n-0.25 0 1 65536\n")
    expect_error(ascii_pcd, r"integer field label holds values outside its type uint16 \(0..65535\): 0..65536",
                 call=rec.read_pcd)  # once wrapped to 0
    scan = small_scan()
    big = rec.write_pcd(scan, tmp_path / "big.pcd", data="ascii", extras={"id": np.full(scan.shape, 2**64 - 1, np.uint64)})
    expect_error(big, r"64-bit integer field id holds values of 2\*\*53 or more", call=rec.read_pcd)  # once read as 0
    small_ids = rec.write_pcd(scan, tmp_path / "ids.pcd", data="ascii", extras={"id": np.full(scan.shape, 7, np.int64)})
    assert (rec.read_pcd(small_ids)[1]["id"] == 7).all()
    # binary with a PCL padding field "_" between z and label
    binary = tmp_path / "b.pcd"
    text = header.format("binary").replace("FIELDS x y z label", "FIELDS x y z _ label")
    text = text.replace("SIZE 4 4 4 2", "SIZE 4 4 4 1 2").replace("TYPE F F F U", "TYPE F F F U U")
    text = text.replace("COUNT 1 1 1 1", "COUNT 1 1 1 2 1")
    records = b"".join(struct.pack("<fffxxH", *p) for p in [(0.001, 0.002, 0.5, 7), (1, 2, 3, 9), (4, 5, 6, 11)])
    binary.write_bytes(text.encode() + records)
    scan, extras = rec.read_pcd(binary)
    assert np.allclose(scan.xyz[0, 1], [1000, 2000, 3000]) and extras["label"].tolist() == [[7, 9, 11]]
    assert "_" not in extras and scan.meta["pcd_fields"] == ["x", "y", "z", "label"]


def test_pcd_bad_files(tmp_path):
    scan = small_scan()
    good = rec.write_pcd(scan, tmp_path / "good.pcd", data="binary").read_bytes()
    head = good[: good.index(b"DATA binary\n") + len(b"DATA binary\n")]
    path = tmp_path / "broken.pcd"
    path.write_bytes(good[:-5])
    expect_error(path, r"truncated: 12 points need 144 bytes of binary data, the file has 139")
    path.write_bytes(good.replace(b"POINTS 12", b"POINTS 10"))
    expect_error(path, r"POINTS 10 but WIDTH x HEIGHT = 4 x 3 = 12")
    path.write_bytes(good.replace(b"WIDTH 4", b"WIDTH nan"))
    expect_error(path, r"WIDTH 'nan' is not a positive integer")
    path.write_bytes(good.replace(b"VIEWPOINT 0 0 0", b"VIEWPOINT nan 0 0"))
    expect_error(path, r"VIEWPOINT .* is not 7 finite numbers")
    path.write_bytes(good.replace(b"DATA binary", b"DATA binary_lzma"))
    expect_error(path, r"unknown DATA 'binary_lzma'")
    path.write_bytes(good.replace(b"SIZE 4 4 4", b"SIZE 4 4"))
    expect_error(path, r"SIZE has 2 entries for 3 FIELDS")
    path.write_bytes(head.replace(b"FIELDS x y z", b"FIELDS a y z") + good[len(head):])
    expect_error(path, r"no x field", call=rec.read_pcd)
    path.write_bytes(head)
    expect_error(path, r"truncated")
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    expect_error(path, r"no DATA line|not a PCD file")
    compressed = rec.write_pcd(scan, tmp_path / "c.pcd", data="binary_compressed").read_bytes()
    path.write_bytes(compressed[:-10])
    expect_error(path, r"truncated: compressed data is \d+ bytes")
    start = compressed.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    corrupt = bytearray(compressed)
    corrupt[start + 8] = 0xE0  # the first token becomes a back reference into nothing
    path.write_bytes(bytes(corrupt))
    expect_error(path, r"corrupt binary_compressed data: back reference")
    ascii_pcd = rec.write_pcd(scan, tmp_path / "d.pcd", data="ascii").read_text()
    path.write_text(ascii_pcd.rsplit("\n", 3)[0] + "\n")
    expect_error(path, r"expected 12 points x 3 values = 36 numbers, found 30 \(truncated\)")


def test_mosd_binary_compressed(data_dir):
    path = data_dir / "mosd-kinect" / "test0.pcd"
    scan, extras = rec.read_pcd(path)
    assert scan.shape == (480, 640) and scan.meta["pcd"]["data"] == "binary_compressed"
    assert set(extras) == {"label", "rgba"} and extras["label"].shape == (480, 640)
    labels = np.unique(extras["label"])
    assert labels[0] == 0 and set(labels) <= {0, *range(1, 10), *range(20, 100)} and (labels >= 20).any()
    assert np.array_equal(extras["label"] == 0, ~scan.valid)  # label 0: no data (NaN point)
    depth = scan.depth[scan.valid]
    assert 300 < depth.min() and depth.max() < 3000  # a table-top scene in mm
    assert rs.load_scan(path).meta["pcd_fields"] == ["label", "x", "y", "z", "rgba"]


def test_mosd_matches_open3d(data_dir):
    o3d = pytest.importorskip("open3d")  # optional ("bench" extra): an independent PCD reader
    path = data_dir / "mosd-kinect" / "test0.pcd"
    scan, extras = rec.read_pcd(path)
    cloud = o3d.t.io.read_point_cloud(str(path), remove_nan_points=False)
    metres = cloud.point.positions.numpy()
    ok = np.isfinite(metres).all(axis=1)
    assert np.array_equal(ok, scan.valid.ravel())
    assert np.array_equal((metres[ok].astype(np.float64) * 1000).astype(np.float32), scan.xyz.reshape(-1, 3)[ok])
    assert np.array_equal(cloud.point.label.numpy()[:, 0], extras["label"].ravel())


def test_pcl_milk_cartoon(data_dir):
    scan = rs.load_scan(data_dir / "pcl-organized" / "milk_cartoon_all_small_clorox.pcd")
    assert scan.shape == (480, 640) and scan.meta["pcd_fields"] == ["x", "y", "z", "rgba"]
    assert 100_000 < scan.valid.sum() < 480 * 640


# -- LZF -------------------------------------------------------------------------------------------
def lzf_compress(data: bytes) -> bytes:
    """A small greedy LZF compressor (test reference: produces literals and back references)."""
    out, literal, table, i = bytearray(), bytearray(), {}, 0

    def flush():
        for k in range(0, len(literal), 32):
            chunk = literal[k:k + 32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
        literal.clear()

    while i < len(data):
        key, ref = data[i:i + 3], None
        if len(key) == 3:
            ref, table[key] = table.get(key), i
        if ref is not None and 0 < i - ref <= 8192:
            length = 3
            while i + length < len(data) and length < 264 and data[ref + length] == data[i + length]:
                length += 1
            flush()
            off, n = i - ref - 1, length - 2
            if n < 7:
                out += bytes([(n << 5) | (off >> 8), off & 0xFF])
            else:
                out += bytes([(7 << 5) | (off >> 8), n - 7, off & 0xFF])
            i += length
        else:
            literal.append(data[i])
            i += 1
    flush()
    return bytes(out)


def test_lzf_hand_made_stream():
    # "abc" literal, then a 9-byte overlapping reference 3 back, then a 12-byte one (length byte)
    stream = bytes([2]) + b"abc" + bytes([(7 << 5) | 0, 0, 2]) + bytes([(7 << 5) | 0, 5 - 0, 11])
    expected = b"abc" * 4 + (b"abc" * 5)[:14]
    assert lzf_decompress(stream, len(expected)) == expected


def test_lzf_round_trips():
    rng = np.random.default_rng(3)
    samples = [
        b"",
        bytes(1000),
        rng.integers(0, 256, 5000, dtype=np.uint8).tobytes(),
        np.repeat(rng.integers(0, 4, 4000, dtype=np.uint8), rng.integers(1, 40, 4000)).tobytes(),
        (b"range scanner " * 300) + np.arange(3000, dtype=np.uint16).tobytes(),
    ]
    for data in samples:
        packed = lzf_compress(data)
        assert lzf_decompress(packed, len(data)) == data
        assert lzf_decompress(lzf_store(data), len(data)) == data
    assert len(lzf_compress(samples[1])) < 40  # back references really were exercised


@pytest.mark.parametrize(
    "stream, size, pattern",
    [
        (bytes([5]) + b"abc", 6, "runs past the end"),
        (bytes([0]) + b"a" + bytes([0x20, 5]), 4, "points before the start"),
        (bytes([0]) + b"a" + bytes([0xE0]), 20, "truncated"),
        (bytes([2]) + b"abc", 5, "decodes to 3 bytes, expected 5"),
        (bytes([2]) + b"abc", 2, "more than the declared 2"),
    ],
)
def test_lzf_corrupt_streams(stream, size, pattern):
    with pytest.raises(LZFError, match=pattern):
        lzf_decompress(stream, size)


# -- MSU ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["part.msu", "part.msu.gz"])
def test_msu_round_trip(tmp_path, name):
    scan = small_scan(5, 6, seed=4)
    path = rec.write_msu(scan, tmp_path / name)
    assert path.read_bytes()[:2] == (b"\x1f\x8b" if name.endswith(".gz") else b"5 ")
    back = rs.load_scan(path)
    assert back.shape == (5, 6) and back.meta["frame"] == "scanner"
    assert np.array_equal(back.valid, scan.valid)
    assert np.array_equal(back.xyz, scan.xyz, equal_nan=True) and np.array_equal(back.depth, scan.depth, equal_nan=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # atomic: no temporary left


@pytest.mark.parametrize(
    "header", ["rows: 2\ncolumns: 3\nWhite Scanner", "Number of rows = 2, cols = 3\n\nflag X Y Z", "2x3 image\nMSU\n"]
)
def test_msu_header_wordings(tmp_path, header):
    path = tmp_path / "scan.msu"
    values = ["1 0 1", "1 1 0"] + ["1.5 2 3", "4 5 6"] * 3
    path.write_text(header + "\n" + "\n".join(values) + "\n")
    scan = rs.load_scan(path)
    assert scan.shape == (2, 3) and scan.valid.tolist() == [[True, False, True], [True, True, False]]
    assert scan.xyz[0, 0].tolist() == [1.5, 1.5, 1.5] and np.isnan(scan.xyz[0, 1]).all()


def test_msu_bad_files(tmp_path):
    path = tmp_path / "bad.msu"
    path.write_text("2 rows\n3 cols\n\n" + "1 " * 23)
    expect_error(path, r"expected 4 images of 2 x 3 = 24 numbers after the header, found 23 \(truncated\)")
    path.write_text("nan rows\n3 cols\n\n" + "1 " * 24)
    expect_error(path, r"NaN or infinity in the header")
    path.write_text("rows\ncols\n\n" + "1 " * 24)
    expect_error(path, r"does not give two positive integers")
    path.write_text("-2 rows\n3 cols\n\n" + "1 " * 24)  # the sign was dropped: read as 2 rows
    expect_error(path, r"does not give two positive integers \(rows, columns\): '-2 rows")
    path.write_text("2 rows\n3 cols\n")
    expect_error(path, r"fewer than 3 header lines")
    gz = tmp_path / "bad.msu.gz"
    gz.write_bytes(gzip.compress(b"2 rows\n3 cols\n\n" + b"1 " * 24)[:-8])
    expect_error(gz, r"corrupt gzip data")
    path.write_text("2 rows\n3 cols\n\n1 0 2 1 1 0.5 " + "1 " * 18)  # flags 2 and 0.5 were "no surface"
    expect_error(path, r"the flag image must hold 0 or 1; 2 values do not \(row 0, column 2: 2\)")


# -- dispatch ------------------------------------------------------------------------------------------
def test_load_scan_options_and_missing_files(tmp_path):
    path = rec.write_msu(small_scan(), tmp_path / "a.msu")
    expect_error(path, r"MSU files take no option colour \(options: units, conf\)", colour=True)
    expect_error(tmp_path / "absent.pcd", r"absent\.pcd: no such file")
    expect_error(tmp_path / "absent.pcd", r"absent\.pcd: no such file", call=rec.read_pcd)
    other = tmp_path / "scan.gz"
    other.write_bytes(gzip.compress(b"x"))
    expect_error(other, r"cannot read scans from '\.gz' files")


def test_far_coordinates_warn_of_float32_steps(tmp_path):
    import dataclasses
    import warnings

    scan = small_scan()
    near = rec.write_pcd(scan, tmp_path / "near.pcd", precision="float64")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec.read_pcd(near)  # plain millimetres: no warning
    shifted = dataclasses.replace(scan, xyz=scan.xyz.astype(np.float64) + [5e8, 4e9, 0.0])
    far = rec.write_pcd(shifted, tmp_path / "far.pcd", precision="float64")
    # georeferenced points once landed on a 256 mm lattice without a word
    with pytest.warns(RuntimeWarning, match=r"far.pcd: coordinates reach 4e\+09 mm, where float32 steps by "
                                            r"256 mm; a scan stores float32: subtract an offset"):
        rec.read_pcd(far)


def test_msu_written_in_inches_reads_back_in_millimetres(tmp_path):
    # write_msu names its unit in the header; the reader took every file as mm (25.4x too small)
    scan = small_scan()
    path = rec.write_msu(scan, tmp_path / "inch.msu", units="in")
    back = rs.load_scan(path)
    assert back.meta["msu_units"] == "in"
    assert np.allclose(back.xyz[back.valid], scan.xyz[scan.valid], rtol=1e-5)
    assert np.allclose(rs.load_scan(path, units="mm").xyz[back.valid] * 25.4, scan.xyz[scan.valid], rtol=1e-5)


def test_pcd_field_count_past_any_descriptor_is_refused(tmp_path):
    """A COUNT of 1e9 ended in NumPy's 'dtype size in bytes must fit into a C int'."""
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z f\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 {}\n"
              "WIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA binary\n")
    path = tmp_path / "wide.pcd"
    path.write_bytes(header.format(1_000_000_000).encode() + b"\0" * 64)
    expect_error(path, r"field f COUNT 1,000,000,000 is more than 65,536 elements per point", call=rec.read_pcd)
    path.write_bytes(header.format(308).encode() + struct.pack("<fff", 0.0, 0.0, 0.5) + b"\0" * 4 * 308)
    assert rec.read_pcd(path)[1]["f"].shape == (1, 1, 308)  # PCL's VFH descriptor


def test_pcd_normals_are_unit_vectors_or_unknown(tmp_path):
    """Zero, infinite or NaN normals at valid points were kept as they were; now they are unknown
    (NaN) and a finite normal of another length is scaled to 1."""
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 4 4 4 4 4 4\n"
              "TYPE F F F F F F\nCOUNT 1 1 1 1 1 1\nWIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n")
    path = tmp_path / "n.pcd"
    path.write_text(header + "0 0 0.5 0 0 -1\n0.1 0 0.5 0 0 0\n0.2 0 0.5 0 0 inf\n"
                    "0.3 0 0.5 0 3 -4\n")
    scan = rec.read_pcd(path)[0]
    assert scan.valid.all()
    n = scan.normal[0]
    assert np.array_equal(n[0], [0, 0, -1]) and np.isnan(n[1]).all() and np.isnan(n[2]).all()
    assert np.allclose(n[3], [0, 0.6, -0.8])


def test_coordinates_past_float32_are_refused_not_dropped(tmp_path):
    """1e300 m in a PCD (or 1e38 m in a range grid) overflowed float32 into 'no surface' with
    only a NumPy warning; such a file is refused naming it."""
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
              "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n")
    path = tmp_path / "far.pcd"
    path.write_text(header + "0 0 0.5\n1e300 0 0.5\n")
    expect_error(path, r"coordinates reach 1e\+303 mm, beyond what a scan's float32 holds", call=rec.read_pcd)
    path.write_text(header + "0 0 0.5\n1e30 0 0.5\n")  # far, yet float32 holds it
    assert rec.read_pcd(path)[0].valid.all()
