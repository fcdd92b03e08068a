"""The baselines' planners on small hand cases: the aggregation baseline's goals and velocities (each agent from its
own neighbourhood only), the vision leader-follower's chain, camera and route, and chapter 4's planner paced by its
host (cycle, latency, one region step per update)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_logic.families.roy.regions.baselines import (
    AggregationPlanner,
    HostedCh4Params,
    HostedCh4Planner,
    VisionLeaderFollowerPlanner,
    chain_order,
    in_view,
    local_centroids,
    toward,
)
from swarm_logic.families.roy.regions.ch4 import Ch4Planner
from swarm_logic.families.roy.regions.planner import PLANNERS, Observation, Plan, velocities


def obs(t: float, x: list[list[float]], target: tuple[float, float], heads: list[float] | None = None) -> Observation:
    n = len(x)
    return Observation(
        t,
        np.arange(n),
        np.asarray(x, float),
        np.zeros(n) if heads is None else np.asarray(heads, float),
        np.full((n, 8), np.nan),
        np.arange(8) * math.pi / 4,
        np.asarray(target, float),
    )


def test_the_planners_are_registered() -> None:
    assert PLANNERS.get("aggregation") is AggregationPlanner
    assert PLANNERS.get("vision_lf") is VisionLeaderFollowerPlanner
    assert PLANNERS.get("ch4_hosted") is HostedCh4Planner


def test_toward_sets_the_pull_to_the_speed_or_the_point_itself() -> None:
    g = toward(np.array([[0.0, 0.0], [0.0, 0.0]]), np.array([[10.0, 0.0], [0.2, 0.0]]), 0.3, 0.5)
    assert g[0] == pytest.approx([0.6, 0.0])  # -k_c (x - g) = 0.3 along the way
    assert g[1] == pytest.approx([0.2, 0.0])  # nearer than 0.6: the point itself


def test_local_centroids_see_only_teammates_in_range() -> None:
    c, k = local_centroids(np.array([[0.0, 0.0], [1.0, 0.0], [10.0, 0.0], [1.0, 1.0]]), 2.0)
    assert k.tolist() == [2, 2, 0, 2]
    assert c[0] == pytest.approx([1.0, 0.5]) and c[1] == pytest.approx([0.5, 0.5])
    assert c[2] == pytest.approx([10.0, 0.0])  # alone: its own position (no pull)


def test_aggregation_goals_and_velocities_on_two_agents() -> None:
    p = AggregationPlanner(v_max=0.3, goal_speed=0.8, cohesion=0.2, k_c=0.5, k_f=1.0, r_s=0.606)
    plan = p.plan(obs(0.0, [[0.0, 0.0], [1.0, 0.0]], (10.0, 0.0)))
    # agent 0: 0.24 toward T + 0.2 toward its teammate = 0.44, capped at 0.3; agent 1: 0.24 - 0.2 = 0.04
    assert plan.goals[0] == pytest.approx([0.6, 0.0]) and plan.goals[1] == pytest.approx([1.08, 0.0])
    assert plan.law == "split_merge" and plan.regions == () and not plan.done
    u = velocities(plan, np.array([[0.0, 0.0], [1.0, 0.0]]), None, 0.3)
    rep = 1.0 * math.exp(-1.0 / 0.606)  # eq. 6.5's kernel at 1 unit: 0.192
    assert u[0] == pytest.approx([0.3 - rep, 0.0]) and u[1] == pytest.approx([0.04 + rep, 0.0])


def test_aggregation_uses_no_communication() -> None:
    """Moving an agent beyond agent 0's sensing range changes nothing of agent 0's goal; within it, it does."""
    p = AggregationPlanner(sense_range=5.0)
    a = p.plan(obs(0.0, [[0.0, 0.0], [1.0, 0.0], [20.0, 5.0]], (30.0, 0.0))).goals[0]
    b = p.plan(obs(0.0, [[0.0, 0.0], [1.0, 0.0], [20.0, -9.0]], (30.0, 0.0))).goals[0]
    c = p.plan(obs(0.0, [[0.0, 0.0], [1.0, 0.0], [3.0, 3.0]], (30.0, 0.0))).goals[0]
    assert a == pytest.approx(b) and not np.allclose(a, c)
    assert p.summary()["alone"] == 2  # the far agent, in the first two plans


def test_aggregation_holds_the_target_and_drops_garbage() -> None:
    p = AggregationPlanner()
    plan = p.plan(obs(0.0, [[10.0, 0.1], [math.nan, 0.0]], (10.0, 0.0)))
    assert plan.goals[0] == pytest.approx([10.0, 0.0])  # within one period's reach: the target itself
    assert plan.events == ({"kind": "input", "dropped": 1, "reason": "garbage"},)
    assert np.isfinite(plan.goals).all()
    with pytest.raises(ValueError, match="goal_speed: must be at most 1"):
        AggregationPlanner(goal_speed=1.5)


def test_chain_order_and_the_camera() -> None:
    x = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [5.0, 0.0]])
    assert chain_order(x, np.array([10.0, 0.0])).tolist() == [3, 2, 1, 0]
    cam = np.zeros((3, 2))
    seen = in_view(cam, np.zeros(3), np.array([[2.0, 0.5], [2.0, 2.0], [4.0, 0.0]]), 3.0, math.radians(62))
    assert seen.tolist() == [True, False, False]  # 14 deg off: seen; 45 deg: out of the 31 deg half-view; 4 > 3


def test_vision_leader_follower_chain_route_lost_and_home() -> None:
    p = VisionLeaderFollowerPlanner(route=[[5.0, 0.0]], v_max=0.3, leader_speed=0.8, k_c=0.5, camera_range=3.0)
    line = [[0.0, 0.0], [-1.0, 0.0], [-2.0, 0.0]]
    plan = p.plan(obs(0.0, line, (10.0, 0.0)))
    assert plan.leaders == (0,) and plan.events[0] == {"kind": "chain", "leader": 0, "order": [0, 1, 2]}
    assert plan.goals[0] == pytest.approx([0.48, 0.0])  # 0.24 toward the waypoint through the k_c = 0.5 pull
    assert plan.goals[1] == pytest.approx([-1.0, 0.0]) and plan.goals[2] == pytest.approx([-2.0, 0.0])  # in place
    # the leader 4 units ahead: follower 1 loses it and heads for where it saw it last, 1 unit behind
    plan = p.plan(obs(0.25, [[3.0, 0.0], [-1.0, 0.0], [-2.0, 0.0]], (10.0, 0.0)))
    assert {"kind": "lost", "agent": 1} in plan.events and plan.goals[1] == pytest.approx([-1.0, 0.0])
    plan = p.plan(obs(0.5, [[2.0, 0.0], [-0.5, 0.0], [-2.0, 0.0]], (10.0, 0.0)))
    assert {"kind": "found", "agent": 1} in plan.events  # 2.5 ahead, where its camera looks
    assert plan.goals[1] == pytest.approx([0.1, 0.0])  # toward 1.0 = 2 - 1, at most 0.3 / 0.5 away
    plan = p.plan(obs(0.75, [[5.2, 0.0], [4.0, 0.0], [3.0, 0.0]], (10.0, 0.0)))
    assert {"kind": "waypoint", "index": 1} in plan.events  # past (5, 0): the target is next
    plan = p.plan(obs(1.0, [[10.0, 0.0], [9.0, 0.5], [4.0, 0.0]], (10.0, 0.0)))
    home = [9.0 + 0.6 / math.sqrt(1.25), 0.5 - 0.3 / math.sqrt(1.25)]
    assert plan.goals[1] == pytest.approx(home)  # its predecessor is home: home too, 0.6 along the way
    plan = p.plan(obs(1.25, [[10.0, 0.0], [9.5, 0.5], [9.0, -0.5]], (10.0, 0.0)))
    assert {"kind": "home", "t": 1.25} in plan.events and p.summary()["home_t"] == 1.25


def test_the_host_cycle_with_the_thesis_figures() -> None:
    pc = HostedCh4Params(host="pc")
    assert pc.cycle_s(6) == pytest.approx(0.30)  # 250 ms window + 50 ms k-means (§7.4.1)
    assert pc.cycle_s(50) == pytest.approx(0.25 + 50 * 0.05 / 6)
    assert HostedCh4Params(host="rpi").cycle_s(6) == pytest.approx(0.25 + 4 * 0.05)
    with pytest.raises(ValueError, match="host: expected one of pc, rpi"):
        HostedCh4Params(host="cloud")
    with pytest.raises(ValueError, match="rpi_factor: must be >= 1"):
        HostedCh4Params(rpi_factor=0.5)


@pytest.mark.parametrize(("host", "starts"), [("pc", [0.0, 0.3, 0.6, 0.9]), ("rpi", [0.0, 0.45, 0.9])])
def test_the_hosted_planner_updates_at_its_pace_and_publishes_a_cycle_late(host: str, starts: list[float]) -> None:
    ring = [[1.0 * math.cos(a), 1.0 * math.sin(a)] for a in np.arange(6) * math.pi / 3]
    p = HostedCh4Planner(host=host, r_c=2.5, centre0=[0.0, 0.0], v_max=0.3)
    assert p.period_s == pytest.approx(0.05)
    plans = [p.plan(obs(round(k * 0.05, 2), ring, (30.0, 0.0))) for k in range(20)]
    assert p.updates == len(starts) and p.summary()["host"] == host
    centres = [round(pl.regions[0].ellipse.x, 9) for pl in plans]
    # the first plan is published at once; each later one when the next update starts (a cycle late)
    changes = [round(k * 0.05, 2) for k in range(1, 20) if centres[k] != centres[k - 1]]
    assert changes == starts[2:]
    step = centres[-1] - centres[0]
    assert step == pytest.approx((len(starts) - 2) * 0.8 * 0.3 * 0.25, rel=1e-6)  # one 0.25-s region step each


def test_each_published_plan_carries_its_events_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """An update's events go out with its plan, when it is published (a cycle late), and once."""

    def marked(self: Ch4Planner, o: Observation) -> Plan:
        return Plan(o.t, np.arange(6), np.zeros((6, 2)), "split_merge", events=({"kind": "mark", "t": o.t},))

    monkeypatch.setattr(Ch4Planner, "plan", marked)
    p = HostedCh4Planner(host="pc", window_s=0.25, compute_s_per_agent=0.0)  # a 0.25-s cycle
    seen = []
    for k in range(20):
        pl = p.plan(obs(round(k * 0.05, 2), [[0.0, 0.0]] * 6, (30.0, 0.0)))
        seen += [(pl.t, e["t"]) for e in pl.events]
    assert seen == [(0.0, 0.0), (0.5, 0.25), (0.75, 0.5)]  # the first at once; then each update's a cycle late
