"""Chapter 5's boundary (eqs. 5.6-5.8): ordering and resampling, the EFA fit against known shapes, and the region
update rules of erratum 19 (the circle in open space, the EFA polygon clipped to a disc one step toward T)."""

import json
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from swarm_logic.families.roy.regions.efa import (
    EfaParams,
    RegionParams,
    clean_points,
    efa_fit,
    order_points,
    polygon_region,
    resample_closed,
)
from swarm_logic.families.roy.regions.shapes import Ellipse


def ellipse_points(a, b, theta, centre, n, rng):
    t = rng.uniform(0.0, 2 * math.pi, n)
    c, s = math.cos(theta), math.sin(theta)
    u, v = a * np.cos(t), b * np.sin(t)
    return np.stack([centre[0] + u * c - v * s, centre[1] + u * s + v * c], axis=1)


def test_efa_reconstructs_a_rotated_ellipse():
    rng = np.random.default_rng(3)
    pts = ellipse_points(6.0, 2.0, 0.4, (3.0, -1.0), 60, rng)  # unordered, as sensed
    fit = efa_fit(pts)
    assert fit.coeffs.shape == (14, 4)
    assert fit.area == pytest.approx(math.pi * 12.0, rel=0.02)  # the chords through 60 random points: -0.9 %
    assert fit.locus == pytest.approx([3.0, -1.0], abs=0.05)
    assert not fit.repaired and fit.pieces_dropped == 0
    c = fit.polygon.centroid
    assert (c.x, c.y) == pytest.approx((3.0, -1.0), abs=0.05)
    truth = Ellipse(3.0, -1.0, 6.0, 2.0, 0.4).polygon(360)
    assert fit.polygon.symmetric_difference(truth).area < 0.03 * truth.area


def test_efa_follows_a_rectangle_ish_blob():
    t = np.linspace(0.0, 2 * math.pi, 80, endpoint=False)
    blob = np.stack(
        [np.sign(np.cos(t)) * np.abs(np.cos(t)) ** 0.3 * 5.0, np.sign(np.sin(t)) * np.abs(np.sin(t)) ** 0.3 * 3.0],
        axis=1,
    )
    truth = Polygon(blob).area
    fit = efa_fit(np.random.default_rng(0).permutation(blob))
    assert fit.area == pytest.approx(truth, rel=0.01)
    assert fit.polygon.symmetric_difference(Polygon(blob)).area < 0.03 * truth


def test_efa_of_a_rectangle_rounds_its_corners_only():
    x = np.linspace(-5.0, 5.0, 21)
    y = np.linspace(-2.0, 2.0, 9)
    pts = np.vstack([np.c_[x, np.full_like(x, -2.0)], np.c_[x, np.full_like(x, 2.0)], np.c_[np.full_like(y, -5.0), y]])
    pts = np.vstack([pts, np.c_[np.full_like(y, 5.0), y]])
    fit = efa_fit(pts)
    assert fit.area == pytest.approx(40.0, rel=0.03)
    assert fit.polygon.buffer(0.5).contains(Polygon([(-5, -2), (5, -2), (5, 2), (-5, 2)]))


def test_literal_order_scrambles_the_contour():
    """Erratum 19: the points in the order they arrive (here shuffled) make a self-crossing contour; the polar sort
    does not."""
    rng = np.random.default_rng(5)
    pts = ellipse_points(6.0, 3.0, 0.0, (0.0, 0.0), 50, rng)
    ours = efa_fit(pts)
    literal = efa_fit(pts, EfaParams(ordering="given"))
    assert ours.area == pytest.approx(math.pi * 18.0, rel=0.03)  # chords through 50 random points: -2.1 %
    assert literal.repaired and literal.area < 0.6 * ours.area


def test_order_drops_duplicates_and_nonfinite_and_sorts_by_bearing():
    pts = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [np.nan, 2.0], [-1.0, 0.0], [0.0, -1.0], [0.0, np.inf]])
    o = order_points(pts, centre=np.zeros(2))
    assert (o.dropped_nonfinite, o.dropped_duplicates) == (2, 1)
    assert o.points.tolist() == [[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]  # bearings -pi/2, 0, pi/2, pi
    # points on one bearing: nearest first
    ray = np.array([[3.0, 3.0], [1.0, 1.0], [2.0, 2.0], [0.0, -1.0]])
    assert order_points(ray, centre=np.zeros(2)).points[1:].tolist() == [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]
    assert order_points(pts, ordering="given").points.tolist() == [[1, 0], [0, 1], [-1, 0], [0, -1]]


def test_clean_points_bad_shapes():
    assert clean_points(np.zeros((0, 2)))[0].shape == (0, 2)
    assert clean_points(np.array([1.0, 2.0, 3.0]))[0].shape == (0, 2)
    assert clean_points(np.array([1.0, 2.0, 3.0, 4.0]))[0].tolist() == [[1, 2], [3, 4]]
    assert clean_points(np.full((4, 2), np.nan))[1] == 4


def test_resample_equal_arc_length():
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    r = resample_closed(square, 32)
    assert r.shape == (32, 2) and r[0].tolist() == [0.0, 0.0]
    steps = np.hypot(*np.diff(np.vstack([r, r[:1]]), axis=0).T)
    assert steps == pytest.approx(np.full(32, 0.5))  # 16 / 32 along every side, corners fall on samples
    line = order_points(np.c_[np.arange(6.0), np.arange(6.0)]).points  # collinear: out along the line and back
    back_and_forth = resample_closed(line, 20)
    assert back_and_forth.shape == (20, 2) and np.allclose(back_and_forth[:, 0], back_and_forth[:, 1])
    assert resample_closed(np.array([[1.0, 1.0]]), 10).shape == (0, 2)
    assert resample_closed(np.array([[1.0, 1.0], [1.0, 1.0]]), 10).shape == (0, 2)


def test_collinear_and_too_few_points_give_no_polygon():
    line = np.c_[np.arange(10.0), 2 * np.arange(10.0)]
    for pts in (line, line[:2], np.zeros((0, 2)), np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])):
        fit = efa_fit(pts)
        assert fit.polygon.is_empty and fit.area == 0.0


def test_open_space_circle_one_step_toward_target():
    pos = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0]])
    reg = polygon_region(np.array([[5.0, 5.0], [np.nan, 1.0]]), pos, np.array([11.0, 1.0]), 1.0, RegionParams(step=2.0))
    assert reg.rule == "circle" and "1 points sensed" in reg.reason
    assert reg.centre.tolist() == [3.0, 1.0]
    assert reg.area == pytest.approx(4 * math.pi / 0.7, rel=2e-3)
    assert reg.dropped_nonfinite == 1 and reg.fit is None
    c = reg.polygon.centroid
    assert (c.x, c.y) == pytest.approx((3.0, 1.0), abs=1e-9)
    near = polygon_region(np.zeros((0, 2)), pos, np.array([1.5, 1.0]), 1.0, RegionParams(step=2.0))
    assert near.centre.tolist() == [1.5, 1.0]  # not past the target


def corridor(half_width=3.0, half_length=8.0):
    x = np.linspace(-half_length, half_length, 33)
    return np.r_[np.c_[x, np.full_like(x, half_width)], np.c_[x, np.full_like(x, -half_width)]]


def test_corridor_region_is_the_clipped_efa_polygon():
    pos = np.random.default_rng(0).uniform(-2.0, 2.0, (14, 2))
    target = np.array([35.0, 0.0])
    reg = polygon_region(corridor(), pos, target, 1.0, RegionParams(step=1.0, grow=False))
    assert reg.rule == "efa_disc" and reg.disc_radius == 5.0
    assert reg.centre == pytest.approx(pos.mean(axis=0) + np.array([1.0, 0.0]), abs=0.02)
    assert reg.polygon.is_valid
    ring = np.asarray(reg.polygon.exterior.coords)
    assert np.hypot(*(ring - reg.centre).T).max() <= 5.0 + 1e-9
    assert reg.polygon.bounds[1] > -3.05 and reg.polygon.bounds[3] < 3.05  # within the walls
    assert reg.fit.area == pytest.approx(16.0 * 6.0, rel=0.02)
    # grown, the disc gets Φ to N pi r_s^2 / eta
    grown = polygon_region(corridor(), pos, target, 1.0, RegionParams(step=1.0))
    assert grown.disc_radius > 5.0
    assert grown.area == pytest.approx(14 * math.pi / 0.7, rel=1e-3)
    json.dumps(grown.as_dict(), allow_nan=False)


def test_grown_disc_stops_at_the_whole_polygon():
    pos = np.zeros((40, 2))
    reg = polygon_region(corridor(half_length=4.0), pos, np.array([0.5, 0.0]), 1.0)
    assert reg.rule == "efa_disc"
    assert reg.area == pytest.approx(reg.fit.area, rel=1e-6)  # 48 < 40 pi / 0.7: all of it


def test_sort_about_the_swarm():
    """A C-shaped pocket open toward +x, the swarm outside its mouth: about the swarm and about the points' centroid
    the polar orders differ, and the option reaches the fit."""
    t = np.linspace(0.5, 2 * math.pi - 0.5, 40)
    pocket = np.c_[4.0 * np.cos(t), 4.0 * np.sin(t)]
    pos = np.tile([6.0, 0.0], (6, 1))
    target = np.array([6.0, 0.0])
    swarm = polygon_region(pocket, pos, target, 0.5, RegionParams(sort_about="swarm", advance="efa"))
    assert swarm.polygon.equals(efa_fit(pocket, centre=pos.mean(axis=0)).polygon)
    points = polygon_region(pocket, pos, target, 0.5, RegionParams(advance="efa"))
    assert points.polygon.equals(efa_fit(pocket).polygon)
    assert not swarm.polygon.equals(points.polygon)


def test_literal_advance_keeps_the_reconstruction():
    pos = np.zeros((14, 2))
    reg = polygon_region(corridor(), pos, np.array([35.0, 0.0]), 1.0, RegionParams(advance="efa"))
    assert reg.rule == "efa" and reg.polygon.equals(reg.fit.polygon)


def test_degenerate_inputs_fall_back_to_the_circle():
    pos = np.array([[0.0, 0.0], [1.0, 0.0]])
    line = np.c_[np.arange(8.0), np.zeros(8)]
    reg = polygon_region(line, pos, np.array([0.0, 10.0]), 1.0)
    assert reg.rule == "circle" and "no area" in reg.reason
    json.dumps(reg.as_dict(), allow_nan=False)
    far = polygon_region(corridor() + np.array([100.0, 0.0]), pos, np.array([0.0, 10.0]), 1.0, RegionParams(grow=False))
    assert far.rule == "circle" and "outside" in far.reason
    bad = polygon_region(np.full((5, 2), np.nan), np.full((3, 2), np.nan), np.array([np.nan, 0.0]), 1.0)
    assert bad.rule == "circle" and bad.centre.tolist() == [0.0, 0.0] and bad.dropped_nonfinite == 5
    assert bad.area == pytest.approx(math.pi / 0.7, rel=2e-3)


def test_one_wall_is_cut_out_of_the_circle():
    """One wall's points are collinear (no EFA area), or with noise a sliver smaller than one circle: the circle
    rule, less a disc of r_s about every point, so Φ stays on the swarm's side of the wall."""
    x = np.linspace(-5.0, 5.0, 21)
    wall = np.c_[x, np.full_like(x, 3.0)]
    pos, target = np.zeros((14, 2)), np.array([0.0, 30.0])
    for pts, why in ((wall, "no area"), (wall + np.random.default_rng(0).normal(0, 0.05, wall.shape), "smaller")):
        reg = polygon_region(pts, pos, target, 1.0)
        assert reg.rule == "circle" and why in reg.reason
        assert reg.polygon.bounds[3] < 2.1 and reg.pieces_dropped == 1  # the cap beyond the wall dropped
        assert shapely.distance(reg.polygon, shapely.multipoints(pts)) >= 1.0 - 1e-2
    uncut = polygon_region(wall, pos, target, 1.0, RegionParams(clearance=0.0))
    assert uncut.area == pytest.approx(14 * math.pi / 0.7, rel=2e-3)


def test_parameters_are_checked():
    with pytest.raises(ValueError, match="harmonics"):
        EfaParams(harmonics=0)
    with pytest.raises(ValueError, match="ordering"):
        EfaParams(ordering="sorted")
    with pytest.raises(ValueError, match="packing_density"):
        RegionParams(packing_density=1.5)
    with pytest.raises(ValueError, match="step"):
        RegionParams(step=float("nan"))
    with pytest.raises(ValueError, match="advance"):
        RegionParams(advance="teleport")
    with pytest.raises(ValueError, match="r_s"):
        polygon_region(corridor(), np.zeros((2, 2)), np.zeros(2), 0.0)
