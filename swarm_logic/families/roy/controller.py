"""``RoyApf`` (behaviour ``roy_apf``): Roy's chapter 3 agent (digest 001 §2.1.13). Every step it reads its pose,
the others' broadcast poses and its sonars, re-tunes its four gains (k_a, k_v, k_r, k_OA) with the chosen optimiser
on Theta (eq. 3.22), computes u = -u^a + u^r + u^OA (+ target term) and commands the velocity v + u dt (saturated)
to the tracking layer: a double integrator (eq. 3.1) whose velocity loop is the robot's.

The law works in thesis units (1 unit = ``unit_m``, 0.1 m, digest §5.4); the devices speak SI.
"""

from __future__ import annotations

from collections import deque
from typing import Any, ClassVar

import numpy as np

from swarm_logic.controller import Controller
from swarm_logic.families.roy.bat import BAT_MODES
from swarm_logic.families.roy.binary_bat import BINARY_TRANSFERS
from swarm_logic.families.roy.objective import MODES, AgentState, observe
from swarm_logic.families.roy.potential import OA_LAWS
from swarm_logic.families.roy.tuning import command, deadlocked, draw, kind, tune
from swarm_logic.robot import Robot
from swarm_logic.robots.sonpi.interfaces import (
    LOCALISATION,
    ODOMETRY,
    POSE,
    SONAR,
    VELOCITY,
    AgentPose,
    HolonomicVelocity,
    Localisation,
    Odometry,
    OwnPose,
    Sonar,
    own_pose,
)

OPTIMISERS = ("bat", "pso", "bfo", "bgpso", "psoabg", "binary_bat", "fixed")
POS = "(0, inf)"
GAIN = "[0.1, 10]"
COUNT = "[1, 10000]"
UNIT = "[0, 1]"


POSE_SOURCES = ("camera", "carried", "odometry", "none")  # ``own_pose``'s answers, in telemetry's ``pose_src`` code


class SonpiAgent(Controller):
    """A chapter 3 agent on the SonPI's four devices (and its odometry, when it has one): ``init`` binds them,
    ``destroy`` commands zero velocity. ``read_pose`` is the agent's own pose: the localisation service's (fresh, or
    carried on by odometry while the camera has lost the robot), the odometry's while the service has none for it
    (``NoPose``: the camera has never seen it), or None when it has neither (the agent then holds still)."""

    pose: OwnPose
    localisation: Localisation
    sonar: Sonar
    velocity: HolonomicVelocity
    odometry: Odometry | None

    def bind(self, robot: Robot, p: dict[str, Any]) -> None:
        """Keep the resolved parameters ``p`` and the period, and look up the devices."""
        self.p = p
        self.period_s = float(p["period_s"])
        self.pose = robot.device(POSE)
        self.localisation = robot.device(LOCALISATION)
        self.sonar = robot.device(SONAR)
        self.velocity = robot.device(VELOCITY)
        self.odometry = robot.devices.get(ODOMETRY, robot.faces.get(ODOMETRY))
        self.pose_steps = dict.fromkeys(POSE_SOURCES, 0)
        self.pose_src = "start"

    def read_pose(self) -> AgentPose | None:
        """This agent's pose now (see the class), its source counted in ``pose_steps``."""
        me, src = own_pose(self.pose, self.odometry, self.robot.id)
        if src != self.pose_src:  # a change of source is worth a line (topic pose_source)
            self.robot.log("pose_source", source=src, previous=self.pose_src, steps=dict(self.pose_steps))
            self.pose_src = src
        self.pose_steps[src] += 1
        return me

    def pose_code(self) -> int:
        """The last step's pose source as its index in ``POSE_SOURCES`` (-1 before the first step)."""
        return POSE_SOURCES.index(self.pose_src) if self.pose_src in POSE_SOURCES else -1

    def hold(self) -> None:
        """No pose at all: stand still (a step without a pose must not steer by a guess)."""
        self.velocity.set_velocity(0.0, 0.0)

    def destroy(self) -> None:
        """Command zero velocity."""
        vel = getattr(self, "velocity", None)
        if vel is not None:
            vel.set_velocity(0.0, 0.0)


class RoyApf(SonpiAgent):
    """Attraction + repulsion + obstacle avoidance with per-step gain tuning (Roy 2022, ch.3)."""

    period_s = 0.05
    defaults: ClassVar[dict[str, Any]] = {
        "period_s": 0.05,  # erratum #1: the thesis gives no dt; ours 0.05 s
        "unit_m": 0.1,  # digest §5.4: 1 unit = 0.1 m
        "r_s": 1.0,  # Table 3.3, units
        "delta": 4.0,  # Table 3.3 (sqrt(delta) r_s = 2 r_s, Theorem 1)
        "target_x": 35.0,  # Table 3.3, T = (35, 35) units
        "target_y": 35.0,
        "v_max": 0.25,  # digest §5.3 [R], units/s: calibrated, BAT arrives near 200 s in roy-ch3-v2 (docs/roy.md)
        "d_max": 5.0,  # sensor range, units (digest §0 item 5): d in Theta when nothing echoes (erratum #3)
        "optimiser": "bat",  # the thesis' choice
        "objective": "lookahead",  # erratum #3: "literal" or "lookahead"; "weighted", "spacing" (docs/roy.md)
        "oa_mode": "per_sensor",  # digest §2.1.6 [R]: one OA term per reading within r_s, or the nearest only
        "oa_law": "bounded",  # [R] not vanishing at contact; "literal": eq. 3.21 as printed
        "lookahead_s": 1.0,  # erratum #3 [R]: the look-ahead's horizon, s; 0 = one period_s (the one-step reading)
        "progress": "swarm",  # erratum #3 [R]: look-ahead target term n |x_bar' - T|; "centroid": |x_bar' - T|
        "neighbour_radius": 0.0,  # erratum #4: 0 = all agents (hardware broadcasts all poses); else units
        "target_term": "saturated",  # erratum #2: "saturated" target term, or "none" (the law as printed)
        "k_target": 1.0,  # erratum #2 [R]
        "target_sat": 1.0,  # units: the offset the target pull saturates at [R]
        "target_damping": 1.0,  # [R] absolute velocity damping of the target term
        "gain_min": 0.1,  # erratum #3: box bounds [0.1, 10]
        "gain_max": 10.0,
        "k_a": 4.4,  # initial (warm start) and "fixed" gains: Table 3.4 BAT means
        "k_v": 0.31,
        "k_r": 6.64,
        "k_oa": 2.5,
        "retune_every": 1,  # steps between re-tunings; 1 = every step, as the thesis
        "pso_particles": 50,  # Table 3.1
        "pso_iters": 50,
        "pso_c1": 1.5,
        "pso_c2": 1.5,
        "pso_w": 0.5,
        "bfo_bacteria": 100,  # Table 3.2
        "bfo_nc": 5,
        "bfo_ns": 4,
        "bfo_nre": 4,
        "bfo_ned": 2,
        "bfo_ped": 0.25,
        "bfo_step": 0.05,  # erratum #6: C = 0.05 x gain range
        "bfo_d_att": 0.1,  # erratum #6: Passino's J_cc defaults
        "bfo_w_att": 0.2,
        "bfo_h_rep": 0.1,
        "bfo_w_rep": 10.0,
        "bat_pop": 25,  # erratum #5: 25 bats x 50 iterations
        "bat_iters": 50,
        "bat_mode": "literal",  # erratum #5: "literal" (alpha 0.05, gamma 0.95) or "standard" (Yang)
        "bat_f_min": 0.0,  # Table 3.3
        "bat_f_max": 1.0,
        "bat_a0": 1.0,
        "bat_alpha": 0.05,
        "bat_gamma": 0.95,
        # the binary (cooperative) bat of ch.7 (Table 7.5) [R]: bat_pop x bat_iters, bat_f_min/f_max/a0 as BAT
        "bbat_bits": 8,  # [R] bits a gain: a grid of 2^8 points over [gain_min, gain_max]
        "bbat_transfer": "sigmoid",  # the thesis' S-shaped map; "v_shaped": BBA's (Mirjalili et al. 2014)
        "bbat_alpha": 0.9,  # the thesis gives none for Zhang's: Yang's standard BA
        "bbat_gamma": 0.9,
        "deadlock_window_s": 2.0,  # erratum #7: PSOABG switches to PSO when the centroid moves
        "deadlock_move": 0.05,  # < deadlock_move x r_s in deadlock_window_s
        "goal_tol": 1.0,  # units (digest §5.5): no deadlock within this of T
    }
    ranges: ClassVar[dict[str, str]] = {
        "period_s": "(0, 10]", "unit_m": POS, "r_s": POS, "delta": POS, "target_x": "(-inf, inf)",
        "target_y": "(-inf, inf)", "v_max": POS, "lookahead_s": "[0, 60]", "d_max": POS,
        "neighbour_radius": "[0, inf)", "k_target": "[0, inf)",
        "target_sat": "[0, inf)", "target_damping": "[0, inf)", "gain_min": POS, "gain_max": POS, "k_a": POS,
        "k_v": POS, "k_r": POS, "k_oa": POS, "retune_every": COUNT, "pso_particles": COUNT, "pso_iters": "[0, 10000]",
        "pso_c1": "[0, 10]", "pso_c2": "[0, 10]", "pso_w": "[0, 2]", "bfo_bacteria": "[2, 10000]", "bfo_nc": COUNT,
        "bfo_ns": "[0, 1000]", "bfo_nre": COUNT, "bfo_ned": COUNT, "bfo_ped": UNIT, "bfo_step": "(0, 1]",
        "bfo_d_att": "[0, inf)", "bfo_w_att": "[0, inf)", "bfo_h_rep": "[0, inf)", "bfo_w_rep": "[0, inf)",
        "bat_pop": COUNT, "bat_iters": "[0, 10000]", "bat_f_min": "[0, inf)", "bat_f_max": "[0, inf)",
        "bat_a0": "[0, 1]", "bat_alpha": "(0, 1]", "bat_gamma": "(0, inf)", "bbat_bits": "[1, 30]",
        "bbat_alpha": "(0, 1]", "bbat_gamma": "(0, inf)", "deadlock_window_s": POS,
        "deadlock_move": "[0, inf)", "goal_tol": "[0, inf)",
    }
    choices: ClassVar[dict[str, tuple[str, ...]]] = {
        "optimiser": OPTIMISERS, "objective": MODES, "oa_mode": ("per_sensor", "nearest"), "oa_law": OA_LAWS,
        "progress": ("swarm", "centroid"),
        "target_term": ("saturated", "none"), "bat_mode": BAT_MODES, "bbat_transfer": BINARY_TRANSFERS,
    }
    static_params = frozenset({"period_s", "deadlock_window_s"})  # both size state built by ``init``

    @classmethod
    def resolve(cls, params: dict[str, Any]) -> dict[str, Any]:
        """``with_defaults``, then the bounds in order and the initial gains within them (ValueError naming them)."""
        p = cls.with_defaults(params)
        if not p["gain_min"] < p["gain_max"]:
            raise ValueError(f"gain_min: must be < gain_max ({p['gain_max']}), got {p['gain_min']}")
        for k in ("k_a", "k_v", "k_r", "k_oa"):
            if p["optimiser"] != "fixed" and not p["gain_min"] <= p[k] <= p["gain_max"]:
                raise ValueError(f"{k}: the warm start must lie in [gain_min, gain_max], got {p[k]}")
        if p["bat_f_min"] > p["bat_f_max"]:
            raise ValueError(f"bat_f_min: must be <= bat_f_max ({p['bat_f_max']}), got {p['bat_f_min']}")
        return p

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.bind(robot, self.resolve(robot.params))
        self.reset()

    def reset(self) -> None:
        p = self.p
        self.gains = np.array([p["k_a"], p["k_v"], p["k_r"], p["k_oa"]], float)
        self.steps = 0
        self.using_pso = False  # PSOABG: PSO engaged by the deadlock detector
        self.centroids: deque[np.ndarray] = deque(maxlen=max(2, round(p["deadlock_window_s"] / self.period_s) + 1))
        self.u = np.zeros(2)

    def state(self, me: AgentPose) -> AgentState:
        """What this agent knows now, its own pose ``me``, in thesis units (a batch of one)."""
        unit = float(self.p["unit_m"])
        x_i = np.array([[me.x_m, me.y_m]]) / unit
        v_i = np.array([[me.vx_mps, me.vy_mps]]) / unit
        poses = self.localisation.poses()
        xs = np.array([[q.x_m, q.y_m] for q in poses], float).reshape(1, -1, 2) / unit
        vs = np.array([[q.vx_mps, q.vy_mps] for q in poses], float).reshape(1, -1, 2) / unit
        readings = self.sonar.readings()
        ranges = np.array([[r.range_m for r in readings]], float) / unit
        angles = np.array([r.angle_rad for r in readings], float)
        return observe(x_i, v_i, xs, vs, np.array([me.yaw_rad]), ranges, angles, self.p)

    def step(self) -> None:
        me = self.read_pose()
        if me is None:
            self.hold()
            return
        s = self.state(me)
        p = self.p
        deadlock = False
        if p["optimiser"] == "psoabg":
            self.centroids.append(s.x_bar[0])
            full = len(self.centroids) == self.centroids.maxlen
            deadlock = full and bool(deadlocked(self.centroids[0], self.centroids[-1], s.x_bar[0], s.target, p))
        if self.steps % int(p["retune_every"]) == 0:
            k = kind(p, deadlock)
            self.using_pso = k == "pso" and p["optimiser"] == "psoabg"
            u = {c: a[None, :] for c, a in draw(p, k, self.robot.rng).items()}
            self.gains = tune(p, k, s, self.gains[None, :], u)[0]
        self.steps += 1
        u, v = command(self.gains[None, :], s)
        self.u = u[0]
        unit = float(p["unit_m"])
        self.velocity.set_velocity(float(v[0, 0]) * unit, float(v[0, 1]) * unit)

    def telemetry(self) -> dict[str, float | int]:
        k = self.gains
        return {"k_a": float(k[0]), "k_v": float(k[1]), "k_r": float(k[2]), "k_oa": float(k[3]),
                "pso_on": int(self.using_pso), "pose_src": self.pose_code()}
