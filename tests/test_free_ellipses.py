"""Model-free ellipses (rangesim.features._arc_ellipses): arcs of smooth edge curves, grown.

Synthetic edge masks with exact ellipses drawn as pixels (with gaps, junctions and clutter),
so the expected centres and axes are known exactly; and one scan of a machined part that the
finder was not tuned on (seed 500; tuning used seeds 0-19).
"""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import rangesim as rs
import rangesim.features as F
from rangesim.core.geometry import look_at
from rangesim.features._arc_ellipses import smooth_curves


def draw_ellipse(mask, center, axes, angle, gaps=(), step=0.2):
    """Pixels of an ellipse (parametric samples rounded), leaving out the parameter ranges
    ``gaps`` (radians)."""
    t = np.arange(0, 2 * np.pi, step / max(axes))
    keep = np.ones(len(t), bool)
    for a, b in gaps:
        keep &= ~((t >= a) & (t < b))
    t = t[keep]
    (a, b), c, s = axes, np.cos(angle), np.sin(angle)
    x = center[0] + a * np.cos(t) * c - b * np.sin(t) * s
    y = center[1] + a * np.cos(t) * s + b * np.sin(t) * c
    mask[np.rint(y).astype(int), np.rint(x).astype(int)] = True


def draw_segment(mask, p, q):
    n = int(np.ceil(np.hypot(*np.subtract(q, p)))) * 3 + 1
    x, y = np.linspace(p[0], q[0], n), np.linspace(p[1], q[1], n)
    mask[np.rint(y).astype(int), np.rint(x).astype(int)] = True


TRUE = [((80.0, 70.0), (30.0, 18.0), 0.3), ((200.0, 80.0), (12.0, 9.0), -1.0),
        ((150.0, 180.0), (45.0, 40.0), 1.2)]


@pytest.fixture(scope="module")
def scene_mask():
    rng = np.random.default_rng(3)
    m = np.zeros((260, 280), bool)
    draw_ellipse(m, *TRUE[0], gaps=[(0.5, 0.75), (2.0, 2.2), (4.0, 4.3)])  # three gaps
    draw_ellipse(m, *TRUE[1])
    draw_ellipse(m, *TRUE[2], gaps=[(3.5, 5.0)])  # a quarter missing
    draw_segment(m, (60, 70 - 30), (150, 70 - 30))  # a line crossing the first ellipse's top
    draw_segment(m, (230, 150), (270, 150))  # a rectangle: corners, no ellipse
    draw_segment(m, (270, 150), (270, 240))
    draw_segment(m, (270, 240), (230, 240))
    draw_segment(m, (230, 240), (230, 150))
    for _ in range(12):  # short dashes inside the big ellipse
        x, y = rng.uniform(120, 180), rng.uniform(150, 210)
        a = rng.uniform(0, np.pi)
        draw_segment(m, (x, y), (x + 4 * np.cos(a), y + 4 * np.sin(a)))
    return m


def _match(found, center, axes):
    """Centre distance and largest semi-axis error of the found ellipse nearest to the given
    one (centre and axes together: concentric ellipses share a centre)."""
    d = np.array([np.hypot(*np.subtract(f.center, center)) for f in found])
    da = np.array([np.abs(np.subtract(f.axes, axes)).max() for f in found])
    k = int(np.argmin(d + da))
    return d[k], da[k]


@pytest.mark.parametrize("hypotheses", ["tilings", "chains"])
def test_exact_ellipses_found_amid_gaps_lines_and_clutter(scene_mask, hypotheses):
    found = F.ellipses(scene_mask, remove_explained=False, hypotheses=hypotheses)
    for center, axes, _ in TRUE:
        d, da = _match(found, center, axes)
        assert d <= 0.3 and da <= 0.5, (center, d, da)
    # nothing else: not the rectangle, not the dashes, not a duplicate
    assert len(found) == len(TRUE), [(np.round(f.center), np.round(f.axes)) for f in found]


def test_same_result_every_run_and_from_the_default_path(scene_mask):
    a = F.ellipses(scene_mask, remove_explained=False)
    b = F.ellipses(scene_mask, remove_explained=False)
    assert [(f.center, f.axes) for f in a] == [(f.center, f.axes) for f in b]
    # the default path removes the straight lines first: the same ellipses
    c = F.ellipses(scene_mask)
    assert len(c) == len(TRUE)
    for center, axes, _ in TRUE:
        assert _match(c, center, axes)[0] <= 0.3


def test_concentric_ellipses_each_found_once():
    m = np.zeros((200, 200), bool)
    draw_ellipse(m, (100, 100), (40, 25), 0.2)
    draw_ellipse(m, (100, 100), (34, 19), 0.2)  # 6 px inside: a hole's wall seen inside its rim
    found = F.ellipses(m, remove_explained=False)
    assert len(found) == 2
    assert sorted(round(f.axes[0]) for f in found) == [34, 40]


def test_corners_end_curves():
    m = np.zeros((60, 60), bool)
    draw_segment(m, (10, 10), (50, 10))
    draw_segment(m, (50, 10), (50, 50))
    from rangesim.features._edge_points import edge_points

    xy, theta = edge_points(m)
    lab = smooth_curves(xy, theta)
    corner_free = (np.abs(xy[:, 0] - 50) > 3) | (np.abs(xy[:, 1] - 10) > 3)
    top = corner_free & (xy[:, 1] == 10)
    side = corner_free & (xy[:, 0] == 50)
    assert len(np.unique(lab[top])) == 1 and len(np.unique(lab[side])) == 1
    assert lab[top][0] != lab[side][0]


def test_hole_rims_of_an_untuned_machined_part():
    """Rims of a part the finder was not tuned on, seen obliquely: found within 1 px."""
    part = rs.cad.machined_part(500)
    sensor = rs.load_sensor("white_scanner").with_params({
        "camera.width": 384, "camera.height": 288, "noise.sigma_px": 0.0, "noise.speckle_contrast": 0.0})
    lo, hi = part.mesh.bounds
    table = trimesh.creation.box((400, 400, 5))
    table.apply_translation((0, 0, lo[2] - 2.5))
    scene = rs.Scene([rs.SceneObject("part", part.mesh, features=part.features, source="machined_part(500)"),
                      rs.SceneObject("table", table, albedo=0.4, source="box")])
    target = (lo + hi) / 2
    eye = target + 330 * np.array([np.cos(np.radians(50)) * np.cos(0.7), np.cos(np.radians(50)) * np.sin(0.7),
                                   np.sin(np.radians(50))])
    scan = rs.scan(scene, sensor, pose=look_at(eye, target), seed=0)
    edges = rs.edges.gradient(scan)
    truth = [c for c in rs.evaluate.ground_truth_features(scan, scene)["circles"]
             if c.name.endswith("_top") and "hole" in c.name and c.visible >= 0.8]
    assert len(truth) >= 2
    found = F.ellipses(edges, min_points=12, axes_range=(2.5, 200))
    hits = [min((np.hypot(*np.subtract(f.center, t.center)) for f in found), default=np.inf) for t in truth]
    assert np.mean(np.array(hits) <= 1.0) >= 0.75, hits


@pytest.mark.parametrize("hypotheses", ["tilings", "chains", "outlines"])
@pytest.mark.parametrize("axes", [(150.0, 90.0), (180.0, 170.0), (100.0, 30.0), (6.0, 4.5)])
def test_sizes_from_small_rims_to_large_ellipses(axes, hypotheses):
    """Large ellipses (arcs longer than the tiles) and small rims (a few pixels) alike, with
    each hypothesis generator."""
    m = np.zeros((420, 420), bool)
    draw_ellipse(m, (210.3, 209.6), axes, 0.4, gaps=[(1.0, 1.4)])
    found = F.ellipses(m, remove_explained=False, min_points=12, axes_range=(2.5, 250), hypotheses=hypotheses)
    assert len(found) == 1
    d, da = _match(found, (210.3, 209.6), axes)
    assert d <= 0.3 and da <= 0.3, (d, da)


def test_rim_around_thread_crests(monkeypatch):
    """A threaded hole: crests (arcs of smaller, shifted ellipses 2 px apart, touching the rim)
    fill the rim, so every arc piece of the rim is linked to clutter; the rim's outer outline
    still gives it."""
    m = np.zeros((140, 140), bool)
    center, axes, angle = (70.0, 68.0), (30.0, 22.0), 0.25
    draw_ellipse(m, center, axes, angle)
    for k in range(1, 9):  # crests: concentric arcs sweeping inwards, each touching the rim
        shrink = 2.0 * k
        draw_ellipse(m, (center[0] + 0.6 * shrink, center[1]), (axes[0] - shrink, axes[1] - shrink), angle,
                     gaps=[(2.6, 6.3)])
    for hypotheses in ("tilings", "outlines"):
        found = F.ellipses(m, remove_explained=False, hypotheses=hypotheses)
        d, da = _match(found, center, axes)
        assert d <= 0.3 and da <= 0.5, (hypotheses, d, da)
    # the arc pieces alone miss it: the outline is what finds it
    import rangesim.features._arc_ellipses as A

    monkeypatch.setattr(A, "outline_hypotheses", lambda xy, **kw: (np.zeros((0, 6)), np.zeros(0, int)))
    alone = F.ellipses(m, remove_explained=False)
    assert not alone or _match(alone, center, axes)[0] > 0.3


def test_coverage_is_the_fraction_of_arc_length_on_thin_ellipses():
    """Coverage counts 1 px bins of arc length: on a thin ellipse (b/a = 0.15) the points of
    the arc from one end of the major axis to the other (half the perimeter, by symmetry)
    cover half of it, and the two flat sides alone (most of the perimeter) not the ends'
    share; equal steps of the parametric angle would give the flat sides far less weight."""
    from rangesim.core.conics import fit_conic
    from rangesim.features._arc_ellipses import coverage

    center, axes, angle = np.array([100.0, 80.0]), (40.0, 6.0), 0.3
    t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    (a, b), c, s = axes, np.cos(angle), np.sin(angle)
    pts = np.column_stack([center[0] + a * np.cos(t) * c - b * np.sin(t) * s,
                           center[1] + a * np.cos(t) * s + b * np.sin(t) * c])
    conic = fit_conic(pts)[None]
    full = coverage(conic, pts, np.zeros(len(pts), int), np.arange(len(pts)))[0][0]
    half_idx = np.nonzero(t < np.pi)[0]
    half = coverage(conic, pts, np.zeros(len(half_idx), int), half_idx)[0][0]
    # the quarter of parametric angle around each end of the major axis holds little arc
    ends = np.nonzero(np.abs(np.cos(t)) > np.cos(np.pi / 4))[0]
    end_cov = coverage(conic, pts, np.zeros(len(ends), int), ends)[0][0]
    assert full == pytest.approx(1.0, abs=0.01)
    assert half == pytest.approx(0.5, abs=0.02)
    # exact share of the arc where |cos t| > cos 45 deg: integrate the speed
    tt = np.linspace(0, 2 * np.pi, 200001)
    speed = np.hypot(a * np.sin(tt), b * np.cos(tt))
    share = speed[np.abs(np.cos(tt)) > np.cos(np.pi / 4)].sum() / speed.sum()
    assert end_cov == pytest.approx(share, abs=0.02) and share < 0.45


def test_circles_are_not_the_ends_of_elongated_ellipses(monkeypatch):
    """Near the ends of its major axis a small elongated ellipse (b/a 0.65-0.7) follows a
    circle over about half of it: the circle finder must not report that circle, while a real
    circle drawn over 60 % of its perimeter beside it is kept."""
    import rangesim.features._circles as C

    for axes in ((16.0, 11.0), (14.0, 9.0)):
        m = np.zeros((120, 200), bool)
        draw_ellipse(m, (60.3, 60.2), axes, 0.3)
        draw_ellipse(m, (150.0, 60.0), (15.0, 15.0), 0.0, gaps=[(0.0, 0.4 * 2 * np.pi)])
        found = F.circles(m, radii=(4, 30))
        assert [round(f.radius) for f in found] == [15], [(np.round(f.center), round(f.radius, 1)) for f in found]
    # without the check, the last ellipse's end is reported as a circle
    monkeypatch.setattr(C, "_ellipse_pieces", lambda found, xy, theta: np.zeros(len(found), bool))
    assert len(F.circles(m, radii=(4, 30))) == 2


def test_grouped_sums_keep_the_last_row_before_empty_groups():
    """Fits per group equal single fits when the last groups are empty (the last non-empty
    group must keep its last point)."""
    from rangesim.core.conics import _group_sums, fit_conic, fit_conics_grouped

    w = np.arange(1.0, 6.0)[:, None]
    np.testing.assert_array_equal(_group_sums(w, np.array([0, 0, 1, 1, 1]), 3)[:, 0], [3.0, 12.0, 0.0])
    t = np.linspace(0, 5, 40)
    xy = np.column_stack([50 + 20 * np.cos(t), 40 + 11 * np.sin(t)])
    grouped, ok = fit_conics_grouped(xy, np.zeros(len(xy), int), 3)
    single = fit_conic(xy)
    assert ok[0] and not ok[1:].any()
    assert abs(abs(grouped[0] @ single) - 1) < 1e-12


def test_outer_outline_holds_every_side_of_a_rim():
    """The outline of a closed rim with clutter inside is the whole rim, top and left included."""
    from rangesim.features._arc_ellipses import outline_hypotheses
    from rangesim.features._edge_points import edge_points

    m = np.zeros((100, 100), bool)
    draw_ellipse(m, (50.0, 48.0), (30.0, 20.0), 0.0)
    draw_ellipse(m, (50.0, 48.0), (20.0, 10.0), 0.0)  # enclosed: a group of its own
    xy, _ = edge_points(m)
    conics, n = outline_hypotheses(xy)  # the rim's outline, and the inner ellipse's own
    assert len(n) == 2
    # the outline points themselves: every quadrant of the rim is there (the dilation that
    # bridges gaps grows up and left; the test must look past it on those sides)
    from rangesim.features._ellipse_kernels import outline_points

    idx, _, _ = outline_points(xy.astype(np.int64), 1)
    p = xy[idx]
    rim = np.hypot((p[:, 0] - 50) / 30, (p[:, 1] - 48) / 20) > 0.8
    all_rim = np.hypot((xy[:, 0] - 50) / 30, (xy[:, 1] - 48) / 20) > 0.8
    for sx in (-1, 1):
        for sy in (-1, 1):
            q = rim & (np.sign(p[:, 0] - 50) == sx) & (np.sign(p[:, 1] - 48) == sy)
            q_all = all_rim & (np.sign(xy[:, 0] - 50) == sx) & (np.sign(xy[:, 1] - 48) == sy)
            assert q.sum() >= 0.35 * q_all.sum(), (sx, sy, q.sum(), q_all.sum())


def test_compiled_helpers_match_the_numpy_they_replace():
    # the moments (float64 sums point by point: within round-off of exact sums, and closer
    # to them than the float32 rows NumPy's batched form summed), the order of the pieces by
    # (curve, count, sum) (np.lexsort), the curves (scipy's connected components of the
    # links) and the outlines (ndimage's dilation and labels)
    import math

    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from rangesim.core.conics import conic_monomials
    from rangesim.features._ellipse_kernels import _by_curve_count_sum, _piece_moments, curve_labels, outline_points

    rng = np.random.default_rng(3)
    xy = rng.integers(0, 400, (3000, 2)).astype(float) + rng.uniform(-0.5, 0.5, (3000, 2))
    got = np.empty(15)
    for n in (1, 5, 8, 127, 129, 300, 2999):
        pts, frame = rng.integers(0, 3000, n), np.array([rng.uniform(0, 400), rng.uniform(0, 400), 64.0])
        _piece_moments(xy, pts, 0, n, frame, got)
        rows = conic_monomials((xy[pts] - frame[:2]) / frame[2])
        exact = np.array([math.fsum(c) for c in rows.T])
        scale = np.abs(rows).sum(0)
        assert np.all(np.abs(got - exact) <= 1e-13 * scale)
        float32 = np.add.reduceat(conic_monomials(((xy[pts] - frame[:2]) / frame[2]).astype(np.float32)), [0])[0]
        assert np.abs(got - exact).max() <= np.abs(float32 - exact).max()

    curve, cnt, psum = rng.integers(0, 30, 2000), rng.integers(5, 9, 2000), rng.integers(0, 4, 2000)
    curve[:300] = 7  # a curve of many pieces (merge sorts)
    assert np.array_equal(_by_curve_count_sum(curve, cnt, psum, 2000, 30), np.lexsort((psum, cnt, curve)))

    x, y = rng.integers(0, 60, 800), rng.integers(0, 50, 800)
    keep = np.unique(y * 60 + x, return_index=True)[1]
    x, y, theta = x[keep], y[keep], rng.uniform(-np.pi, np.pi, len(keep))
    lab, n_lab = curve_labels(x, y, theta, 3, np.cos(0.6), np.sin(0.6), np.cos(0.5))
    pairs = [(i, k) for i in range(len(x)) for k in range(len(x))
             if (y[k] - y[i], x[k] - x[i]) > (0, 0) and max(abs(x[k] - x[i]), abs(y[k] - y[i])) <= 3
             and abs(np.cos(theta[i] - theta[k])) >= np.cos(0.6)
             and all(abs((x[k] - x[i]) * np.cos(t) + (y[k] - y[i]) * np.sin(t))
                     <= (np.sin(0.6) if max(abs(x[k] - x[i]), abs(y[k] - y[i])) > 1 else np.cos(0.5))
                     * np.hypot(x[k] - x[i], y[k] - y[i]) for t in (theta[i], theta[k]))]
    r, c = np.array(pairs).T
    n_ref, ref = connected_components(coo_matrix((np.ones(len(r)), (r, c)), shape=(len(x),) * 2), directed=False)
    assert n_lab == n_ref and np.array_equal(lab, ref)

    pix = np.column_stack([x, y]).astype(np.int64)
    for g in (1, 2):
        m = np.zeros((y.max() + 2 * g + 3, x.max() + 2 * g + 3), bool)
        m[y + g + 1, x + g + 1] = True
        grown = ndimage.binary_dilation(m, np.ones((2 * g + 1,) * 2, bool))
        groups = ndimage.label(grown, np.ones((3, 3), bool))[0]
        spaces = ndimage.label(~grown)[0]
        gl = groups[y + g + 1, x + g + 1]
        on = np.zeros(len(x), bool)
        for k in np.unique(gl):
            gy, gx = np.nonzero(groups == k)
            j = np.argmin(gx * grown.shape[0] + gy)
            outer = spaces[gy[j], gx[j] - 1]
            for dy, dx in ((-g - 1, 0), (g + 1, 0), (0, -g - 1), (0, g + 1)):
                on |= (gl == k) & (spaces[y + g + 1 + dy, x + g + 1 + dx] == outer)
        idx, group, n = outline_points(pix, g)
        ref = np.nonzero(on)[0]
        ref = ref[np.argsort(gl[ref], kind="stable")]
        assert np.array_equal(idx, ref)
        assert np.array_equal(n, np.unique(gl[ref], return_counts=True)[1])


def test_inner_outlines_match_ndimage_regions():
    # outline_points' inner outlines (inner=True): after the groups' outer outlines, each
    # background region a group encloses (4-connected regions of the dilated mask, numbered as
    # the points meet them in raster order) with the group's points whose footprint's
    # 4-neighbour lies in it; checked against ndimage's dilation and labels on rings that
    # touch, nest and cross
    from scipy import ndimage

    from rangesim.features._ellipse_kernels import outline_points

    rng = np.random.default_rng(11)
    n_regions = 0
    for _ in range(6):
        m = np.zeros((90, 110), bool)
        for _ in range(5):
            draw_ellipse(m, rng.uniform(15, 95, 2) * (1, 0.8), rng.uniform((6, 3), (18, 12)), rng.uniform(0, np.pi))
        draw_segment(m, rng.integers(5, 85, 2), rng.integers(5, 85, 2))
        y, x = np.nonzero(m)
        pix = np.column_stack([x, y]).astype(np.int64)
        for g in (0, 1, 2):
            idx, group, n = outline_points(pix, g)
            idx_in, group_in, n_in = outline_points(pix, g, True)
            G = len(n)
            assert np.array_equal(idx_in[:len(idx)], idx) and np.array_equal(n_in[:G], n)
            pad = np.zeros((m.shape[0] + 2 * g + 2, m.shape[1] + 2 * g + 2), bool)
            pad[y + g + 1, x + g + 1] = True
            grown = ndimage.binary_dilation(pad, np.ones((2 * g + 1,) * 2, bool))
            groups = ndimage.label(grown, np.ones((3, 3), bool))[0]
            spaces = ndimage.label(~grown)[0]
            gl = groups[y + g + 1, x + g + 1]
            outer_of = {}
            for k in np.unique(gl):
                gy, gx = np.nonzero(groups == k)
                j = np.argmin(gx * grown.shape[0] + gy)
                outer_of[k] = spaces[gy[j], gx[j] - 1]
            regions, members = [], {}
            for i in np.lexsort((x, y)):  # raster order
                for dy, dx in ((-g - 1, 0), (g + 1, 0), (0, -g - 1), (0, g + 1)):
                    s = spaces[y[i] + g + 1 + dy, x[i] + g + 1 + dx]
                    if s and s != outer_of[gl[i]]:
                        if s not in members:
                            regions.append(s)
                            members[s] = []
                        if i not in members[s]:
                            members[s].append(i)
            n_regions += len(regions)
            assert np.array_equal(n_in[G:], [len(members[s]) for s in regions])
            if regions:
                assert np.array_equal(idx_in[len(idx):], np.concatenate([members[s] for s in regions]))
            assert np.array_equal(group_in[len(idx):], np.repeat(np.arange(G, G + len(regions)), n_in[G:]))
            # points in any order: the same outlines, by the points' new indices
            perm = rng.permutation(len(pix))
            idx_p, group_p, n_p = outline_points(np.ascontiguousarray(pix[perm]), g, True)
            assert np.array_equal(n_p, n_in) and np.array_equal(group_p, group_in)
            for k in range(len(n_in)):  # within an outline, the same points
                assert np.array_equal(np.sort(perm[idx_p[group_p == k]]), np.sort(idx_in[group_in == k]))
    assert n_regions >= 40  # the rings enclosed regions, some of them shared by touching rings


def test_grouped_frames_and_sampson_pairs_match_numpy():
    # fit_conics_grouped's centroids, scales and moments (empty groups too; the moments to
    # round-off, as they are summed point by point) and the Sampson distances, to the bits
    from rangesim.core import conics as C
    from rangesim.features._conic_kernels import grouped_frames, sampson_pairs

    rng = np.random.default_rng(8)
    xy = rng.uniform(0, 500, (2000, 2))
    for G in (1, 7, 300):
        group = np.sort(rng.integers(0, G, 5000))
        pt = rng.integers(0, 2000, 5000)
        keep = rng.random(5000) < 0.6
        g2, p2 = group[keep], xy[pt[keep]]
        n = np.bincount(g2, minlength=G)
        m = C._group_sums(p2, g2, G) / np.maximum(n, 1)[:, None]
        q = p2 - m[g2]
        s = np.maximum(np.maximum.reduceat(np.abs(q).max(1), np.minimum(np.searchsorted(g2, np.arange(G)), len(g2) - 1)),
                       1e-9)
        s[n == 0] = 1.0
        rows = C.conic_monomials(q / s[g2, None])
        mom = C._group_sums(rows, g2, G)
        m2, s2, mom2 = grouped_frames(xy, pt, keep, group, G)
        np.testing.assert_allclose(m2, m, rtol=1e-13)
        np.testing.assert_allclose(s2, s, rtol=1e-12)
        assert np.all(np.abs(mom2 - mom) <= 1e-12 * C._group_sums(np.abs(rows), g2, G) + 1e-300)
        assert np.array_equal(mom2[n == 0], np.zeros(((n == 0).sum(), 15)))
        conics = rng.normal(size=(G, 6))
        assert np.array_equal(sampson_pairs(conics, group, xy, pt), C.sampson_distance_rows(conics[group], xy[pt]))


def test_compiled_coverage_and_claims_match_the_batched_coverage():
    # the free path's coverage (compiled, pairs by conic) is the circle finder's batched one
    # (coverage): the same bins, the RMS to an ulp (sqrt for hypot)
    from rangesim.core.conics import fit_conic
    from rangesim.features._arc_ellipses import _COS_T, _SIN_T, MAX_PERIMETER_PX, coverage
    from rangesim.features._ellipse_kernels import coverage_rows

    rng = np.random.default_rng(5)
    conics, hyp, pts = [], [], []
    xy = rng.uniform(0, 200, (4000, 2))
    for k in range(30):
        c, a = rng.uniform(40, 160, 2), rng.uniform(3, 60)
        b, ang = a * rng.uniform(0.1, 1.0), rng.uniform(0, np.pi)
        t = rng.uniform(0, 2 * np.pi, 200)
        e = np.column_stack([a * np.cos(t), b * np.sin(t)]) @ np.array([[np.cos(ang), np.sin(ang)],
                                                                       [-np.sin(ang), np.cos(ang)]])
        xy[k * 100:k * 100 + 100] = c + e[:100] + rng.normal(0, 0.3, (100, 2))
        conics.append(fit_conic(c + e) if k % 7 else np.array([0.0, 0, 0, 1, 1, -5]))  # a line too
        hyp.append(np.full(100, k))
        pts.append(np.arange(k * 100, k * 100 + 100))
    conics, hyp, pts = np.array(conics), np.concatenate(hyp), np.concatenate(pts)
    cov0, rms0, per0 = coverage(conics, xy, hyp, pts)
    cov1, rms1, per1 = coverage_rows(conics, xy, hyp, pts, _SIN_T, _COS_T, MAX_PERIMETER_PX)
    assert np.array_equal(cov0, cov1) and np.array_equal(per0, per1)
    assert np.allclose(rms0, rms1, rtol=1e-14) and np.array_equal(np.isinf(rms0), np.isinf(rms1))


# -- the chain hypotheses (free_ellipses(..., hypotheses="chains"), opt-in) -------------------

@pytest.fixture
def chains(monkeypatch):
    """``rs.features.ellipses`` without a model on the chain hypotheses."""
    import rangesim.features._arc_ellipses as A

    monkeypatch.setattr(A, "HYPOTHESES", "chains")


def test_chains_concentric_ellipses_each_found_once(chains):
    m = np.zeros((200, 200), bool)
    draw_ellipse(m, (100, 100), (40, 25), 0.2)
    draw_ellipse(m, (100, 100), (34, 19), 0.2)
    found = F.ellipses(m, remove_explained=False)
    assert sorted(round(f.axes[0]) for f in found) == [34, 40]


def test_chains_rim_around_thread_crests(chains):
    m = np.zeros((140, 140), bool)
    center, axes, angle = (70.0, 68.0), (30.0, 22.0), 0.25
    draw_ellipse(m, center, axes, angle)
    for k in range(1, 9):
        shrink = 2.0 * k
        draw_ellipse(m, (center[0] + 0.6 * shrink, center[1]), (axes[0] - shrink, axes[1] - shrink), angle,
                     gaps=[(2.6, 6.3)])
    d, da = _match(F.ellipses(m, remove_explained=False), center, axes)
    assert d <= 0.3 and da <= 0.5, (d, da)


def _large_partials(seed: int = 7):
    """A 1024^2 mask: 4 partial ellipses of semi-axes 150-195 px (60-90 % drawn, 0.25 px
    jitter) amid 20 segments and 500 noise pixels; and the ellipses' (centre, axes)."""
    rng = np.random.default_rng(seed)
    size = 1024
    m = np.zeros((size, size), bool)
    truth = []
    for _ in range(4):
        a = rng.uniform(150, 195)
        b, t = a * rng.uniform(0.4, 0.75), rng.uniform(0, np.pi)
        c = rng.uniform(a * 0.5, size - a * 0.5, 2)
        frac = rng.uniform(0.6, 0.9)
        s = rng.uniform(0, 2 * np.pi) + np.linspace(0, frac * 2 * np.pi, int(frac * 2 * np.pi * a * 3))
        x, y = a * np.cos(s), b * np.sin(s)
        px = c[0] + x * np.cos(t) - y * np.sin(t) + rng.normal(0, 0.25, len(s))
        py = c[1] + x * np.sin(t) + y * np.cos(t) + rng.normal(0, 0.25, len(s))
        ok = (px >= 0) & (px <= size - 1) & (py >= 0) & (py <= size - 1)
        m[np.rint(py[ok]).astype(int), np.rint(px[ok]).astype(int)] = True
        truth.append((c, (a, b)))
    for _ in range(20):
        p0, L, t = rng.uniform(0, size, 2), rng.uniform(20, 200), rng.uniform(0, np.pi)
        q = np.clip(p0 + L * np.array([np.cos(t), np.sin(t)]), 0, size - 1)
        draw_segment(m, np.clip(p0, 0, size - 1), q)
    m[rng.integers(0, size, 500), rng.integers(0, size, 500)] = True
    return m, truth


def _truths_found(found, truth) -> int:
    """How many of the true ellipses some found one matches (centre and semi-major axis
    within 1 px)."""
    return sum(any(np.hypot(*np.subtract(f.center, c)) <= 1.0 and abs(f.axes[0] - ax[0]) <= 1.0 for f in found)
               for c, ax in truth)


def test_chains_large_partial_ellipses_amid_clutter(chains):
    """Partial ellipses of semi-axes 150-195 px amid segments and noise pixels: at least 3 of
    the 4 found within 1 px (the tilings find 2 here)."""
    m, truth = _large_partials()
    found = F.ellipses(m, remove_explained=False)
    assert _truths_found(found, truth) >= 3, [(np.round(f.center), np.round(f.axes)) for f in found]


def test_the_public_call_picks_the_hypotheses(chains, monkeypatch):
    """``ellipses(..., hypotheses=...)`` picks the generator whatever the module default, on a
    map where the two differ (the large partial ellipses: chains find more); anything else is
    refused, naming the argument."""
    import rangesim.features._arc_ellipses as A
    m, truth = _large_partials()
    asked_chains = F.ellipses(m, remove_explained=False, hypotheses="chains")
    asked_tilings = F.ellipses(m, remove_explained=False, hypotheses="tilings")
    assert _truths_found(asked_chains, truth) > _truths_found(asked_tilings, truth)
    monkeypatch.setattr(A, "HYPOTHESES", "tilings")
    assert [e.center for e in F.ellipses(m, remove_explained=False)] == [e.center for e in asked_tilings]
    assert [e.center for e in F.ellipses(m, remove_explained=False, hypotheses="chains")] == \
        [e.center for e in asked_chains]
    with pytest.raises(ValueError, match="hypotheses"):
        F.ellipses(m, hypotheses="contours")


def test_outlines_fit_each_edge_group_as_fitellipse_would(scene_mask):
    """``hypotheses="outlines"``: one fit per edge group's outline, outer and inner (after one
    trimmed refit), grown and claimed as the other generators' fits. On the clutter map every
    ellipse is its own group's outline (a crossing line is trimmed away) and found as the
    tilings find it, nothing else. An ellipse inside a rectangle that touches it is not on its
    group's outer outline but is the outline of the region it encloses: found with the inner
    outlines, missed without them. Split by a line across its inside, no outline is the
    ellipse: this generator misses it where the tilings find it."""
    found = F.ellipses(scene_mask, remove_explained=False, hypotheses="outlines")
    assert len(found) == len(TRUE)
    for center, axes, _ in TRUE:
        d, da = _match(found, center, axes)
        assert d <= 0.3 and da <= 0.5, (center, d, da)
    m = np.zeros((120, 140), bool)
    draw_ellipse(m, (60.3, 59.6), (25.0, 16.0), 0.0)
    top = int(np.rint(59.6 - 16.0))  # the rectangle's top side touches the ellipse's top
    for p, q in (((20, top), (110, top)), ((110, top), (110, 100)), ((110, 100), (20, 100)), ((20, 100), (20, top))):
        draw_segment(m, p, q)
    for hypotheses in ("outlines", "tilings"):
        d, da = _match(F.ellipses(m, remove_explained=False, hypotheses=hypotheses), (60.3, 59.6), (25.0, 16.0))
        assert d <= 0.3 and da <= 0.3, (hypotheses, d, da)
    from rangesim.features import _arc_ellipses as A
    xy = np.column_stack(np.nonzero(m)[::-1]).astype(float)
    outer_only, inner_too = A.outline_hypotheses(xy), A.outline_hypotheses(xy, inner=True)
    assert len(outer_only[0]) == 0 and len(inner_too[0]) >= 1
    draw_segment(m, (60, 43), (60, 76))  # splits the ellipse's inside in two
    assert F.ellipses(m, remove_explained=False, hypotheses="outlines") == []
    d, da = _match(F.ellipses(m, remove_explained=False, hypotheses="tilings"), (60.3, 59.6), (25.0, 16.0))
    assert d <= 0.3 and da <= 0.3, (d, da)


def test_outlines_without_dilation_keep_apart_what_it_joins(monkeypatch):
    """A broken ellipse with a line 2 px beside it (a cylinder's side beside its top): dilated
    by a pixel, the two make one group whose outline is neither, and the ellipse's inside
    leaks through the break; the undilated outlines keep the arc its own group, so the
    "outlines" generator (both, :data:`OUTLINE_PASSES`) finds it within 0.1 px, as the
    tilings do, and the dilated outlines alone do not."""
    import rangesim.features._arc_ellipses as A
    m = np.zeros((110, 130), bool)
    draw_ellipse(m, (60.3, 50.4), (25.0, 15.0), 0.1, gaps=[(2.2, 2.6)])
    x = int(np.ceil(60.3 + 25.2)) + 2
    draw_segment(m, (x, 45), (x, 100))
    assert A.OUTLINE_PASSES == ((1, True), (0, False))
    for hypotheses in ("outlines", "tilings"):
        d, da = _match(F.ellipses(m, remove_explained=False, hypotheses=hypotheses), (60.3, 50.4), (25.0, 15.0))
        assert d <= 0.1 and da <= 0.1, (hypotheses, d, da)
    monkeypatch.setattr(A, "OUTLINE_PASSES", ((1, True),))
    assert F.ellipses(m, remove_explained=False, hypotheses="outlines") == []


@pytest.mark.parametrize("hypotheses", ["tilings", "chains", "outlines"])
def test_concentric_ellipses_a_few_pixels_apart_are_both_found(hypotheses):
    """Concentric rims (a counterbore, a chamfer, a hole's two rims head-on) 8-12 px apart:
    their hypotheses are within 20 % of each other's size, which alone made them one before
    growth (only the outer one was found); hypotheses whose semi-axes differ by more than the
    first growth band (:data:`DISTINCT_MAX_PX`) grow onto different edges and are kept apart.
    Ten rings 10 px apart: each found, nothing else."""
    m = np.zeros((300, 300), bool)
    draw_ellipse(m, (150.3, 149.6), (100.0, 70.0), 0.3)
    draw_ellipse(m, (150.3, 149.6), (88.0, 61.6), 0.3)
    found = F.ellipses(m, remove_explained=False, hypotheses=hypotheses)
    assert len(found) == 2
    for axes in ((100.0, 70.0), (88.0, 61.6)):
        d, da = _match(found, (150.3, 149.6), axes)
        assert d <= 0.3 and da <= 0.3, (axes, d, da)
    m = np.zeros((240, 240), bool)
    for a in range(20, 120, 10):
        draw_ellipse(m, (120.2, 119.7), (float(a), 0.7 * a), 0.0)
    found = F.ellipses(m, remove_explained=False, hypotheses=hypotheses)
    assert len(found) == 10
    for a in range(20, 120, 10):
        d, da = _match(found, (120.2, 119.7), (float(a), 0.7 * a))
        assert d <= 0.3 and da <= 0.3, (a, d, da)


def test_a_chord_that_bows_explains_no_points():
    """A very elongated ellipse's flat sides: the line finder's chords there turn by less
    than :data:`CURVED_SEGMENT_DEG` (a 100 px chord where the curvature radius is 800 px:
    7 degrees) but bow from a straight line by over half a pixel (:func:`_sagitta`), so they
    explain no points and the default call finds the ellipse (it found none of these). A
    digitised straight edge at any angle, with or without noise, does not bow."""
    from rangesim.features._ellipses import CURVED_SEGMENT_SAGITTA_PX, _sagitta
    for (a, b), angle in [((180.0, 40.0), 0.7), ((200.0, 44.0), 0.0), ((160.0, 35.0), 0.7)]:
        m = np.zeros((450, 450), bool)
        draw_ellipse(m, (225.3, 224.8), (a, b), angle)
        d, da = _match(F.ellipses(m), (225.3, 224.8), (a, b))
        assert d <= 0.3 and da <= 0.5, (a, b, angle, d, da)
    rng = np.random.default_rng(4)
    for angle in np.linspace(0, np.pi, 13):
        for noise in (0.0, 0.3):
            t = np.arange(0, 120.0, 0.5)
            p = np.rint(np.column_stack([20 + t * np.cos(angle), 20 + t * np.sin(angle)]) + rng.normal(0, noise, (len(t), 2)))
            p = np.unique(p, axis=0)
            ab = np.array([np.cos(angle), np.sin(angle)]) * 120
            assert _sagitta(p, np.array([20.0, 20.0]), ab) <= CURVED_SEGMENT_SAGITTA_PX, (angle, noise)
    # a 100 px chord of a circle of radius 800 px bows 100^2 / (8 * 800) = 1.56 px
    u = np.arange(-50.0, 50.5, 1.0)
    arc = np.column_stack([u, 800 - np.sqrt(800 ** 2 - u ** 2)])
    assert abs(_sagitta(arc, np.array([-50.0, 0.0]), np.array([100.0, 0.0])) - 1.56) < 0.05


def test_a_segment_along_a_curve_explains_no_points():
    """The line finder draws chords along a large ellipse's flatter sides (30-55 px on a
    120 x 60 px one); their points' normals turn along them, so they are not removed as
    straight lines and the ellipse is found by the default call. A straight line's normals do
    not turn: ``_turns`` of a digitised line stays under 2 degrees, while an arc of radius
    150 px over 60 px (L / R = 23 degrees; the mask's normals read 0.4-0.53 rad) is far over
    the threshold."""
    from rangesim.features._ellipses import CURVED_SEGMENT_DEG, _turns
    for angle in (0.0, 0.2, 0.4):
        m = np.zeros((280, 280), bool)
        draw_ellipse(m, (140.0, 140.0), (120.0, 60.0), angle)
        assert len(F.lines(m)) >= 3                    # chords of the curve
        d, da = _match(F.ellipses(m), (140.0, 140.0), (120.0, 60.0))
        assert d <= 0.3 and da <= 0.5, (angle, d, da)
    line = np.zeros((100, 100), bool)
    draw_segment(line, (5.0, 20.0), (95.0, 47.0))
    xy, theta = F._edge_points.edge_points(line)
    ab = np.array([90.0, 27.0])
    u = (xy - [5.0, 20.0]) @ ab / np.hypot(*ab)
    assert _turns(u, theta, ab) < np.radians(2.0)
    R, L = 150.0, 60.0
    arc = np.zeros((400, 400), bool)
    s = np.linspace(-L / (2 * R), L / (2 * R), 400)
    arc[np.rint(200 + R * np.sin(s)).astype(int), np.rint(50 + R * np.cos(s)).astype(int)] = True
    xy, theta = F._edge_points.edge_points(arc)
    ab = np.array([0.0, 1.0])
    turn = _turns(xy[:, 1] - xy[:, 1].min(), theta, ab)
    assert 0.8 * L / R <= turn <= 1.4 * L / R and turn > 2 * np.radians(CURVED_SEGMENT_DEG)
