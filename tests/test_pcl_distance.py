"""pcl_organized's depth threshold is relative to the distance from the sensor (issue 14, item 4).

A box of height h on a floor, seen straight down from 400 mm: PCL's rule makes its outline a
jump when h > 0.02 x 400 mm = 8 mm. The same scan moved into a frame whose range axis is
centred on 0 (as the Cyberware's) must not flood: without a distance it falls back, with a
warning, to the footprint rule; with the distance it gives PCL's answer again.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import box, make_sensor, plane, top_down_pose

import rangesim as rs
from rangesim.core.errors import RangesimError

HEIGHT_MM = 400.0


def _scan(h):
    scene = rs.load_scene([plane(), box((-30, -20, 0), (30, 20, h))])
    return rs.scan(scene, make_sensor(), pose=top_down_pose(HEIGHT_MM))


def _centred(scan):
    """The scan in a 'scanner frame': depth axis shifted to centre 0, no pinhole model."""
    xyz = scan.xyz.copy()
    xyz[..., 2] -= HEIGHT_MM
    meta = {k: v for k, v in scan.meta.items() if k != "K"}
    return dataclasses.replace(scan, xyz=xyz, depth=scan.depth - np.float32(HEIGHT_MM), meta=meta)


@pytest.mark.parametrize("h, jumps", [(5.0, False), (7.0, False), (9.0, True), (14.0, True)])
def test_threshold_is_two_percent_of_the_distance(h, jumps):
    # the box top is at 400 - h mm: the step h against 0.02 x (400 - h) = 7.7-7.9 mm; the
    # outline is ~200 px (a corner pixel may compare across the laser shadow beside it)
    em = rs.edges.pcl_organized(_scan(h))
    assert em.params["distance"] == "|xyz|"
    n = int((em.occluding | em.occluded).sum())
    assert (n > 150) if jumps else (n <= 4), n


def test_centred_range_axis_does_not_flood_and_distance_restores_pcl():
    scan = _scan(14.0)
    reference = rs.edges.pcl_organized(scan)
    moved = _centred(scan)
    assert np.nanmin(moved.depth) < 0 < np.nanmax(moved.depth)
    with pytest.warns(RuntimeWarning, match="not the distance to the sensor"):
        fallback = rs.edges.pcl_organized(moved)
    assert fallback.params["distance"] == "footprints"
    # PCL's 0.02 |z| is ~0 near z = 0: it marked most of the floor; the fallback marks the outline
    assert fallback.mask.sum() < 0.05 * moved.valid.sum()
    distance = np.linalg.norm(scan.xyz, axis=-1)
    given = rs.edges.pcl_organized(moved, distance_mm=distance)
    assert given.params["distance"] == "distance_mm"
    assert np.array_equal(given.occluding, reference.occluding)
    assert np.array_equal(given.occluded, reference.occluded)
    # one number (a stand-off) works too: the box is far above 2 % of 400 mm
    assert (rs.edges.pcl_organized(moved, distance_mm=HEIGHT_MM).occluding).any()


def test_bad_distance_is_refused():
    scan = _scan(14.0)
    with pytest.raises(RangesimError, match="distance_mm must be"):
        rs.edges.pcl_organized(scan, distance_mm=np.ones((3, 3)))
    with pytest.raises(RangesimError, match="positive"):
        rs.edges.pcl_organized(scan, distance_mm=-1.0)
