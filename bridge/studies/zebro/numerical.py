"""The thesis' NetLogo model in numbers: point Zebros whose devices implement the Zebro's protocols
(``swarm_logic.robots.decizebro.interfaces``), running the family's controllers unchanged.

Tick semantics (thesis sections 3.5, 4.1, 4.2.2): one tick is every robot's ``step()`` once, in a random order
drawn each tick from the run's seeded stream; a robot walks its tick right after its own step (NetLogo moves
each turtle in its turn); a broadcast reaches the sender's neighbours within the communication radius at once,
so robots later in the same tick read it (information can cross several hops in one tick). Sensing is error-free:
exact ranges, bearings and headings, the utility cone's exact sum. A particle is eaten by the first robot whose
walk passes within the consumption radius of it.

Lengths in the scenario are body lengths (1 u = 0.268 m, the DeciZebro); the devices speak SI.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarm_logic.clock import SteppedClock
from swarm_logic.controller import Controller
from swarm_logic.families.zebro.messages import NAMES
from swarm_logic.geometry import wrap
from swarm_logic.graph import components
from swarm_logic.robot import Robot
from swarm_logic.robots.decizebro.interfaces import (
    BODY_LENGTH_M,
    FAST_FACTOR,
    IMU,
    LEGS,
    UTILITY,
    UWB_RADIO,
    Message,
    Neighbour,
)

U = BODY_LENGTH_M  # metres per body length


@dataclass
class Particle:
    x: float  # m
    y: float
    utility: int
    eaten_by: int | None = None
    tick: int | None = None
    order: int = 0  # 1 for the first particle eaten, 2 for the next ...


@dataclass
class Model:
    """The model's figures (digest 2.7, 5.4), in body lengths and ticks."""

    tick_s: float = 1.0
    speed_u: float = 0.2  # flocking speed, u/tick (the leader: 3x)
    cone_half_deg: float = 30.0  # the 60 degree cone is +-30
    cone_len_u: float = 3.0
    consume_u: float = 0.5
    max_turn_deg: float = 90.0  # what the legs can turn in a tick
    delivery: str = "at_once"  # at_once (NetLogo: later robots in the tick read it) | next_tick (one hop per tick)
    frozen: bool = False  # robots never move (a static graph, for the unit targets)


class ZebroWorld:
    """Positions, headings, particles and the radio of ``n`` point Zebros."""

    def __init__(self, pos_u: np.ndarray, heading: np.ndarray, r_comm_u: float, particles: list[Particle],
                 model: Model) -> None:
        self.n = len(pos_u)
        self.x = [float(v) * U for v in pos_u[:, 0]]
        self.y = [float(v) * U for v in pos_u[:, 1]]
        self.h = [float(v) for v in heading]
        self.r = r_comm_u * U
        self.particles = particles
        self.m = model
        self.dt = model.tick_s
        self.speed = model.speed_u * U / model.tick_s
        self.cone_half = math.radians(model.cone_half_deg)
        self.cone_len = model.cone_len_u * U
        self.consume = model.consume_u * U
        self.max_turn = math.radians(model.max_turn_deg)
        self.inbox: list[list[Message]] = [[] for _ in range(self.n)]
        self.pending: list[tuple[int, Message]] = []  # next_tick delivery: (receiver, frame) until the tick ends
        self.at_once = model.delivery == "at_once"
        if model.delivery not in ("at_once", "next_tick"):
            raise ValueError(f"delivery: at_once or next_tick, got {model.delivery!r}")
        self.cmd: list[tuple[float, bool, bool]] = [(0.0, False, False)] * self.n  # (turn rate, fast, walking)
        self.eaten = [0] * self.n
        self.eat_count = 0
        self.tick = 0
        self.first_fast: int | None = None  # the first tick a robot walked at the leader's pace
        self.tx: Counter[int] = Counter()  # frames sent, by type byte
        self.rx: Counter[int] = Counter()  # frames delivered, by type byte
        self.rx_bytes = 0

    def dist(self, i: int, j: int) -> float:
        return math.hypot(self.x[j] - self.x[i], self.y[j] - self.y[i])

    def neighbours(self, i: int) -> list[Neighbour]:
        xi, yi, hi, r, out = self.x[i], self.y[i], self.h[i], self.r, []
        for j in range(self.n):
            if j == i:
                continue
            dx, dy = self.x[j] - xi, self.y[j] - yi
            d = math.hypot(dx, dy)
            if d <= r:
                out.append(Neighbour(j, d, wrap(math.atan2(dy, dx) - hi), self.h[j]))
        return out

    def broadcast(self, i: int, data: bytes) -> bool:
        kind = data[0] if data else -1
        self.tx[kind] += 1
        xi, yi, r = self.x[i], self.y[i], self.r
        msg = Message(i, bytes(data))
        for j in range(self.n):
            if j != i and math.hypot(self.x[j] - xi, self.y[j] - yi) <= r:
                if self.at_once:
                    self.inbox[j].append(msg)
                else:
                    self.pending.append((j, msg))
                self.rx[kind] += 1
                self.rx_bytes += len(data)
        return True

    def in_cone(self, i: int) -> list[tuple[Particle, float]]:
        """The uneaten particles in robot i's cone, with their bearings."""
        out = []
        for p in self.particles:
            if p.eaten_by is not None:
                continue
            dx, dy = p.x - self.x[i], p.y - self.y[i]
            d = math.hypot(dx, dy)
            if d <= self.cone_len:
                b = wrap(math.atan2(dy, dx) - self.h[i]) if d > 0 else 0.0
                if abs(b) <= self.cone_half:
                    out.append((p, b))
        return out

    def advance(self, i: int) -> None:
        """Robot i's walk for this tick (its command), then whatever it reached is eaten."""
        rate, fast, walking = self.cmd[i]
        if self.m.frozen:
            return
        turn = max(-self.max_turn, min(self.max_turn, rate * self.dt))
        self.h[i] = wrap(self.h[i] + turn)
        if not walking:
            return
        if fast and self.first_fast is None:
            self.first_fast = self.tick
        step = self.speed * (FAST_FACTOR if fast else 1.0) * self.dt
        x0, y0 = self.x[i], self.y[i]
        dx, dy = step * math.cos(self.h[i]), step * math.sin(self.h[i])
        self.x[i], self.y[i] = x0 + dx, y0 + dy
        for p in self.particles:  # reached: within the radius anywhere along this tick's walk
            f = max(0.0, min(1.0, ((p.x - x0) * dx + (p.y - y0) * dy) / (step * step))) if step > 0 else 0.0
            if p.eaten_by is None and math.hypot(p.x - x0 - f * dx, p.y - y0 - f * dy) <= self.consume:
                self.eat_count += 1
                p.eaten_by, p.tick, p.order = i, self.tick, self.eat_count
                self.eaten[i] += p.utility

    def end_tick(self) -> None:
        """Deliver what waits for the next tick (``next_tick`` delivery)."""
        for j, m in self.pending:
            self.inbox[j].append(m)
        self.pending.clear()

    def adjacency(self) -> np.ndarray:
        x, y = np.array(self.x), np.array(self.y)
        return np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :]) <= self.r


class PointRadio:
    """``ZebroRadio``: exact ranging of the robots within the radius, at-once delivery."""

    max_payload = 3 + 255 * 3  # the thesis' model has no frame size: a link list of 255 links fits

    def __init__(self, world: ZebroWorld, i: int) -> None:
        self.w, self.i = world, i

    def neighbours(self) -> list[Neighbour]:
        return self.w.neighbours(self.i)

    def broadcast(self, data: bytes) -> bool:
        return self.w.broadcast(self.i, data)

    def wait_neighbourhood(self, timeout: float | None = None) -> None:
        """The model's ranging is exact and immediate: nothing to wait for."""

    def receive(self) -> list[Message]:
        box = self.w.inbox[self.i]
        self.w.inbox[self.i] = []
        return box


class PointUtility:
    """``UtilitySensor``: the exact sum of the utilities in the cone, their weighted direction, what was eaten."""

    def __init__(self, world: ZebroWorld, i: int) -> None:
        self.w, self.i = world, i

    def read(self) -> int:
        return sum(p.utility for p, _ in self.w.in_cone(self.i))

    def bearing(self) -> float | None:
        seen = self.w.in_cone(self.i)
        if not seen:
            return None
        s = sum(abs(p.utility) * math.sin(b) for p, b in seen)
        c = sum(abs(p.utility) * math.cos(b) for p, b in seen)
        return math.atan2(s, c)

    def consumed(self) -> int:
        u, self.w.eaten[self.i] = self.w.eaten[self.i], 0
        return u


class PointImu:
    def __init__(self, world: ZebroWorld, i: int) -> None:
        self.w, self.i = world, i

    def heading(self) -> float:
        return self.w.h[self.i]


class PointLegs:
    """``Locomotion``: the command holds until changed; the world walks it in the robot's turn."""

    def __init__(self, world: ZebroWorld, i: int) -> None:
        self.w, self.i = world, i
        self.speed_mps = world.speed

    def walk(self, turn_rate_rps: float, fast: bool = False) -> None:
        self.w.cmd[self.i] = (float(turn_rate_rps), bool(fast), True)

    def halt(self) -> None:
        self.w.cmd[self.i] = (0.0, False, False)


# -- scenarios (thesis section 4.2.1) ------------------------------------------------------------------------------

@dataclass
class Scenario:
    """Initial positions and headings, the particles (body lengths) and the communication radius."""

    pos: np.ndarray
    heading: np.ndarray
    particles: list[tuple[float, float, int]]
    r_comm: float
    finders: tuple[int, ...]


def wrap_all(a: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(a), np.cos(a))


def mst_longest_edge(pos: np.ndarray) -> float:
    """The longest edge of the Euclidean minimum spanning tree (Prim): the shortest radius that connects."""
    n = len(pos)
    d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
    inside = np.zeros(n, bool)
    inside[0] = True
    best = d[0].copy()
    longest = 0.0
    for _ in range(n - 1):
        cand = np.where(inside, np.inf, best)
        j = int(np.argmin(cand))
        longest = max(longest, float(cand[j]))
        inside[j] = True
        best = np.minimum(best, d[j])
    return longest


def make_scenario(n: int, p: int, long_range: bool, rng: np.random.Generator, spacing_u: float = 2.0,
                  min_sep_u: float = 1.0, utilities: tuple[int, ...] = (95, 15), model: Model | None = None,
                  min_split_deg: float = 90.0, src_margin: float = 1.01,
                  heading_spread_deg: float = 360.0) -> Scenario:
    """A connected random graph of ``n`` robots (uniform in a square of side spacing * sqrt(n), at least
    ``min_sep_u`` apart), random headings, and ``p`` particles each in a different robot's cone at launch, in
    directions from the swarm's centre at least ``min_split_deg`` apart (eating both would break the swarm). SRC: the
    radius is the MST's longest edge + 1 %; LRC: the swarm's diameter + 1 % (a complete graph)."""
    model = model or Model()
    side = spacing_u * math.sqrt(n)
    for _ in range(1000):
        pos = _positions(n, side, min_sep_u, rng)
        spread = math.radians(min(heading_spread_deg, 360.0)) / 2
        heading = wrap_all(rng.uniform(-math.pi, math.pi) + rng.uniform(-spread, spread, n))
        placed = _particles(pos, heading, p, rng, model, min_split_deg)
        if placed is None:
            continue
        finders, spots = placed
        us = list(utilities[:p]) if p > 1 else [int(rng.choice(utilities))]
        rng.shuffle(us)
        d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
        r = (float(d.max()) * 1.01 if long_range else mst_longest_edge(pos) * src_margin)
        return Scenario(pos, heading, [(x, y, int(u)) for (x, y), u in zip(spots, us, strict=True)], r, finders)
    raise RuntimeError("no scenario found: loosen the placement")


def _positions(n: int, side: float, min_sep: float, rng: np.random.Generator) -> np.ndarray:
    pos = np.zeros((n, 2))
    k = 0
    while k < n:
        q = rng.uniform(0, side, 2)
        if all(math.hypot(*(q - pos[j])) >= min_sep for j in range(k)):
            pos[k] = q
            k += 1
    return pos


def _particles(pos: np.ndarray, heading: np.ndarray, p: int, rng: np.random.Generator, model: Model,
               min_split_deg: float) -> tuple[tuple[int, ...], list[tuple[float, float]]] | None:
    n = len(pos)
    centre = pos.mean(axis=0)
    half = math.radians(model.cone_half_deg) * 0.9
    for _ in range(200):
        finders = tuple(int(i) for i in rng.choice(n, size=p, replace=False))
        spots = []
        for i in finders:
            d = rng.uniform(1.0, model.cone_len_u * 0.95)
            a = heading[i] + rng.uniform(-half, half)
            spots.append((float(pos[i, 0] + d * math.cos(a)), float(pos[i, 1] + d * math.sin(a))))
        if any(math.hypot(sx - pos[j, 0], sy - pos[j, 1]) <= model.consume_u + 0.5 for sx, sy in spots
               for j in range(n)):
            continue
        if p == 2:
            a0 = math.atan2(spots[0][1] - centre[1], spots[0][0] - centre[0])
            a1 = math.atan2(spots[1][1] - centre[1], spots[1][0] - centre[0])
            if abs(wrap(a0 - a1)) < math.radians(min_split_deg):
                continue
        return finders, spots
    return None


# -- a run -------------------------------------------------------------------------------------------------------

@dataclass
class ZebroRun:
    ticks_run: int
    consumed: list[tuple[int, int, int]]  # (tick, robot, utility), in the order eaten
    split: bool
    max_components: int
    components_end: int
    tx: dict[str, int]
    rx: dict[str, int]
    rx_bytes: int
    first_apart: int | None = None  # the first tick the communication graph was in pieces
    first_fast: int | None = None  # the first tick a robot walked at 3x (the mature leader)
    logs: list[dict[str, Any]] = field(default_factory=list)
    world: ZebroWorld | None = None

    @property
    def first(self) -> tuple[int, int, int] | None:
        return self.consumed[0] if self.consumed else None


class Swarm:
    """A scenario's world and one started controller per robot (their devices the point robot's), stepped a tick
    at a time: every robot's ``step()`` once, in a random order from the seeded stream, each walking in its turn."""

    def __init__(self, cls: type[Controller], params: dict[str, Any], scenario: Scenario, seed: int,
                 model: Model | None = None, keep_logs: bool = False) -> None:
        self.model = model = model or Model()
        self.logs: list[dict[str, Any]] = []
        parts = [Particle(x * U, y * U, u) for x, y, u in scenario.particles]
        self.world = world = ZebroWorld(scenario.pos, scenario.heading, scenario.r_comm, parts, model)
        self.clock = SteppedClock("the Zebro model drives controllers by ticks; they must not sleep")
        self.order_rng = np.random.default_rng(seed)
        self.ctls: list[Controller] = []
        for i in range(world.n):
            def sink(topic: str, values: dict[str, Any], i: int = i) -> None:
                if keep_logs:
                    self.logs.append({"tick": world.tick, "robot": i, "topic": topic, **values})
            robot = Robot(i, self.clock, None, np.random.Generator(np.random.PCG64([seed, i])), dict(params),
                          log_sink=sink, devices={UWB_RADIO: PointRadio(world, i), UTILITY: PointUtility(world, i),
                                                  IMU: PointImu(world, i), LEGS: PointLegs(world, i)})
            c = cls()
            c.init(robot)
            self.ctls.append(c)

    def tick(self) -> None:
        w = self.world
        w.tick += 1
        self.clock.t = w.tick * self.model.tick_s
        for i in self.order_rng.permutation(w.n).tolist():
            self.ctls[i].step()
            w.advance(i)
        w.end_tick()

    def topic(self, name: str) -> list[dict[str, Any]]:
        """The log records of one topic (``keep_logs``)."""
        return [r for r in self.logs if r["topic"] == name]


def run(cls: type[Controller], params: dict[str, Any], scenario: Scenario, seed: int, max_ticks: int = 300,
        settle_ticks: int = 10, split_ticks: int = 10, model: Model | None = None, keep_logs: bool = False) -> ZebroRun:
    """Run the swarm from ``scenario`` until ``settle_ticks`` after the first particle is eaten, or ``max_ticks``.

    A-13: the swarm split when its communication graph was in two or more pieces for ``split_ticks`` ticks in a
    row, or is at the end."""
    swarm = Swarm(cls, params, scenario, seed, model, keep_logs)
    world = swarm.world
    apart = most = comps = 0
    split = False
    first_apart: int | None = None
    first_tick: int | None = None
    while world.tick < max_ticks:
        swarm.tick()
        comps = components(world.adjacency())
        most = max(most, comps)
        if comps > 1 and first_apart is None:
            first_apart = world.tick
        apart = apart + 1 if comps > 1 else 0
        split |= apart >= split_ticks
        if first_tick is None and world.eat_count:
            first_tick = world.tick
        if first_tick is not None and world.tick >= first_tick + settle_ticks:
            break
    for c in swarm.ctls:
        c.destroy()
    split |= comps > 1
    eaten = [(p.tick, p.eaten_by, p.utility) for p in sorted(world.particles, key=lambda p: p.order) if p.order]
    return ZebroRun(world.tick, eaten, split, most, comps, {NAMES.get(k, str(k)): v for k, v in world.tx.items()},
                    {NAMES.get(k, str(k)): v for k, v in world.rx.items()}, world.rx_bytes, first_apart,
                    world.first_fast, swarm.logs, world)
