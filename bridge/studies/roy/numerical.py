"""Roy's chapter 3 simulation in numbers (digest 001 §4.1): point agents with double-integrator dynamics (eq. 3.1,
as the thesis' MATLAB runs) in a 40 x 40 unit world with line obstacles, one moving circular obstacle and the target
(35, 35).

Two ways to run it, the same model: ``Swarm`` runs ``RoyApf`` unchanged, one controller per agent, through Point*
implementations of the SonPI's device protocols (``swarm_logic.robots.sonpi.interfaces``); ``BatchSwarm`` steps many
seeded runs at once, every agent of every run in one numpy batch, through the functions ``RoyApf`` itself calls
(``swarm_logic.families.roy.objective.observe``, ``tuning.tune``, ``tuning.command``), with the same unit
conversions, each agent drawing from its own generator as its controller would: a run gives the same numbers alone,
in a batch or through the controllers (tests/studies/roy check it).

The world is in thesis units; the devices speak SI at 1 unit = ``UNIT_M`` (digest §5.4). Tick semantics: every tick
all agents sense the world as the previous tick left it, every controller steps once (its command is v + u dt, so
the velocity loop is ideal and the agent a double integrator), then every agent moves x <- x + v dt. A move that
would cross a line or enter the circle is refused (the agent stops, and it is counted as a collision). Sonars are
rays at -90..+90 degrees from the agent's heading (the direction of its velocity, the last one when it stops) to the
walls, lines and circle, within ``SONAR_RANGE`` units; agents are points, so sonars do not see each other.

The layout is ours (the figures are lost, digest §5.4), versioned: ``Ch3Scenario`` "roy-ch3-v2" (``SCENARIOS``
keeps "roy-ch3-v1"). Metrics (§5.5): path length, success, mission time, cohesion index CI, lambda_min(F), the
gains' moments, and a 1 s trace of the formation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from bridge.core.rng import stream
from bridge.studies.roy.checks import scenario_target_error
from swarm_logic.clock import SteppedClock
from swarm_logic.controller import Controller
from swarm_logic.families.roy.controller import RoyApf
from swarm_logic.families.roy.objective import observe
from swarm_logic.families.roy.tuning import command, deadlocked, draw, kind, take, tune
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
TRACE_S = 1.0  # the formation trace's period
ANGLES = np.array(SONAR_ANGLES_RAD)
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
    """The chapter 3 world [R where the figures are lost]: T = (35, 35), ``n`` agents placed at random in the start
    box at least ``min_sep`` apart (§4.1), line obstacles, a moving circle, walls.

    "roy-ch3-v2" (the default): a baffle y = 11 from the west wall to x = 12 (the swarm, heading along the diagonal,
    meets it at 45 degrees and slides east round its end); a wall along x + y = 40 from wall to wall, closed but for
    a 3-unit gap centred on (20, 20) (narrower than a 6-agent formation at 2 r_s spacing: it must stretch to pass);
    and a circle of radius 1.5 crossing the diagonal near (27, 27). Against either line the target's pull slides an
    agent towards the way on: east along the baffle, and along the wall towards the gap, the foot of the
    perpendicular from T (a wall across the approach whose opening lies elsewhere traps a potential field).
    ``v1`` gives the first layout."""

    version: str = "roy-ch3-v2"
    side: float = 40.0
    n: int = 6
    target: tuple[float, float] = (35.0, 35.0)
    start_lo: tuple[float, float] = (2.0, 2.0)
    start_hi: tuple[float, float] = (8.0, 8.0)
    min_sep: float = 1.0
    lines: tuple[Segment, ...] = (((0.0, 11.0), (12.0, 11.0)), ((0.0, 40.0), (18.939, 21.061)),
                                  ((21.061, 18.939), (40.0, 0.0)))
    movers: tuple[Mover, ...] = (Mover((22.0, 32.0), (32.0, 22.0), 1.5, 0.2),)
    goal_radius: float = 1.0  # digest §5.5 (see ``all_arrived``)
    timeout_s: float = 600.0  # 3 x the BAT's 200 s (§5.5)

    def __post_init__(self) -> None:
        if self.n < 1:
            raise ValueError(f"n: at least one agent, got {self.n}")
        if not self.side > 0:
            raise ValueError(f"side: must be > 0, got {self.side}")
        why = scenario_target_error(self.target, self.goal_radius, self.side, self.lines, self.movers)
        if why is not None:
            raise ValueError(f"{self.version}: target {self.target} {why}: the swarm cannot reach it")

    @property
    def segments(self) -> tuple[Segment, ...]:
        return _wall(self.side) + self.lines

    @classmethod
    def v1(cls) -> Ch3Scenario:
        """The first layout: a line across the diagonal from (8, 14) to (14, 8), a line along x + y = 40 with a
        4-unit gap at (20, 20) that ends 8 units short of the walls, the same circle."""
        return cls(version="roy-ch3-v1", lines=(((8.0, 14.0), (14.0, 8.0)), ((8.0, 32.0), (18.586, 21.414)),
                                                ((21.414, 18.586), (32.0, 8.0))))

    def with_agents(self, n: int) -> Ch3Scenario:
        """The same world with ``n`` agents, the start box grown to hold them (its side 6 units x sqrt(n / 6),
        from (2, 2))."""
        s = 6.0 * math.sqrt(max(n, 6) / 6)
        return replace(self, n=n, start_hi=(2.0 + s, 2.0 + s))


SCENARIOS = {"roy-ch3-v2": Ch3Scenario(), "roy-ch3-v1": Ch3Scenario.v1()}


def deploy(sc: Ch3Scenario, seed: int) -> np.ndarray:
    """``sc.n`` start points uniform in the start box, ``min_sep`` apart, from ``stream(seed, "deploy")``;
    ValueError naming the box when they do not fit."""
    return scatter(stream(seed, "deploy"), sc.n, sc.start_lo, sc.start_hi, sc.min_sep)


def scatter(
    rng: np.random.Generator, n: int, lo: tuple[float, float], hi: tuple[float, float], min_sep: float
) -> np.ndarray:
    """``n`` points (n, 2) drawn uniform in the box ``lo``..``hi``, each kept if ``min_sep`` from those before it;
    ValueError naming the box when they do not fit."""
    out = np.zeros((n, 2))
    k = tries = 0
    while k < n:
        q = rng.uniform(lo, hi)
        if k == 0 or np.min(np.hypot(*(out[:k] - q).T)) >= min_sep:
            out[k] = q
            k += 1
        else:
            tries += 1
            if tries > 1000 * n:
                raise ValueError(f"start box {lo}..{hi}: cannot hold {n} agents {min_sep} units apart")
    return out


def ray_segments(o: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance along the unit rays o + s d (..., 2) to each segment ab (G, 2) -> (..., G); inf where it misses.
    ``a``, ``b`` may also carry leading dimensions that broadcast against the rays' (per-ray candidates, e.g.
    (N, 1, G, 2) for N agents' m rays (N, m, 2))."""
    e = b - a
    o0, o1, d0, d1 = o[..., 0, None], o[..., 1, None], d[..., 0, None], d[..., 1, None]
    den = d0 * e[..., 1] - d1 * e[..., 0]
    ok = np.abs(den) >= 1e-12
    den = np.where(ok, den, 1.0)
    w0, w1 = a[..., 0] - o0, a[..., 1] - o1
    s = (w0 * e[..., 1] - w1 * e[..., 0]) / den
    u = (w0 * d1 - w1 * d0) / den
    return np.where(ok & (s >= 0) & (u >= 0) & (u <= 1), s, np.inf)


def ray_circle(o: np.ndarray, d: np.ndarray, c: np.ndarray, r: float) -> np.ndarray:
    """Distance along the unit rays o + s d (..., 2) to the circle (c, r); 0 inside it; inf where it misses."""
    w0, w1 = o[..., 0] - c[0], o[..., 1] - c[1]
    bq = w0 * d[..., 0] + w1 * d[..., 1]
    cq = w0 * w0 + w1 * w1 - r * r
    disc = bq * bq - cq
    s = -bq - np.sqrt(np.maximum(disc, 0.0))
    return np.where(cq <= 0, 0.0, np.where((disc >= 0) & (s >= 0), s, np.inf))


def crosses(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each move p -> q (..., 2) crosses (or touches) any segment ab (G, 2) -> (...); ``a``, ``b`` may carry
    leading dimensions that broadcast against the moves' (per-move candidates, e.g. (N, G, 2) for N moves)."""
    def orient(u0: Any, u1: Any, v0: Any, v1: Any, w0: Any, w1: Any) -> Any:
        return (v0 - u0) * (w1 - u1) - (v1 - u1) * (w0 - u0)
    p0, p1, q0, q1 = p[..., 0, None], p[..., 1, None], q[..., 0, None], q[..., 1, None]
    a0, a1, b0, b1 = a[..., 0], a[..., 1], b[..., 0], b[..., 1]
    d1, d2 = orient(a0, a1, b0, b1, p0, p1), orient(a0, a1, b0, b1, q0, q1)
    d3, d4 = orient(p0, p1, q0, q1, a0, a1), orient(p0, p1, q0, q1, b0, b1)
    hit = (d1 * d2 <= 0) & (d3 * d4 <= 0) & ~((d1 == d2) & (d2 == 0))
    return np.any(hit, axis=-1)


def track(v: np.ndarray, max_speed: float) -> np.ndarray:
    """The ideal tracking layer: the commanded velocity (..., 2), scaled down to ``max_speed`` where faster."""
    s = np.hypot(v[..., 0], v[..., 1])
    over = s > max_speed
    return np.where(over[..., None], v * (max_speed / np.where(over, s, 1.0))[..., None], v)


class PointWorld:
    """The agents' positions, velocities and headings (units), the obstacles, and what each sonar reads. Arrays
    have leading dimensions ``lead``: (N,) for one run, (R, N) for R runs stepped together."""

    def __init__(self, sc: Ch3Scenario, start: np.ndarray) -> None:
        self.sc = sc
        self.pos = np.asarray(start, float).copy()
        self.n = self.pos.shape[-2]
        self.vel = np.zeros_like(self.pos)
        t = np.array(sc.target)
        self.heading = np.arctan2(t[1] - self.pos[..., 1], t[0] - self.pos[..., 0])
        self.cmd = np.zeros_like(self.pos)
        self.tick = 0
        self.hits = np.zeros(self.pos.shape[:-2], int)
        seg = np.array(sc.segments, float).reshape(-1, 2, 2)
        self.seg_a, self.seg_b = seg[:, 0], seg[:, 1]
        self.sense()

    @property
    def collisions(self) -> int:
        return int(self.hits.sum())

    @property
    def t(self) -> float:
        return self.tick * TICK_S

    def movers(self) -> list[tuple[np.ndarray, float]]:
        return [(m.centre(self.t), m.radius) for m in self.sc.movers]

    def sense(self) -> None:
        """The snapshot this tick's readings come from: poses and sonar ranges (..., N, 5)."""
        a = self.heading[..., None] + ANGLES
        d = np.stack([np.cos(a), np.sin(a)], axis=-1)
        o = np.broadcast_to(self.pos[..., None, :], d.shape)
        best = ray_segments(o, d, self.seg_a, self.seg_b).min(axis=-1)
        for c, r in self.movers():
            best = np.minimum(best, ray_circle(o, d, c, r))
        self.ranges = np.where(best <= SONAR_RANGE, best, np.inf)
        self.snap_pos, self.snap_vel, self.snap_heading = self.pos.copy(), self.vel.copy(), self.heading.copy()

    def pose(self, i: int) -> AgentPose:
        p, v = self.snap_pos[i] * UNIT_M, self.snap_vel[i] * UNIT_M
        return AgentPose(i, float(p[0]), float(p[1]), float(self.snap_heading[i]), float(v[0]), float(v[1]))

    def move(self, dt: float, active: np.ndarray | None = None) -> None:
        """Each agent (of the ``active`` runs) takes its commanded velocity and moves; a move into an obstacle is
        refused (a collision)."""
        self.tick += 1
        p, v = self.pos, self.cmd
        q = p + v * dt
        blocked = crosses(p, q, self.seg_a, self.seg_b)
        for c, r in self.movers():
            blocked = blocked | (np.hypot(q[..., 0] - c[0], q[..., 1] - c[1]) < r)
        go = np.ones(blocked.shape, bool) if active is None else np.broadcast_to(active[..., None], blocked.shape)
        stop = go & blocked
        self.hits = self.hits + stop.sum(axis=-1)
        ok = go & ~blocked
        self.pos = np.where(ok[..., None], q, p)
        self.vel = np.where(stop[..., None], 0.0, np.where(ok[..., None], v, self.vel))
        turn = ok & (np.hypot(v[..., 0], v[..., 1]) > 1e-9)
        self.heading = np.where(turn, np.arctan2(v[..., 1], v[..., 0]), self.heading)


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
        self.world.cmd[self.i] = track(np.array([vx_mps, vy_mps], float), self.max_speed_mps) / UNIT_M


def cohesion_index(pos: np.ndarray, r_s: float) -> np.ndarray | float:
    """CI(t) (digest §2.1.12 [R]): the fraction of agents within r_s sqrt(N) of the centroid; pos (..., N, 2)."""
    c = pos.mean(axis=-2)
    d = np.hypot(pos[..., 0] - c[..., None, 0], pos[..., 1] - c[..., None, 1])
    ci = np.mean(d <= r_s * math.sqrt(pos.shape[-2]), axis=-1)
    return float(ci) if np.ndim(ci) == 0 else ci


def pair_distances(pos: np.ndarray) -> np.ndarray:
    """x_ij for every pair (..., N, N)."""
    return np.hypot(pos[..., :, None, 0] - pos[..., None, :, 0], pos[..., :, None, 1] - pos[..., None, :, 1])


def lambda_min(pos: np.ndarray, r_s: float) -> np.ndarray | float:
    """lambda_min(F), F_ij = x_ij when x_ij <= 2 r_s else 0 (eqs. 3.26-3.27, digest §2.1.12 [R]); pos (..., N, 2)."""
    d = pair_distances(pos)
    lam = np.linalg.eigvalsh(np.where(d <= 2 * r_s, d, 0.0))[..., 0]
    return float(lam) if np.ndim(lam) == 0 else lam


def nearest_neighbour(pos: np.ndarray) -> np.ndarray:
    """Each agent's distance to its nearest neighbour (..., N) (inf for a lone agent)."""
    d = pair_distances(pos)
    n = pos.shape[-2]
    return np.min(np.where(np.eye(n, dtype=bool), np.inf, d), axis=-1)


def all_arrived(pos: np.ndarray, sc: Ch3Scenario, r_s: float) -> np.ndarray:
    """Arrival [R] per run (..., N, 2) -> (...): 6 agents 2 r_s apart cannot all be within 1 unit of T, so the
    centroid within ``goal_radius`` of T and every agent within ``goal_radius`` + r_s sqrt(N) (the CI disc) of it."""
    t = np.array(sc.target)
    d = np.hypot(pos[..., 0] - t[0], pos[..., 1] - t[1])
    c = pos.mean(axis=-2)
    near = np.hypot(c[..., 0] - t[0], c[..., 1] - t[1]) <= sc.goal_radius
    return near & np.all(d <= sc.goal_radius + r_s * math.sqrt(pos.shape[-2]), axis=-1)


TRACE = ("t", "cx", "cy", "nn_min", "nn_mean", "lambda_min", "ci", "oa")


@dataclass
class Ch3Run:
    """One run's figures (digest §5.5): success, mission time, mean path length, CI mean and COV, the gains' sums
    and sums of squares over agents and ticks (Table 3.4's moments), collisions, and a trace every ``TRACE_S``
    (``TRACE`` columns: time, centroid, nearest-neighbour distances' minimum and mean, lambda_min(F), CI, how
    many agents sense an obstacle within r_s)."""

    success: bool
    mission_s: float | None
    path_length: float
    ci_mean: float
    ci_cov: float
    collisions: int
    ticks: int
    gain_sum: np.ndarray = field(repr=False)
    gain_sq: np.ndarray = field(repr=False)
    gain_n: int
    trace: np.ndarray = field(repr=False)
    final: np.ndarray = field(repr=False)
    pso_share: float = 0.0  # PSOABG: the fraction of agent-steps tuned by PSO

    @property
    def gain_mean(self) -> np.ndarray:
        return self.gain_sum / max(self.gain_n, 1)

    @property
    def gain_std(self) -> np.ndarray:
        m = self.gain_mean
        return np.sqrt(np.maximum(self.gain_sq / max(self.gain_n, 1) - m * m, 0.0))


class Recorder:
    """The metrics of R runs stepped together (R = 1 for ``Swarm``), updated after every move."""

    def __init__(self, sc: Ch3Scenario, runs: int, n: int, r_s: float) -> None:
        self.sc, self.r_s = sc, r_s
        self.path = np.zeros((runs, n))
        self.ci_sum = np.zeros(runs)
        self.ci_sq = np.zeros(runs)
        self.count = np.zeros(runs, int)
        self.gain_sum = np.zeros((runs, 4))
        self.gain_sq = np.zeros((runs, 4))
        self.pso = np.zeros(runs, int)
        self.arrived_s: list[float | None] = [None] * runs
        self.trace: list[list[np.ndarray]] = [[] for _ in range(runs)]
        self.every = max(1, round(TRACE_S / TICK_S))

    def update(self, t: float, tick: int, before: np.ndarray, after: np.ndarray, gains: np.ndarray,
               ranges: np.ndarray, rows: np.ndarray, pso_on: np.ndarray | None = None) -> np.ndarray:
        """Add one tick of the runs ``rows`` (positions (A, N, 2) before and after, gains (A, N, 4), ranges
        (A, N, 5)); returns which of them have all arrived."""
        self.path[rows] += np.hypot(after[..., 0] - before[..., 0], after[..., 1] - before[..., 1])
        ci = cohesion_index(after, self.r_s)
        self.ci_sum[rows] += ci
        self.ci_sq[rows] += ci * ci
        self.count[rows] += 1
        self.gain_sum[rows] += gains.sum(axis=-2)
        self.gain_sq[rows] += (gains * gains).sum(axis=-2)
        if pso_on is not None:
            self.pso[rows] += pso_on.sum(axis=-1)
        if tick % self.every == 0:
            nn = nearest_neighbour(after)
            lam = lambda_min(after, self.r_s)
            c = after.mean(axis=-2)
            oa = np.sum(np.min(ranges, axis=-1) <= self.r_s, axis=-1)
            for k, r in enumerate(rows.tolist()):
                self.trace[r].append(np.array([t, c[k, 0], c[k, 1], nn[k].min(), nn[k].mean(), lam[k], ci[k],
                                               oa[k]]))
        arrived = all_arrived(after, self.sc, self.r_s)
        for k, r in enumerate(rows.tolist()):
            if arrived[k] and self.arrived_s[r] is None:
                self.arrived_s[r] = t
        return arrived

    def result(self, r: int, collisions: int, ticks: int, final: np.ndarray) -> Ch3Run:
        m = self.count[r]
        mean = self.ci_sum[r] / m if m else math.nan
        var = max(self.ci_sq[r] / m - mean * mean, 0.0) if m else math.nan
        n_agents = self.path.shape[1]
        return Ch3Run(self.arrived_s[r] is not None, self.arrived_s[r], float(self.path[r].mean()), float(mean),
                      float(math.sqrt(var) / mean) if m and mean > 0 else math.nan, collisions, ticks,
                      self.gain_sum[r].copy(), self.gain_sq[r].copy(), int(m * n_agents),
                      np.array(self.trace[r]).reshape(-1, len(TRACE)), final.copy(),
                      float(self.pso[r] / max(m * n_agents, 1)))


def controller_params(sc: Ch3Scenario, params: dict[str, Any] | None) -> dict[str, Any]:
    """The controllers' parameters in this world: its target, tick, unit and sonar range, then ``params``."""
    return {"target_x": sc.target[0], "target_y": sc.target[1], "period_s": TICK_S, "unit_m": UNIT_M,
            "d_max": SONAR_RANGE, **(params or {})}


class Swarm:
    """The world and one started ``RoyApf`` per agent, its devices the point agent's."""

    def __init__(self, sc: Ch3Scenario, start: np.ndarray, seed: int, params: dict[str, Any] | None = None,
                 controller: type[Controller] = RoyApf) -> None:
        self.sc = sc
        self.world = w = PointWorld(sc, start)
        self.clock = SteppedClock("the point-agent model drives controllers by ticks; they must not sleep")
        world = controller_params(sc, None)  # what this world sets, for a controller that has the parameter
        own = {**{k: v for k, v in world.items() if k in controller.defaults}, **(params or {})}
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
        self.rec = Recorder(sc, 1, w.n, self.r_s)
        self.gains: list[np.ndarray] = []  # every agent's gains at every tick

    @property
    def arrived_s(self) -> float | None:
        return self.rec.arrived_s[0]

    def tick(self) -> None:
        w = self.world
        self.clock.t = w.t
        for c in self.ctls:
            c.step()
        before = w.pos.copy()
        w.move(TICK_S)
        w.sense()
        g = np.array([getattr(c, "gains", np.full(4, np.nan)) for c in self.ctls])
        self.gains.append(g)
        pso_on = np.array([[bool(getattr(c, "using_pso", False)) for c in self.ctls]])
        self.rec.update(w.t, w.tick, before[None], w.pos[None], g[None], w.ranges[None], np.zeros(1, int), pso_on)

    def all_arrived(self) -> bool:
        return bool(all_arrived(self.world.pos, self.sc, self.r_s))

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
        return self.rec.result(0, self.world.collisions, self.world.tick, self.world.pos)


class BatchSwarm:
    """R seeded runs of one scenario and one parameter set stepped together: run r starts at ``deploy(sc,
    seeds[r])`` and its agent i draws from ``stream(seeds[r], "robot", i)``, as in ``Swarm``. A run that has
    arrived stops (``until_arrived``) and the rest go on; each run's figures are those it has alone."""

    def __init__(self, sc: Ch3Scenario, seeds: list[int], params: dict[str, Any] | None = None) -> None:
        self.sc = sc
        self.p = p = RoyApf.resolve(controller_params(sc, params))
        if float(p["unit_m"]) != UNIT_M or float(p["period_s"]) != TICK_S:
            raise ValueError(f"unit_m, period_s: the point model runs at {UNIT_M} m and {TICK_S} s")
        self.seeds = list(seeds)
        r_n, n = len(seeds), sc.n
        self.world = PointWorld(sc, np.array([deploy(sc, s) for s in seeds]).reshape(r_n, n, 2))
        clock = SteppedClock("the batched point-agent model has no controllers to sleep")
        # each agent's generator as its ``Robot`` leaves it for the controller (``Swarm``)
        self.rngs = [[Robot(i, clock, None, stream(s, "robot", i), {}, devices={}).rng for i in range(n)]
                     for s in seeds]
        self.gains = np.tile(np.array([p["k_a"], p["k_v"], p["k_r"], p["k_oa"]], float), (r_n, n, 1))
        self.r_s = float(p["r_s"])
        self.max_speed = 2 * float(p["v_max"]) * UNIT_M  # the tracking layer's clip, as ``Swarm`` gives it
        self.window = max(2, round(p["deadlock_window_s"] / TICK_S) + 1)
        self.centroids = np.zeros((r_n, n, self.window, 2))  # PSOABG: each agent's last x_bar, a ring
        self.steps = 0
        self.active = np.ones(r_n, bool)
        self.rec = Recorder(sc, r_n, n, self.r_s)
        self.others = np.array([[j for j in range(n) if j != i] for i in range(n)], int).reshape(n, n - 1)

    def tick(self) -> None:
        w, p = self.world, self.p
        rows = np.flatnonzero(self.active)
        a_n, n = len(rows), self.sc.n
        x = (w.snap_pos[rows] * UNIT_M) / UNIT_M  # the devices' SI round trip, as the controllers see it
        v = (w.snap_vel[rows] * UNIT_M) / UNIT_M
        rng_ = (w.ranges[rows] * UNIT_M) / UNIT_M
        s = observe(x.reshape(-1, 2), v.reshape(-1, 2), x[:, self.others].reshape(a_n * n, n - 1, 2),
                    v[:, self.others].reshape(a_n * n, n - 1, 2), w.snap_heading[rows].reshape(-1),
                    rng_.reshape(-1, len(ANGLES)), ANGLES, p)
        gains = self.gains[rows].reshape(-1, 4)
        kinds = np.full(a_n * n, p["optimiser"], dtype=object)
        pso_on = np.zeros(a_n * n, bool)
        if p["optimiser"] == "psoabg":
            ring = self.centroids[rows]
            slot = self.steps % self.window
            ring[:, :, slot] = s.x_bar.reshape(a_n, n, 2)
            first = ring[:, :, (self.steps + 1) % self.window].reshape(-1, 2)
            stuck = deadlocked(first, s.x_bar, s.x_bar, s.target, p) & (self.steps + 1 >= self.window)
            self.centroids[rows] = ring
            kinds = np.array([kind(p, bool(b)) for b in stuck], dtype=object)
            pso_on = stuck
        if self.steps % int(p["retune_every"]) == 0:
            for k in dict.fromkeys(kinds.tolist()):
                idx = np.flatnonzero(kinds == k)
                drawn = [draw(p, k, self.rngs[rows[i // n]][i % n]) for i in idx.tolist()]
                u = {c: np.stack([d[c] for d in drawn]) for c in (drawn[0] if drawn else {})}
                gains[idx] = tune(p, k, take(s, idx), gains[idx], u)
        self.steps += 1
        _, vel = command(gains, s)
        cmd = np.array(w.cmd)
        cmd[rows] = (track(vel * UNIT_M, self.max_speed) / UNIT_M).reshape(a_n, n, 2)
        w.cmd = cmd
        self.gains[rows] = gains.reshape(a_n, n, 4)
        before = w.pos[rows]
        w.move(TICK_S, self.active)
        w.sense()
        arrived = self.rec.update(w.t, w.tick, before, w.pos[rows], self.gains[rows], w.ranges[rows], rows,
                                  pso_on.reshape(a_n, n))
        self.arrived_now = rows[arrived]

    def run(self, max_s: float | None = None, until_arrived: bool = True) -> list[Ch3Run]:
        """Tick until every run has arrived (``until_arrived``) or ``max_s`` (default the scenario's timeout) of
        simulated time; each run's figures stop where it arrived."""
        limit = self.sc.timeout_s if max_s is None else max_s
        ticks = np.zeros(len(self.seeds), int)
        while self.world.t < limit - 1e-9 and self.active.any():
            self.tick()
            ticks[self.active] = self.world.tick
            if until_arrived:
                self.active[self.arrived_now] = False
        return [self.rec.result(r, int(self.world.hits[r]), int(ticks[r]), self.world.pos[r])
                for r in range(len(self.seeds))]


def ch3_trial(seed: int, params: dict[str, Any] | None = None, sc: Ch3Scenario | None = None,
              max_s: float | None = None) -> Ch3Run:
    """One run of the chapter 3 scenario from a seeded random start, through the controllers."""
    sc = sc or Ch3Scenario()
    return Swarm(sc, deploy(sc, seed), seed, params).run(max_s)


def ch3_batch(seeds: list[int], params: dict[str, Any] | None = None, sc: Ch3Scenario | None = None,
              max_s: float | None = None) -> list[Ch3Run]:
    """Runs of the chapter 3 scenario from the seeds' random starts, stepped together (``BatchSwarm``)."""
    return BatchSwarm(sc or Ch3Scenario(), seeds, params).run(max_s)
