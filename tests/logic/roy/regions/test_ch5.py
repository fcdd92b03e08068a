"""Chapter 5's global controller (``Ch5Planner``, region planner ``ch5``) driving point agents: the agents' ranges
are ray cast against wall segments (and their teammates' bodies), the agents follow the plan's law (eq. 5.2) by an
Euler step, and the planner is asked every 0.25 s. The barrier holds each region until every agent is in its circle;
every packing has >= N non-overlapping circles inside its region; 14 agents pass a corridor and reach T; bad input is
a logged decision."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from bridge.studies.roy.numerical import crosses, ray_circle, ray_segments
from swarm_logic.families.roy.regions.ch5 import STEP_RULES, Ch5Params, Ch5Planner
from swarm_logic.families.roy.regions.planner import PLANNERS, Observation, Plan, velocities
from swarm_logic.families.roy.regions.sensing import ring_angles

ANGLES = ring_angles(8)  # Table 5.1: m = 8, z = 45°
SENSOR_RANGE = 6.0  # beyond it: no echo (the window keeps <= 5)


def walls(*polylines: list[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Segments (a, b) of the given open polylines."""
    a = [p for line in polylines for p in line[:-1]]
    b = [p for line in polylines for p in line[1:]]
    return np.array(a, float), np.array(b, float)


def sonar(x: np.ndarray, segs: tuple[np.ndarray, np.ndarray], r_robot: float = 0.5) -> np.ndarray:
    """Each agent's 8 ranges (heading 0) to the walls and to the other agents' bodies; NaN: no echo."""
    n = len(x)
    d = np.stack([np.cos(ANGLES), np.sin(ANGLES)], axis=1)
    o = np.repeat(x[:, None, :], len(ANGLES), axis=1)
    dirs = np.broadcast_to(d, o.shape)
    hit = ray_segments(o, dirs, *segs).min(axis=-1) if len(segs[0]) else np.full((n, len(ANGLES)), np.inf)
    for j in range(n):
        body = ray_circle(o, dirs, x[j], r_robot)
        body[j] = np.inf
        hit = np.minimum(hit, body)
    return np.where(hit <= SENSOR_RANGE, hit, np.nan)


def observe(t: float, ids: np.ndarray, x: np.ndarray, ranges: np.ndarray, target: np.ndarray) -> Observation:
    return Observation(t, ids, x, np.zeros(len(ids)), ranges, ANGLES, target)


@dataclass
class Run:
    """A run's record: every plan, every event, and the positions at each plan."""

    plans: list[Plan] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    positions: list[np.ndarray] = field(default_factory=list)
    x: np.ndarray | None = None

    def kinds(self, kind: str) -> list[dict]:
        return [e for e in self.events if e["kind"] == kind]


def run(
    planner: Ch5Planner,
    x0: np.ndarray,
    target: tuple[float, float],
    segs: tuple[np.ndarray, np.ndarray],
    seconds: float,
    v_max: float = 2.0,
    dt: float = 0.05,
    corrupt=None,
) -> Run:
    """Single integrators following the plan's law, re-planned every 0.25 s, until ``seconds`` or done; ``corrupt``
    (t, ids, x, ranges) -> (ids, x, ranges) changes what the planner observes."""
    out = Run()
    x = np.array(x0, float)
    ids = np.arange(len(x))
    tgt = np.array(target, float)
    every = round(planner.period_s / dt)
    plan = None
    for k in range(round(seconds / dt)):
        t = k * dt
        if k % every == 0:
            o_ids, o_x, o_r = ids, x.copy(), sonar(x, segs)
            if corrupt is not None:
                o_ids, o_x, o_r = corrupt(t, o_ids, o_x, o_r)
            plan = planner.plan(observe(t, o_ids, o_x, o_r, tgt))
            out.plans.append(plan)
            out.events += list(plan.events)
            out.positions.append(x.copy())
            if plan.done:
                break
        rows = np.searchsorted(ids, plan.ids)
        u = velocities(plan, x[rows], v_max=v_max)
        x[rows] += dt * u
    out.x = x
    return out


def block(n: int, centre: tuple[float, float], spacing: float = 2.4) -> np.ndarray:
    """``n`` agents on a square grid about ``centre``."""
    side = math.ceil(math.sqrt(n))
    g = np.array([(i % side, i // side) for i in range(n)], float) * spacing
    return g - g.mean(axis=0) + np.array(centre)


CORRIDOR = walls(
    [(8.0, 14.0), (8.0, 3.5), (22.0, 3.5), (22.0, 14.0)],
    [(8.0, -14.0), (8.0, -3.5), (22.0, -3.5), (22.0, -14.0)],
)

OPEN = walls()  # no walls


@pytest.fixture(scope="module")
def corridor() -> tuple[Ch5Planner, Run]:
    """14 agents (Table 5.1's N) from a block at the origin through a corridor 7 wide and 14 long to T = (30, 0)."""
    planner = Ch5Planner()
    return planner, run(planner, block(14, (0.0, 0.0)), (30.0, 0.0), CORRIDOR, 200.0)


def test_registered_and_parameters_checked() -> None:
    assert PLANNERS.get("ch5") is Ch5Planner
    for bad, field_name in (
        ({"assignment": "nearest"}, "assignment"),
        ({"repulsion_cutoff": -1.0}, "repulsion_cutoff"),
        ({"done_rule": "soon"}, "done_rule"),
        ({"tolerance": 0.0}, "tolerance"),
        ({"d_min": 6.0}, "d_max"),
        ({"harmonics": 0}, "harmonics"),
        ({"step_rule": "far"}, "step_rule"),
    ):
        with pytest.raises(ValueError, match=field_name):
            Ch5Params(**bad)


def test_barrier_holds_each_region_until_every_agent_is_in_its_circle() -> None:
    planner = Ch5Planner()
    r = run(planner, block(6, (0.0, 0.0), 3.0), (12.0, 0.0), OPEN, 60.0)
    assert r.plans[-1].done
    updates = [k for k, p in enumerate(r.plans) if any(e["kind"] == "region" for e in p.events)]
    assert len(updates) >= 8  # the region advanced one step (1 unit) at a time over 12 units
    for a, b in itertools.pairwise(updates):
        # the plan is held from one update to the next (B8) ...
        for k in range(a + 1, b):
            np.testing.assert_array_equal(r.plans[k].goals, r.plans[a].goals)
        # ... and the next region comes right after the release, which came when every agent was in its circle
        release = [e for e in r.plans[b].events if e["kind"] == "barrier"]
        assert release and release[0]["reason"] == "all in circles"
        d = np.hypot(*(r.positions[b] - r.plans[a].goals).T)
        assert d.max() <= 0.1 * r.plans[a].params["r_s"] + 1e-12
        assert np.hypot(*(r.positions[b - 1] - r.plans[a].goals).T).max() > 0.1 * r.plans[a].params["r_s"]
    assert planner.summary()["timeouts"] == []


def test_an_agent_that_cannot_move_holds_the_region_until_the_timeout() -> None:
    planner = Ch5Planner(timeout=10.0)
    x0 = block(6, (0.0, 0.0), 3.0)
    out = Run()
    x = x0.copy()
    ids = np.arange(6)
    for k in range(int(25 / 0.05)):
        t = k * 0.05
        if k % 5 == 0:
            plan = planner.plan(observe(t, ids, x.copy(), sonar(x, OPEN), np.array([12.0, 0.0])))
            out.plans.append(plan)
            out.events += list(plan.events)
        u = velocities(plan, x, v_max=2.0)
        u[0] = 0.0  # agent 0 is stuck
        x += 0.05 * u
    regions = out.kinds("region")
    barriers = out.kinds("barrier")
    assert [e["t"] for e in regions] == [0.0, 10.0, 20.0]  # nothing moves on while agent 0 is out of its circle
    assert [(e["t"], e["reason"], e["waiting"]) for e in barriers] == [(10.0, "timeout", [0]), (20.0, "timeout", [0])]


def test_every_packing_holds_n_non_overlapping_circles_inside_its_region(corridor: tuple[Ch5Planner, Run]) -> None:
    _, r = corridor
    checked = 0
    for plan in r.plans:
        if not any(e["kind"] == "region" for e in plan.events):
            continue
        radius = plan.params["r_s"]
        phi = Polygon(plan.regions[0].vertices).buffer(1e-7)
        goals = plan.goals
        assert len(goals) == 14  # B7: >= N circles, one per agent
        gaps = np.hypot(*(goals[:, None] - goals[None]).transpose(2, 0, 1)) + np.eye(14) * 9
        assert gaps.min() >= 2 * radius - 1e-9
        assert all(phi.contains(Point(g).buffer(radius, quad_segs=16)) for g in goals)
        checked += 1
    assert checked >= 20


def test_the_fallback_packs_what_the_lattice_cannot_in_the_corridor(corridor: tuple[Ch5Planner, Run]) -> None:
    planner, r = corridor
    events = r.kinds("region")
    short = [e for e in events if not e["lattice_holds"]]
    assert short, "the corridor never needed the fallback"
    assert all(e["method"] in ("relaxed", "shrunk") and e["circles"] >= e["n"] for e in short)
    assert all(e["lattice_count"] < e["n"] for e in short)
    assert {"lattice", "relaxed"} <= set(planner.summary()["methods"])


def test_fourteen_agents_pass_the_corridor_and_reach_the_target(corridor: tuple[Ch5Planner, Run]) -> None:
    planner, r = corridor
    s = planner.summary()
    assert r.plans[-1].done and s["done_t"] is not None and s["done_t"] < 120.0
    assert r.kinds("done") and r.kinds("done")[0]["rule"] == "region"
    assert np.hypot(*(np.array(r.kinds("region")[-1]["centre"]) - [30.0, 0.0])) <= 1.0  # the last region: at T
    assert np.hypot(*(r.x.mean(axis=0) - np.array([30.0, 0.0]))) < 2.0
    assert np.hypot(*(r.x - r.plans[-1].goals).T).max() <= 0.1
    track = np.stack([*r.positions, r.x])
    assert not crosses(track[:-1], track[1:], *CORRIDOR).any()  # no agent went through a wall
    assert s["updates"] >= 25 and len(s["arrivals"]) >= 25
    assert all(u["area"] > 0 for u in s["regions"])


def test_the_horizon_step_puts_the_region_edge_on_the_sensing_horizon() -> None:
    """``step_rule`` "horizon": the centre moves front + d_thre+ - sqrt(N r_s^2 / eta) toward T, at least ``step``."""
    x = block(14, (0.0, 0.0))
    front = float((x - x.mean(axis=0))[:, 0].max())  # T lies along +x
    planner = Ch5Planner(step_rule="horizon")
    assert planner.horizon_step(x, np.array([30.0, 0.0])) == pytest.approx(front + 5.0 - math.sqrt(14 / 0.7))
    assert planner.horizon_step(x, np.array([30.0, 0.0])) == pytest.approx(4.4707, abs=1e-4)
    assert planner.horizon_step(np.zeros((14, 2)), np.array([30.0, 0.0])) == 1.0  # never less than ``step``
    assert Ch5Planner(step_rule="horizon", step=2.0).horizon_step(np.zeros((14, 2)), np.array([9.0, 0.0])) == 2.0
    assert planner.horizon_step(x, x.mean(axis=0)) == 1.0  # at T: no direction


def test_the_horizon_rule_crosses_open_space_in_fewer_regions() -> None:
    """14 agents across open space to T = (30, 0): one region per step of 1 (43 updates) against one per sensing
    horizon (10); every release by arrival in both."""
    counts = {}
    for rule in STEP_RULES:
        planner = Ch5Planner(step_rule=rule)
        r = run(planner, block(14, (0.0, 0.0)), (30.0, 0.0), OPEN, 60.0)
        s = planner.summary()
        assert r.plans[-1].done and not s["timeouts"], rule
        assert np.hypot(*(r.x - r.plans[-1].goals).T).max() <= 0.1
        counts[rule] = s["updates"]
    assert counts["fixed"] >= 40 and counts["horizon"] <= 12


def test_same_seed_same_plans() -> None:
    a = run(Ch5Planner(seed=3), block(6, (0.0, 0.0)), (6.0, 0.0), OPEN, 10.0)
    b = run(Ch5Planner(seed=3), block(6, (0.0, 0.0)), (6.0, 0.0), OPEN, 10.0)
    assert a.events == b.events
    np.testing.assert_array_equal(a.x, b.x)


def test_the_printed_law_never_lets_the_barrier_release_by_arrival() -> None:
    planner = Ch5Planner(repulsion_cutoff=None, timeout=10.0)
    run(planner, block(6, (0.0, 0.0), 3.0), (12.0, 0.0), OPEN, 35.0)
    s = planner.summary()
    assert s["arrivals"] == [] and s["timeouts"] == [10.0, 20.0, 30.0]


# --- bad input: a logged decision, never an exception ----------------------------------------------------------------


def test_all_nan_ranges() -> None:
    for frontier in (False, True):
        planner = Ch5Planner(frontier=frontier)
        x = block(6, (0.0, 0.0))
        plan = planner.plan(observe(0.0, np.arange(6), x, np.full((6, 8), np.nan), np.array([10.0, 0.0])))
        region = plan.events[0]
        assert region["kind"] == "region" and np.isfinite(plan.goals).all()
        if not frontier:
            assert region["rule"] == "circle" and region["reason"].startswith("0 points")
        assert planner.summary()["dropped"]["no_echo"] == 48


def test_one_agents_garbage_readings_are_dropped_and_logged() -> None:
    def corrupt(t, ids, x, ranges):
        ranges = ranges.copy()
        ranges[2] = [np.inf, -1.0, 1e9, -np.inf, np.inf, -3.0, np.inf, -np.inf]
        return ids, x, ranges

    planner = Ch5Planner()
    r = run(planner, block(6, (0.0, 0.0), 3.0), (8.0, 0.0), OPEN, 40.0, corrupt=corrupt)
    flagged = [e for e in r.kinds("input") if e["reason"] == "garbage"]
    assert len(flagged) == 1 and flagged[0]["agents"] == [2] and flagged[0]["readings"] == 7
    assert r.plans[-1].done
    assert planner.summary()["dropped"]["garbage"] == 7 * len(r.plans)


def test_an_agent_missing_from_the_observation_is_not_waited_for() -> None:
    def corrupt(t, ids, x, ranges):
        if 2.0 <= t < 6.0:
            keep = ids != 4
            return ids[keep], x[keep], ranges[keep]
        return ids, x, ranges

    planner = Ch5Planner()
    r = run(planner, block(6, (0.0, 0.0), 3.0), (8.0, 0.0), OPEN, 40.0, corrupt=corrupt)
    absent = [(e["t"], e["agents"]) for e in r.kinds("input") if e["reason"] == "absent"]
    assert absent[0] == (2.0, [4])  # logged; the next region is made for the five present (then nobody is absent)
    assert all(4 not in p.ids for p in r.plans if 2.0 <= p.t < 6.0)
    during = [e for e in r.kinds("region") if 2.0 <= e["t"] < 6.0]
    assert during and all(e["n"] == 5 for e in during)
    back = [e for e in r.kinds("region") if e["t"] == 6.0]
    assert back and back[0]["why"] == "membership" and back[0]["n"] == 6  # back: re-packed into the same region
    assert r.plans[-1].done


def test_a_new_agent_gets_a_circle_in_the_same_region() -> None:
    planner = Ch5Planner()
    x = block(7, (0.0, 0.0), 3.0)
    target = np.array([10.0, 0.0])
    first = planner.plan(observe(0.0, np.arange(6), x[:6], np.full((6, 8), np.nan), target))
    second = planner.plan(observe(0.25, np.arange(7), x, np.full((7, 8), np.nan), target))
    region = [e for e in second.events if e["kind"] == "region"]
    assert region and region[0]["why"] == "membership" and region[0]["rule"] == "repack" and region[0]["n"] == 7
    np.testing.assert_array_equal(first.regions[0].vertices, second.regions[0].vertices)  # the region did not move
    assert len(np.unique(second.goals.round(9), axis=0)) == 7


def test_an_agent_without_a_position() -> None:
    planner = Ch5Planner()
    x = block(6, (0.0, 0.0), 3.0)
    x[3] = np.nan
    plan = planner.plan(observe(0.0, np.arange(6), x, np.full((6, 8), np.nan), np.array([10.0, 0.0])))
    assert [e["agents"] for e in plan.events if e["kind"] == "input" and e["reason"] == "no_pose"] == [[3]]
    assert np.isfinite(plan.goals).all() and plan.events[-1]["n"] == 5


SLOT = walls(
    [(0.0, 10.0), (0.0, 0.9), (20.0, 0.9)], [(0.0, -10.0), (0.0, -0.9), (20.0, -0.9)]
)  # a passage 1.8 wide: not one circle of r_s = 1 fits


def test_a_region_too_small_for_the_swarm_is_a_logged_decision() -> None:
    # inside the slot from the start: nothing feasible ever, every agent holds where it is, retried every retry_s;
    # r_robot 0.95: the circles may not shrink below the robots
    x = np.array([[2.0, 0.0], [4.0, 0.0], [6.0, 0.0]])
    for fallback, decisions in (
        ("keep", ["hold where they are"]),
        ("circle", ["circle rule", "hold where they are"]),
    ):
        planner = Ch5Planner(fallback=fallback, r_robot=0.95)
        r = run(planner, x, (30.0, 0.0), SLOT, 12.0)
        bad = r.kinds("infeasible")
        assert [(e["t"], e["decision"]) for e in bad] == [(t, d) for t in (0.0, 5.0, 10.0) for d in decisions]
        assert bad[0]["why_not"] == "the packing failed (0 circles for 3)" and bad[0]["rule"] == "efa_disc"
        assert r.kinds("region") == [] and all(np.isfinite(p.goals).all() for p in r.plans)
        np.testing.assert_allclose(r.x, x)
    # a feasible plan first (open space), then the agents are observed inside the slot (the barrier's timeout
    # releases it): the last plan is kept
    planner = Ch5Planner(fallback="keep", r_robot=0.95, timeout=0.25)
    target = np.array([30.0, 0.0])
    first = planner.plan(observe(0.0, np.arange(3), x - [20.0, 0.0], np.full((3, 8), np.nan), target))
    assert first.events[0]["kind"] == "region"
    second = planner.plan(observe(0.25, np.arange(3), first.goals, np.full((3, 8), np.nan), target))
    assert [e["kind"] for e in second.events] == ["barrier", "region"]
    inside = planner.plan(observe(0.5, np.arange(3), x, sonar(x, SLOT), target))
    assert [(e["kind"], e.get("decision"), e.get("kept")) for e in inside.events] == [
        ("barrier", None, None),
        ("infeasible", "last plan", 0.25),
    ]
    np.testing.assert_array_equal(inside.goals, second.goals)
    np.testing.assert_array_equal(inside.regions[0].vertices, second.regions[0].vertices)
    assert planner.summary()["updates"] == 2


def test_no_agent_at_all() -> None:
    plan = Ch5Planner().plan(observe(0.0, np.zeros(0, int), np.zeros((0, 2)), np.zeros((0, 8)), np.zeros(2)))
    assert plan.events[0]["kind"] == "held" and plan.goals.shape == (0, 2)


def test_no_agent_with_a_position() -> None:
    planner = Ch5Planner()
    x = np.full((3, 2), np.nan)
    for t in (0.0, 0.25):
        plan = planner.plan(observe(t, np.arange(3), x, np.full((3, 8), 2.0), np.array([10.0, 0.0])))
        assert np.isfinite(plan.goals).all() and not [e for e in plan.events if e["kind"] == "region"]
    assert planner.summary()["updates"] == 0 and planner.summary()["dropped"]["garbage"] == 48
