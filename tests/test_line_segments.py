"""rs.features.lines on digital lines: whole segments along staircases, gaps bridged up to
max_gap and no further, lines that cross kept apart."""
import numpy as np
import pytest
from conftest import pinhole_scan
from skimage.draw import line as draw_line

import rangesim as rs
from rangesim.edges import EdgeMap
from rangesim.features._lines import MAX_GAP_PX


def _step_scan(deg: float, h: int = 120, w: int = 160):
    """A depth step (500 -> 530 mm) along the line through pixel (20, 100) rising at ``deg``
    to the right, with a 6 px band of missing data on its far side (a shadow): the gradient
    detector's jump pixels follow it as an 8-connected staircase."""
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    a = np.radians(deg)
    s = (xx - 20) * np.sin(a) + (yy - 100) * np.cos(a)
    scan = pinhole_scan(np.where(s < 0, 500.0, 530.0), 400.0)
    scan.valid[(s >= 0) & (s < 6)] = False
    return scan, a


def _in_image_length(a: float, h: int = 120, w: int = 160) -> float:
    """Length (px) of the step line inside the image."""
    t = np.linspace(-400, 400, 160001)
    x, y = 20 + t * np.cos(a), 100 - t * np.sin(a)
    inside = (x >= 0) & (x <= w) & (y >= 0) & (y <= h)
    return float(np.ptp(t[inside]))


@pytest.mark.parametrize("deg", [18.0, 31.0, 45.0, 60.0])
def test_a_diagonal_step_is_one_segment(deg):
    """The step's jump pixels are one segment along the whole step (its ends within 5 px of
    the image border), lying on the step's line (within 1 px). At 45 degrees the detector's
    own directions at the staircase alone broke it into a 52 px piece."""
    scan, a = _step_scan(deg)
    edges = rs.edges.gradient(scan)
    segs = rs.features.lines(edges, scan)
    assert len(segs) == 1
    seg = segs[0]
    assert seg.length >= _in_image_length(a) - 10.0, (seg.length, _in_image_length(a))
    n = np.array([np.sin(a), np.cos(a)])  # the step's normal: s = (p - (20, 100)) . n
    for end in (seg.start, seg.end):
        # the jump pixels are the near side's last row, their points half a pixel towards the gap
        assert abs((np.asarray(end) + 0.5 - (20, 100)) @ n) <= 1.0


def _mask_line(shape, p0, p1, gaps=()):
    """A 1 px digital line p0 -> p1 ((x, y)) with the pixels at arc positions in ``gaps``
    ((start, length) px along it) left out."""
    m = np.zeros(shape, bool)
    rr, cc = draw_line(int(p0[1]), int(p0[0]), int(p1[1]), int(p1[0]))
    t = np.hypot(cc - p0[0], rr - p0[1])
    keep = np.ones(len(rr), bool)
    for g0, n in gaps:
        keep &= ~((t >= g0) & (t < g0 + n))
    m[rr[keep], cc[keep]] = True
    return m


def test_gaps_up_to_max_gap_are_bridged():
    """Gaps of 3-4 px between points (a staircase's unaligned pixels leave such) keep one
    segment; a gap of twice max_gap splits it into two."""
    assert MAX_GAP_PX >= 4
    one = rs.features.lines(_mask_line((120, 200), (10, 100), (190, 20), gaps=[(40, 2), (80, 2), (120, 2)]))
    assert len(one) == 1 and one[0].length >= 190
    gap = int(2 * MAX_GAP_PX)
    two = rs.features.lines(_mask_line((120, 200), (10, 100), (190, 20), gaps=[(100, gap)]))
    assert len(two) == 2
    assert all(s.length >= 80 for s in two)


def test_crossing_lines_are_both_found():
    """Two lines crossing at 60 degrees: the first found whole; the second may be cut where
    the first took the pixels of the crossing (2 x band / sin 60 deg, 3.5 px, plus a pixel),
    but its pieces lie on it and cover it but for that; no segment mixes the two."""
    lines = (((20, 100), (180, 100)), ((55, 39), (145, 161)))
    m = _mask_line((200, 200), *lines[0]) | _mask_line((200, 200), *lines[1])
    segs = rs.features.lines(m)
    for p0, p1 in lines:
        p0, p1 = np.array(p0, float), np.array(p1, float)
        u = (p1 - p0) / np.linalg.norm(p1 - p0)
        n = np.array([-u[1], u[0]])
        on = [s for s in segs if max(abs((np.asarray(e) - p0) @ n) for e in (s.start, s.end)) <= 1.0]
        assert 1 <= len(on) <= 2
        covered = sum(s.length for s in on)
        assert covered >= np.linalg.norm(p1 - p0) - 7.0, (p0, p1, covered)
    assert len(segs) <= 3


def test_the_local_line_decides_where_the_map_directions_swing():
    """An EdgeMap whose directions are off by 30 degrees on every other pixel of a straight
    line (a 3 x 3 operator's answer on a staircase) still gives the whole line."""
    m = _mask_line((120, 200), (10, 100), (190, 20))
    rr, cc = np.nonzero(m)
    normal = np.arctan2(180, 80)  # the line's normal, (dx, dy) = (180, -80) rotated
    direction = np.full(m.shape, np.nan, np.float32)
    direction[rr, cc] = normal + np.where(np.arange(len(rr)) % 2, np.radians(30), 0.0)
    em = EdgeMap(mask=m, labels=m.astype(np.uint8), strength=m.astype(np.float32), direction=direction,
                 method="test")
    segs = rs.features.lines(em)
    assert len(segs) == 1 and segs[0].length >= 190
