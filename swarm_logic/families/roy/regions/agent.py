"""``RegionAgent`` (behaviour ``roy_region``): a SonPI following a region controller's plans (Roy 2022 chapters
4-6, the robots' side). Every ``sonar_period_s`` it sends its sonar window to the controller; every step it applies
the latest plan's law to its own row, with the overhead camera's broadcast poses of the plan's other agents and its
own sonar points, in the plan's units, and commands that velocity through the tracking layer.

It holds still, logging why (topic ``hold``, once per change of reason), when it has no plan, when the plan is older
than ``stale_s`` (by its own clock since it arrived), when it has no pose, when the plan does not name it, when
the plan's length unit is not its own ``unit_m`` (no guess at a conversion), or when the plan's law refuses the plan's
parameters (``bad_plan``: a datagram that decodes but names parameters its law does not take, or values it cannot
use; checked once per plan, ``plan_error``, the error logged under topic ``bad_plan``), so no datagram stops the
robot's program.

When the plan names a heading to face (``Plan.face``: chapter 6's region held before a wall) and ``face_tol_deg``
is above 0, a robot turned more than that from it turns in place toward it (its point ahead sent across its heading:
the tracking layer then turns the body about its axle), until within a third of it, and only then follows the law
again: its fixed front sonars look at the wall instead of at its teammates.

The plan's rows of agents the camera does not see this step are left out of the law (``restrict``): the law acts on
the agents this robot can place. ``to_packet`` and ``from_packet`` carry a ``Plan`` over the SonPI's wire.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from swarm_logic.families.roy.controller import POS, SonpiAgent
from swarm_logic.families.roy.regions.planner import Plan, velocities
from swarm_logic.families.roy.regions.sensing import SensingParams, sense
from swarm_logic.log import plain
from swarm_logic.robot import Robot
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.interfaces import SonarReading
from swarm_logic.robots.sonpi.wifi import PLAN, PlanOrder

HOLD_REASONS = ("no_plan", "stale_plan", "no_pose", "not_in_plan", "unit", "bad_plan")


def to_packet(plan: Plan, unit_m: float) -> pp.PlanPacket:
    """A plan as the wire carries it (its lengths in units of ``unit_m`` m)."""
    leaders = set(plan.leaders)
    groups = [None] * len(plan.ids) if plan.groups is None else [int(g) for g in plan.groups]
    agents = tuple(
        pp.PlanAgent(int(i), g, int(i) in leaders, float(x), float(y))
        for i, g, (x, y) in zip(plan.ids, groups, np.asarray(plan.goals, float), strict=True)
    )
    return pp.PlanPacket(agents, plan.law, plain(dict(plan.params)), unit_m, plan.done, plan.face)


def from_packet(packet: pp.PlanPacket, t: float) -> Plan:
    """The plan a packet carries, stamped ``t``."""
    a = packet.agents
    groups = None if all(x.group is None for x in a) else np.array([-1 if x.group is None else x.group for x in a])
    return Plan(
        t,
        np.array([x.id for x in a], int),
        np.array([[x.goal_x, x.goal_y] for x in a], float).reshape(-1, 2),
        packet.law,
        dict(packet.params),
        groups=groups,
        leaders=tuple(x.id for x in a if x.leader),
        done=packet.done,
        face=packet.face_rad,
    )


def plan_error(packet: pp.PlanPacket) -> str | None:
    """Why a robot cannot follow the plan ``packet`` carries (its law refuses the plan's parameters: missing, unknown,
    of the wrong type or shape), or None: the plan, cut as a robot cuts it, with its law run once at its goals."""
    try:
        plan = restrict(from_packet(packet, 0.0), np.ones(len(packet.agents), bool))
        with np.errstate(all="ignore"):  # agents sharing a goal are at distance 0 here: only a refusal counts
            velocities(plan, np.asarray(plan.goals, float))
    except (TypeError, ValueError, IndexError, KeyError, ArithmeticError) as e:
        return f"{type(e).__name__}: {e}"[:300]
    return None


def window_ranges(readings: list[SonarReading]) -> tuple[list[float | None], int]:
    """A window's ranges as the wire carries them (m; ``inf`` no echo) and how many readings it could not carry (not
    finite, negative or beyond its 65.533 m), which go as "no reading" (None)."""
    out: list[float | None] = []
    for r in readings:
        ok = r.range_m == math.inf or (math.isfinite(r.range_m) and 0 <= r.range_m <= pp.MAX_RANGE_MM / 1000)
        out.append(r.range_m if ok else None)
    return out, sum(x is None for x in out)


def _square(v: Any, n: int) -> bool:
    return isinstance(v, (list, tuple, np.ndarray)) and np.shape(v) == (n, n)


def restrict(plan: Plan, keep: np.ndarray) -> Plan:
    """The plan for its agents where ``keep`` (N,) is true: their rows, and every N x N parameter (the formation's
    desired distances) cut to them."""
    keep = np.asarray(keep, bool)
    n = len(plan.ids)
    params = {
        k: np.asarray(v, float)[np.ix_(keep, keep)].tolist() if _square(v, n) else v for k, v in plan.params.items()
    }
    return Plan(
        plan.t,
        plan.ids[keep],
        np.asarray(plan.goals)[keep],
        plan.law,
        params,
        groups=None if plan.groups is None else np.asarray(plan.groups)[keep],
        leaders=tuple(i for i in plan.leaders if i in set(plan.ids[keep].tolist())),
        done=plan.done,
        face=plan.face,
    )


class RegionAgent(SonpiAgent):
    """A SonPI applying the region controller's plan to itself (see the module)."""

    period_s = 0.05
    defaults: ClassVar[dict[str, Any]] = {
        "period_s": 0.05,  # the control step, s (the tracking layer's set-point rate)
        "unit_m": 0.1,  # digest §5.4: 1 unit = 0.1 m; a plan in another unit is not applied
        "v_max": 1.5,  # units/s: 0.15 m/s, the speed chapter 3's SonPI sessions use
        "sonar_period_s": 0.25,  # the thesis' 250 ms windows
        "stale_s": 1.0,  # a plan this old (since it arrived) is not applied
        "d_max": 5.0,  # units: sonar points beyond this are not obstacles (chapter 4's cap, SensingParams)
        "face_tol_deg": 0.0,  # turn toward the plan's face heading when more than this off it (0: never)
        "turn_mps": 0.05,  # the point ahead's speed across the heading while turning (0.1 m ahead: 0.5 rad/s)
    }
    ranges: ClassVar[dict[str, str]] = {
        "period_s": "(0, 10]",
        "unit_m": POS,
        "v_max": POS,
        "sonar_period_s": "(0, 60]",
        "stale_s": POS,
        "d_max": POS,
        "face_tol_deg": "[0, 180]",
        "turn_mps": POS,
    }

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.bind(robot, self.resolve(robot.params))
        self.plan_face = robot.device(PLAN)
        self.reset()

    def reset(self) -> None:
        self.order: PlanOrder | None = None
        self.order_at = 0.0
        self.next_sonar = 0.0
        self.reason: str | None = "start"
        self.holds = dict.fromkeys(HOLD_REASONS, 0)
        self.applied = 0
        self.missing_rows = 0  # plan agents left out of the law: the camera had no pose for them
        self.bad_readings = 0  # sonar readings sent as "no reading" (not finite, negative, beyond the wire's range)
        self.v = np.zeros(2)
        self.turning = False
        self.turns = 0  # turns toward the plan's face heading begun
        self.checked: PlanOrder | None = None  # the last plan checked (plan_error), and what was wrong with it
        self.check_error: str | None = None

    def face(self, plan: Plan, yaw: float) -> bool:
        """Whether to turn in place toward the plan's face heading this step (and, if so, the command sent)."""
        tol = math.radians(float(self.p["face_tol_deg"]))
        want = plan.face
        if tol <= 0 or want is None:
            self.turning = False
            return False
        err = math.atan2(math.sin(want - yaw), math.cos(want - yaw))
        if not self.turning and abs(err) > tol:
            self.turning = True
            self.turns += 1
        elif self.turning and abs(err) < tol / 3:
            self.turning = False
        if not self.turning:
            return False
        u = math.copysign(float(self.p["turn_mps"]), err)  # across the heading: a pure turn about the axle
        self.v = np.zeros(2)
        self.velocity.set_velocity(-u * math.sin(yaw), u * math.cos(yaw))
        return True

    def send_window(self, now: float) -> None:
        """The latest sonar window to the controller, every ``sonar_period_s``."""
        if now < self.next_sonar:
            return
        p = float(self.p["sonar_period_s"])
        self.next_sonar = self.next_sonar + p if now - self.next_sonar < p else now + p
        ranges, bad = window_ranges(self.sonar.readings())
        self.bad_readings += bad
        self.plan_face.send_sonar(now, ranges)

    def why_hold(self, now: float, order: PlanOrder | None, me: Any) -> str | None:
        if order is None:
            return "no_plan"
        if now - self.order_at > float(self.p["stale_s"]):
            return "stale_plan"
        if me is None:
            return "no_pose"
        if self.robot.id not in {a.id for a in order.plan.agents}:
            return "not_in_plan"
        unit = float(self.p["unit_m"])
        if not math.isclose(order.plan.unit_m, unit, rel_tol=1e-6):
            return "unit"
        return None

    def hold_for(self, reason: str, now: float, order: PlanOrder | None) -> None:
        self.holds[reason] += 1
        self.v = np.zeros(2)
        self.hold()
        if reason != self.reason:
            detail: dict[str, Any] = {"reason": reason, "t": now}
            if order is not None:
                detail["plan_t"] = order.t_s
                detail["plan_age_s"] = now - self.order_at
                detail["plan_unit_m"] = order.plan.unit_m
            self.robot.log("hold", **detail)
            self.reason = reason

    def bad_plan(self, now: float, order: PlanOrder) -> bool:
        """Whether the robot cannot follow ``order``'s plan (``plan_error``), checked once per plan; logged once."""
        if order is not self.checked:
            self.checked, self.check_error = order, plan_error(order.plan)
            if self.check_error is not None:
                self.robot.log("bad_plan", t=now, plan_t=order.t_s, law=order.plan.law, error=self.check_error)
        return self.check_error is not None

    def step(self) -> None:
        now = self.robot.clock.now()
        me = self.read_pose()
        self.send_window(now)
        order = self.plan_face.read()
        if order is not self.order:
            self.order, self.order_at = order, now
        reason = self.why_hold(now, order, me)
        if reason is None and order is not None and self.bad_plan(now, order):
            reason = "bad_plan"
        if reason is not None:
            self.hold_for(reason, now, order)
            return
        assert order is not None and me is not None
        if self.reason is not None:
            self.robot.log("follow", t=now, plan_t=order.t_s, law=order.plan.law, previous=self.reason)
            self.reason = None
        unit = float(self.p["unit_m"])
        plan = from_packet(order.plan, order.t_s)
        if self.face(plan, me.yaw_rad):
            return
        seen = {q.id: q for q in self.localisation.poses()}
        seen[self.robot.id] = me
        keep = np.array([int(i) in seen for i in plan.ids])
        self.missing_rows += int((~keep).sum())
        plan = restrict(plan, keep)
        x = np.array([[seen[int(i)].x_m, seen[int(i)].y_m] for i in plan.ids], float) / unit
        row = int(np.flatnonzero(plan.ids == self.robot.id)[0])
        readings = self.sonar.readings()
        ranges = np.full((len(x), len(readings)), np.nan)
        ranges[row] = [r.range_m / unit if math.isfinite(r.range_m) else np.nan for r in readings]
        headings = np.zeros(len(x))
        headings[row] = me.yaw_rad
        angles = np.array([r.angle_rad for r in readings], float)
        points = sense(x, headings, ranges, angles, SensingParams(d_max=float(self.p["d_max"]))).points
        v = velocities(plan, x, points, float(self.p["v_max"]))[row]
        self.v = v
        self.applied += 1
        self.velocity.set_velocity(float(v[0]) * unit, float(v[1]) * unit)

    def telemetry(self) -> dict[str, float | int]:
        return {
            "vx": float(self.v[0]),
            "vy": float(self.v[1]),
            "holding": HOLD_REASONS.index(self.reason) if self.reason in HOLD_REASONS else -1,
            "applied": self.applied,
            "turns": self.turns,
            "pose_src": self.pose_code(),
        }
