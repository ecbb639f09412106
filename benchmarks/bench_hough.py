"""Hough benchmark: rangesim's feature finders against OpenCV (the baseline) on the same edge maps,
timed interleaved in one process (median of the runs), with recall, precision and errors.

- circles: ``rs.features.circles`` against ``cv2.HoughCircles`` (HOUGH_GRADIENT), on synthetic
  edge maps (512^2 with 12 circles, 1024^2 with 24, amid segments, arcs, ellipses and noise
  pixels) and on head-on scans of the Green Piece (white_scanner, noisy seed 0 and noise-free,
  gradient edges with rim creases kept), 12 visible rims from the CAD part, the tapped holes'
  crest outlines (real circles, not scored rims) set aside in a second scoring; and on
  circles nearly tangent inside others (``tangent_pairs``), with ``split_tangent`` on and off;
- ellipses (model-free path): ``rs.features.ellipses(mask, remove_explained=False)`` (the
  default, and each hypothesis generator: the tilings, the chains and the outlines alone,
  :data:`rangesim.features._arc_ellipses.HYPOTHESES`) against ``cv2.fitEllipse`` on each
  contour of ``cv2.findContours`` (linked edge pixels) and ``cv2.ximgproc.findEllipses``
  (opencv-contrib), on the tilted Green Piece, with a second timing in CPU time of this thread
  (median of 25, which a loaded machine disturbs less); the model-guided path
  (``ellipses(edges, scan, scene)``) is printed beside them;
- segments: ``rs.features.lines`` against ``cv2.HoughLinesP`` and scikit-image's
  ``probabilistic_hough_line``, on the same tilted and head-on maps (the part's plate edges).

Tuning and reporting are kept apart: every rangesim default and OpenCV's ``param2`` (accumulator
threshold; chosen by the best F1 over 10..40 with ``--tune``) were set on synthetic seeds 0-4
(rangesim's also on noisy Green Piece seeds 1 and 2); the synthetic rows here use seeds 100-104
(512^2) and 100-102 (1024^2). The Green Piece rows
(seed 0 and noise-free) were in sight while the finder was developed, so they are not held out.
``split_tangent`` (its ring width, thickness, seed and explained-fraction settings) was set on
tangent pairs drawn like ``tangent_pairs`` from another seed stream (seeds 10-15) and on noisy
Green Piece seeds 1 and 2; its rows here are tangent-pair seeds 100-104.

    python benchmarks/bench_hough.py [--repeat 5] [--tune] [--skimage]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    import cv2
except ImportError:  # the bench extra: pip install -e ".[bench]"
    sys.exit("bench_hough needs OpenCV with the contrib modules: pip install opencv-contrib-python-headless")

import rangesim as rs
import rangesim.edges  # noqa: F401
import rangesim.evaluate  # noqa: F401
import rangesim.features as F
from rangesim.core.geometry import look_at
from rangesim.evaluate._feature_scores import feature_scores

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_info  # noqa: E402

QUIET = {"noise.sigma_px": 0, "noise.speckle_contrast": 0, "noise.quantization_px": 0}
TUNE_SEEDS = (0, 1, 2, 3, 4)
REPORT_SEEDS = {512: (100, 101, 102, 103, 104), 1024: (100, 101, 102)}
SYNTH = {512: dict(n=12, radii=(6, 60), search=(5, 64)), 1024: dict(n=24, radii=(8, 120), search=(5, 128))}
#: truth rims scored: seen at least this much (feature_scores' default min_visible)
MIN_VISIBLE = 0.5
GREEN_RADII = (5, 70)  # px, the Green Piece's rims are 10-60 px head-on
CV_PARAM2 = {512: 20, 1024: 25}  # best F1 on TUNE_SEEDS (run with --tune)
cv2.setNumThreads(1)  # the 2-core VM is shared; rangesim is single-threaded numpy too


# -- inputs ------------------------------------------------------------------------------------

@dataclass
class TrueRound:
    """A ground-truth circle/ellipse as feature_scores reads it."""

    name: str
    center: np.ndarray
    axes: np.ndarray
    visible: float = 1.0


class Found:
    """A found circle/ellipse (centre, radius or axes) for feature_scores."""

    def __init__(self, center, radius=None, axes=None):
        self.center = (float(center[0]), float(center[1]))
        if radius is not None:
            self.radius = float(radius)
        else:
            self.axes = (float(axes[0]), float(axes[1]))


def _draw(mask: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    H, W = mask.shape
    xi, yi = np.rint(x).astype(int), np.rint(y).astype(int)
    ok = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
    mask[yi[ok], xi[ok]] = True


def _free_spots(rng: np.random.Generator, size: int, radii, n: int, margin: float, gap: float):
    """Up to ``n`` circles (centre (2,), radius px) drawn at random inside a size x size image,
    ``margin`` px from its border and ``gap`` px clear of each other (20,000 tries at most);
    each is yielded as it is placed, so the caller's own draws interleave with these."""
    placed = []
    for _ in range(20000):
        if len(placed) == n:
            return
        r = rng.uniform(*radii)
        c = rng.uniform(r + margin, size - r - margin, 2)
        if any(np.hypot(*(c - c2)) < r + r2 + gap for c2, r2 in placed):
            continue
        placed.append((c, r))
        yield c, r


def _draw_partial_circle(mask: np.ndarray, rng: np.random.Generator, c, r: float, sigma: float) -> None:
    """Draw 70-100 % of the circle (centre ``c``, radius ``r`` px) from a random start, its
    points jittered by ``sigma`` px."""
    a = np.linspace(0, 2 * np.pi, int(np.ceil(6 * np.pi * r)), endpoint=False)
    a = a[np.mod(a - rng.uniform(0, 2 * np.pi), 2 * np.pi) < rng.uniform(0.7, 1.0) * 2 * np.pi]
    _draw(mask, c[0] + r * np.cos(a) + rng.normal(0, sigma, len(a)),
          c[1] + r * np.sin(a) + rng.normal(0, sigma, len(a)))


def synthetic_edges(size: int, n_circles: int, seed: int, radii=(6, 60), sigma: float = 0.25):
    """A size x size edge mask: ``n_circles`` non-overlapping circles (70-100 % of each drawn,
    positions with sigma px noise, rounded to pixels), 20 segments, 8 arcs of 15-40 % of a
    circle and 6 ellipses (b/a 0.4-0.75, a - b >= 4 px) per 512^2, and 0.05 % noise pixels.

    Returns
    -------
    mask : (size, size) bool
    truth : dict
        ``{"circles": [TrueRound], "segments": []}``: only the circles.
    """
    rng = np.random.default_rng(seed)
    mask = np.zeros((size, size), bool)
    truth = []
    for c, r in _free_spots(rng, size, radii, n_circles, margin=2, gap=3):
        _draw_partial_circle(mask, rng, c, r, sigma)
        truth.append(TrueRound(f"circle_{len(truth)}", c, np.array([r, r])))
    k = size // 512
    for _ in range(20 * k):
        p, L, t = rng.uniform(0, size, 2), rng.uniform(20, 200), rng.uniform(0, np.pi)
        s = np.linspace(0, L, int(L * 2))
        _draw(mask, p[0] + s * np.cos(t) + rng.normal(0, sigma, len(s)),
              p[1] + s * np.sin(t) + rng.normal(0, sigma, len(s)))
    for _ in range(8 * k):
        r, c, span = rng.uniform(*radii), rng.uniform(0, size, 2), rng.uniform(0.15, 0.4) * 2 * np.pi
        a = rng.uniform(0, 2 * np.pi) + np.linspace(0, span, int(span * r * 3))
        _draw(mask, c[0] + r * np.cos(a), c[1] + r * np.sin(a))
    for _ in range(6 * k):
        A = rng.uniform(radii[0] + 5, radii[1])
        B, c, t = min(A * rng.uniform(0.4, 0.75), A - 4), rng.uniform(0, size, 2), rng.uniform(0, np.pi)
        a = np.linspace(0, 2 * np.pi, int(2 * np.pi * A * 3))
        x, y = A * np.cos(a), B * np.sin(a)
        _draw(mask, c[0] + x * np.cos(t) - y * np.sin(t), c[1] + x * np.sin(t) + y * np.cos(t))
    n_noise = int(0.0005 * size * size)
    mask[rng.integers(0, size, n_noise), rng.integers(0, size, n_noise)] = True
    return mask, {"circles": truth, "segments": []}


def tangent_pairs(size: int, seed: int, n_pairs: int = 6, n_single: int = 4, radii=(10, 40), ecc=(1.0, 3.0),
                  sigma: float = 0.25):
    """A size x size edge mask of circles nearly tangent inside others: ``n_pairs`` outer
    circles of radius R (``radii``) each with an inner one of radius R - e (e in ``ecc`` px)
    whose centre lies e +- 0.3 px away (a tapped hole's rim and crest outline, a counterbore),
    ``n_single`` lone circles, each drawn over 70-100 % with sigma px noise, and 0.05 % noise
    pixels. Both circles of a pair are truth.

    Returns
    -------
    mask : (size, size) bool
    truth : dict
        ``{"circles": [TrueRound], "segments": []}`` (names ``outer_k``, ``inner_k``, ``single_k``).
    """
    rng = np.random.default_rng([seed, 15])
    mask = np.zeros((size, size), bool)
    truth = []
    for k, (c, r) in enumerate(_free_spots(rng, size, radii, n_pairs + n_single, margin=3, gap=4), start=1):
        _draw_partial_circle(mask, rng, c, r, sigma)
        if k <= n_pairs:
            e, phi = rng.uniform(*ecc), rng.uniform(0, 2 * np.pi)
            ci = c + max(e + rng.uniform(-0.3, 0.3), 0.0) * np.array([np.cos(phi), np.sin(phi)])
            _draw_partial_circle(mask, rng, ci, r - e, sigma)
            truth += [TrueRound(f"outer_{k}", c, np.array([r, r])), TrueRound(f"inner_{k}", ci, np.array([r - e] * 2))]
        else:
            truth.append(TrueRound(f"single_{k}", c, np.array([r, r])))
    n_noise = int(0.0005 * size * size)
    mask[rng.integers(0, size, n_noise), rng.integers(0, size, n_noise)] = True
    return mask, {"circles": truth, "segments": []}


def green_piece():
    """Head-on (circles) and tilted (ellipses) scans of the Green Piece, noisy (seed 0) and
    noise-free, with gradient edges (rim creases kept) and the CAD part's ground truth (the
    head-on truth also carries the tapped holes' crest outlines, :func:`crest_outlines`)."""
    scene = rs.load_scene(ROOT / "scenes/green_piece.toml")
    out = {}
    for label, params in (("noisy seed 0", {}), ("noise-free", QUIET)):
        sensor = rs.load_sensor("white_scanner").with_params(params)
        for view, pose in (("head-on", look_at((0, 0, 300), (0, 0, 0), up=(0, 1, 0))), ("tilted", None)):
            scan = rs.scan(scene, sensor, seed=0, pose=pose)
            truth = rs.evaluate.ground_truth_features(scan, scene)
            if view == "head-on":
                truth["crests"] = crest_outlines(scan, scene)
            out[(label, view)] = (scan, rs.edges.gradient(scan, jump_clearance=0), truth)
    return scene, out


def crest_outlines(scan, scene) -> list[TrueRound]:
    """The tapped holes' crest outlines in the image: real circular edges that are not rims.

    Seen down a tapped hole, the thread's crests outline the opening that no section of the
    helix covers: a circle of the minor radius (r_major - 0.6 pitch) about the hole's axis,
    which meets the top rim (radius r_major - 0.3 pitch, centre 0.3 pitch off the axis) on
    one side and lies 0.6 pitch inside it on the other. It is projected here at the top
    face; the crests that draw it lie 0-1 pitch deeper, which shrinks it by at most
    pitch / distance (0.6 %, 0.15 px head-on at 300 mm). Found circles matched to these are
    real circles, not the rims the issue scores: :func:`_round_scores` sets them aside.
    """
    from rangesim.cad._green_piece import DEFAULTS, THREAD_DEPTH_PER_PITCH
    from rangesim.core.conics import ellipse_from_conic
    from rangesim.core.geometry import project_circle

    obj = next(o for o in scene.objects if o.name == "green_piece")
    built = rs.cad.green_piece()
    rims = {c.name: c for c in obj.features.circles}
    inv = np.linalg.inv(scan.pose)
    out = []
    for k, (x, y, r_major, pitch) in enumerate(DEFAULTS["threads"], start=1):
        rim = rims[f"thread_{k}_rim_top"]
        own = next(c for c in built.features.circles if c.name == rim.name)
        # the scene's features are the part's own (no placement), so the axis is (x, y)
        assert np.allclose(rim.center, own.center), "the Green Piece is placed: transform the axis too"
        centre = inv[:3, :3] @ np.array([x, y, rim.center[2]]) + inv[:3, 3]
        conic = project_circle(centre, inv[:3, :3] @ np.array([0, 0, 1.0]),
                               r_major - THREAD_DEPTH_PER_PITCH * pitch, scan.K)
        centre_px, axes, _ = ellipse_from_conic(conic)  # as ground_truth_features projects the rims
        out.append(TrueRound(f"thread_{k}_crests", np.asarray(centre_px, float), np.asarray(axes, float)))
    return out


# -- methods -----------------------------------------------------------------------------------

def free_ellipses_with(hypotheses: str, mask: np.ndarray) -> list:
    """``rs.features.ellipses(mask)`` (no model) with the hypothesis generator ``hypotheses``
    ("tilings", "chains" or "outlines")."""
    return F.ellipses(mask, remove_explained=False, hypotheses=hypotheses)


def cv_circles(mask: np.ndarray, search, param2: int) -> list:
    """cv2.HoughCircles (HOUGH_GRADIENT, dp 1, minDist 10 px, Canny high 100) on the edge map."""
    res = cv2.HoughCircles(mask.astype(np.uint8) * 255, cv2.HOUGH_GRADIENT, 1, 10, param1=100,
                           param2=param2, minRadius=int(search[0]), maxRadius=int(search[1]))
    return [] if res is None else [Found(c[:2], radius=c[2]) for c in res[0]]


def cv_fit_ellipses(mask: np.ndarray, min_points: int = 20) -> list:
    """cv2.fitEllipse on every contour (cv2.findContours: linked edge pixels) of >= min_points."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    out = []
    for c in contours:
        if len(c) >= min_points:
            (x, y), (w, h), _ = cv2.fitEllipse(c)
            if min(w, h) > 0:
                out.append(Found((x, y), axes=(max(w, h) / 2, min(w, h) / 2)))
    return out


def cv_find_ellipses(mask: np.ndarray) -> list:
    """cv2.ximgproc.findEllipses (Jia et al. 2017) on the edge map as an image."""
    res = cv2.ximgproc.findEllipses(mask.astype(np.uint8) * 255)
    if res is None:
        return []
    return [Found(e[:2], axes=(max(e[2], e[3]), min(e[2], e[3]))) for e in res.reshape(-1, res.shape[-1])]


class Seg:
    def __init__(self, a, b):
        self.start, self.end = (float(a[0]), float(a[1])), (float(b[0]), float(b[1]))


def cv_segments(mask: np.ndarray) -> list:
    """cv2.HoughLinesP (1 px, 0.5 degree, 15 votes, min length 30, max gap 3)."""
    res = cv2.HoughLinesP(mask.astype(np.uint8) * 255, 1, np.deg2rad(0.5), 15, minLineLength=30, maxLineGap=3)
    return [] if res is None else [Seg(s[:2], s[2:]) for s in np.asarray(res).reshape(-1, 4)]


def sk_segments(mask: np.ndarray) -> list:
    """skimage probabilistic_hough_line (threshold 15, length 30, gap 3, 0.5 degree, seeded)."""
    from skimage.transform import probabilistic_hough_line
    theta = np.deg2rad(np.arange(-90, 90, 0.5))
    return [Seg(a, b) for a, b in probabilistic_hough_line(mask, 15, 30, 3, theta=theta, rng=0)]


# -- measurement -------------------------------------------------------------------------------

def interleaved(fns: dict, repeat: int, clock=time.perf_counter) -> tuple[dict, dict]:
    """Median seconds of each callable, run in turn ``repeat`` times after one warm-up each
    (``clock``: wall time, or ``time.thread_time`` for the CPU time of this thread, which a
    loaded machine disturbs less)."""
    out = {k: f() for k, f in fns.items()}
    times = {k: [] for k in fns}
    for _ in range(repeat):
        for k, f in fns.items():
            t = clock()
            out[k] = f()
            times[k].append(clock() - t)
    return {k: statistics.median(v) for k, v in times.items()}, out


def _round_scores(found, truth, set_aside: bool = False) -> dict:
    """Recall, precision, centre and radius errors of found circles against ``truth["circles"]``.

    With ``set_aside``, the found circles are matched against the circles and the real
    circles of ``truth["crests"]`` together (one-to-one, nearest centre first, so each found
    circle goes to the edge it lies on); those matched to a crest outline are real circles
    outside the scored truth and count neither as hits nor as false ones (``n_aside``).
    """
    if not set_aside or not truth.get("crests"):
        s = feature_scores({"circles": found}, truth, center_tol_px=2.0)["round"]
        return {"recall": s["recall"], "precision": s["precision"], "n": s["n_found"],
                "centre": s["center_error_px"], "radius": s["radius_error_px"], "n_aside": 0}
    scored = [t for t in truth["circles"] if t.visible >= MIN_VISIBLE]
    s = feature_scores({"circles": found}, {"circles": [*scored, *truth["crests"]]}, center_tol_px=2.0)["round"]
    size = {t.name: float(np.mean(t.axes)) for t in scored}
    hits = [(i, name, e) for i, name, e in s["matches"] if name in size]
    aside = len(s["matches"]) - len(hits)
    ce = [e for _, _, e in hits]
    re = [abs(found[i].radius - size[name]) for i, name, _ in hits]
    stat = lambda v: {"mean": float(np.mean(v)) if v else None, "max": float(np.max(v)) if v else None}  # noqa: E731
    return {"recall": len(hits) / len(scored), "precision": len(hits) / max(len(found) - aside, 1),
            "n": len(found) - aside, "centre": stat(ce), "radius": stat(re), "n_aside": aside, "matches": hits}


def _rims_by_kind(found, truth, set_aside: bool = False) -> list[tuple[int, int, float | None, float | None]]:
    """(matched, truth count, mean and max centre error px) of the plain rims (holes, dent)
    and of the tapped holes' rims, in that order (``set_aside``: as :func:`_round_scores`)."""
    if set_aside:
        matches = _round_scores(found, truth, set_aside=True).get("matches", [])
    else:
        matches = feature_scores({"circles": found}, truth, center_tol_px=2.0)["round"]["matches"]
    scored = [t for t in truth["circles"] if t.visible >= MIN_VISIBLE]  # as feature_scores scores
    out = []
    for tapped in (False, True):
        names = [t.name for t in scored if t.name.startswith("thread") == tapped]
        err = [e for _, name, e in matches if name in names]
        out.append((len(err), len(names), float(np.mean(err)) if err else None, float(np.max(err)) if err else None))
    return out


def _crests_found(found, truth) -> tuple[int, int, float | None]:
    """(found, truth count, mean centre error px) of the crest outlines, as matched by
    :func:`_round_scores` with ``set_aside``."""
    crests = truth.get("crests", [])
    s = feature_scores({"circles": found}, {"circles": [*[t for t in truth["circles"] if t.visible >= MIN_VISIBLE],
                                                        *crests]}, center_tol_px=2.0)["round"]
    err = [e for _, name, e in s["matches"] if name.endswith("_crests")]
    return len(err), len(crests), float(np.mean(err)) if err else None


def _fmt(v, digits=2):
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.{digits}f}"


def _row(inp: str, method: str, t: float, t_base: float | None, s: dict) -> None:
    ratio = f"{t / t_base:5.2f}x" if t_base else "     -"
    print(f"| {inp} | {method} | {t * 1e3:8.1f} | {ratio} | {_fmt(s['recall'])} | {_fmt(s['precision'])} | "
          f"{_fmt(s['centre']['mean'], 3)} / {_fmt(s['centre']['max'], 3)} | "
          f"{_fmt(s['radius']['mean'], 3)} / {_fmt(s['radius']['max'], 3)} |")


def _pooled(scores: list[dict]) -> dict:
    """Scores of several images pooled: recall/precision from the totals, errors over all."""
    def agg(key, part):
        vals = [s[key][part] for s in scores if s[key][part] is not None]
        return (float(np.mean(vals)) if part == "mean" else float(np.max(vals))) if vals else None
    matched = sum(s["recall"] * s["n_truth"] for s in scores)
    return {"recall": matched / sum(s["n_truth"] for s in scores),
            "precision": matched / max(sum(s["n"] for s in scores), 1),
            "centre": {"mean": agg("centre", "mean"), "max": agg("centre", "max")},
            "radius": {"mean": agg("radius", "mean"), "max": agg("radius", "max")}}


def tune_opencv() -> None:
    """OpenCV's param2 by the best F1 on the tuning seeds (printed; copy into CV_PARAM2)."""
    for size, cfg in SYNTH.items():
        maps = [synthetic_edges(size, cfg["n"], s, cfg["radii"]) for s in TUNE_SEEDS]
        for p2 in range(10, 45, 5):
            sc = []
            for m, t in maps:
                s = _round_scores(cv_circles(m, cfg["search"], p2), t)
                s["n_truth"] = len(t["circles"])
                sc.append(s)
            p = _pooled(sc)
            f1 = 2 * p["recall"] * p["precision"] / max(p["recall"] + p["precision"], 1e-9)
            print(f"tune {size}: param2 {p2}: recall {p['recall']:.2f} precision {p['precision']:.2f} F1 {f1:.3f}")


def bench_circles(views, repeat: int) -> None:
    print("\n## circles (times: median of interleaved runs; ratio: rangesim / OpenCV)\n")
    print("| input | method | ms | vs OpenCV | recall | precision | centre error mean / max px | "
          "radius error mean / max px |")
    print("|---|---|---|---|---|---|---|---|")
    for size, cfg in SYNTH.items():
        ours_s, cv_s, t_ours, t_cv = [], [], [], []
        for seed in REPORT_SEEDS[size]:
            mask, truth = synthetic_edges(size, cfg["n"], seed, cfg["radii"])
            t, out = interleaved({"ours": lambda m=mask, r=cfg["search"]: F.circles(m, radii=r),
                                  "cv": lambda m=mask, r=cfg["search"], p=CV_PARAM2[size]: cv_circles(m, r, p)},
                                 repeat)
            for lst, key in ((ours_s, "ours"), (cv_s, "cv")):
                s = _round_scores(out[key], truth)
                s["n_truth"] = len(truth["circles"])
                lst.append(s)
            t_ours.append(t["ours"])
            t_cv.append(t["cv"])
        inp = f"synthetic {size}^2, {cfg['n']} circles, seeds {REPORT_SEEDS[size][0]}-{REPORT_SEEDS[size][-1]}"
        to, tc = statistics.median(t_ours), statistics.median(t_cv)
        _row(inp, "rangesim circles", to, tc, _pooled(ours_s))
        _row(inp, f"OpenCV HOUGH_GRADIENT (param2 {CV_PARAM2[size]})", tc, None, _pooled(cv_s))
    # circles nearly tangent inside others (design seeds 10-15; these are not those)
    scores = {k: [] for k in ("ours", "split", "cv")}
    times = {k: [] for k in scores}
    for seed in REPORT_SEEDS[512]:
        mask, truth = tangent_pairs(512, seed)
        t, out = interleaved({"ours": lambda m=mask: F.circles(m, radii=(5, 64)),
                              "split": lambda m=mask: F.circles(m, radii=(5, 64), split_tangent=True),
                              "cv": lambda m=mask: cv_circles(m, (5, 64), CV_PARAM2[512])}, repeat)
        for k in scores:
            s = _round_scores(out[k], truth)
            s["n_truth"] = len(truth["circles"])
            scores[k].append(s)
            times[k].append(t[k])
    inp = f"tangent pairs 512^2, 6 pairs + 4 lone circles, seeds {REPORT_SEEDS[512][0]}-{REPORT_SEEDS[512][-1]}"
    tc = statistics.median(times["cv"])
    _row(inp, "rangesim circles", statistics.median(times["ours"]), tc, _pooled(scores["ours"]))
    _row(inp, "rangesim circles (split_tangent)", statistics.median(times["split"]), tc, _pooled(scores["split"]))
    _row(inp, f"OpenCV HOUGH_GRADIENT (param2 {CV_PARAM2[512]})", tc, None, _pooled(scores["cv"]))
    by_kind = {}
    for label in ("noisy seed 0", "noise-free"):
        scan, edges, truth = views[(label, "head-on")]
        H, W = edges.mask.shape
        t, out = interleaved({"ours": lambda e=edges: F.circles(e, radii=GREEN_RADII),
                              "split": lambda e=edges: F.circles(e, radii=GREEN_RADII, split_tangent=True),
                              "cv": lambda e=edges: cv_circles(e.mask, GREEN_RADII, CV_PARAM2[512])}, repeat)
        inp = f"Green Piece head-on {W}x{H}, {label} ({int(edges.mask.sum())} edge px)"
        methods = (("ours", "rangesim circles"), ("split", "rangesim circles (split_tangent)"),
                   ("cv", f"OpenCV HOUGH_GRADIENT (param2 {CV_PARAM2[512]})"))
        for key, name in methods:
            _row(inp, name, t[key], t["cv"] if key != "cv" else None, _round_scores(out[key], truth))
        for key, name in methods:
            s = _round_scores(out[key], truth, set_aside=True)
            _row(f"{inp}, crest outlines set aside ({s['n_aside']})", name, t[key], t["cv"] if key != "cv" else None, s)
        by_kind[label] = {k: (_rims_by_kind(out[k], truth), _rims_by_kind(out[k], truth, set_aside=True),
                              _crests_found(out[k], truth)) for k, _ in methods}
    # the tapped holes' top rims are eccentric circles (the helix's section at the top face),
    # while their crests, seen down the hole, outline a circle about the axis 0.3 pitch away:
    # the edge maps hold both, so their errors are told apart from the plain rims'
    # (and a found circle may be either: scored against the rims alone, a crest outline within
    # 2 px of its rim counts as that rim; with the crest outlines set aside, it is matched to
    # the edge it lies on)
    print("\nGreen Piece head-on, rims by kind (found / truth, centre error mean / max px; "
          "crest outlines matched as crest outlines, centre error mean px):\n")
    print("| scan | method | scoring | plain holes and dent | tapped holes (top rims) | crest outlines |")
    print("|---|---|---|---|---|---|")
    for label, methods in by_kind.items():
        for key, name in (("ours", "rangesim circles"), ("split", "rangesim circles (split_tangent)"),
                          ("cv", "OpenCV HOUGH_GRADIENT")):
            rims, aside, (n_c, n_ct, e_c) = methods[key]
            for scoring, kinds in (("rims only", rims), ("crests set aside", aside)):
                cells = [f"{n} / {n_truth}, {_fmt(mean, 3)} / {_fmt(mx, 3)}" for n, n_truth, mean, mx in kinds]
                crest = f"{n_c} / {n_ct}, {_fmt(e_c, 3)}" if scoring != "rims only" else "-"
                print(f"| {label} | {name} | {scoring} | {cells[0]} | {cells[1]} | {crest} |")


def bench_skimage(views) -> None:
    from skimage.transform import hough_circle, hough_circle_peaks

    scan, edges, truth = views[("noise-free", "head-on")]
    radii = np.arange(5, 71)
    t = time.perf_counter()
    acc = hough_circle(edges.mask, radii)
    _, cx, cy, r = hough_circle_peaks(acc, radii, min_xdistance=3, min_ydistance=3, total_num_peaks=15)
    dt = time.perf_counter() - t
    s = _round_scores([Found((x, y), radius=rr) for x, y, rr in zip(cx, cy, r)], truth)
    print(f"\nscikit-image hough_circle + peaks (15), Green Piece noise-free head-on: {dt * 1e3:.0f} ms, "
          f"recall {_fmt(s['recall'])}, precision {_fmt(s['precision'])}")


def bench_ellipses(scene, views, repeat: int) -> None:
    print("\n## ellipses, model-free (times: median of interleaved runs; ratio: rangesim / cv2.fitEllipse)\n")
    print("| input | method | ms | vs fitEllipse | recall | precision | centre error mean / max px | "
          "mean semi-axis error mean / max px |")
    print("|---|---|---|---|---|---|---|---|")
    for label in ("noisy seed 0", "noise-free"):
        scan, edges, truth = views[(label, "tilted")]
        mask = edges.mask
        t, out = interleaved({"ours": lambda m=mask: F.ellipses(m, remove_explained=False),
                              "tilings": lambda m=mask: free_ellipses_with("tilings", m),
                              "chains": lambda m=mask: free_ellipses_with("chains", m),
                              "outlines": lambda m=mask: free_ellipses_with("outlines", m),
                              "fit": lambda m=mask: cv_fit_ellipses(m),
                              "find": lambda m=mask: cv_find_ellipses(m)}, repeat)
        t_cpu, _ = interleaved({"ours": lambda m=mask: F.ellipses(m, remove_explained=False),
                                "tilings": lambda m=mask: free_ellipses_with("tilings", m),
                                "chains": lambda m=mask: free_ellipses_with("chains", m),
                                "outlines": lambda m=mask: free_ellipses_with("outlines", m),
                                "fit": lambda m=mask: cv_fit_ellipses(m)}, 25, clock=time.thread_time)
        inp = f"Green Piece tilted, {label} ({int(mask.sum())} edge px)"
        for key, name in (("ours", "rangesim ellipses (no model, default)"),
                          ("tilings", "rangesim ellipses (no model, tilings)"),
                          ("chains", "rangesim ellipses (no model, chains)"),
                          ("outlines", "rangesim ellipses (no model, outlines)"),
                          ("fit", "cv2.findContours + fitEllipse"), ("find", "cv2.ximgproc.findEllipses")):
            s = feature_scores({"ellipses": out[key]}, truth, center_tol_px=2.0)["round"]
            s = {"recall": s["recall"], "precision": s["precision"], "centre": s["center_error_px"],
                 "radius": s["radius_error_px"]}
            _row(inp, name, t[key], t["fit"] if key != "fit" else None, s)
            if key in t_cpu and key != "fit":
                print(f"|   | (CPU time, median of 25) | {t_cpu[key] * 1e3:.2f} | {t_cpu[key] / t_cpu['fit']:.2f}x "
                      f"(fitEllipse {t_cpu['fit'] * 1e3:.2f} ms) | | | | |")
        t_mg, found = interleaved({"mg": lambda e=edges, s=scan: F.ellipses(e, s, scene)}, max(1, repeat // 2))
        s = feature_scores({"ellipses": found["mg"]}, truth, center_tol_px=2.0)["round"]
        s = {"recall": s["recall"], "precision": s["precision"], "centre": s["center_error_px"],
             "radius": s["radius_error_px"]}
        _row(inp, "rangesim ellipses (model-guided)", t_mg["mg"], None, s)


def bench_segments(views, repeat: int) -> None:
    print("\n## segments (times: median of interleaved runs; ratio: rangesim / cv2.HoughLinesP)\n")
    print("| input | method | ms | vs HoughLinesP | recall | precision | endpoint error mean / max px |")
    print("|---|---|---|---|---|---|---|")
    for key in (("noise-free", "head-on"), ("noise-free", "tilted"), ("noisy seed 0", "tilted")):
        scan, edges, truth = views[key]
        truth = {"circles": [], "segments": [s for s in truth["segments"]
                                              if np.hypot(*(s.xyxy[2:] - s.xyxy[:2])) >= 30]}
        t, out = interleaved({"ours": lambda e=edges: F.lines(e), "cv": lambda e=edges: cv_segments(e.mask),
                              "sk": lambda e=edges: sk_segments(e.mask)}, repeat)
        inp = f"Green Piece {key[1]}, {key[0]} ({len(truth['segments'])} truth segments >= 30 px)"
        for k, name in (("ours", "rangesim lines"), ("cv", "cv2.HoughLinesP"),
                        ("sk", "skimage probabilistic_hough_line")):
            s = feature_scores({"segments": out[k]}, truth, segment_tol_px=5.0)["segments"]
            ratio = f"{t[k] / t['cv']:5.2f}x" if k != "cv" else "     -"
            print(f"| {inp} | {name} | {t[k] * 1e3:8.1f} | {ratio} | {_fmt(s['recall'])} | "
                  f"{_fmt(s['precision'])} | {_fmt(s['endpoint_error_px']['mean'])} / "
                  f"{_fmt(s['endpoint_error_px']['max'])} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--tune", action="store_true", help="choose OpenCV's param2 on the tuning seeds")
    ap.add_argument("--skimage", action="store_true", help="also scikit-image hough_circle (slow)")
    args = ap.parse_args()
    print(f"cpu: {cpu_info()}; OpenCV {cv2.__version__} (1 thread); tuning seeds {TUNE_SEEDS}, "
          f"report seeds {REPORT_SEEDS}")
    if args.tune:
        tune_opencv()
    scene, views = green_piece()
    bench_circles(views, args.repeat)
    if args.skimage:
        bench_skimage(views)
    bench_ellipses(scene, views, args.repeat)
    bench_segments(views, args.repeat)


if __name__ == "__main__":
    main()
