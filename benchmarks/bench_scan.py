#!/usr/bin/env python
"""Speed of a full ``rangesim.scan`` against bare ray casting on the same rays.

Scene: a bumpy icosphere (>= 300k triangles by default, radius ~80 mm) on a ground plane,
millimetres, built deterministically. Sensor: white_scanner with a SIZE x SIZE camera and a
field of view that the object fills at the fixed pose.

Timed (each: one warm-up / cold run, then the median of --repeat runs):

* ``rangesim.scan``: the whole geometric scan (primary rays, shared-edge guard, laser
  shadows, signal, working range, mixed pixels, noise, labels, RangeScan).
* ``open3d``: ``o3d.t.geometry.RaycastingScene().cast_rays`` on the same rays, t_hit only.
* ``mitsuba ray_intersect``: ``scene.ray_intersect`` of the Mitsuba scene rangesim built,
  same rays, ``si.t`` copied to NumPy.
* ``mitsuba preliminary``: ``scene.ray_intersect_preliminary``, same rays, ``t`` to NumPy.
* ``mitsuba coherent``: ``scene.ray_intersect(ray, RayFlags.All, coherent=True)`` (Embree's
  coherent traversal, what the scan's camera rays use), ``si.t`` to NumPy.

The scene is loaded once and reused; the cold rangesim run includes building the Mitsuba
scene (Embree BVH) and tracing/compiling the Dr.Jit kernels (compiled kernels may come from
Dr.Jit's on-disk cache of an earlier process), the cold Open3D run its BVH build. Agreement:
rangesim's true distance |xyz_true| against Open3D's t_hit, per pixel.

``--profile`` adds, for the warm scan, a per-section and per-line breakdown of
``scan_geometric`` (sys.settrace; the library is not modified), Dr.Jit's kernel history of one
scan, and a cProfile listing.

Usage::

    python benchmarks/bench_scan.py [--size 1024] [--triangles 327680] [--repeat 5]
                                    [--json OUT.json] [--profile]
"""
from __future__ import annotations

import argparse
import cProfile
import datetime
import io
import json
import math
import platform
import pstats
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_info, interleaved  # noqa: E402

#: the target: a full scan within this factor of Open3D's bare depth
TARGET_RATIO = 1.5
#: distance (mm) from the camera to the object's centre: mid working range of white_scanner
VIEW_DISTANCE = 350.0
#: fraction of the narrower field of view the object's bounding sphere fills
FILL = 0.85


# -- scene, sensor, pose ---------------------------------------------------------------------
def bumpy_sphere(triangles: int, radius: float = 80.0):
    """Icosphere with at least ``triangles`` faces, radially displaced by a sum of sines."""
    import trimesh

    subdivisions = max(0, math.ceil(math.log(max(triangles, 20) / 20, 4) - 1e-12))
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    u = np.asarray(mesh.vertices, dtype=np.float64)
    u /= np.linalg.norm(u, axis=1)[:, None]
    x, y, z = u.T
    bumps = (
        np.sin(7.0 * x + 0.3) * np.sin(6.0 * y + 1.1)
        + 0.7 * np.sin(11.0 * z + 0.5)
        + 0.5 * np.sin(17.0 * x - 13.0 * y + 9.0 * z)
    ) / 2.2
    r = radius * (1.0 + 0.06 * bumps)  # +-6 % of the radius: concave dents, self-shadows
    return trimesh.Trimesh(vertices=u * r[:, None], faces=mesh.faces, process=False)


def ground_plane(z: float, half: float = 250.0, cells: int = 8):
    """A flat square grid at height ``z`` (2 * cells^2 triangles), normal +z."""
    import trimesh

    g = np.linspace(-half, half, cells + 1)
    xx, yy = np.meshgrid(g, g)
    vertices = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], axis=1)
    k = np.arange(cells * cells)
    i, j = k // cells, k % cells
    a = i * (cells + 1) + j
    b, c, d = a + 1, a + cells + 1, a + cells + 2
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


def build_sensor(size: int, object_radius: float):
    import rangesim as rs

    half_angle = math.asin(object_radius / VIEW_DISTANCE) / FILL
    fov = math.degrees(2 * half_angle)
    return rs.load_sensor("white_scanner").with_params(
        {"camera.width": size, "camera.height": size, "camera.fov_deg": round(fov, 3)}
    )


def build_pose(centre: np.ndarray) -> np.ndarray:
    from rangesim.core.geometry import look_at

    direction = np.array([0.35, -1.0, 0.9])
    direction /= np.linalg.norm(direction)
    return look_at(centre + VIEW_DISTANCE * direction, centre, up=(0, 0, 1))


def world_rays(sensor, pose) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit world directions (N, 3), row-major over pixels."""
    K = sensor.K
    h, w = sensor.height, sensor.width
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d = np.stack(
        [(jj.ravel() + 0.5 - K[0, 2]) / K[0, 0], (ii.ravel() + 0.5 - K[1, 2]) / K[1, 1],
         np.ones(h * w)], axis=1,
    )
    d = d @ pose[:3, :3].T
    d /= np.linalg.norm(d, axis=1)[:, None]
    return pose[:3, 3].copy(), d


# -- timing ----------------------------------------------------------------------------------



# -- the large-mesh sweep (issue: mesh loading time and memory) -------------------------------
def sweep_child(args) -> int:
    """One configuration in a fresh process: load the mesh file, first depth image, warm casts, peak RSS.

    Prints one JSON line. ``rangesim``: ``load_scene`` + ``scan`` (the full geometric scan);
    ``open3d``: ``read_triangle_mesh`` + ``RaycastingScene`` + ``cast_rays`` on the same rays.
    """
    import resource

    if args.child == "rangesim":
        import rangesim as rs
        from rangesim.core.backend import mitsuba

        mitsuba()  # the variant is set before the clock starts, as Open3D is imported before it
    else:
        import open3d as o3d
    out: dict = {"child": args.child, "mesh": str(args.mesh)}
    t0 = time.perf_counter()
    if args.child == "rangesim":
        scene = rs.load_scene(str(args.mesh))
        t_load = time.perf_counter() - t0
        radius = float(max(np.linalg.norm(o.mesh.vertices, axis=1).max() for o in scene.objects))
        sensor = build_sensor(args.size, radius)
        pose = build_pose(np.zeros(3))
        scan = rs.scan(scene, sensor, pose=pose, seed=0)
        out.update(load_s=t_load, first_image_s=time.perf_counter() - t0, valid=int(scan.valid.sum()),
                   triangles=int(sum(len(o.mesh.faces) for o in scene.objects)))
        warm = []
        for k in range(args.repeat):
            t = time.perf_counter()
            rs.scan(scene, sensor, pose=pose, seed=k + 1)
            warm.append(time.perf_counter() - t)
    else:
        legacy = o3d.io.read_triangle_mesh(str(args.mesh))
        mesh = o3d.t.geometry.TriangleMesh.from_legacy(legacy)
        t_load = time.perf_counter() - t0
        radius = float(np.linalg.norm(np.asarray(legacy.vertices), axis=1).max())
        sensor = build_sensor(args.size, radius)
        pose = build_pose(np.zeros(3))
        origin, dirs = world_rays(sensor, pose)
        rays = o3d.core.Tensor(np.hstack([np.broadcast_to(origin, dirs.shape), dirs]).astype(np.float32))
        rc = o3d.t.geometry.RaycastingScene()
        rc.add_triangles(mesh)
        t_hit = rc.cast_rays(rays)["t_hit"].numpy()
        out.update(load_s=t_load, first_image_s=time.perf_counter() - t0, valid=int(np.isfinite(t_hit).sum()),
                   triangles=int(len(legacy.triangles)))
        warm = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            rc.cast_rays(rays)["t_hit"].numpy()
            warm.append(time.perf_counter() - t)
    out["warm_s"] = statistics.median(warm)
    out["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps(out))
    return 0


def sweep_main(args, counts: list[int]) -> int:
    """Every triangle count: write the mesh file, then run rangesim and Open3D children, interleaved."""
    import subprocess
    import tempfile

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in counts:
            path = Path(tmp) / f"sphere_{n}.ply"
            bumpy_sphere(n).export(path)  # binary PLY, not timed
            row = {"requested": n}
            for child in ("rangesim", "open3d"):
                cmd = [sys.executable, __file__, "--child", child, "--mesh", str(path), "--size", str(args.size),
                       "--repeat", str(args.repeat)]
                done = subprocess.run(cmd, capture_output=True, text=True)
                lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
                if done.returncode != 0 or not lines:
                    print(f"{child} at {n} failed: {done.stderr.strip().splitlines()[-1:] or done.returncode}")
                    continue
                row[child] = json.loads(lines[-1])
            rows.append(row)
    print(f"large-mesh sweep, {args.size} x {args.size} rays, 2-core CPU (one process per configuration)")
    print(f"{'triangles':>10} {'load s':>8} {'first image s (rs / o3d = x)':>30} {'warm s (rs / o3d = x)':>26} "
          f"{'peak MiB (rs / o3d = x)':>26}")
    for row in rows:
        r, o = row.get("rangesim"), row.get("open3d")
        if not r or not o:
            continue
        row["ratios"] = {k: r[k] / o[k] for k in ("first_image_s", "warm_s", "peak_rss_mib")}
        q = row["ratios"]
        print(f"{r['triangles']:>10,} {r['load_s']:>8.2f} {r['first_image_s']:>11.2f} / {o['first_image_s']:5.2f} = "
              f"{q['first_image_s']:4.2f}x {r['warm_s']:>9.3f} / {o['warm_s']:5.3f} = {q['warm_s']:4.2f}x "
              f"{r['peak_rss_mib']:>9.0f} / {o['peak_rss_mib']:5.0f} = {q['peak_rss_mib']:4.2f}x")
    if args.json:
        args.json.write_text(json.dumps({"benchmark": "large-mesh sweep", "size": args.size, "machine": cpu_info(),
                                         "date": datetime.date.today().isoformat(), "rows": rows}, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


# -- per-stage profile -----------------------------------------------------------------------
# Nothing in the library is changed: a sys.settrace tracer times the source lines of
# scan_geometric, and Dr.Jit's kernel history times the kernels. Dr.Jit is lazy, so a
# kernel's time lands on the line that evaluates it (dr.eval, np.array, a reduction), not on
# the line that records it; the kernel table says what ran.


def _geometric_sections():
    """(first line, title) of each section of scan_geometric: its ``# ...`` comment lines at
    the function's top indentation (``# 1. primary rays``, ``# 2-5. ...``)."""
    import inspect

    import rangesim.sensor.geometric as geo

    source, first = inspect.getsourcelines(geo.scan_geometric)
    sections = [(first, "setup")]
    for k, text in enumerate(source):
        if text.startswith("    # "):
            sections.append((first + k, text.strip()[2:]))
        elif text.startswith("    meta = "):
            sections.append((first + k, "output: meta, NumPy copies, RangeScan"))
    return sections


def line_breakdown(scene, sensor, pose, repeat: int):
    """Median seconds per source line of ``scan_geometric`` over ``repeat`` scans (a line's
    time includes the calls it makes and the Dr.Jit kernels it waits for).

    Returns (lines, sections, total): lines as (lineno, seconds, text) sorted by time,
    sections as (title, seconds) in source order, total the median scan time.
    """
    import linecache

    import rangesim as rs
    import rangesim.sensor.geometric as geo

    code = geo.scan_geometric.__code__
    per_run: list[dict[int, float]] = []
    totals = []
    state: dict = {}

    def local(frame, event, arg):
        now = time.perf_counter()
        last = state.get("line")
        if last is not None:
            acc = per_run[-1]
            acc[last] = acc.get(last, 0.0) + now - state["t"]
        state["line"] = frame.f_lineno if event == "line" else None
        state["t"] = time.perf_counter()
        return local

    def tracer(frame, event, arg):
        if event == "call" and frame.f_code is code:
            state["line"] = None
            return local
        return None

    for _ in range(repeat):
        per_run.append({})
        t0 = time.perf_counter()
        sys.settrace(tracer)
        try:
            rs.scan(scene, sensor, pose=pose, seed=0)
        finally:
            sys.settrace(None)
        totals.append(time.perf_counter() - t0)
    numbers = sorted({k for run in per_run for k in run})
    med = {k: statistics.median(run.get(k, 0.0) for run in per_run) for k in numbers}
    lines = sorted(
        ((k, v, linecache.getline(code.co_filename, k).strip()) for k, v in med.items()),
        key=lambda row: -row[1],
    )
    sections = _geometric_sections()
    starts = [s for s, _ in sections]
    sums = [0.0] * len(sections)
    for k, v in med.items():
        i = max(j for j, s in enumerate(starts) if s <= k) if k >= starts[0] else 0
        sums[i] += v
    return lines, [(t, v) for (_, t), v in zip(sections, sums)], statistics.median(totals)


def kernel_table(scene, sensor, pose) -> tuple[list[dict], float]:
    """Dr.Jit's kernel history of one warm scan: what ran, how big, how long (ms)."""
    import re

    import drjit as dr

    import rangesim as rs

    dr.kernel_history_clear()
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        t0 = time.perf_counter()
        rs.scan(scene, sensor, pose=pose, seed=0)
        wall = time.perf_counter() - t0
        history = dr.kernel_history()
    rows = []
    for k, entry in enumerate(history):
        kind = str(entry.get("type", "?")).split(".")[-1]
        row = {
            "order": k, "type": kind, "size": entry.get("size"),
            "ops": entry.get("operation_count"), "exec_ms": float(entry.get("execution_time", 0.0)),
            "codegen_ms": float(entry.get("codegen_time") or 0.0),
            "compile_ms": float(entry.get("backend_time") or 0.0),
        }
        ir = entry.get("ir")
        if ir is not None:
            text = ir.getvalue() if hasattr(ir, "getvalue") else str(ir)
            calls = sorted({c for c in re.findall(r"call [^@\n]*@([A-Za-z_][\w.]*)", text)
                            if not c.startswith("llvm.")})
            # a call through a pointer: Embree (ray_intersect / ray_test) or another host function
            if re.search(r"call [^@\n]*%", text):
                calls.append("<indirect call>")
            row["calls"] = calls
        rows.append(row)
    return rows, wall


def cprofile_scan(scene, sensor, pose, top: int = 25) -> str:
    import rangesim as rs

    prof = cProfile.Profile()
    prof.enable()
    rs.scan(scene, sensor, pose=pose, seed=0)
    prof.disable()
    out = io.StringIO()
    stats = pstats.Stats(prof, stream=out).strip_dirs()
    stats.sort_stats("cumulative").print_stats(top)
    out.write("\n--- sorted by own time (tottime) ---\n")
    stats.sort_stats("tottime").print_stats(15)
    return out.getvalue()


def open3d_runs(o3d, scene, origin, dirs, n_rays, laser_world=None) -> dict:
    """Open3D's bare ``cast_rays`` of the same rays (t_hit to NumPy), as a timed function.

    With ``laser_world`` (3,) also the cast followed by one shadow ray per hit towards that
    point (``test_occlusions``: any hit, like Mitsuba's ``ray_test``): the ray-casting work
    of a laser-stripe scan, the fair baseline of the full scan's physics.
    """
    o3d_scene = o3d.t.geometry.RaycastingScene()
    for obj in scene.objects:
        o3d_scene.add_triangles(
            o3d.core.Tensor(np.asarray(obj.mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(obj.mesh.faces, dtype=np.uint32)),
        )
    rays6 = np.empty((n_rays, 6), dtype=np.float32)
    rays6[:, :3] = origin
    rays6[:, 3:] = dirs
    o3d_rays = o3d.core.Tensor(rays6)

    def run_open3d():
        return o3d_scene.cast_rays(o3d_rays)["t_hit"].numpy()

    runs = {"open3d cast_rays (t_hit)": run_open3d}
    if laser_world is not None:
        def run_open3d_shadow():
            t = o3d_scene.cast_rays(o3d_rays)["t_hit"].numpy()
            hit = np.isfinite(t)
            p = origin + dirs[hit] * t[hit, None]
            to_laser = laser_world - p
            dist = np.linalg.norm(to_laser, axis=1)
            shadow = np.empty((len(p), 6), np.float32)
            shadow[:, :3] = p
            shadow[:, 3:] = to_laser / dist[:, None]
            return o3d_scene.test_occlusions(o3d.core.Tensor(shadow), tnear=1e-3, tfar=float(dist.max())).numpy()

        runs["open3d cast + shadow rays"] = run_open3d_shadow
    return runs


# -- main ------------------------------------------------------------------------------------
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1024, help="image width = height (pixels)")
    ap.add_argument("--triangles", default="327680",
                    help="minimum triangle count of the object (icosphere: 20 * 4^k); a comma list "
                         "(e.g. 20000,327680,1310720,5242880) runs the large-mesh sweep: time to the first "
                         "depth image and peak memory per configuration, each in its own process")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs after the warm-up")
    ap.add_argument("--json", type=Path, help="write the figures to this JSON file")
    ap.add_argument("--profile", action="store_true",
                    help="also print a per-stage breakdown and a cProfile of one scan")
    ap.add_argument("--child", choices=["rangesim", "open3d"], help=argparse.SUPPRESS)
    ap.add_argument("--mesh", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    counts = [int(t) for t in str(args.triangles).split(",") if t.strip()]
    if args.size < 2 or args.repeat < 1 or not counts or min(counts) < 1:
        ap.error("--size >= 2, --repeat >= 1, --triangles >= 1")
    if args.child:
        return sweep_child(args)
    if len(counts) > 1:
        return sweep_main(args, counts)
    args.triangles = counts[0]

    import drjit as dr
    import scipy

    try:
        import open3d as o3d
    except ImportError as exc:  # e.g. on a GPU box without the wheel: Mitsuba's bare cast is the baseline
        print(f"open3d unavailable ({exc}); baseline = mitsuba ray_intersect")
        o3d = None
    import trimesh

    import rangesim as rs
    from rangesim.core.backend import mitsuba

    mi = mitsuba()  # sets the variant rangesim uses (RANGESIM_VARIANT overrides)

    # scene -----------------------------------------------------------------------------
    t0 = time.perf_counter()
    sphere = bumpy_sphere(args.triangles)
    plane = ground_plane(float(sphere.vertices[:, 2].min()) - 0.5)
    scene = rs.load_scene([sphere, plane])
    t_load = time.perf_counter() - t0
    n_tri = sum(len(o.mesh.faces) for o in scene.objects)
    object_radius = float(np.linalg.norm(sphere.vertices, axis=1).max())
    sensor = build_sensor(args.size, object_radius)
    pose = build_pose(np.zeros(3))
    origin, dirs = world_rays(sensor, pose)
    n_rays = len(dirs)

    cpu = cpu_info()
    print("rangesim scan benchmark")
    print(f"  date        {datetime.date.today().isoformat()}")
    print(f"  machine     {cpu.get('model', platform.processor() or platform.machine())}; "
          f"cores: os.cpu_count={cpu['os.cpu_count']}, usable={cpu.get('affinity', '?')}")
    print(f"  python      {platform.python_version()}  numpy {np.__version__}  scipy {scipy.__version__}")
    print(f"  rangesim    {rs.__version__}  mitsuba {mi.__version__} (variant {mi.variant()})  "
          f"drjit {dr.__version__}")
    print(f"  open3d      {o3d.__version__ if o3d else 'not installed'}  trimesh {trimesh.__version__}")
    print(f"  scene       bumpy icosphere {len(scene.objects[0].mesh.faces):,} tris "
          f"(r <= {object_radius:.1f} mm, watertight={scene.objects[0].watertight}) + ground "
          f"plane {len(scene.objects[1].mesh.faces)} tris = {n_tri:,} triangles; "
          f"load_scene {t_load:.2f} s")
    print(f"  sensor      white_scanner, {sensor.width}x{sensor.height}, "
          f"fov {sensor.params['camera']['fov_deg']:.2f} deg, range "
          f"[{sensor.params['range']['near']:.0f}, {sensor.params['range']['far']:.0f}] mm; "
          f"camera {VIEW_DISTANCE:.0f} mm from the object centre")
    print(f"  rays        {n_rays:,} per run; repeat {args.repeat} (median), after 1 cold run")
    print()

    results: dict[str, dict] = {}

    # every contender as a function, then timed in turns (interleaved, so a busy moment of
    # the machine hits them all alike); the cold rangesim run builds the Mitsuba scene/BVH and
    # compiles kernels, the cold Open3D run its BVH
    def run_scan():
        return rs.scan(scene, sensor, pose=pose, seed=0)

    runs = {"rangesim.scan (full)": run_scan}
    if o3d is not None:
        laser_world = (pose @ np.r_[sensor.laser_origin, 1.0])[:3]
        runs.update(open3d_runs(o3d, scene, origin, dirs, n_rays, laser_world))
    mscene = scene.mitsuba_scene()
    d32 = np.ascontiguousarray(dirs.T, dtype=np.float32)
    mi_ray = mi.Ray3f(mi.Point3f(*(float(c) for c in origin)), mi.Vector3f(d32[0], d32[1], d32[2]))
    dr.eval(mi_ray.d)

    def run_mitsuba():
        si = mscene.scene.ray_intersect(mi_ray)
        return np.array(si.t, dtype=np.float32)

    def run_mitsuba_pre():
        pi = mscene.scene.ray_intersect_preliminary(mi_ray)
        return np.array(pi.t, dtype=np.float32)

    def run_mitsuba_coherent():
        si = mscene.scene.ray_intersect(mi_ray, mi.RayFlags.All, True)
        return np.array(si.t, dtype=np.float32)

    runs["mitsuba ray_intersect (t)"] = run_mitsuba
    runs["mitsuba preliminary (t)"] = run_mitsuba_pre
    runs["mitsuba coherent (t)"] = run_mitsuba_coherent
    outputs = {}
    for name, (cold, med, times, out) in interleaved(runs, args.repeat).items():
        results[name] = {"cold_s": cold, "median_s": med, "times_s": times}
        outputs[name] = out
    scan, t_mi = outputs["rangesim.scan (full)"], outputs["mitsuba ray_intersect (t)"]
    t_o3d = outputs.get("open3d cast_rays (t_hit)")

    # agreement with Open3D ------------------------------------------------------------------
    t_true = np.linalg.norm(scan.xyz_true.reshape(-1, 3).astype(np.float64), axis=1)  # NaN on miss
    rs_hit = np.isfinite(t_true)

    def agreement(t_other):
        t_other = np.asarray(t_other, dtype=np.float64)
        o_hit = np.isfinite(t_other)
        both = rs_hit & o_hit
        close = both.copy()
        close[both] = np.abs(t_other[both] - t_true[both]) < 1e-3 * t_true[both]
        either = int(np.count_nonzero(rs_hit | o_hit))
        return {
            "either_hit": either,
            "both_hit": int(np.count_nonzero(both)),
            "only_rangesim": int(np.count_nonzero(rs_hit & ~o_hit)),
            "only_other": int(np.count_nonzero(o_hit & ~rs_hit)),
            "agree": int(np.count_nonzero(close)),
            "fraction": float(np.count_nonzero(close) / max(either, 1)),
        }

    agree = {"mitsuba ray_intersect": agreement(t_mi)}
    if o3d is not None:
        agree["open3d"] = agreement(t_o3d)

    # report ---------------------------------------------------------------------------------
    base_name = "open3d cast_rays (t_hit)" if o3d is not None else "mitsuba ray_intersect (t)"
    base = results[base_name]["median_s"]
    for r in results.values():
        r["rays_per_s"] = n_rays / r["median_s"]
        r["ratio_to_open3d"] = r["median_s"] / base
    name_w = max(len(k) for k in results) + 2
    print(f"{'name':<{name_w}}{'median s':>10}{'min s':>9}{'cold s':>9}{'Mrays/s':>9}{'x Open3D':>10}")
    for name, r in results.items():
        print(f"{name:<{name_w}}{r['median_s']:>10.3f}{min(r['times_s']):>9.3f}{r['cold_s']:>9.3f}"
              f"{r['rays_per_s'] / 1e6:>9.2f}{r['ratio_to_open3d']:>10.2f}")
    print()
    status_counts = {rs.Status(s).name.lower(): int(n) for s, n in zip(*np.unique(scan.status, return_counts=True))}
    print(f"scan: {status_counts}; recast rays (shared-edge guard): {scan.meta['recast_rays']}")
    for name, a in agree.items():
        print(f"agreement rangesim true distance vs {name}: {a['fraction'] * 100:.3f} % of the "
              f"{a['either_hit']:,} pixels hit by either ({a['agree']:,} agree to 1e-3 t; "
              f"only rangesim hits {a['only_rangesim']}, only {name} hits {a['only_other']})"
              f" -> {'OK' if a['fraction'] > 0.99 else 'BELOW 99 %'}")
    ratio = results["rangesim.scan (full)"]["ratio_to_open3d"]
    verdict = "PASS" if ratio <= TARGET_RATIO else "FAIL"
    if o3d is None:
        verdict = "NOT CHECKED (no Open3D; ratios are to Mitsuba's bare ray_intersect)"
    cores = cpu.get("affinity", cpu["os.cpu_count"])
    print(f"target: full scan within {TARGET_RATIO}x of Open3D bare depth on 2 CPU cores: "
          f"{verdict} (ratio {ratio:.2f}; this machine: {cores} usable cores)")
    if "open3d cast + shadow rays" in results:
        same = results["rangesim.scan (full)"]["median_s"] / results["open3d cast + shadow rays"]["median_s"]
        print(f"same ray-casting work: full scan / Open3D cast + shadow rays = {same:.2f}")

    profile = None
    if args.profile:
        lines, sections, total = line_breakdown(scene, sensor, pose, args.repeat)
        print(f"\nper-stage breakdown of scan_geometric (median of {args.repeat} traced runs, "
              f"{total:.3f} s each with the tracer; sections are its # comments)")
        for title, v in sections:
            print(f"  {v:>8.3f} s {100 * v / total:>6.1f} %  {title[:80]}")
        print("\nslowest lines of scan_geometric (a line's time includes the calls it makes and "
              "the Dr.Jit kernels it waits for)")
        for lineno, v, text in lines[:15]:
            print(f"  geometric.py:{lineno:<4}{v:>8.3f} s  {text[:90]}")
        kernels, wall = kernel_table(scene, sensor, pose)
        busy = sum(r["exec_ms"] for r in kernels)
        print(f"\nDr.Jit kernels of one warm scan ({len(kernels)} launches, {busy:.1f} ms executing "
              f"of {wall * 1e3:.1f} ms wall; the rest is Python, NumPy and transfers)")
        print(f"  {'#':>3} {'type':<18}{'size':>10}{'ops':>6}{'exec ms':>9}{'codegen ms':>11}  calls")
        for r in kernels:
            if r["exec_ms"] < 0.05 and r["type"] != "JIT":
                continue
            print(f"  {r['order']:>3} {r['type']:<18}{r['size'] or 0:>10}{r['ops'] or 0:>6}"
                  f"{r['exec_ms']:>9.2f}{r['codegen_ms']:>11.2f}  {' '.join(r.get('calls', []))}")
        print("\ncProfile of one warm rangesim.scan (top 25 by cumulative time)")
        text = cprofile_scan(scene, sensor, pose)
        print(text)
        profile = {
            "sections": [{"name": t, "median_s": v} for t, v in sections],
            "lines": [{"line": n, "median_s": v, "source": t} for n, v, t in lines],
            "kernels": kernels, "kernels_wall_s": wall,
        }

    if args.json:
        payload = {
            "date": datetime.date.today().isoformat(),
            "cpu": cpu,
            "versions": {
                "python": platform.python_version(), "numpy": np.__version__,
                "rangesim": rs.__version__, "mitsuba": mi.__version__, "drjit": dr.__version__,
                "open3d": o3d.__version__ if o3d else None, "trimesh": trimesh.__version__,
            },
            "variant": mi.variant(),
            "size": args.size, "rays": n_rays, "triangles": n_tri, "repeat": args.repeat,
            "fov_deg": sensor.params["camera"]["fov_deg"], "pose": pose.tolist(),
            "results": results, "agreement": agree, "status_counts": status_counts,
            "target": {"ratio": ratio, "limit": TARGET_RATIO, "pass": verdict == "PASS"},
            "profile": profile,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(payload, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
