"""``CircleGathering`` (behaviour ``roy_gathering``): the circle-based gathering baseline chapter 3 (Table 3.6) and
chapter 7 (Table 7.4) compare BAT against (Sharma, Busch, Mukhopadhyay and Malveaux, "Tight analysis of a
collisionless robot gathering algorithm", ACM TAAS 12(1), 2017), as a navigation controller on the SonPI's devices.

The thesis says of it only that "the circular structure always sustains rigidity" (low formation error, slow) and
that it "often fails to reach the goal" in narrow passages. Our reading [R], in the same units and devices as
``RoyApf``:

- the gathering point is Sharma et al.'s: the centre c of the smallest circle enclosing the robots' start positions;
- every robot owns a slot on concentric circles about c, 2 r_s apart (the inner circle of radius 2 r_s holds 6
  robots, the k-th 6k), filled from the inside out, robots ranked by distance to c then bearing (each robot ranks
  all from the same broadcast poses, so they agree); with ``ring_spacing`` > 0 a swarm of at most 6 sits on one
  circle whose neighbours are ``ring_spacing`` r_s apart (a larger one on circles that far apart);
- the formation advances in synchronous rounds (Look-Compute-Move): c moves ``v_max`` dt towards T only in a step
  in which every robot is within ``slot_tol`` r_s of its slot, so the circle stays rigid and waits for the last;
- each robot follows its slot as a double integrator: u = k_p (slot - x) - k_d v + k_OA u^OA (eq. 3.21's bounded
  reading), its command v + u dt saturated at ``v_max`` (``tracking = "double_integrator"``, the thesis' point agents
  of chapter 3), or, on a robot body that tracks a velocity command (``tracking = "velocity"``), by the velocity
  k_p (slot - x) + k_OA u^OA saturated at ``v_max``: a differential-drive SonPI integrating the first law from its
  measured velocity overshoots its slot by tens of centimetres (it must turn about to come back) and the circle,
  waiting for every robot to be in place, never moves.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from swarm_logic.families.roy import potential
from swarm_logic.families.roy.controller import RoyApf, SonpiAgent
from swarm_logic.robot import Robot

TRACKING = ("double_integrator", "velocity")


def enclosing_circle(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The smallest circle enclosing ``points`` (n, 2): its centre and radius (Welzl's incremental construction in
    the points' order, deterministic)."""
    p = [np.asarray(q, float) for q in points]

    def two(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
        c = (a + b) / 2
        return c, float(np.hypot(*(a - c)))

    def three(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float]:
        d = 2 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        if abs(d) < 1e-12:  # collinear: the widest pair
            return max((two(a, b), two(a, c), two(b, c)), key=lambda t: t[1])
        sa, sb, sc = a @ a, b @ b, c @ c
        o = np.array([sa * (b[1] - c[1]) + sb * (c[1] - a[1]) + sc * (a[1] - b[1]),
                      sa * (c[0] - b[0]) + sb * (a[0] - c[0]) + sc * (b[0] - a[0])]) / d
        return o, float(np.hypot(*(a - o)))

    def inside(c: tuple[np.ndarray, float], q: np.ndarray) -> bool:
        return float(np.hypot(*(q - c[0]))) <= c[1] + 1e-9

    circle = (p[0], 0.0)
    for i in range(1, len(p)):
        if inside(circle, p[i]):
            continue
        circle = (p[i], 0.0)
        for j in range(i):
            if inside(circle, p[j]):
                continue
            circle = two(p[i], p[j])
            for k in range(j):
                if not inside(circle, p[k]):
                    circle = three(p[i], p[j], p[k])
    return circle


def ring_slots(n: int, r_s: float, spacing: float = 0.0) -> np.ndarray:
    """Offsets (n, 2) of n slots on concentric circles 2 r_s apart, the k-th holding up to 6k, filled inside out,
    each circle's robots evenly spaced. ``spacing`` > 0 (x r_s): a swarm of at most 6 on one circle whose neighbours
    are that far apart (one robot at the centre), a larger one on circles that far apart."""
    if spacing > 0 and n <= 6:
        r = 0.0 if n <= 1 else spacing * r_s / (2 * math.sin(math.pi / n))
        return np.array([(r * math.cos(2 * math.pi * j / n), r * math.sin(2 * math.pi * j / n)) for j in range(n)],
                        float).reshape(n, 2)
    step = (spacing if spacing > 0 else 2.0) * r_s
    out: list[tuple[float, float]] = []
    k = 1
    while len(out) < n:
        m = min(6 * k, n - len(out))
        r = step * k
        out += [(r * math.cos(2 * math.pi * j / m), r * math.sin(2 * math.pi * j / m)) for j in range(m)]
        k += 1
    return np.array(out, float).reshape(n, 2)


class CircleGathering(SonpiAgent):
    """Circle-based gathering as a rigid formation marched to the target (our reading of Sharma et al. 2017)."""

    period_s = 0.05
    defaults: ClassVar[dict[str, Any]] = {
        "period_s": 0.05,
        "unit_m": 0.1,
        "r_s": 1.0,
        "target_x": 35.0,
        "target_y": 35.0,
        "v_max": RoyApf.defaults["v_max"],  # the same calibrated speed as RoyApf
        "k_p": 1.0,  # [R] slot tracking, critically damped with k_d
        "k_d": 2.0,
        "k_oa": 5.0,  # [R] the bounded eq. 3.21 term's gain
        "slot_tol": 0.25,  # [R] x r_s: a robot this near its slot is "in place" for the round
        "tracking": "double_integrator",  # [R] the slot law: "double_integrator" (point agents) or "velocity"
        "ring_spacing": 0.0,  # [R] x r_s: 0 = circles 2 r_s apart, six on the first; > 0: neighbours this far apart
    }
    ranges: ClassVar[dict[str, str]] = {
        "period_s": "(0, 10]", "unit_m": "(0, inf)", "r_s": "(0, inf)", "target_x": "(-inf, inf)",
        "target_y": "(-inf, inf)", "v_max": "(0, inf)", "k_p": "[0, inf)", "k_d": "[0, inf)", "k_oa": "[0, inf)",
        "slot_tol": "(0, inf)", "ring_spacing": "[0, 10]",
    }
    choices: ClassVar[dict[str, tuple[str, ...]]] = {"tracking": TRACKING}
    static_params = frozenset({"period_s"})

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.bind(robot, self.with_defaults(robot.params))
        self.centre: np.ndarray | None = None
        self.offsets: dict[int, np.ndarray] = {}
        self.rounds = 0

    def start(self, ids: list[int], xs: np.ndarray) -> None:
        """The gathering point and every robot's slot, from the first poses (all robots compute the same)."""
        r_s = float(self.p["r_s"])
        self.centre = enclosing_circle(xs)[0]
        rel = xs - self.centre
        order = sorted(range(len(ids)), key=lambda k: (round(float(np.hypot(*rel[k])), 9),
                                                       math.atan2(rel[k][1], rel[k][0]), ids[k]))
        slots = ring_slots(len(ids), r_s, float(self.p["ring_spacing"]))
        self.offsets = {ids[k]: slots[rank] for rank, k in enumerate(order)}

    def step(self) -> None:
        p = self.p
        unit = float(p["unit_m"])
        me = self.read_pose()
        if me is None:
            self.hold()
            return
        poses = self.localisation.poses()
        ids = [self.robot.id, *(q.id for q in poses)]
        xs = np.array([[me.x_m, me.y_m], *([q.x_m, q.y_m] for q in poses)], float) / unit
        if self.centre is None or not set(ids) <= set(self.offsets):  # a robot missing from one broadcast keeps
            self.start(ids, xs)  # the circle: only one never seen starts it again
        assert self.centre is not None
        slots = self.centre + np.array([self.offsets[i] for i in ids])
        off = np.hypot(*(xs - slots).T)
        target = np.array([p["target_x"], p["target_y"]], float)
        if float(off.max()) <= p["slot_tol"] * p["r_s"]:  # everyone in place: the round moves the circle on
            e = target - self.centre
            dist = float(np.hypot(*e))
            if dist > 0:
                self.centre = self.centre + e * (min(p["v_max"] * self.period_s, dist) / dist)
                self.rounds += 1
            slots = self.centre + np.array([self.offsets[i] for i in ids])
        x_i, v_i = xs[0], np.array([me.vx_mps, me.vy_mps]) / unit
        readings = self.sonar.readings()
        ranges = np.array([r.range_m for r in readings], float) / unit
        angles = np.array([r.angle_rad for r in readings], float)
        points = potential.obstacle_points(x_i, me.yaw_rad, ranges, angles)
        oa = potential.obstacle_avoidance(x_i, points, ranges, float(p["r_s"]), "per_sensor", "bounded",
                                          potential.ray_directions(me.yaw_rad, angles))
        if p["tracking"] == "velocity":
            self.u = p["k_p"] * (slots[0] - x_i) + p["k_oa"] * oa
            v = potential.saturate(self.u, float(p["v_max"]))
        else:
            self.u = p["k_p"] * (slots[0] - x_i) - p["k_d"] * v_i + p["k_oa"] * oa
            v = potential.saturate(v_i + self.u * self.period_s, float(p["v_max"]))
        self.velocity.set_velocity(float(v[0]) * unit, float(v[1]) * unit)

    def telemetry(self) -> dict[str, float | int]:
        return {"rounds": self.rounds, "pose_src": self.pose_code()}
