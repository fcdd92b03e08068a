"""Roy's chapter 3 simulation in numbers (digest 001 §4.1): point agents with double-integrator dynamics (eq. 3.1,
as the thesis' MATLAB runs) in a 40 x 40 unit world with line obstacles, one moving circular obstacle and the target
(35, 35), running ``RoyApf`` unchanged through Point* implementations of the SonPI's device protocols
(``swarm_logic.robots.sonpi.interfaces``).

The world is in thesis units; the devices speak SI at 1 unit = ``UNIT_M`` (digest §5.4). Tick semantics: every tick
all agents sense the world as the previous tick left it, every controller steps once (its command is v + u dt, so
the velocity loop is ideal and the agent a double integrator), then every agent moves x <- x + v dt. A move that
would cross a line or enter the circle is refused (the agent stops, and it is counted as a collision). Sonars are
rays at -90..+90 degrees from the agent's heading (the direction of its velocity, the last one when it stops) to the
walls, lines and circle, within ``SONAR_RANGE`` units; agents are points, so sonars do not see each other.

The layout is ours (the figures are lost, digest §5.4): ``Ch3Scenario`` version "roy-ch3-v1". Metrics (§5.5):
path length, success, mission time, cohesion index CI, lambda_min(F).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bridge.core.rng import stream
from swarm_logic.clock import SteppedClock
from swarm_logic.controller import Controller
from swarm_logic.families.roy.controller import RoyApf
from swarm_logic.robot import Robot
from swarm_logic.robots.sonpi.interfaces import (
    LOCALISATION,
    POSE,
    SONAR,
    SONAR_ANGLES_RAD,
    VELOCITY,
    AgentPose,
    SonarReading,
)

UNIT_M = 0.1  # digest §5.4
TICK_S = 0.05  # erratum #1
SONAR_RANGE = 5.0  # units (digest §0 item 5)
Segment = tuple[tuple[float, float], tuple[float, float]]


@dataclass(frozen=True)
class Mover:
    """A circular obstacle going back and forth between ``a`` and ``b`` at ``speed`` units/s."""

    a: tuple[float, float]
    b: tuple[float, float]
    radius: float
    speed: float

    def centre(self, t: float) -> np.ndarray:
        a, b = np.array(self.a), np.array(self.b)
        length = float(np.hypot(*(b - a)))
        if length == 0 or self.speed == 0:
            return a
        s = (self.speed * t) % (2 * length)
        return a + (b - a) * (min(s, 2 * length - s) / length)


def _wall(side: float) -> tuple[Segment, ...]:
    return (((0, 0), (side, 0)), ((side, 0), (side, side)), ((side, side), (0, side)), ((0, side), (0, 0)))


@dataclass(frozen=True)
class Ch3Scenario:
    """The chapter 3 world [R where the figures are lost]: T = (35, 35), 6 agents placed at random in the start
    box at least ``min_sep`` apart (§4.1), a line across the diagonal at (11, 11), a line along x + y = 40 with a
    4-unit gap at (20, 20), and a circle crossing the diagonal near (27, 27)."""

    version: str = "roy-ch3-v1"
    side: float = 40.0
    n: int = 6
    target: tuple[float, float] = (35.0, 35.0)
    start_lo: tuple[float, float] = (2.0, 2.0)
    start_hi: tuple[float, float] = (8.0, 8.0)
    min_sep: float = 1.0
    lines: tuple[Segment, ...] = (((8.0, 14.0), (14.0, 8.0)),
                                  ((8.0, 32.0), (18.586, 21.414)), ((21.414, 18.586), (32.0, 8.0)))
    movers: tuple[Mover, ...] = (Mover((22.0, 32.0), (32.0, 22.0), 1.5, 0.2),)
    goal_radius: float = 1.0  # digest §5.5 (see ``Swarm.all_arrived``)
    timeout_s: float = 600.0  # 3 x the BAT's 200 s (§5.5)

    def __post_init__(self) -> None:
        if self.n < 1:
            raise ValueError(f"n: at least one agent, got {self.n}")
        if not self.side > 0:
            raise ValueError(f"side: must be > 0, got {self.side}")

    @property
    def segments(self) -> tuple[Segment, ...]:
        return _wall(self.side) + self.lines


def deploy(sc: Ch3Scenario, seed: int) -> np.ndarray:
    """``sc.n`` start points uniform in the start box, ``min_sep`` apart, from ``stream(seed, "deploy")``;
    ValueError naming the box when they do not fit."""
    rng = stream(seed, "deploy")
    out = np.zeros((sc.n, 2))
    k = tries = 0
    while k < sc.n:
        q = rng.uniform(sc.start_lo, sc.start_hi)
        if k == 0 or np.min(np.hypot(*(out[:k] - q).T)) >= sc.min_sep:
            out[k] = q
            k += 1
        else:
            tries += 1
            if tries > 1000 * sc.n:
                raise ValueError(f"start box {sc.start_lo}..{sc.start_hi}: cannot hold {sc.n} agents "
                                 f"{sc.min_sep} units apart")
    return out


def ray_segment(o: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance along the unit ray o + s d to segment ab; inf when it misses."""
    e = b - a
    den = d[0] * e[1] - d[1] * e[0]
    if abs(den) < 1e-12:
        return math.inf
    w = a - o
    s = (w[0] * e[1] - w[1] * e[0]) / den
    u = (w[0] * d[1] - w[1] * d[0]) / den
    return s if s >= 0 and 0 <= u <= 1 else math.inf


def ray_circle(o: np.ndarray, d: np.ndarray, c: np.ndarray, r: float) -> float:
    """Distance along the unit ray o + s d to the circle (c, r); 0 inside it; inf when it misses."""
    w = o - c
    bq = float(w @ d)
    cq = float(w @ w) - r * r
    if cq <= 0:
        return 0.0
    disc = bq * bq - cq
    if disc < 0:
        return math.inf
    s = -bq - math.sqrt(disc)
    return s if s >= 0 else math.inf


def segments_cross(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the move p -> q crosses (or touches) segment ab."""
    def orient(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> float:
        return float((v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0]))
    d1, d2 = orient(a, b, p), orient(a, b, q)
    d3, d4 = orient(p, q, a), orient(p, q, b)
    return d1 * d2 <= 0 and d3 * d4 <= 0 and not (d1 == d2 == 0)


class PointWorld:
    """The agents' positions, velocities and headings (units), the obstacles, and what each sonar reads."""

    def __init__(self, sc: Ch3Scenario, start: np.ndarray) -> None:
        self.sc = sc
        self.n = len(start)
        self.pos = np.asarray(start, float).reshape(-1, 2).copy()
        self.vel = np.zeros((self.n, 2))
        t = np.array(sc.target)
        self.heading = np.arctan2(t[1] - self.pos[:, 1], t[0] - self.pos[:, 0])
        self.cmd = np.zeros((self.n, 2))
        self.tick = 0
        self.collisions = 0
        self.segs = [(np.array(a, float), np.array(b, float)) for a, b in sc.segments]
        self.sense()

    @property
    def t(self) -> float:
        return self.tick * TICK_S

    def movers(self) -> list[tuple[np.ndarray, float]]:
        return [(m.centre(self.t), m.radius) for m in self.sc.movers]

    def sense(self) -> None:
        """The snapshot this tick's readings come from: poses and sonar ranges."""
        circles = self.movers()
        self.ranges = np.full((self.n, len(SONAR_ANGLES_RAD)), math.inf)
        for i in range(self.n):
            o = self.pos[i]
            for k, a in enumerate(SONAR_ANGLES_RAD):
                d = np.array([math.cos(self.heading[i] + a), math.sin(self.heading[i] + a)])
                best = min((ray_segment(o, d, p, q) for p, q in self.segs), default=math.inf)
                for c, r in circles:
                    best = min(best, ray_circle(o, d, c, r))
                if best <= SONAR_RANGE:
                    self.ranges[i, k] = best
        self.snap_pos, self.snap_vel, self.snap_heading = self.pos.copy(), self.vel.copy(), self.heading.copy()

    def pose(self, i: int) -> AgentPose:
        p, v = self.snap_pos[i] * UNIT_M, self.snap_vel[i] * UNIT_M
        return AgentPose(i, float(p[0]), float(p[1]), float(self.snap_heading[i]), float(v[0]), float(v[1]))

    def move(self, dt: float) -> None:
        """Each agent takes its commanded velocity and moves; a move into an obstacle is refused (a collision)."""
        self.tick += 1
        circles = self.movers()
        for i in range(self.n):
            v = self.cmd[i]
            p, q = self.pos[i], self.pos[i] + v * dt
            blocked = any(segments_cross(p, q, a, b) for a, b in self.segs)
            blocked = blocked or any(float(np.hypot(*(q - c))) < r for c, r in circles)
            if blocked:
                self.collisions += 1
                self.vel[i] = 0.0
                continue
            self.pos[i], self.vel[i] = q, v
            if float(np.hypot(*v)) > 1e-9:
                self.heading[i] = math.atan2(v[1], v[0])


class PointPose:
    def __init__(self, world: PointWorld, i: int) -> None:
        self.world, self.i = world, i

    def read(self) -> AgentPose:
        return self.world.pose(self.i)


class PointLocalisation:
    """Every other agent's pose, exact and without delay (the thesis' ideal overhead camera)."""

    def __init__(self, world: PointWorld, i: int) -> None:
        self.world, self.i = world, i

    def poses(self) -> list[AgentPose]:
        return [self.world.pose(j) for j in range(self.world.n) if j != self.i]


class PointSonar:
    max_range_m = SONAR_RANGE * UNIT_M

    def __init__(self, world: PointWorld, i: int) -> None:
        self.world, self.i = world, i

    def readings(self) -> list[SonarReading]:
        return [SonarReading(float(r) * UNIT_M, a) for r, a in zip(self.world.ranges[self.i], SONAR_ANGLES_RAD,
                                                                   strict=True)]


class PointVelocity:
    """The ideal tracking layer: the agent's velocity is the command (clipped to ``max_speed_mps``)."""

    def __init__(self, world: PointWorld, i: int, max_speed_mps: float) -> None:
        self.world, self.i, self.max_speed_mps = world, i, max_speed_mps

    def set_velocity(self, vx_mps: float, vy_mps: float) -> None:
        v = np.array([vx_mps, vy_mps], float)
        s = float(np.hypot(*v))
        if s > self.max_speed_mps:
            v *= self.max_speed_mps / s
        self.world.cmd[self.i] = v / UNIT_M


def cohesion_index(pos: np.ndarray, r_s: float) -> float:
    """CI(t) (digest §2.1.12 [R]): the fraction of agents within r_s sqrt(N) of the centroid."""
    c = pos.mean(axis=0)
    return float(np.mean(np.hypot(*(pos - c).T) <= r_s * math.sqrt(len(pos))))


def lambda_min(pos: np.ndarray, r_s: float) -> float:
    """lambda_min(F), F_ij = x_ij when x_ij <= 2 r_s else 0 (eqs. 3.26-3.27, digest §2.1.12 [R])."""
    d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
    f = np.where(d <= 2 * r_s, d, 0.0)
    return float(np.linalg.eigvalsh(f).min())


@dataclass
class Ch3Run:
    """One run's figures (digest §5.5): success, mission time, mean path length, CI mean and COV, the gains of
    every agent at every tick (ticks, N, 4), lambda_min(F) per tick, collisions."""

    success: bool
    mission_s: float | None
    path_length: float
    ci_mean: float
    ci_cov: float
    collisions: int
    ticks: int
    gains: np.ndarray = field(repr=False)
    lambda_min: np.ndarray = field(repr=False)
    final: np.ndarray = field(repr=False)


class Swarm:
    """The world and one started ``RoyApf`` per agent, its devices the point agent's."""

    def __init__(self, sc: Ch3Scenario, start: np.ndarray, seed: int, params: dict[str, Any] | None = None,
                 controller: type[Controller] = RoyApf) -> None:
        self.sc = sc
        self.world = w = PointWorld(sc, start)
        self.clock = SteppedClock("the point-agent model drives controllers by ticks; they must not sleep")
        own = {"target_x": sc.target[0], "target_y": sc.target[1], "period_s": TICK_S, "unit_m": UNIT_M,
               "d_max": SONAR_RANGE, **(params or {})}
        self.ctls: list[Controller] = []
        for i in range(w.n):
            v_max = float(own.get("v_max", RoyApf.defaults["v_max"]))
            devs = {POSE: PointPose(w, i), LOCALISATION: PointLocalisation(w, i), SONAR: PointSonar(w, i),
                    VELOCITY: PointVelocity(w, i, 2 * v_max * UNIT_M)}
            robot = Robot(i, self.clock, None, stream(seed, "robot", i), dict(own), devices=devs)
            c = controller()
            c.init(robot)
            self.ctls.append(c)
        self.r_s = float(own.get("r_s", RoyApf.defaults["r_s"]))
        self.path = np.zeros(w.n)
        self.ci: list[float] = []
        self.lam: list[float] = []
        self.gains: list[np.ndarray] = []
        self.arrived_s: float | None = None

    def tick(self) -> None:
        w = self.world
        self.clock.t = w.t
        for c in self.ctls:
            c.step()
        before = w.pos.copy()
        w.move(TICK_S)
        w.sense()
        self.path += np.hypot(*(w.pos - before).T)
        self.ci.append(cohesion_index(w.pos, self.r_s))
        self.lam.append(lambda_min(w.pos, self.r_s))
        self.gains.append(np.array([getattr(c, "gains", np.full(4, np.nan)) for c in self.ctls]))
        if self.arrived_s is None and self.all_arrived():
            self.arrived_s = w.t

    def all_arrived(self) -> bool:
        """Arrival [R]: 6 agents 2 r_s apart cannot all be within 1 unit of T, so the centroid within
        ``goal_radius`` of T and every agent within ``goal_radius`` + r_s sqrt(N) (the CI disc) of it."""
        p, t = self.world.pos, np.array(self.sc.target)
        d = np.hypot(*(p - t).T)
        near = float(np.hypot(*(p.mean(axis=0) - t))) <= self.sc.goal_radius
        return near and bool(np.all(d <= self.sc.goal_radius + self.r_s * math.sqrt(len(p))))

    def run(self, max_s: float | None = None, until_arrived: bool = True) -> Ch3Run:
        """Tick until every agent is within the goal radius (``until_arrived``) or ``max_s`` (default the
        scenario's timeout) of simulated time."""
        limit = self.sc.timeout_s if max_s is None else max_s
        while self.world.t < limit - 1e-9:
            self.tick()
            if until_arrived and self.arrived_s is not None:
                break
        for c in self.ctls:
            c.destroy()
        ci = np.array(self.ci) if self.ci else np.array([math.nan])
        mean = float(ci.mean())
        return Ch3Run(self.arrived_s is not None, self.arrived_s, float(self.path.mean()), mean,
                      float(ci.std() / mean) if mean > 0 else math.nan, self.world.collisions, self.world.tick,
                      np.array(self.gains).reshape(-1, self.world.n, 4), np.array(self.lam), self.world.pos.copy())


def ch3_trial(seed: int, params: dict[str, Any] | None = None, sc: Ch3Scenario | None = None,
              max_s: float | None = None) -> Ch3Run:
    """One run of the chapter 3 scenario from a seeded random start."""
    sc = sc or Ch3Scenario()
    return Swarm(sc, deploy(sc, seed), seed, params).run(max_s)
