"""The robots' side of a region controller: a plan over the SonPI's wire and back, a plan cut to the agents a robot
can place (the law unchanged for them), and why a robot holds still."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from swarm_logic.behaviours import load_behaviour
from swarm_logic.families.roy.regions.agent import RegionAgent, from_packet, restrict, to_packet, window_ranges
from swarm_logic.families.roy.regions.formation import DELTA_TRI, desired_distances
from swarm_logic.families.roy.regions.planner import Plan, velocities
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.interfaces import SonarReading
from swarm_logic.robots.sonpi.wifi import PlanOrder

X = np.array([[0.0, 0.0], [3.0, 0.5], [1.0, 4.0], [6.0, 6.0], [2.0, 2.5], [5.0, 1.0]])


def _plan() -> Plan:
    return Plan(
        12.5,
        np.array([3, 5, 8, 9, 11, 12]),
        np.tile([4.0, 3.0], (6, 1)) + np.arange(6)[:, None] * 0.25,
        "formation",
        {"desired": desired_distances(DELTA_TRI, 2.0), "k_c": 3.0, "k_f": 5.0, "safety": {"r_robot": 0.9}},
        groups=np.array([0, 0, 0, 1, 1, 1]),
        leaders=(5, 11),
        done=True,
    )


def test_a_plan_crosses_the_wire_unchanged() -> None:
    plan = _plan()
    head, packet = pp.decode(pp.encode_plan(4, plan.t, to_packet(plan, 0.1)))
    got = from_packet(packet, head.t_s)
    assert got.t == 12.5 and got.law == "formation" and got.done and got.leaders == (5, 11)
    assert got.ids.tolist() == plan.ids.tolist() and got.groups.tolist() == plan.groups.tolist()
    assert np.allclose(got.goals, plan.goals) and packet.unit_m == pytest.approx(0.1)
    assert np.array_equal(np.array(got.params["desired"]), plan.params["desired"])
    assert np.allclose(velocities(got, X, v_max=1.5), velocities(plan, X, v_max=1.5), atol=1e-5)


def test_a_plan_cut_to_the_agents_a_robot_sees_is_the_law_for_them() -> None:
    plan = _plan()
    keep = np.array([True, True, False, True, True, True])
    cut = restrict(plan, keep)
    assert cut.ids.tolist() == [3, 5, 9, 11, 12] and cut.leaders == (5, 11) and cut.groups.tolist() == [0, 0, 1, 1, 1]
    d = desired_distances(DELTA_TRI, 2.0)[np.ix_(keep, keep)]
    direct = Plan(plan.t, plan.ids[keep], plan.goals[keep], "formation", {**plan.params, "desired": d})
    assert np.array_equal(velocities(cut, X[keep], v_max=1.5), velocities(direct, X[keep], v_max=1.5))
    # agent 8 gone: its two neighbours lose its repulsion, so their velocities differ from the full plan's
    full = velocities(plan, X, v_max=None)[keep]
    assert not np.allclose(velocities(cut, X[keep]), full)


def _agent(order_at: float) -> RegionAgent:
    a = RegionAgent()
    a.robot = SimpleNamespace(id=5)
    a.p = RegionAgent.with_defaults({})
    a.order_at = order_at
    return a


@pytest.mark.parametrize(
    "order, me, now, reason",
    [
        (None, object(), 1.0, "no_plan"),
        ("plan", object(), 2.1, "stale_plan"),
        ("plan", None, 1.5, "no_pose"),
        ("other", object(), 1.5, "not_in_plan"),
        ("metres", object(), 1.5, "unit"),
        ("plan", object(), 1.5, None),
    ],
)
def test_why_a_robot_holds(order: str | None, me: object, now: float, reason: str | None) -> None:
    plan = to_packet(_plan(), 1.0 if order == "metres" else 0.1)
    if order == "other":
        plan = to_packet(restrict(_plan(), _plan().ids != 5), 0.1)
    a = _agent(order_at=1.0)
    assert a.why_hold(now, None if order is None else PlanOrder(plan, 1.0), me) == reason


def test_the_behaviour_is_registered() -> None:
    assert load_behaviour("roy_region") is RegionAgent
    with pytest.raises(ValueError, match="stale_s"):
        RegionAgent.with_defaults({"stale_s": 0})


def test_a_window_carries_what_the_wire_can_and_no_reading_for_the_rest() -> None:
    readings = [SonarReading(r, 0.0) for r in (0.5, math.inf, math.nan, -0.2, 80.0, 4.0)]
    ranges, bad = window_ranges(readings)
    assert ranges == [0.5, math.inf, None, None, None, 4.0] and bad == 3
    data = pp.encode_sonar(0, 1.0, pp.SonarWindow(2, tuple(ranges)))
    assert pp.decode(data)[1].ranges_m == (0.5, math.inf, None, None, None, 4.0)


def test_a_robot_turns_in_place_toward_the_plans_face_heading_and_then_follows_the_law() -> None:
    sent: list[tuple[float, float]] = []
    a = RegionAgent()
    a.p = RegionAgent.with_defaults({"face_tol_deg": 45})
    a.velocity = SimpleNamespace(set_velocity=lambda vx, vy: sent.append((vx, vy)))
    a.reset()
    plan = Plan(0.0, np.array([1]), np.zeros((1, 2)), "split_merge", {"k_c": 3.0}, face=0.0)
    # facing back (pi): the point ahead goes across the heading, a pure turn (the forward component is 0)
    assert a.face(plan, math.pi) and a.turning and a.turns == 1
    (vx, vy) = sent[-1]
    assert math.isclose(vx * math.cos(math.pi) + vy * math.sin(math.pi), 0.0, abs_tol=1e-12)
    assert math.isclose(math.hypot(vx, vy), 0.05)
    # it keeps turning until within a third of the tolerance (15 degrees), the same turn counted once
    assert a.face(plan, math.radians(30)) and a.turns == 1
    assert not a.face(plan, math.radians(10)) and not a.turning
    # within the tolerance it follows the law; a turn of 50 degrees starts another turn, toward the heading (right)
    assert not a.face(plan, math.radians(40))
    assert a.face(plan, math.radians(50)) and a.turns == 2
    vx, vy = sent[-1]
    yaw = math.radians(50)
    assert -vx * math.sin(yaw) + vy * math.cos(yaw) < 0  # clockwise: the across-heading component points right
    # no heading in the plan, or face_tol_deg 0 (the default): never
    a.turning = False
    assert not a.face(Plan(0.0, np.array([1]), np.zeros((1, 2)), "split_merge", {"k_c": 3.0}), math.pi)
    a.p = RegionAgent.with_defaults({})
    assert not a.face(plan, math.pi) and a.turns == 2
    # the laws never see it; a heading that is not one is refused
    with pytest.raises(ValueError, match="face: a heading must be finite"):
        Plan(0.0, np.array([1]), np.zeros((1, 2)), "split_merge", {}, face=math.nan)
    assert np.array_equal(
        velocities(plan, np.array([[1.0, 2.0]])),
        velocities(Plan(0.0, np.array([1]), np.zeros((1, 2)), "split_merge", {"k_c": 3.0}), np.array([[1.0, 2.0]])),
    )
