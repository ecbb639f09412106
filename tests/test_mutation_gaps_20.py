"""Rules the nineteenth session's mutation audit found untested (items M11, M20 and M28): each test
here fails when its rule is changed by hand."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import rangesim as rs
from rangesim.core.constants import EdgeLabel
from rangesim.core.geometry import look_at
from tests.conftest import make_sensor


# -- M11: the stripe peak detector's window ----------------------------------------------------
def test_peak_window_is_two_stripe_fwhms_at_the_near_end():
    """The centroid window's half-width W is two imaged stripe FWHMs at the near end of the range,
    ceil(2 s f / near) px (s the sheet's FWHM, mm): at +-2F a Gaussian of FWHM F has fallen to
    exp(-(2F)^2 / (2 sigma^2)) = 2^-16 of its peak, so the window holds the stripe where it is
    imaged widest. At least 1 px, at most MAX_WINDOW_PX; no stripe, no window."""
    from rangesim.sensor.mixed_pixels import MAX_WINDOW_PX, peak_window_px

    assert peak_window_px(0.5, 1000.0, 250.0) == 4           # 2 x 2.0 px
    assert peak_window_px(0.5, 1100.0, 250.0) == 5           # 2 x 2.2 px, rounded up
    assert peak_window_px(0.01, 1000.0, 250.0) == 1          # a sub-pixel stripe: 1 px
    assert peak_window_px(5.0, 1000.0, 250.0) == MAX_WINDOW_PX
    assert peak_window_px(0.0, 1000.0, 250.0) == 0
    sensor = rs.load_sensor("white_scanner")
    p = sensor.params
    scene = rs.load_scene(trimesh.creation.box(extents=(40.0, 40.0, 10.0)))
    scan = rs.scan(scene, sensor, seed=0)
    f = scan.meta["K"][0][0]
    expected = min(max(math.ceil(2 * p["laser"]["stripe_width"] * f / p["range"]["near"]), 1), MAX_WINDOW_PX)
    assert scan.meta["peak_window_px"] == expected


# -- M20: a crease needs both of its faces in the data ------------------------------------------
def _ledge(width: float, slope_deg: float = 25.0) -> trimesh.Trimesh:
    """An open sheet: a flat panel, a ramp ``width`` mm wide falling at ``slope_deg``, and a flat
    panel again (80 mm along y), so two creases of dihedral ``slope_deg`` along y."""
    drop = width * math.tan(math.radians(slope_deg))
    xs, zs = [-50.0, 0.0, width, 50.0], [0.0, 0.0, -drop, -drop]
    v = [(x, y, z) for y in (-40.0, 40.0) for x, z in zip(xs, zs)]
    f = []
    for i in range(3):
        f += [[i, i + 1, 5 + i], [i, 5 + i, 4 + i]]
    return trimesh.Trimesh(np.array(v), np.array(f), process=False)


@pytest.mark.parametrize(("width", "creases"), [(0.05, False), (4.0, True)])
def test_a_ramp_narrower_than_a_pixel_has_no_creases(width, creases):
    """A crease is in the truth only where the scan samples both its faces (a pixel of the 3 x 3
    around it sees a normal within crease_deg / 2 = 10 degrees of each). A 25-degree ramp 0.05 mm
    wide, seen from 200 mm (0.9 mm footprint), is hit by no ray: its pixels see the two flat
    panels, whose normals are 25 degrees off the ramp's, so neither crease is in the data. A 4 mm
    ramp is seen: a convex and a concave crease along y. (A tolerance loosened past 25 degrees
    marks the sliver's creases.)"""
    scene = rs.load_scene(_ledge(width))
    pose = look_at((0.0, -40.0, 200.0), (0.0, 0.0, 0.0), up=(0, 1, 0))
    scan = rs.scan(scene, make_sensor(), pose=pose, seed=0)
    assert 200.0 / scan.meta["K"][0][0] > 10 * width or creases  # sub-footprint
    truth = rs.ground_truth_edges(scan, scene)
    convex, concave = int((truth == EdgeLabel.CONVEX).sum()), int((truth == EdgeLabel.CONCAVE).sum())
    if creases:
        assert convex > 60 and concave > 60  # both run across the 120 px image
    else:
        assert convex == 0 and concave == 0
        assert (truth == EdgeLabel.JUMP).sum() > 300  # the sheet's outline is there


# -- M28: a lattice needs (nearly) all of its resolved gaps -------------------------------------
def test_a_frame_partly_on_a_lattice_is_not_block_matched():
    """The disparity-lattice rule asks that at least 70 % of the level gaps deeper than where the
    lattice's step reaches two rounding units be resolved (two units or more): a block matcher
    leaves every such gap resolved, a fixed-unit quantiser mostly one unit. Here rows of a Kinect
    lattice (8 f b = 344 k px mm, 700-1500 mm, rounded to whole mm) are accepted alone; beside a
    region holding every whole millimetre over 1100-1500 mm (a frame partly interpolated, or two
    sensors' depths merged) 22 % of the deeper gaps are resolved and the frame is refused,
    though the resolved gaps left (700-1100 mm) still follow q z^2."""
    from rangesim.core.quantisation import disparity_lattice

    fb8 = 344000.0
    lattice = np.sort(np.round(fb8 / np.arange(fb8 / 1500.0, fb8 / 700.0)))
    alone = disparity_lattice(np.repeat(lattice[:, None], 40, axis=1))
    assert alone is not None and alone["resolved_share"] == 1.0
    every_mm = np.arange(1100.0, 1500.0)
    mixed = np.full((max(lattice.size, every_mm.size), 80), np.nan)
    mixed[:lattice.size, :40] = lattice[:, None]
    mixed[:every_mm.size, 40:] = every_mm[:, None]
    assert disparity_lattice(mixed) is None
