"""Edge ground truth from the geometry behind a scan, edge scores, and edge linking."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import box, make_sensor, plane, top_down_pose
from scipy import ndimage

import rangesim as rs
from rangesim.cad.features import AnalyticFeatures, Circle3D, Segment3D
from rangesim.core.constants import EdgeLabel
from rangesim.core.geometry import look_at
from rangesim.edges import EdgeChain, EdgeMap, link
from rangesim.evaluate import edge_scores, ground_truth_edges, ground_truth_features, jump_edges
from rangesim.scene.scene import Scene, SceneObject

LO, HI = np.array([-30.0, -20.0, 0.0]), np.array([30.0, 20.0, 40.0])
TILTED = look_at((0, -300, 350), (0, 0, 20))


# -- helpers ----------------------------------------------------------------------------
def project(scan, world):
    """(N, 2) (col, row) pixel-centre coordinates of world points (pixel (i, j) centre = (j, i))."""
    inv = np.linalg.inv(scan.pose)
    cam = np.asarray(world, float) @ inv[:3, :3].T + inv[:3, 3]
    uvw = cam @ scan.K.T
    return uvw[:, :2] / uvw[:, 2:] - 0.5


def distance_to_segments(points, segs):
    """Smallest distance (px) from (N, 2) points to (M, 2, 2) image segments."""
    a, b = segs[None, :, 0], segs[None, :, 1]
    p = points[:, None, :]
    t = np.clip(np.sum((p - a) * (b - a), -1) / np.sum((b - a) ** 2, -1), 0, 1)
    return np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1).min(axis=1)


def image_segments(scan, world_segs):
    """(M, 2, 2) image segments of (M, 2, 3) world segments."""
    world_segs = np.asarray(world_segs, float)
    return project(scan, world_segs.reshape(-1, 3)).reshape(-1, 2, 2)


def pixels(mask):
    """(N, 2) (col, row) of the pixels of a mask."""
    r, c = np.nonzero(mask)
    return np.stack([c, r], axis=1).astype(float)


def covered(mask, segs, margin_px=2.0, reach=1):
    """True where every point of the segments (ends trimmed by margin_px) has a mask pixel
    within ``reach`` pixels (Chebyshev)."""
    near = ndimage.binary_dilation(mask, np.ones((2 * reach + 1,) * 2, bool))
    for a, b in segs:
        n = int(np.linalg.norm(b - a) * 4)
        t = np.linspace(0, 1, n)[:, None]
        pts = a + t * (b - a)
        keep = (np.linalg.norm(pts - a, axis=1) >= margin_px) & (np.linalg.norm(pts - b, axis=1) >= margin_px)
        col, row = np.round(pts[keep]).astype(int).T
        if not near[row, col].all():
            return False
    return True


def edges_of_box(lo, hi, which):
    """World segments of named box edges: 'top_xm' = top edge at x = lo, etc."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    table = {
        "top_ym": [(x0, y0, z1), (x1, y0, z1)], "top_yp": [(x0, y1, z1), (x1, y1, z1)],
        "top_xm": [(x0, y0, z1), (x0, y1, z1)], "top_xp": [(x1, y0, z1), (x1, y1, z1)],
        "bottom_ym": [(x0, y0, z0), (x1, y0, z0)],
        "vert_xm_ym": [(x0, y0, z0), (x0, y0, z1)], "vert_xp_ym": [(x1, y0, z0), (x1, y0, z1)],
    }
    return np.array([table[w] for w in which])


@pytest.fixture(scope="module")
def box_scene():
    return rs.load_scene([plane(), box(LO, HI)])


@pytest.fixture(scope="module")
def sensor():
    return make_sensor()


def step_block(length=40.0):
    """A closed step (L profile in x-z, extruded along y): low step x in [0, 30] at z = 15,
    high step x in [-30, 0] at z = 40; the concave edge runs along y at x = 0, z = 15."""
    profile = np.array([[0, 0], [60, 0], [60, 15], [30, 15], [30, 40], [0, 40]], float)
    mesh = trimesh.creation.extrude_triangulation(profile, np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]), length)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    mesh.apply_translation([-30, length / 2, 0])
    return mesh


# -- jump rule ---------------------------------------------------------------------------
def pinhole_plane(normal, point, f=2000.0, size=64):
    """(size, size, 3) camera-frame points of a plane seen by a pinhole (principal point centred)."""
    j, i = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5)
    rays = np.stack([(j - size / 2) / f, (i - size / 2) / f, np.ones_like(j)], axis=-1)
    normal, point = np.asarray(normal, float), np.asarray(point, float)
    t = (point @ normal) / (rays @ normal)
    return rays * t[..., None]


def test_jump_rule_steps_and_steep_planes():
    # a step from z = 100 to z = 150 between columns 31 and 32: the near column is marked
    xyz = pinhole_plane((0, 0, 1), (0, 0, 100))
    far = pinhole_plane((0, 0, 1), (0, 0, 150))
    xyz[:, 32:] = far[:, 32:]
    hit = np.ones(xyz.shape[:2], bool)
    jump = jump_edges(xyz, hit)
    assert np.array_equal(np.flatnonzero(jump.any(axis=0)), [31])
    # continuous planes at 70 degrees incidence: nothing; at 80 degrees: jumps (narrow view)
    for incidence, expect in ((70.0, False), (80.0, True)):
        a = np.radians(incidence)
        steep = pinhole_plane((np.sin(a), 0, -np.cos(a)), (0, 0, 100))
        assert jump_edges(steep, hit).any() == expect
    # hit next to miss: the hit side
    hit[:, 40:] = False
    assert np.array_equal(np.flatnonzero(jump_edges(xyz, hit).any(axis=0)), [31, 39])


# -- ground truth ------------------------------------------------------------------------
def test_plane_alone_has_no_edges(sensor):
    scene = rs.load_scene([plane()])
    for pose in (top_down_pose(400), look_at((0, -300, 300), (0, 0, 0))):
        scan = rs.scan(scene, sensor, pose=pose)
        assert not ground_truth_edges(scan, scene).any()


def test_box_from_above_outline_is_jump(box_scene, sensor):
    """Straight from above the walls face away (edge-on at best): the top outline occludes
    the floor, so it is all jump, marked on the box top; no crease is seen."""
    scan = rs.scan(box_scene, sensor, pose=top_down_pose(400))
    gt = ground_truth_edges(scan, box_scene)
    assert set(np.unique(gt)) == {0, EdgeLabel.JUMP}
    outline = image_segments(scan, edges_of_box(LO, HI, ["top_ym", "top_yp", "top_xm", "top_xp"]))
    jump = gt == EdgeLabel.JUMP
    assert distance_to_segments(pixels(jump), outline).max() <= 1.0
    assert np.all(scan.part[jump] == 1)  # the near (occluding) side
    assert covered(jump, outline, margin_px=0.5)


def test_tilted_box_creases_and_jumps(box_scene, sensor):
    """From the front and above: the near top edge is a convex crease (top and front wall
    both seen), the front wall meets the floor in a concave crease, and the far and side
    top edges and the front vertical edges (walls facing away behind them) are jumps."""
    scan = rs.scan(box_scene, sensor, pose=TILTED)
    gt = ground_truth_edges(scan, box_scene)
    convex, concave, jump = (gt == EdgeLabel.CONVEX), (gt == EdgeLabel.CONCAVE), (gt == EdgeLabel.JUMP)
    near_top = image_segments(scan, edges_of_box(LO, HI, ["top_ym"]))
    bottom = image_segments(scan, edges_of_box(LO, HI, ["bottom_ym"]))
    silhouette = image_segments(scan, edges_of_box(LO, HI, ["top_yp", "top_xm", "top_xp", "vert_xm_ym", "vert_xp_ym"]))
    assert convex.sum() > 20 and concave.sum() > 20 and jump.sum() > 50
    assert distance_to_segments(pixels(convex), near_top).max() <= 1.0
    assert distance_to_segments(pixels(concave), bottom).max() <= 1.0
    assert distance_to_segments(pixels(jump), silhouette).max() <= 1.0
    assert np.all(scan.part[jump] == 1)
    # convex and concave run the whole edge between the corners, where jump takes over
    assert covered(convex, near_top, margin_px=2.0) and covered(concave, bottom, margin_px=2.0)
    assert covered(jump, silhouette[:1], margin_px=2.0)

    # 90-degree creases vanish above crease_deg = 90; the jumps stay
    gt95 = ground_truth_edges(scan, box_scene, crease_deg=95.0)
    assert set(np.unique(gt95)) == {0, EdgeLabel.JUMP}
    assert np.array_equal(gt95 == EdgeLabel.JUMP, jump)


def test_concave_mesh_crease_of_a_step(sensor):
    scene = rs.load_scene([step_block()])
    scan = rs.scan(scene, sensor, pose=look_at((250, 0, 300), (0, 0, 15)))
    gt = ground_truth_edges(scan, scene)
    concave = gt == EdgeLabel.CONCAVE
    inner = image_segments(scan, [[(0, -20, 15), (0, 20, 15)]])
    assert concave.sum() > 15
    assert distance_to_segments(pixels(concave), inner).max() <= 1.0
    assert covered(concave, inner, margin_px=2.0)
    # convex: the low step's front top edge and the high step's top edge over the wall
    convex_edges = image_segments(scan, [[(30, -20, 15), (30, 20, 15)], [(0, -20, 40), (0, 20, 40)]])
    assert distance_to_segments(pixels(gt == EdgeLabel.CONVEX), convex_edges).max() <= 1.0
    # against empty space every silhouette pixel is a jump on the object
    assert np.all(scan.part[gt == EdgeLabel.JUMP] == 0)


def test_ground_truth_needs_synthetic_scan(box_scene, sensor):
    scan = rs.scan(box_scene, sensor, pose=top_down_pose(400))
    scan.xyz_true = None
    with pytest.raises(ValueError, match="synthetic"):
        ground_truth_edges(scan, box_scene)


def test_features_projected_with_visibility(sensor):
    feats = AnalyticFeatures(
        circles=[Circle3D("top_circle", np.array([0.0, 0, 40]), np.array([0, 0, 1.0]), 10.0, 0.0)],
        segments=[
            Segment3D("top_front", np.array([-30.0, -20, 40]), np.array([30.0, -20, 40])),
            Segment3D("bottom_back", np.array([-30.0, 20, 0]), np.array([30.0, 20, 0])),
        ],
    )
    scene = Scene([SceneObject("floor", plane()), SceneObject("box", box(LO, HI), features=feats)])
    scan = rs.scan(scene, sensor, pose=top_down_pose(400))
    out = ground_truth_features(scan, scene)
    (circle,), (front, back) = out["circles"], out["segments"]
    f = scan.K[0, 0]
    np.testing.assert_allclose(circle.center, [79.5, 59.5], atol=1e-6)
    np.testing.assert_allclose(circle.axes, [10 * f / 360] * 2, rtol=1e-6)
    assert circle.visible == 1.0 and circle.object == 1
    np.testing.assert_allclose(front.xyxy, image_segments(scan, [[(-30, -20, 40), (30, -20, 40)]]).ravel(), atol=1e-6)
    assert front.visible > 0.95 and back.visible < 0.05  # the box hides its own bottom back edge

    # a tilted view: the ellipse passes through the projected circle points
    scan = rs.scan(scene, sensor, pose=TILTED)
    (circle,) = ground_truth_features(scan, scene)["circles"]
    pts = project(scan, Circle3D("c", np.array([0.0, 0, 40]), np.array([0, 0, 1.0]), 10.0).points(50))
    c, s = np.cos(circle.angle), np.sin(circle.angle)
    d = pts - circle.center
    u, v = d @ [c, s], d @ [-s, c]
    np.testing.assert_allclose((u / circle.axes[0]) ** 2 + (v / circle.axes[1]) ** 2, 1.0, atol=1e-6)
    assert circle.axes[0] > circle.axes[1] and circle.visible == 1.0


# -- scores ------------------------------------------------------------------------------
def vertical_lines(shape=(64, 64), cols=(10, 30, 50), rows=slice(8, 56)):
    m = np.zeros(shape, bool)
    for c in cols:
        m[rows, c] = True
    return m


def test_scores_identical_and_shifted():
    gt = vertical_lines()
    s = edge_scores(gt, gt)
    assert (s["precision"], s["recall"], s["f1"], s["fom"]) == (1.0, 1.0, 1.0, 1.0)
    assert s["n_pred"] == s["n_gt"] == s["matched"] == gt.sum()
    s1 = edge_scores(np.roll(gt, 1, axis=1), gt, tolerance_px=2)
    assert s1["precision"] == s1["recall"] == 1.0
    assert s1["fom"] == pytest.approx(1 / (1 + 1 / 9))
    s3 = edge_scores(np.roll(gt, 3, axis=1), gt, tolerance_px=2)
    assert s3["matched"] == 0 and s3["precision"] == s3["recall"] == s3["f1"] == 0.0


def test_scores_one_to_one_and_empty_cases():
    gt = np.zeros((9, 9), bool)
    gt[4, 4] = True
    pred = np.zeros_like(gt)
    pred[4, 3] = pred[4, 5] = True
    s = edge_scores(pred, gt)
    assert s["matched"] == 1 and s["precision"] == 0.5 and s["recall"] == 1.0
    assert s["f1"] == pytest.approx(2 / 3)
    empty = np.zeros_like(gt)
    assert edge_scores(empty, empty)["f1"] == 1.0 and edge_scores(empty, empty)["fom"] == 1.0
    s = edge_scores(empty, gt)
    assert (s["precision"], s["recall"], s["f1"], s["fom"]) == (1.0, 0.0, 0.0, 0.0)
    s = edge_scores(pred, empty)
    assert (s["precision"], s["recall"], s["f1"], s["fom"]) == (0.0, 1.0, 0.0, 0.0)


def test_scores_per_label():
    gt_labels = np.zeros((64, 64), np.uint8)
    gt_labels[vertical_lines(cols=(10,))] = EdgeLabel.JUMP
    gt_labels[vertical_lines(cols=(30,))] = EdgeLabel.CONVEX
    gt_labels[vertical_lines(cols=(50,))] = EdgeLabel.CONCAVE
    pred_labels = gt_labels.copy()
    pred_labels[pred_labels == EdgeLabel.CONCAVE] = EdgeLabel.CONVEX  # concave called convex
    s = edge_scores(pred_labels != 0, gt_labels != 0, pred_labels=pred_labels, gt_labels=gt_labels)
    assert s["f1"] == 1.0
    per = s["per_label"]
    assert set(per) == {"jump", "convex", "concave"}
    assert per["jump"]["f1"] == 1.0
    assert per["convex"]["recall"] == 1.0 and per["convex"]["precision"] == 0.5
    assert per["concave"]["recall"] == 0.0 and per["concave"]["n_pred"] == 0
    # an EdgeMap brings its own labels
    em = EdgeMap(pred_labels != 0, pred_labels, np.zeros(pred_labels.shape))
    assert edge_scores(em, gt_labels, gt_labels=gt_labels)["per_label"] == per


def test_scores_on_large_masks():
    """~50k true pixels, every one with a prediction 1 px off, amid 0.5 % noise pixels: all
    matched (speed is a benchmark's business, not a timed test's)."""
    rng = np.random.default_rng(0)
    gt = np.zeros((1024, 1024), bool)
    gt[:, rng.choice(1024, 49, replace=False)] = True  # ~50k edge pixels
    pred = np.roll(gt, 1, axis=1) | (rng.random(gt.shape) < 0.005)
    s = edge_scores(pred, gt, tolerance_px=2.0)
    assert s["recall"] == 1.0 and s["n_gt"] == 49 * 1024


def test_scores_on_ground_truth_of_a_scan(box_scene, sensor):
    scan = rs.scan(box_scene, sensor, pose=TILTED)
    gt = ground_truth_edges(scan, box_scene)
    s = edge_scores(gt != 0, gt != 0, pred_labels=gt, gt_labels=gt)
    assert s["f1"] == 1.0 and all(v["f1"] == 1.0 for v in s["per_label"].values())


# -- linking -----------------------------------------------------------------------------
def test_link_rectangle_is_one_closed_chain():
    m = np.zeros((60, 80), np.uint8)
    m[10, 10:40] = m[30, 10:40] = EdgeLabel.CONVEX
    m[10:31, 10] = m[10:31, 39] = EdgeLabel.CONVEX
    m[10:31, 39] = EdgeLabel.JUMP  # a minority of jump pixels
    (chain,) = link(m)
    assert isinstance(chain, EdgeChain) and chain.closed
    assert len(chain) == 2 * (21 + 30) - 4 == np.count_nonzero(m)
    assert chain.label == EdgeLabel.CONVEX
    steps = np.abs(np.diff(np.vstack([chain.points, chain.points[:1]]), axis=0))
    assert steps.max() == 1  # consecutive pixels, around and back to the start
    # a two-pixel gap in the outline is bridged and the loop closes again
    m[10, 20:22] = 0
    (chain,) = link(m, max_gap=2)
    assert chain.closed and len(chain) == 98


def test_link_bridges_gaps_up_to_max_gap():
    m = np.zeros((20, 50), np.uint8)
    m[10, 5:21] = EdgeLabel.CONCAVE
    m[10, 23:41] = EdgeLabel.CONCAVE  # columns 21 and 22 missing
    (chain,) = link(m, max_gap=2)
    assert len(chain) == 36 and not chain.closed and chain.label == EdgeLabel.CONCAVE
    np.testing.assert_array_equal(chain.points[:, 1], np.arange(5, 41) if chain.points[0, 1] == 5 else np.arange(40, 4, -1))
    assert sorted(len(c) for c in link(m, max_gap=1)) == [16, 18]


def test_link_labels_thick_lines_and_large_maps():
    labels = np.zeros((40, 80), np.uint8)
    labels[5, 5:60] = EdgeLabel.JUMP
    labels[20:23, 5:60] = EdgeLabel.CONVEX  # three pixels wide: thinned to one chain
    em = EdgeMap(labels != 0, labels, np.zeros(labels.shape))
    chains = link(em)
    assert [c.label for c in chains] == [EdgeLabel.JUMP, EdgeLabel.CONVEX] or \
        sorted(c.label for c in chains) == [EdgeLabel.JUMP, EdgeLabel.CONVEX]
    assert len(chains) == 2 and all(len(c) >= 50 for c in chains)
    # split_labels breaks a line where its label changes
    line = np.zeros((10, 40), np.uint8)
    line[5, 2:20], line[5, 20:38] = EdgeLabel.CONVEX, EdgeLabel.CONCAVE
    assert len(link(line)) == 1
    assert sorted(c.label for c in link(line, split_labels=True)) == [EdgeLabel.CONVEX, EdgeLabel.CONCAVE]
    # a 512 x 512 image with a few thousand edge pixels
    from skimage.draw import circle_perimeter

    big = np.zeros((512, 512), np.uint8)
    rng = np.random.default_rng(1)
    for _ in range(30):
        r, c = circle_perimeter(*rng.integers(60, 450, 2), rng.integers(10, 55), shape=big.shape)
        big[r, c] = rng.integers(1, 4)
    chains = link(big)
    assert sum(len(c) for c in chains) >= 0.95 * np.count_nonzero(big)


# -- crease rasterisation and visibility --------------------------------------------------
def test_diagonal_creases_are_one_pixel_wide(sensor):
    """A box turned 45 degrees about z, seen from above and in front: its near top edges
    project diagonally; each crease is rasterised 8-connected (one pixel per column or row
    it crosses), so no 2 x 2 block of crease pixels, within 1 px of the analytic edges."""
    box45 = box(LO, HI)
    box45.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 4, [0, 0, 1]))
    scene = rs.load_scene([plane(), box45])
    scan = rs.scan(scene, sensor, pose=look_at((0, -250, 350), (0, 0, 20)))
    gt = ground_truth_edges(scan, scene)
    convex = gt == EdgeLabel.CONVEX
    rot = trimesh.transformations.rotation_matrix(np.pi / 4, [0, 0, 1])[:3, :3]
    near = edges_of_box(LO, HI, ["top_ym", "top_xm"]) @ rot.T
    segs = image_segments(scan, near)
    front = image_segments(scan, edges_of_box(LO, HI, ["vert_xm_ym"]) @ rot.T)  # the near corner
    assert convex.sum() > 30
    assert distance_to_segments(pixels(convex), np.concatenate([segs, front])).max() <= 1.0
    assert covered(convex, segs, margin_px=2.0)
    blocks = convex[:-1, :-1] & convex[1:, :-1] & convex[:-1, 1:] & convex[1:, 1:]
    assert not blocks.any()
    # one pixel per crossed column (lines flatter than 45 degrees)
    for a, b in segs:
        cols = np.arange(int(np.ceil(min(a[0], b[0]))) + 2, int(np.floor(max(a[0], b[0]))) - 2)
        if abs(b[0] - a[0]) >= abs(b[1] - a[1]):
            rows = a[1] + (cols - a[0]) * (b[1] - a[1]) / (b[0] - a[0])
            lo_, hi_ = np.floor(rows - 2).astype(int), np.ceil(rows + 2).astype(int)
            counts = [convex[r0:r1, c].sum() for c, r0, r1 in zip(cols, lo_, hi_)]
            assert max(counts) == 1


def test_crease_hidden_behind_an_occluder_is_not_marked(sensor):
    """The tilted box's near top edge is a convex crease; a thin wall in front of the box,
    taller than the box, hides it: the crease must not be marked (the old 3-footprint depth
    test and face test could let hidden samples through)."""
    wall = box(np.array([-40.0, -60.0, 0.0]), np.array([40.0, -58.0, 80.0]))
    scene = rs.load_scene([plane(), box(LO, HI), wall])
    free = rs.load_scene([plane(), box(LO, HI)])
    pose = look_at((0, -300, 150), (0, 0, 20))
    scan_free = rs.scan(free, sensor, pose=pose)
    near_top = image_segments(scan_free, edges_of_box(LO, HI, ["top_ym"]))
    gt_free = ground_truth_edges(scan_free, free)
    on_edge = distance_to_segments(pixels(gt_free == EdgeLabel.CONVEX), near_top) <= 1.0
    assert on_edge.sum() > 20  # seen without the wall
    scan = rs.scan(scene, sensor, pose=pose)
    gt = ground_truth_edges(scan, scene)
    hidden = pixels((gt == EdgeLabel.CONVEX) & (scan.part != 1))
    assert len(hidden) == 0 or distance_to_segments(hidden, near_top).min() > 1.0
    # no convex crease of the box where the wall is seen
    box_convex = (gt == EdgeLabel.CONVEX) & (scan.part == 2)
    if box_convex.any():
        assert distance_to_segments(pixels(box_convex), near_top).min() > 1.0


def test_exact_matching_is_maximum_on_dense_random_blobs():
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import maximum_bipartite_matching

    from rangesim.evaluate._edge_scores import _exact_match

    rng = np.random.default_rng(4)
    for _ in range(5):
        pred = np.unique(rng.integers(0, 30, (400, 2)), axis=0)
        gt = np.unique(rng.integers(0, 30, (400, 2)), axis=0)
        i, j = np.nonzero(((pred[:, None] - gt[None]) ** 2).sum(-1) <= 4)
        graph = csr_matrix((np.ones(len(i), np.int8), (i, j)), shape=(len(pred), len(gt)))
        reference = np.count_nonzero(maximum_bipartite_matching(graph, perm_type="column") >= 0)
        assert _exact_match(i, j, len(pred), len(gt)) == reference
