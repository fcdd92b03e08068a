"""Chapter 4's global controller: the gap by k-means, the moving-obstacle test, the region update with its equal
area, the failure detector and shrink, and Theorem 3's R_s."""

import json
import math

import numpy as np
import pytest

from swarm_logic.families.roy.regions.ellipse import (
    FailureDetector,
    FailureParams,
    Gap,
    MovingObstacleTest,
    RegionParams,
    RegionState,
    axis_targets,
    cohesion_radius,
    failure_area_factor,
    free_space,
    gap_bisector,
    region_with_failures,
    shrunk_major_axis,
    step_region,
)
from swarm_logic.families.roy.regions.shapes import Ellipse


def walls(gap: float, x0: float = 4.0, depth: float = 2.0, n: int = 20) -> np.ndarray:
    """Two obstacle point clouds either side of the x axis, the free space between them ``gap`` wide."""
    xs = np.linspace(x0, x0 + depth, n)
    up = np.stack([xs, np.full(n, gap / 2)], axis=1)
    up = np.concatenate([up, up + np.array([0.0, 1.0])])
    return np.concatenate([up, up * np.array([1.0, -1.0])])


def test_gap_closest_pair_and_centroid():
    p = walls(1.6)
    closest, centroid = free_space(p, np.zeros(2), "closest"), free_space(p, np.zeros(2), "centroid")
    assert closest.b_fs == pytest.approx(1.6)
    assert centroid.b_fs == pytest.approx(2.6)  # the centroids sit inside the clouds: erratum 12's over-estimate
    assert closest.theta1 == pytest.approx(-closest.theta2) and abs(closest.theta1) < math.pi / 2
    assert free_space(p[::-1], np.zeros(2)).b_fs == closest.b_fs  # order-free, deterministic
    assert free_space(p, np.zeros(2)).as_dict() == closest.as_dict()


def test_one_wall_is_no_gap_when_sides_are_required():
    wall = np.stack([np.linspace(0.0, 8.0, 30), np.full(30, 2.0)], axis=1)  # one wall along the path, on the left
    literal = free_space(wall, np.zeros(2))
    assert literal.sensed and literal.b_fs < 0.3  # k-means cuts the wall in two: a "gap" of one point spacing
    assert free_space(wall, np.zeros(2), heading=0.0).reason == "one side"
    assert free_space(walls(1.6), np.zeros(2), heading=0.0).b_fs == pytest.approx(1.6)  # both sides: kept


def test_inside_a_corridor_the_sides_split_finds_its_width():
    long = walls(2.0, x0=-6.0, depth=12.0, n=40)  # the region's centre halfway down a 2-wide corridor
    assert free_space(long, np.zeros(2)).b_fs < 0.5  # k-means: front and back halves, two points of one wall
    sides = free_space(long, np.zeros(2), heading=0.0, split="sides")
    assert sides.b_fs == pytest.approx(2.0) and abs(gap_bisector(sides, 0.0)) < 1e-9
    assert free_space(long[long[:, 1] > 0], np.zeros(2), heading=0.0, split="sides").reason == "one side"
    with pytest.raises(ValueError, match="split"):
        free_space(long, np.zeros(2), split="sides")


def test_no_gap_sensed():
    assert free_space(np.zeros((0, 2)), np.zeros(2)).reason == "fewer than 2 points"
    assert free_space(np.array([[1.0, 1.0], [np.nan, 2.0]]), np.zeros(2)).b_fs == math.inf
    one = free_space(np.ones((5, 2)), np.zeros(2))
    assert not one.sensed and one.reason == "one cluster"
    with pytest.raises(ValueError, match="mode"):
        free_space(np.ones((5, 2)), np.zeros(2), "nearest")


def test_moving_obstacle_blocks_then_accepts():
    """B6: a mover entering the gap between two windows lowers AD; the gap is committed only when AD recovers."""
    test = MovingObstacleTest()
    p1 = walls(3.0)
    g1 = free_space(p1, np.zeros(2))
    assert test.feed(p1, g1).status == "pending"
    mover = np.concatenate([p1, np.array([[5.0, 0.0], [5.2, 0.1], [5.1, -0.1], [4.9, 0.0]])])
    d = test.feed(mover, free_space(mover, np.zeros(2)))
    assert d.status == "blocked" and d.gap is None and d.ad_now < d.ad_ref
    d = test.feed(p1, g1)  # the mover has left: the reference (the blocked window) is re-tested and passes
    assert d.status == "accepted" and d.ad_now >= d.ad_ref
    d = test.feed(p1, g1)
    assert d.status == "accepted" and d.gap.b_fs == pytest.approx(3.0)
    none = MovingObstacleTest().feed(np.zeros((0, 2)), Gap(math.inf))
    assert none.status == "no_gap"
    logged = json.loads(json.dumps(d.as_dict(), allow_nan=False))
    assert logged["gap"]["b_fs"] == pytest.approx(3.0) and logged["status"] == "accepted"
    assert json.loads(json.dumps(none.as_dict(), allow_nan=False))["ad_ref"] is None


@pytest.mark.parametrize("b_fs", [0.05, 0.7, 1.3, 2.0, 2.49])
def test_equal_area_literal_a4(b_fs):
    p = RegionParams(axes="literal")
    a, b = axis_targets(b_fs, p)
    assert b == b_fs and math.pi * a * b == pytest.approx(math.pi * 2.5**2, abs=1e-9)
    assert axis_targets(2.5, p) == (2.5, 2.5) and axis_targets(math.inf, p) == (2.5, 2.5)


def test_geometric_axes():
    p = RegionParams(axes="geometric", clearance=0.5)
    assert axis_targets(5.0, p) == (2.5, 2.5)  # the gap fits the diameter: a circle
    a, b = axis_targets(3.0, p)
    assert b == pytest.approx(1.0) and a * b == pytest.approx(6.25, abs=1e-12)
    assert axis_targets(0.8, p)[1] < 0  # narrower than twice the clearance: no region


def walls_step(state, gap_points, target, n, params, positions=None):
    gap = free_space(gap_points, state.region.centre)
    return step_region(state, gap, target, 0.25, params, positions=positions)


def test_region_becomes_ellipse_in_gap_and_circle_after():
    """B3: circle in the open, equal-area ellipse along the gap bisector in a gap, circle again afterwards."""
    params = RegionParams(barrier=False)
    s = RegionState(Ellipse.circle(0.0, 0.0, 2.5))
    target = np.array([30.0, 0.0])
    open_step = step_region(s, Gap(math.inf), target, 0.25, params)
    assert open_step.state.region.is_circle and open_step.advanced
    assert open_step.state.region.x == pytest.approx(0.3 * 0.25)  # v_e = min(k_vcir |O - T|, v_max)
    s = open_step.state
    for _ in range(12):
        s = walls_step(s, walls(3.0, x0=s.region.x + 1.0), target, 6, params).state
    e = s.region
    assert e.b == pytest.approx(3.0 / 2 - 0.5) and e.area == pytest.approx(math.pi * 6.25, abs=1e-9)
    assert abs(e.theta) < 0.05  # the major axis along the corridor
    s = step_region(s, Gap(math.inf), target, 0.25, params).state
    assert s.region.is_circle and s.region.a == pytest.approx(2.5)


def test_region_turns_toward_the_gap_bisector():
    params = RegionParams(barrier=False, k_theta=2.0)
    # a corridor along +y: theta turns toward its bisector at k_theta dt = 0.5 of the error per update
    pts = walls(2.0) @ np.array([[0.0, 1.0], [-1.0, 0.0]]).T + [0.0, 0.0]  # the corridor along +y
    s = RegionState(Ellipse.circle(0.0, 0.0, 2.5))
    thetas = []
    for _ in range(40):
        s = step_region(s, free_space(pts, s.region.centre), np.array([0.1, 30.0]), 0.25, params).state
        thetas.append(s.region.theta)
    assert thetas[0] == pytest.approx(0.5 * math.pi / 2, abs=0.15)
    assert thetas[-1] == pytest.approx(math.pi / 2, abs=0.05) and max(thetas) < math.pi / 2 + 0.05


def test_barrier_and_blocked_hold_the_centre():
    params = RegionParams(barrier=True)
    s = RegionState(Ellipse.circle(0.0, 0.0, 2.5))
    out = step_region(
        s, Gap(math.inf), np.array([10.0, 0.0]), 0.25, params, positions=np.array([[0.0, 0.0], [4.0, 0.0]])
    )
    assert not out.advanced and out.held == "barrier" and out.state.region.x == 0.0
    ok = step_region(
        s,
        Gap(math.inf),
        np.array([10.0, 0.0]),
        0.25,
        params,
        positions=np.array([[0.0, 0.0], [4.0, 0.0]]),
        active=np.array([True, False]),
    )
    assert ok.advanced
    held = step_region(s, Gap(math.inf), np.array([10.0, 0.0]), 0.25, params, blocked=True)
    assert held.held == "gap blocked" and held.state is s


def test_region_that_cannot_hold_the_swarm_is_not_adopted():
    params = RegionParams(barrier=False, clearance=0.5, r_robot=0.5)
    s = RegionState(Ellipse.circle(0.0, 0.0, 2.5))
    narrow = step_region(s, free_space(walls(0.9), np.zeros(2)), np.array([10.0, 0.0]), 0.25, params)
    assert narrow.state is s and narrow.held.startswith("infeasible: semi-axes")
    assert json.loads(json.dumps(narrow.as_dict(), allow_nan=False))["a_target"] is None  # a = inf, logged as null
    with pytest.raises(ValueError, match="target"):
        step_region(s, Gap(math.inf), np.array([np.nan, 0.0]), 0.25, params)
    crowd = step_region(s, Gap(math.inf), np.array([10.0, 0.0]), 0.25, params, positions=np.zeros((30, 2)))
    assert crowd.state is s and "N pi r_robot^2" in crowd.held


def test_literal_dynamics_integrate_targets_as_rates():
    """Erratum 10: as printed, a and b grow by their targets every second and the speed grows without bound."""
    params = RegionParams(dynamics="literal", axes="literal", barrier=False)
    s = RegionState(Ellipse.circle(0.0, 0.0, 2.5))
    s = step_region(s, Gap(math.inf), np.array([30.0, 0.0]), 0.25, params).state
    assert s.v == pytest.approx(10 * 30 * 0.25) and s.region.x == 0.0  # u_v = k_vcir |O - T| integrated
    for _ in range(3):
        s = step_region(s, Gap(math.inf), np.array([30.0, 0.0]), 0.25, params).state
    assert s.region.a == pytest.approx(2.5 + 2.5) and s.region.b == pytest.approx(5.0)  # 1 s of u_a = u_b = r_c
    assert s.v > 100 * params.v_max and s.region.x > 30.0  # overshoots the target


def test_failure_shrink_a5_and_cohesion_radius_a6():
    area = 57.65
    for frac, want in ((0.05, 54.77), (0.10, 51.89), (0.20, 46.12)):
        assert area * failure_area_factor(50, 50 * frac) == pytest.approx(want, abs=0.0051)
    r_c = math.sqrt(area / math.pi)
    u_b = 1.2
    assert math.pi * shrunk_major_axis(r_c, u_b, 50, 5) * u_b == pytest.approx(51.885, abs=1e-9)
    assert cohesion_radius(area / math.pi, 1.0, 50) == pytest.approx(0.606, abs=5e-4)
    e = region_with_failures(Ellipse(0, 0, r_c * r_c / u_b, u_b), r_c, 50, 10)
    assert e.b == u_b and e.area == pytest.approx(area * 0.8)
    assert region_with_failures(Ellipse.circle(0, 0, r_c), r_c, 50, 10).is_circle
    # the planner's update: 40 active agents and 10 failed ones, in the open
    params = RegionParams(r_c=r_c, barrier=False, r_robot=0.1)
    x = np.zeros((50, 2))
    active = np.arange(50) >= 10
    out = step_region(RegionState(Ellipse.circle(0, 0, r_c)), Gap(math.inf), np.ones(2), 0.25, params, x, active, 10)
    assert out.state.region.is_circle and out.state.region.area == pytest.approx(area * 0.8)
    with pytest.raises(ValueError, match="n_failed"):
        step_region(RegionState(Ellipse.circle(0, 0, r_c)), Gap(math.inf), np.ones(2), 0.25, params, n_failed=1)
    with pytest.raises(ValueError, match="n_failed"):
        failure_area_factor(6, 7)


def test_failure_detector_b5():
    det = FailureDetector(3, FailureParams(v_max=0.3))
    x = np.array([[0.0, 0.0], [0.5, 0.0], [6.0, 0.0]])  # agent 2 stays put outside the moving region
    failed = None
    for k in range(13):
        t = 0.25 * k
        region = Ellipse.circle(0.1 * k, 0.0, 2.5)  # the centre moves at 0.4 > 0.2 v_max
        x[:2, 0] += 0.1  # agents 0, 1 follow
        failed = det.update(t, x, region)
        if k == 7:  # 1.75 s of being stuck (counted from the second tick): not yet
            assert not failed.any()
    assert failed.tolist() == [False, False, True]
    # an agent stopped inside the region, or a region that does not move, is not a failure
    det2 = FailureDetector(1)
    for k in range(20):
        assert not det2.update(0.25 * k, np.array([[6.0, 0.0]]), Ellipse.circle(0, 0, 2.5)).any()


def test_axes_lag_is_first_order():
    params = RegionParams(barrier=False, axes_lag=1.0, clearance=0.5)
    s = RegionState(Ellipse.circle(0.0, 0.0, 2.5))
    gap = free_space(walls(3.0), np.zeros(2))  # targets b = 1.0, a = 6.25
    out = step_region(s, gap, np.array([30.0, 0.0]), 0.25, params)
    g = 1 - math.exp(-0.25)
    assert out.state.region.b == pytest.approx(2.5 + g * (1.0 - 2.5))
    assert out.state.region.a == pytest.approx(2.5 + g * (6.25 - 2.5))
    assert (out.a_target, out.b_target) == pytest.approx((6.25, 1.0))
