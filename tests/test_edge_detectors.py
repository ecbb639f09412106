"""Edge detectors on noise-free scans: where they fire, what they call it, and what they ignore.

The main scene is a box on a floor seen obliquely, so one view holds convex creases (the
box's top edges), concave creases (where its walls meet the floor), jump edges (its
silhouette over the floor) and a laser shadow (a NaN gap beside the box). The box's 12
edges are projected analytically with ``meta["K"]`` and the inverse pose.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.geometry import look_at
from rangesim.core.rangescan import RangeScan
from rangesim.edges import RIM, EdgeMap, OrganizedEdgeMap, curvature, gradient, line_fit, normal, pcl_organized
from rangesim.edges._scan_access import pixel_geometry
from tests.conftest import box, make_sensor, plane, top_down_pose

LO, HI = np.array([-40.0, -30.0, 0.0]), np.array([40.0, 30.0, 30.0])
DETECTORS = {
    "gradient": gradient, "normal": normal, "curvature": curvature, "line_fit": line_fit,
    "pcl_organized": pcl_organized,
}


# -- scenes and analytic edges -------------------------------------------------------------
@pytest.fixture(scope="module")
def box_scene():
    return [plane(), box(LO, HI)]


@pytest.fixture(scope="module")
def box_scan(box_scene):
    """200 x 150, f = 275 px, camera up front and to the right: the box's front and right
    walls, its top, and the floor are visible; the laser (on the camera's right) shadows the
    floor left of the box."""
    sensor = make_sensor(**{"camera.width": 200, "camera.height": 150})
    pose = look_at((170.0, -230.0, 300.0), (0.0, 0.0, 10.0), up=(0, 0, 1))
    return rs.scan(box_scene, sensor, pose=pose, seed=0)


@pytest.fixture(scope="module")
def top_scan():
    """A larger box seen from straight above: big flat faces (top and floor) for holes."""
    sensor = make_sensor(**{"camera.width": 200, "camera.height": 150})
    return rs.scan([plane(), box([-50, -40, 0], [50, 40, 30])], sensor,
                   pose=top_down_pose(400.0), seed=0)


#: (row, col) of hole centres in top_scan: the box top's centre and the floor in front of it
TOP_HOLES = ((75, 100), (136, 100))


def box_edges() -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """The box's 12 edges (world mm) grouped as top (z = HI), bottom (z = LO), vertical."""
    corners = {(i, j, k): np.array([(LO, HI)[i][0], (LO, HI)[j][1], (LO, HI)[k][2]])
               for i in (0, 1) for j in (0, 1) for k in (0, 1)}
    groups: dict[str, list] = {"top": [], "bottom": [], "vertical": []}
    for a in corners:
        for axis in range(3):
            if a[axis] == 0:
                b = list(a)
                b[axis] = 1
                seg = (corners[a], corners[tuple(b)])
                key = "vertical" if axis == 2 else ("top" if a[2] == 1 else "bottom")
                groups[key].append(seg)
    return groups


def project(scan: RangeScan, pts: np.ndarray) -> np.ndarray:
    """World points -> continuous pixel coordinates (u, v) with pixel (i, j) at (j + .5, i + .5)."""
    to_cam = np.linalg.inv(scan.pose)
    pc = pts @ to_cam[:3, :3].T + to_cam[:3, 3]
    uv = pc @ np.asarray(scan.meta["K"]).T
    return uv[:, :2] / uv[:, 2:]


def segment_distance(scan: RangeScan, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(H, W) distance, pixels, from every pixel centre to the projected segment p-q."""
    h, w = scan.shape
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    pix = np.stack([jj, ii], axis=-1)
    a, b = project(scan, np.array([p, q]))
    d = b - a
    t = np.clip(((pix - a) @ d) / (d @ d), 0.0, 1.0)
    return np.linalg.norm(pix - (a + t[..., None] * d), axis=-1)


@pytest.fixture(scope="module")
def edge_distance(box_scan) -> dict[str, np.ndarray]:
    """Distance (px) to the nearest projected box edge of each group, and of all ("any")."""
    out = {k: np.min([segment_distance(box_scan, p, q) for p, q in segs], axis=0)
           for k, segs in box_edges().items()}
    out["any"] = np.minimum(np.minimum(out["top"], out["bottom"]), out["vertical"])
    return out


def with_hole(scan: RangeScan, centre: tuple[int, int], half: int) -> RangeScan:
    """The scan with a (2 half + 1)^2 block of invalid pixels (NaN points and depth)."""
    i, j = centre
    sl = (slice(i - half, i + half + 1), slice(j - half, j + half + 1))
    depth, xyz, valid = scan.depth.copy(), scan.xyz.copy(), scan.valid.copy()
    depth[sl], xyz[sl], valid[sl] = np.nan, np.nan, False
    return dataclasses.replace(scan, depth=depth, xyz=xyz, valid=valid)


def pinhole_rays(size: int, f: float) -> tuple[np.ndarray, np.ndarray]:
    """K and the camera-frame rays (z = 1) through the pixel centres of a size x size pinhole."""
    K = np.array([[f, 0.0, size / 2], [0.0, f, size / 2], [0.0, 0.0, 1.0]])
    jj, ii = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5)
    rays = np.stack([(jj - size / 2) / f, (ii - size / 2) / f, np.ones_like(jj)], axis=-1)
    return K, rays


def grid_scan(xyz: np.ndarray, K: np.ndarray, sigma: np.ndarray | None = None) -> RangeScan:
    """A fully valid RangeScan of camera-frame points (H, W, 3), with the noise model's sigma or none."""
    xyz = np.asarray(xyz, np.float32)
    shape = xyz.shape[:2]
    return RangeScan(
        depth=xyz[..., 2], xyz=xyz, valid=np.ones(shape, bool),
        normal=np.full(shape + (3,), np.nan, np.float32), intensity=np.ones(shape, np.float32),
        part=np.zeros(shape, np.int32), face=np.zeros(shape, np.int32),
        status=np.zeros(shape, np.uint8), meta={"K": K.tolist()}, sigma=sigma,
    )


def synthetic_roof(bend_deg: float, edge_deg: float, convex: bool, offset_px: float = 0.3,
                   size: int = 61, f: float = 400.0, z0: float = 500.0) -> RangeScan:
    """A pinhole view of two planes meeting in a straight crease through the image centre.

    The faces are tilted by -+ bend / 2 about the crease (towards the camera for a valley,
    away for a roof); ``edge_deg`` is the angle of the (x, y) vector across the crease.
    """
    K, rays = pinhole_rays(size, f)
    a = np.radians(edge_deg)
    across = np.array([np.cos(a), np.sin(a), 0.0])
    p0 = np.array([0.0, 0.0, z0]) + across * offset_px * z0 / f
    sign = 1.0 if convex else -1.0

    def face(tilt_deg: float) -> np.ndarray:
        t = np.radians(tilt_deg)
        n = -np.cos(t) * np.array([0.0, 0.0, 1.0]) + np.sin(t) * across
        return rays * ((p0 @ n) / (rays @ n))[..., None]

    pa, pb = face(-sign * bend_deg / 2), face(sign * bend_deg / 2)
    return grid_scan(np.where((((pa - p0) @ across) < 0)[..., None], pa, pb), K)


def roof_distance(scan: RangeScan, edge_deg: float, offset_px: float = 0.3) -> np.ndarray:
    """Distance (px) of each pixel centre to the crease line of :func:`synthetic_roof`."""
    h, w = scan.shape
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    a = np.radians(edge_deg)
    return np.abs((jj - w / 2) * np.cos(a) + (ii - h / 2) * np.sin(a) - offset_px)


def test_curvature_rules_extrema_marks_creases_both_marks_corners(box_scan, edge_distance):
    """The extrema rule finds the box's straight creases as 1 px lines; the paper's Fig. 12
    rule (both curvatures large) only the neighbourhoods of its corners."""
    d = edge_distance
    lines = curvature(box_scan)
    corners = curvature(box_scan, rule="both")
    crease = lines.mask & (lines.labels != EdgeLabel.JUMP)
    corner = corners.mask & (corners.labels != EdgeLabel.JUMP)
    assert crease.sum() >= 4 * max(corner.sum(), 1)
    # straight crease pixels far from every corner: only the extrema rule has them
    far_from_corner = (np.sort(np.stack([d["top"], d["bottom"], d["vertical"]]), axis=0)[1] > 6)
    assert (crease & far_from_corner).sum() >= 40
    assert not (corner & far_from_corner).any()
    with pytest.raises(ValueError, match="rule"):
        curvature(box_scan, rule="max")


# -- every detector ------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(DETECTORS))
def test_detections_lie_on_the_box_edges(name, box_scan, edge_distance):
    em = DETECTORS[name](box_scan)
    assert isinstance(em, EdgeMap) and em.method == name
    assert em.mask.shape == em.labels.shape == em.strength.shape == box_scan.shape
    mask = em.mask
    if name == "pcl_organized":
        # PCL's occluded class is the far side of every jump, here also the floor beyond the
        # laser shadow, away from the box; its occluding side must be on the box edges
        mask = mask & ~em.occluded
    assert mask.sum() >= 180        # 1 px lines along the visible box edges and the jumps
    assert (em.mask & (em.labels != EdgeLabel.JUMP)).sum() >= 60       # creases, not jumps only
    d = edge_distance["any"]
    assert d[mask].max() <= 2.0, f"{name}: detections {d[mask].max():.1f} px from any box edge"
    flat = (d > 4.0) & box_scan.valid
    assert not (mask & flat).any()
    assert not (em.mask & ~box_scan.valid).any()
    assert set(np.unique(em.labels[~em.mask])) <= {0}


@pytest.mark.parametrize("name", ["gradient", "normal", "curvature", "line_fit"])
def test_convex_top_edges_concave_floor_edges(name, box_scan, edge_distance):
    em = DETECTORS[name](box_scan)
    top, bottom, vert = edge_distance["top"], edge_distance["bottom"], edge_distance["vertical"]
    crease = em.mask & np.isin(em.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
    near_top = crease & (top <= 2) & (bottom > 3) & (vert > 3)
    near_floor = crease & (bottom <= 2) & (top > 3) & (vert > 3)
    least = 20 if name == "line_fit" else 30        # line_fit misses the floor crease's ends
    assert near_top.sum() >= least and near_floor.sum() >= least
    assert np.mean(em.labels[near_top] == EdgeLabel.CONVEX) >= 0.9
    assert np.mean(em.labels[near_floor] == EdgeLabel.CONCAVE) >= 0.9
    # the silhouette (top and vertical edges, never the floor's) is labelled jump
    jump = em.label_mask(EdgeLabel.JUMP)
    assert jump.sum() >= 50
    assert np.minimum(top, vert)[jump].max() <= 2.0


@pytest.mark.parametrize("name", list(DETECTORS))
def test_nan_hole_in_a_flat_face_makes_no_edges(name, top_scan):
    plain = DETECTORS[name](top_scan)
    holed = top_scan
    around = np.zeros(top_scan.shape, bool)
    for i, j in TOP_HOLES:
        holed = with_hole(holed, (i, j), 3)
        around[i - 8:i + 9, j - 8:j + 9] = True
    assert top_scan.valid[around].all() and not plain.mask[around].any()
    em = DETECTORS[name](holed)
    assert not (em.mask & around).any(), f"{name} marks the rim of a hole in a flat face"
    if name == "pcl_organized":
        assert not (em.nan_boundary & around).any()    # found the far side within max_search


def test_pcl_marks_nan_boundaries_only_where_the_search_gives_up(top_scan):
    i, j = TOP_HOLES[0]
    holed = with_hole(top_scan, (i, j), 4)
    em = pcl_organized(holed, max_search=3)          # the 9 px hole is wider than the search
    rim = np.zeros(top_scan.shape, bool)
    rim[i - 5:i + 6, j - 5:j + 6] = True
    rim &= holed.valid
    assert em.nan_boundary[rim].sum() >= 20
    assert (em.mask & rim).sum() == (em.nan_boundary & rim).sum()
    assert not em.labels[em.nan_boundary & rim].any()   # the type cannot be told
    assert not pcl_organized(holed).mask[rim].any()     # max_search = 50 crosses it


def test_pcl_occluding_and_occluded(box_scan, edge_distance):
    em = pcl_organized(box_scan)
    assert isinstance(em, OrganizedEdgeMap)
    assert em.occluding.sum() >= 50 and em.occluded.sum() >= 50
    assert not (em.occluding & em.occluded).any()
    assert (em.labels[em.occluding | em.occluded] == EdgeLabel.JUMP).all()
    assert edge_distance["any"][em.occluding].max() <= 2.0
    # the far side of the box's back silhouette lies on the floor behind it: farther away
    assert np.nanmedian(box_scan.depth[em.occluded]) > np.nanmedian(box_scan.depth[em.occluding])
    only = pcl_organized(box_scan, edge_types=("occluding",))
    np.testing.assert_array_equal(only.mask, em.occluding & box_scan.valid)
    with pytest.raises(ValueError, match="unknown edge types"):
        pcl_organized(box_scan, edge_types=("corners",))


@pytest.mark.parametrize("name", ["gradient", "normal", "line_fit"])
def test_scores_against_ground_truth(name, box_scan, box_scene):
    from rangesim.evaluate import edge_scores, ground_truth_edges

    gt = ground_truth_edges(box_scan, box_scene)
    gt = np.where(box_scan.valid, gt, 0)       # no detector sees edges in the laser shadow
    s = edge_scores(DETECTORS[name](box_scan), gt, 2.0)
    # gradient: 0.97 measured (its staircase thinning makes diagonal edges 1 px wide,
    # as the 8-connected truth; 0.89 before it)
    assert s["f1"] >= {"line_fit": 0.85, "gradient": 0.94}.get(name, 0.9), s


def test_without_intrinsics_the_footprint_is_estimated(box_scan):
    bare = dataclasses.replace(box_scan, meta={})
    geo, true = pixel_geometry(bare), pixel_geometry(box_scan)
    assert geo.perspective and geo.focal_length == pytest.approx(true.focal_length, rel=0.05)
    for fn in (gradient, normal):
        a, b = fn(box_scan).mask, fn(bare).mask
        assert (a & b).sum() >= 0.95 * max(a.sum(), b.sum())


# -- gradient ------------------------------------------------------------------------------
@pytest.mark.parametrize("edge_deg", [0.0, 20.0, 45.0, 70.0, 110.0, 160.0])
@pytest.mark.parametrize("convex", [True, False])
def test_gradient_roof_type_bend_and_direction(edge_deg, convex):
    scan = synthetic_roof(30.0, edge_deg, convex)
    em = gradient(scan)
    dist = roof_distance(scan, edge_deg)
    inner = np.zeros(scan.shape, bool)
    inner[8:-8, 8:-8] = True
    found = em.mask & inner
    assert found.sum() >= 40
    assert dist[found].max() <= 1.0
    assert (em.labels[found] == (EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE)).all()
    # strength: the bend in degrees, 0.75-1 of the true one
    assert np.all((em.strength[found] > 22.0) & (em.strength[found] < 31.0))
    # direction: across the crease, within ~15 degrees (mod 180)
    err = np.abs((em.direction[found] - np.radians(edge_deg) + np.pi / 2) % np.pi - np.pi / 2)
    assert np.degrees(err).max() <= 15.0


def test_gradient_direction_is_perpendicular_to_the_box_edges(box_scan):
    em = gradient(box_scan)
    checked = 0
    # the front-top (convex) and front-bottom (concave) edges, away from their ends
    for z in (HI[2], LO[2]):
        p, q = np.array([LO[0], LO[1], z]), np.array([HI[0], LO[1], z])
        (a, b) = project(box_scan, np.array([p, q]))
        d = segment_distance(box_scan, p, q)
        h, w = box_scan.shape
        jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        ends = np.minimum(np.hypot(jj - a[0], ii - a[1]), np.hypot(jj - b[0], ii - b[1]))
        sel = em.mask & (d <= 1.5) & (ends > 6) & (em.labels != EdgeLabel.JUMP)
        normal_angle = np.arctan2(b[0] - a[0], -(b[1] - a[1]))     # (x, y) across the edge
        err = np.abs((em.direction[sel] - normal_angle + np.pi / 2) % np.pi - np.pi / 2)
        assert sel.sum() >= 20 and np.degrees(err).max() <= 15.0
        checked += sel.sum()
    assert checked >= 40


def test_gradient_threshold_is_a_bend_angle():
    scan = synthetic_roof(12.0, 30.0, True)
    assert not gradient(scan).mask.any()                 # below the default 15 degrees
    assert gradient(scan, threshold=8.0).mask.sum() >= 40


# -- normal --------------------------------------------------------------------------------
@pytest.mark.parametrize("edge_deg", [0.0, 35.0, 90.0, 125.0])
def test_normal_strength_is_the_bend(edge_deg):
    for convex in (True, False):
        scan = synthetic_roof(40.0, edge_deg, convex)
        em = normal(scan)
        found = em.mask.copy()
        found[:6], found[-6:], found[:, :6], found[:, -6:] = False, False, False, False
        assert found.sum() >= 40
        assert roof_distance(scan, edge_deg)[found].max() <= 1.0
        np.testing.assert_allclose(em.strength[found], 40.0, atol=1.0)
        assert (em.labels[found] == (EdgeLabel.CONVEX if convex else EdgeLabel.CONCAVE)).all()


def test_normal_ignores_the_true_normals(box_scan):
    wrong = dataclasses.replace(box_scan, normal=np.zeros_like(box_scan.normal))
    np.testing.assert_array_equal(normal(wrong).mask, normal(box_scan).mask)


# -- line fitting --------------------------------------------------------------------------
def _rotation(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q


def test_line_fit_plane_with_nonuniform_spacing_has_no_inner_edges():
    rng = np.random.default_rng(1)
    xs = np.cumsum(np.linspace(1.0, 2.0, 30))            # spacing grows from 1 to 2
    ys = np.cumsum(np.linspace(1.5, 0.8, 30))
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx, gy, np.zeros_like(gx)], axis=-1).reshape(-1, 3)
    pts[:, :2] += rng.uniform(-0.03, 0.03, (len(pts), 2))
    pts = pts @ _rotation(2).T + [10.0, -5.0, 300.0]
    edge = line_fit(pts).reshape(gx.shape)
    assert edge.dtype == bool
    assert not edge[3:-3, 3:-3].any()
    assert edge[0, 5:-5].all() and edge[5:-5, -1].all()   # the list's own boundary is an edge


def test_line_fit_ridge_of_two_planes_at_90_degrees():
    g = np.arange(-10, 11, dtype=float)
    gx, gy = np.meshgrid(np.arange(30, dtype=float), g)
    pts = np.stack([gx, gy * np.sqrt(0.5), -np.abs(gy) * np.sqrt(0.5)], axis=-1)  # unit steps
    pts = pts.reshape(-1, 3) @ _rotation(3).T
    edge = line_fit(pts).reshape(gx.shape)
    ridge = gy == 0
    inner = (gx >= 3) & (gx <= 26)
    assert edge[ridge & inner].all()
    assert not edge[~ridge & inner & (np.abs(gy) >= 2) & (np.abs(gy) <= 8)].any()


def test_line_fit_points_takes_a_tolerance_per_point():
    """A 90 degree ridge (bend 90, neighbours across it at 90 degrees): an edge where the
    opposite-pair tolerance is below 90 - 45 (the diagonal pairs across the ridge make 135
    degrees), not where it is 60 degrees; per point, each half of the ridge keeps its own."""
    from rangesim.edges import line_fit_points
    g = np.arange(-10, 11, dtype=float)
    gx, gy = np.meshgrid(np.arange(30, dtype=float), g)
    pts = np.stack([gx, gy * np.sqrt(0.5), -np.abs(gy) * np.sqrt(0.5)], axis=-1).reshape(-1, 3)
    ridge = ((gy == 0) & (gx >= 3) & (gx <= 26)).ravel()
    assert line_fit_points(pts, angle_tol_deg=15.0)[ridge].all()
    assert not line_fit_points(pts, angle_tol_deg=60.0)[ridge].any()
    tol = np.where(gx.ravel() < 15, 15.0, 60.0)
    edge = line_fit_points(pts, angle_tol_deg=tol)
    assert edge[ridge & (gx.ravel() < 14)].all() and not edge[ridge & (gx.ravel() > 15)].any()
    with pytest.raises(ValueError, match="one per point"):
        line_fit_points(pts, angle_tol_deg=tol[:-1])


def test_line_fit_many_random_points_and_nan_rows():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 100, (20000, 3))
    pts[::1000] = np.nan
    edge = line_fit(pts, k=8)
    assert edge.shape == (20000,) and edge.dtype == bool
    assert not edge[::1000].any()
    with pytest.raises(ValueError):
        line_fit(np.zeros((10, 2)))


def test_line_fit_on_a_scan_labels_creases_by_their_neighbourhood(box_scan):
    plain = line_fit(box_scan, label_creases=False)
    # jumps, and rims (the box's edge against its own laser shadow on the floor)
    assert set(np.unique(plain.labels[plain.mask])) <= {EdgeLabel.NONE, EdgeLabel.JUMP, RIM}
    assert (plain.labels[plain.mask] == EdgeLabel.NONE).sum() >= 90
    labelled = line_fit(box_scan)
    assert np.array_equal(plain.mask, labelled.mask)
    crease = plain.mask & (plain.labels == EdgeLabel.NONE)
    assert set(np.unique(labelled.labels[crease])) <= {EdgeLabel.CONVEX, EdgeLabel.CONCAVE}


def test_line_fit_thins_crease_bands_to_lines(box_scan, edge_distance):
    band = line_fit(box_scan, thin=False)
    lines = line_fit(box_scan)
    crease_band = band.mask & (band.labels == EdgeLabel.NONE)
    crease = lines.mask & (lines.labels == EdgeLabel.NONE)
    # every point within a neighbour's reach of a crease is an edge point: bands 2-3 px wide
    assert crease_band.sum() >= 1.6 * crease.sum()
    assert not (crease & ~crease_band).any()
    # a 1 px line: no crease pixel has more than 2 crease 8-neighbours, except a few junctions
    from scipy import ndimage
    neighbours = ndimage.convolve(crease.astype(int), np.ones((3, 3), int), mode="constant") - 1
    assert (neighbours[crease] > 2).sum() <= 6
    # the jumps are kept as the jump rule marks them
    jump = band.mask & (band.labels == EdgeLabel.JUMP)
    assert np.array_equal(jump, lines.mask & (lines.labels == EdgeLabel.JUMP))


def _steep_plane(sigma_mm: float, with_sigma: bool, step_col: int = 64, step_mm: float = 15.0) -> RangeScan:
    """A plane at 71.6 deg slant (neighbours 3.0 footprints apart, the jump rule's 3.73 close
    above), with heavy-tailed depth noise of std ``sigma_mm`` (Student t, 3 degrees of
    freedom, as a laser scanner's errors near grazing incidence), a 15 mm step down at
    column ``step_col``; the noise model's ``sigma`` is attached or not."""
    size, z0 = 96, 400.0
    K, rays = pinhole_rays(size, 300.0)
    t = np.arctan(3.0)
    n = np.array([np.sin(t), 0.0, -np.cos(t)])
    depth = ((np.array([0, 0, z0]) @ n) / (rays @ n))
    depth[:, step_col:] += step_mm
    depth = depth + sigma_mm / np.sqrt(3.0) * np.random.default_rng(0).standard_t(3, depth.shape)
    return grid_scan(rays * depth[..., None], K, np.full(depth.shape, sigma_mm, np.float32) if with_sigma else None)


@pytest.mark.parametrize("name", ["gradient", "normal", "line_fit", "curvature"])
def test_jump_rule_allows_for_the_predicted_noise(name):
    """Neighbours 3.0 footprints apart with heavy-tailed noise of 1 mm std (footprint
    ~1.3 mm) cross the 3.73-footprint jump threshold, beyond what the fold test explains,
    at many pixels; sqrt(2) sigma more (SIGMA_STEPS) leaves under half of them (the t distribution's
    tails keep some), and the real 15 mm (11 footprint) step stays a jump."""
    from rangesim.edges._discontinuities import SIGMA_STEPS
    assert SIGMA_STEPS == 1.0
    jumps = {}
    for with_sigma in (False, True):
        em = DETECTORS[name](_steep_plane(1.0, with_sigma))
        jump = em.mask & (em.labels == EdgeLabel.JUMP)
        cols = np.arange(jump.shape[1])
        off_step = jump[:, (cols < 61) | (cols > 66)]
        jumps[with_sigma] = (off_step.sum(), jump[2:-2, 61:67].any(axis=1).mean())
    assert jumps[False][0] >= 100, jumps
    assert jumps[True][0] <= 0.5 * jumps[False][0], jumps
    assert jumps[True][1] >= 0.95, jumps       # the step: a jump in (nearly) every row


def _noisy_frontal_step(sigma_fp: float, step_fp: float = 30.0) -> RangeScan:
    """A frontal plane at 400 mm (footprint z / f = 1.33 mm) with Gaussian depth noise of
    ``sigma_fp`` footprints, its sigma attached, and a step of ``step_fp`` footprints down at
    column 48."""
    K, rays = pinhole_rays(96, 300.0)
    fp = 400.0 / 300.0
    depth = np.full((96, 96), 400.0)
    depth[:, 48:] += step_fp * fp
    depth += sigma_fp * fp * np.random.default_rng(2).standard_normal(depth.shape)
    return grid_scan(rays * depth[..., None], K, np.full(depth.shape, sigma_fp * fp, np.float32))


@pytest.mark.parametrize("name", ["gradient", "normal"])
def test_jump_rule_keeps_a_false_alarm_floor_under_heavy_noise(name, monkeypatch):
    """Noise of 2 footprints on a frontal plane: a pair's difference has std 2.83 footprints,
    and the footprint rule plus one std (3.73 + 2.83) is 2.3 std, crossed by 2 % of the
    ~18,000 neighbour pairs; the floor of FALSE_JUMP_Z = 3.9 std crosses 1e-4 of them (about
    2 pairs), and a 30-footprint step (7.5 std) stays a jump in every row."""
    import rangesim.edges._discontinuities as disc
    assert disc.FALSE_JUMP_Z == 3.9
    scan = _noisy_frontal_step(2.0)
    counts = {}
    for floor in (0.0, disc.FALSE_JUMP_Z):
        monkeypatch.setattr(disc, "FALSE_JUMP_Z", floor)
        em = DETECTORS[name](scan)
        jump = em.mask & (em.labels == EdgeLabel.JUMP)
        cols = np.arange(96)
        counts[floor] = (int(jump[:, (cols < 45) | (cols > 50)].sum()), jump[2:-2, 45:51].any(axis=1).mean())
    assert counts[0.0][0] >= 100, counts
    assert counts[disc.FALSE_JUMP_Z][0] <= 12, counts
    assert counts[disc.FALSE_JUMP_Z][1] >= 0.95, counts


def test_line_fit_marks_no_crease_where_noise_passes_its_largest_tolerance():
    """A roof (faces 30 degrees either side of frontal: a 60 degree crease at column 32) whose
    right third, on one face, has 10 footprints of noise (a face at grazing incidence): a unit
    vector one footprint out swings there by atan(2.25 sqrt(2) 10) = 88 degrees, past the
    largest opposite-pair tolerance (MAX_TOL_DEG, 60), so no crease can be told from the noise
    and none is marked (828 were); the quiet part's 0.3 footprints give a tolerance of 44
    degrees, and its 60 degree crease is found."""
    import rangesim.edges._line_fit as lf
    assert lf.MAX_TOL_DEG == 60.0
    K, rays = pinhole_rays(96, 300.0)
    fp = 400.0 / 300.0
    cols = np.arange(96)
    sigma = np.where(cols < 64, 0.3 * fp, 10.0 * fp).astype(np.float32)[None, :].repeat(96, 0)
    depth = 400.0 + np.tan(np.radians(30.0)) * fp * np.abs(cols - 32)[None, :] \
        + sigma * np.random.default_rng(3).standard_normal(sigma.shape)
    em = DETECTORS["line_fit"](grid_scan(rays * depth[..., None], K, sigma))
    crease = em.mask & np.isin(em.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
    assert crease[:, 68:].sum() == 0
    assert crease[4:-4, 30:35].any(axis=1).mean() >= 0.9           # the roof's crease
    assert crease[:, :60].sum() - crease[:, 30:35].sum() <= 20      # and little else


def _two_noise_plane(with_sigma: bool) -> RangeScan:
    """A frontal plane at 400 mm, depth noise 0.15 mm on the left two thirds, 0.6 mm on the
    right third (a far or grazing part of a scene), the noise model's sigma attached or not."""
    K, rays = pinhole_rays(96, 300.0)
    sigma = np.where(np.arange(96) < 64, 0.15, 0.6).astype(np.float32)[None, :].repeat(96, 0)
    depth = 400.0 + sigma * np.random.default_rng(1).standard_normal(sigma.shape)
    return grid_scan(rays * depth[..., None], K, sigma if with_sigma else None)


@pytest.mark.parametrize("name", ["gradient", "normal", "curvature"])
def test_crease_threshold_follows_the_predicted_noise_per_pixel(name):
    """The noise-derived threshold is set by the median pixel (the quiet part here); where
    the scan's sigma says the noise is 4x larger, the threshold is 4x larger too
    (local_noise_scale), so the noisy half is not strewn with creases."""
    from rangesim.edges._noise import local_noise_scale
    scan = _two_noise_plane(True)
    footprint = np.full(scan.shape, 400.0 / 300.0, np.float32)      # z / f, a frontal plane
    scale = local_noise_scale(scan, scan.valid, footprint)
    # the least sigma over 5 x 5: the two columns beside the border take the quiet side's
    assert np.allclose(scale[:, :66], 1.0) and np.allclose(scale[:, 66:], 4.0, rtol=0.05)
    assert local_noise_scale(_two_noise_plane(False), scan.valid, footprint) is None
    # in footprints: the same sigma twice as far away is half as noisy relative to a pixel
    assert np.allclose(local_noise_scale(scan, scan.valid, footprint * np.where(np.arange(96) < 64, 1.0, 2.0))[:, 68:],
                       2.0, rtol=0.05)
    creases = {}
    for with_sigma in (False, True):
        em = DETECTORS[name](_two_noise_plane(with_sigma))
        crease = em.mask & np.isin(em.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
        creases[with_sigma] = int(crease[:, 68:].sum())
    assert creases[False] >= 20, creases
    assert creases[True] <= 0.2 * creases[False], creases


def test_predicted_noise_ignores_sigma_raised_at_the_edge_itself():
    """The noise model raises sigma on an edge's own pixels (mixed, truncated stripes): the
    least sigma over 5 x 5 keeps the face's level there, while a face noisy as a whole stays
    noisy; NaN is no information, and a scan without sigma has none."""
    from types import SimpleNamespace

    from rangesim.edges._noise import predicted_noise
    sigma = np.full((40, 40), 0.1, np.float32)
    sigma[:, 10] = 2.0                    # an edge's pixels
    sigma[20:, 25:] = 0.8                 # a face seen near grazing
    sigma[5, 30] = np.nan
    got = predicted_noise(SimpleNamespace(sigma=sigma))
    assert np.allclose(got[:, 10], 0.1)
    assert np.allclose(got[23:, 28:], 0.8)
    assert got[5, 30] == np.float32(0.1)
    assert predicted_noise(SimpleNamespace(sigma=None)) is None


def test_curvature_direction_projects_by_the_scans_geometry():
    """Across-crease directions: pinhole projection of the 3D direction, or its (x, y) on a
    grid of constant spacing (a sweep scanner's depth need not be a camera distance)."""
    from types import SimpleNamespace

    from rangesim.edges._curvature import _image_angle
    xyz = np.array([[[100.0, 0.0, 100.0]]])
    d = np.array([[[0.0, 0.0, 1.0]]])               # straight away from a camera at the origin
    scan = SimpleNamespace(xyz=xyz)
    # pinhole: moving along +z at x = z shrinks x / z, the image moves along -x
    assert np.isclose(_image_angle(d, scan, xyz[..., 2])[0, 0], 0.0, atol=1e-6)
    d = np.array([[[1.0, 1.0, 0.0]]]) / np.sqrt(2)
    assert np.isclose(_image_angle(d, scan, xyz[..., 2], perspective=False)[0, 0], np.pi / 4)
    assert np.isclose(_image_angle(d, scan, np.zeros((1, 1)), perspective=False)[0, 0], np.pi / 4)


def test_window_minimum_matches_scipy():
    from scipy.ndimage import minimum_filter

    from rangesim.edges._noise import _window_min
    a = np.random.default_rng(3).random((37, 11)).astype(np.float32)
    a[::7, ::5] = np.inf
    a[::3, ::4] = np.nan  # no information: read as +inf
    a[5, 6] = -np.inf     # likewise
    for r in (1, 2, 3):
        expected = minimum_filter(np.where(np.isfinite(a), a, np.inf), 2 * r + 1, mode="nearest")
        assert np.array_equal(_window_min(a, r), expected)


def test_compiled_hessian_and_smoothing_match_scipy():
    # the Hessian's 3x3 sums (the reference the fused kernel is held to, bit for bit, in
    # tests/test_gradient_kernels.py) and the 5-tap smoothing against scipy's filters (NaN read as 0)
    from scipy.ndimage import correlate1d, uniform_filter

    from rangesim.edges._gradient import _smooth5, _taps5
    from tests.gradient_reference import _hessian
    rng = np.random.default_rng(4)
    r = rng.normal(size=(4, 23, 31)).astype(np.float32)
    r[0, 3, 4] = r[1, 10, 0] = r[2, 22, 30] = r[3, 0, 7] = np.nan
    a = r[0]
    a0 = np.nan_to_num(a)

    def box(x):
        return uniform_filter(np.nan_to_num(x).astype(np.float64), 3, mode="constant") * 9

    dxx, dyy = box(r[0]), box(r[2])
    dxy = box(r[1] - r[3]) * np.sqrt(2) / 6          # a NaN on either diagonal: 0
    mean, rad, minor, two_dxy, dxx_dyy = _hessian(*r)
    assert np.allclose(dxx_dyy, dxx - dyy, atol=1e-5) and np.allclose(two_dxy, 2 * dxy, atol=1e-5)
    assert np.allclose(mean, (dxx + dyy) / 2, atol=1e-5)
    assert np.allclose(rad, np.hypot((dxx - dyy) / 2, dxy), atol=1e-5)
    lo, hi = (dxx + dyy) / 2 - rad, (dxx + dyy) / 2 + rad
    decided = np.abs(np.abs(lo) - np.abs(hi)) > 1e-4
    assert np.array_equal(minor[decided], (np.abs(lo) > np.abs(hi))[decided])
    taps = np.array(_taps5(1.0), np.float64)[[2, 1, 0, 1, 2]]
    ref = correlate1d(correlate1d(a0.astype(np.float64), taps, axis=1, mode="constant"), taps, axis=0, mode="constant")
    assert np.allclose(_smooth5(a0, 1.0), ref, atol=1e-5)


def test_second_differences_of_a_roof_and_a_plane():
    # a plane (depth linear in x and y) gives 0 from every operator; a roof along the
    # columns gives the slope change per pixel from the 0 degree operator on its crest
    from rangesim.edges._gradient import second_differences
    yy, xx = np.mgrid[0:9, 0:9].astype(np.float32)
    plane = 100 + 0.5 * xx - 0.25 * yy
    for r in second_differences(plane):
        assert np.allclose(r[1:-1, 1:-1], 0, atol=1e-4)
    roof = 100 + np.abs(xx - 4) * 2.0
    r0, _, r90, _ = second_differences(roof)
    assert np.isclose(r0[4, 4], 4.0) and np.allclose(r0[4, 1:3], 0) and np.allclose(r90[4, 1:-1], 0)


def test_weno_tangent_is_one_sided_at_a_crease():
    # on a roof the tangent along x at the crest's neighbours is that pixel's own face's
    from rangesim.edges._differences import eno_tangent
    yy, xx = np.mgrid[0:7, 0:9].astype(np.float32)
    z = 100 + np.abs(xx - 4) * 2.0
    xyz = np.stack([xx, yy, z])
    t = eno_tangent(xyz, 0, None)
    assert np.allclose(t[2, 3, 1:4], -2.0, atol=1e-3) and np.allclose(t[2, 3, 5:8], 2.0, atol=1e-3)
    assert np.allclose(t[0], 1.0)


def test_jump_threshold_row_broadcasts_like_the_full_image():
    # a threshold per column (1, W) means the same as that row repeated over the image; the
    # compiled pair tests read the broadcast copy, never past a short array
    from rangesim.edges._discontinuities import find_discontinuities
    z = np.random.default_rng(0).uniform(100, 200, (6, 8)).astype(np.float32)
    row = np.linspace(10, 40, 8, dtype=np.float32)[None]
    a = find_discontinuities(z, row, folds=True)
    b = find_discontinuities(z, np.repeat(row, 6, axis=0), folds=True)
    assert np.array_equal(a.pairs, b.pairs) and np.array_equal(a.occluding, b.occluding)
    assert a.pairs.any()


def _noisy(scan: RangeScan, sigma_mm: float, seed: int = 0, smooth_px: float = 0.0) -> RangeScan:
    """``scan`` with Gaussian depth noise of ``sigma_mm`` along the rays (white, or smoothed
    by a Gaussian of ``smooth_px`` and rescaled to the same std), and that sigma attached."""
    from scipy import ndimage
    e = np.random.default_rng(seed).standard_normal(scan.shape)
    if smooth_px:
        e = ndimage.gaussian_filter(e, smooth_px, mode="wrap")
        e /= e.std()
    depth = scan.xyz[..., 2].astype(np.float64)
    xyz = scan.xyz * ((depth + sigma_mm * e) / depth)[..., None]
    return grid_scan(xyz, np.asarray(scan.meta["K"]), np.full(scan.shape, sigma_mm, np.float32))


@pytest.mark.parametrize("smooth_px", [0.0, 2.0])
def test_stride_gain_is_the_second_difference_law(smooth_px):
    """The bend noise at lag s over lag 1, measured on a noisy frontal plane: for errors with
    correlation rho(l) the second difference at lag s has variance (6 - 8 rho(s) + 2 rho(2s))
    sigma^2, so the gain is sqrt of that over its lag-1 value, over s (1 / s for white noise,
    rho = 0; rho(l) = exp(-l^2 / (4 w^2)) for white noise smoothed by a Gaussian of w px)."""
    from rangesim.edges._noise import stride_gain
    K, rays = pinhole_rays(256, 400.0)
    plane = grid_scan(rays * 500.0, K)
    scan = _noisy(plane, 0.3, smooth_px=smooth_px)
    gain = stride_gain(scan.depth, np.full(scan.shape, 1.25, np.float32), 6)

    def var(lag):
        rho = (lambda l: np.exp(-l * l / (4 * smooth_px ** 2))) if smooth_px else (lambda l: 0.0)
        return 6 - 8 * rho(lag) + 2 * rho(2 * lag)
    expect = np.array([np.sqrt(var(s) / var(1)) / s for s in range(1, 7)])
    assert gain[1] == 1.0
    assert np.allclose(gain[1:], expect, rtol=0.08), (gain, expect)
    if smooth_px:
        assert gain[2] > 0.8                     # correlated errors: a longer line barely helps


def test_ring_strides_follow_the_noise_and_stop_at_blocked_pixels():
    """Noise 0.25 footprints with k = 2.25 bends lines by atan(2.25 sqrt(2) 0.25) = 38.5 deg
    at stride 1; with independent errors (gain 1 / s) stride ceil(2.97) = 3 brings that to
    15 deg. A window may hold no blocked pixel nor reach past the border; a stride that
    gains nothing over a shorter one is never used."""
    from rangesim.edges._line_rings import ring_strides
    n = 41
    noise = np.full((n, n), 0.25)
    blocked = np.zeros((n, n), bool)
    blocked[20, 20] = True
    gain = 1.0 / np.maximum(np.arange(9), 1)
    s = ring_strides(noise, 2.25, blocked, 15.0, gain)
    assert s[20, 20] == 0
    # beside it and one further: nearest neighbours (the jump rule decides beside it)
    assert s[20, 21] == 1 and s[20, 22] == 1 and s[20, 23] == 2 and s[20, 24] == 3 and s[20, 30] == 3
    assert s[0, 10] == 1 and s[1, 10] == 1 and s[2, 10] == 2 and s[10, 10] == 3
    # quieter pixels need less: noise 0.1 -> ceil(1.19) = 2
    assert ring_strides(np.full((n, n), 0.1), 2.25, np.zeros((n, n), bool), 15.0, gain)[20, 20] == 2
    # a stride that does not beat a shorter one is skipped
    flat = gain.copy()
    flat[3] = flat[2]
    assert ring_strides(noise, 2.25, np.zeros((n, n), bool), 15.0, flat)[20, 20] == 4
    # no stride good enough: the one with the least gain that fits
    assert ring_strides(np.full((n, n), 5.0), 2.25, np.zeros((n, n), bool), 15.0, gain)[20, 20] == 8


def test_line_fit_finds_a_noisy_crease_with_longer_lines():
    """A 40 degree roof under white depth noise of 0.3 footprints: the nearest-neighbour test
    needs a 43.6 degree tolerance to stay silent on the noise, so it misses the crease; lines
    drawn 4 px out (angle noise / 4) find it in nearly every row and leave the faces clean."""
    roof = synthetic_roof(40.0, 90.0, convex=True, size=81)
    scan = _noisy(roof, 0.3 * 500.0 / 400.0)
    near = roof_distance(scan, 90.0) <= 2.0
    far = roof_distance(scan, 90.0) >= 8.0
    cols = slice(6, -6)
    long_lines = line_fit(scan)
    short_lines = line_fit(scan, max_stride=1)
    assert long_lines.params["median_stride"] >= 3
    assert (long_lines.mask & near)[:, cols].any(axis=0).mean() >= 0.9
    assert (short_lines.mask & near)[:, cols].any(axis=0).mean() <= 0.3
    assert long_lines.mask[far].mean() <= 0.01
    crease = long_lines.mask & near
    assert (long_lines.labels[crease] == EdgeLabel.CONVEX).mean() >= 0.9


def test_compiled_axis_difference_matches_the_sides_rule():
    # the compiled x / y central difference of an image against the array rule (_sides) that
    # stacks take, with NaN, broken pairs and 1-px images: the same bits
    from rangesim.edges._differences import central_difference

    rng = np.random.default_rng(11)
    for h, w in ((1, 7), (6, 1), (9, 13), (31, 24)):
        for dtype in (np.float32, np.float64):
            a = (rng.normal(size=(h, w)) * 10).astype(dtype)
            a[rng.random((h, w)) < 0.15] = np.nan
            pairs = rng.random((4, h, w)) < 0.1
            for axis in (0, 2):
                for pr in (pairs, None):
                    image = central_difference(a, axis, pr)
                    stacked = central_difference(a[None], axis, pr)[0]
                    assert image.dtype == dtype
                    np.testing.assert_array_equal(image, stacked)


def test_line_fit_keeps_no_crease_beside_a_stripe_rounded_step():
    """A noise-free White Scanner scan of an 8 mm block on a plane, from straight above at
    350 mm (footprint 0.27 mm, stripe 0.5 mm FWHM): the stripe's width rounds every step
    over a pixel or two each side, which bends the nearest-neighbour lines of the pixels
    beside the jump's pair. Without the clearance those become parallel false creases along
    every step (the scene has no crease in view: the walls are vertical); the default (1 px
    beyond the far side) clears the step's foot, the shoulder's (on the block's top, beside
    the jump pixels) are left, and the jump pixels are the same."""
    from rangesim.edges._discontinuities import JUMP_THRESHOLD, discontinuities
    from rangesim.edges._line_fit import LINE_FIT_CLEARANCE
    from rangesim.edges._scan_access import scan_arrays
    from rangesim.edges._thinning import near_mask

    def bare_occluded(scan):
        return discontinuities(scan, scan_arrays(scan)[1], JUMP_THRESHOLD, 50)[0].occluded
    sensor = rs.load_sensor("white_scanner").with_params({"noise.sigma_px": 0, "noise.speckle_contrast": 0})
    scan = rs.scan([plane(), box([-30, -20, 0], [30, 20, 8])], sensor, pose=top_down_pose(350.0), seed=0)
    bare, cleared = line_fit(scan, jump_clearance=0), line_fit(scan)
    assert LINE_FIT_CLEARANCE == 1 and cleared.params["jump_clearance"] == 1

    def parts(em):
        crease = em.mask & np.isin(em.labels, [EdgeLabel.CONVEX, EdgeLabel.CONCAVE])
        return crease, em.mask & (em.labels == EdgeLabel.JUMP)
    crease0, jump0 = parts(bare)
    crease1, jump1 = parts(cleared)
    assert jump0.sum() > 500 and np.array_equal(jump0, jump1)
    top = scan.depth < 350.0 - 4.0                   # the block's top (342 mm) vs the floor (350)
    assert (jump0 & ~top).sum() == 0                 # the jumps are marked on the near side
    # without the clearance: the step's foot (and the floor's border beyond the laser
    # shadow, the same step's far side across the gap) is a line of false creases
    foot = crease0 & ~top
    assert foot.sum() > 200
    assert near_mask(foot, bare_occluded(scan), 1).sum() >= 0.98 * foot.sum()   # 1 px beyond the far side
    assert (crease1 & ~top).sum() == 0               # cleared
    assert (crease1 & top).sum() == (crease0 & top).sum() > 0   # the shoulder's are left
    with pytest.raises(ValueError, match="jump_clearance"):
        line_fit(scan, jump_clearance=-1)


def _l_corners(mask: np.ndarray) -> int:
    """Pixels with two 4-neighbours at a right angle set and the diagonal between them clear
    (the inner corner of a 4-connected staircase: an 8-connected line does without it)."""
    p = np.pad(mask, 1)
    c = p[1:-1, 1:-1]
    n, s_, w, e = p[:-2, 1:-1], p[2:, 1:-1], p[1:-1, :-2], p[1:-1, 2:]
    nw, ne, sw, se = p[:-2, :-2], p[:-2, 2:], p[2:, :-2], p[2:, 2:]
    corner = (n & e & ~ne & ~s_ & ~w) | (n & w & ~nw & ~s_ & ~e) | (s_ & e & ~se & ~n & ~w) | (s_ & w & ~sw & ~n & ~e)
    return int((c & corner).sum())


def _step_corners(mask: np.ndarray) -> int:
    """L corners that the line can do without (two 4-neighbours at a right angle set, their
    diagonal and the three opposite pixels clear) one of whose arms is a single pixel: a
    staircase's step, not two straight runs meeting."""
    p = np.pad(mask, 2)
    h, w = mask.shape
    at = lambda dr, dc: p[2 + dr:2 + dr + h, 2 + dc:2 + dc + w]
    c = at(0, 0)
    total = np.zeros_like(mask)
    for (r1, c1), (r2, c2) in (((-1, 0), (0, 1)), ((0, 1), (1, 0)), ((1, 0), (0, -1)), ((0, -1), (-1, 0))):
        l_shape = (at(r1, c1) & at(r2, c2) & ~at(r1 + r2, c1 + c2) & ~at(-r1, -c1) & ~at(-r2, -c2)
                   & ~at(-r1 - r2, -c1 - c2))        # nothing hangs on it from the other side
        total |= c & l_shape & ~(at(2 * r1, 2 * c1) & at(2 * r2, 2 * c2))
    return int(total.sum())


def _jumps_with_and_without_thinning(name: str, scan, monkeypatch) -> tuple[np.ndarray, np.ndarray]:
    """Detector ``name``'s jump pixels on ``scan``, then the same with the jump thinning of
    ``discontinuities`` switched off (monkeypatched for the rest of the test)."""
    import rangesim.edges._discontinuities as disc_module

    def jumps():
        em = DETECTORS[name](scan)
        return em.mask & (em.labels == EdgeLabel.JUMP)
    thinned = jumps()
    monkeypatch.setattr(disc_module, "thin_staircases", lambda mask, droppable=None, keep_corners=False: mask.copy())
    return thinned, jumps()


@pytest.mark.parametrize("name", ["gradient", "normal", "line_fit", "curvature"])
def test_jumps_beside_a_ragged_gap_are_8_connected_lines(name, monkeypatch):
    """A plane 20 mm in front of another, its edge at 30 degrees to the rows, and a band of
    dropouts beyond the edge that eats 0-2 px into the near plane at random (a block
    matcher's ragged occluding boundary): every measured pixel beside the band is a jump by
    the rule, which leaves 4-connected staircases; the marked jumps drop their inner corners
    (``thin_staircases`` in ``discontinuities``) and nothing else: no step corner left, no
    pixel added, every raw jump pixel within 1 px of a kept one."""
    from scipy import ndimage

    size, f = 120, 300.0
    K, rays = pinhole_rays(size, f)
    v, u = np.mgrid[0:size, 0:size]
    s = (u - 60) * np.sin(np.radians(30)) - (v - 60) * np.cos(np.radians(30))  # px across the edge
    depth = np.where(s < 0, 380.0, 400.0)
    gap = (s >= -np.random.default_rng(3).integers(0, 3, depth.shape)) & (s < 5)
    depth[gap] = np.nan
    scan = grid_scan(rays * depth[..., None], K, None)

    thinned, raw = _jumps_with_and_without_thinning(name, scan, monkeypatch)
    assert raw.sum() > 100 and _step_corners(raw) >= 5
    assert _step_corners(thinned) == 0            # every step's corner gone
    assert _l_corners(thinned) < _l_corners(raw)  # (corners of two longer runs stay, as the truth's)
    assert not (thinned & ~raw).any() and thinned.sum() < raw.sum()
    assert ndimage.binary_dilation(thinned, np.ones((3, 3), bool))[raw].all()


@pytest.mark.parametrize("name", ["gradient", "normal", "line_fit", "curvature"])
def test_a_square_boxs_jump_outline_keeps_its_corners(name, monkeypatch):
    """A box seen square on (a 40 x 24 px rectangle 20 mm in front of a plane): its jump
    outline is four straight runs meeting at right angles, and the truth marks the corner
    pixels; the staircase thinning leaves them (both arms run on), so the outline is the
    jump rule's own, corners included."""
    size, f = 80, 300.0
    K, rays = pinhole_rays(size, f)
    depth = np.full((size, size), 400.0)
    depth[28:52, 20:60] = 380.0
    scan = grid_scan(rays * depth[..., None], K, None)

    thinned, raw = _jumps_with_and_without_thinning(name, scan, monkeypatch)
    assert raw.sum() >= 2 * (40 + 24) - 4
    assert np.array_equal(thinned, raw)
    assert thinned[[28, 28, 51, 51], [20, 59, 20, 59]].all()
