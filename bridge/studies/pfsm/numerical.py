"""Khan's ARGoS setup in numbers: point foot-bots in a walled square arena with a base strip along one wall (a grey
floor patch under a light), running the PFSM family's controllers unchanged through Point* implementations of the
foot-bot's device protocols (``swarm_logic.robots.footbot.interfaces``).

Tick semantics (ARGoS's): every tick all robots sense the world as the previous tick left it, every controller steps
once, then every robot moves (unicycle from its wheel speeds, ``TICK_S``), bodies never overlap (a move that would
overlap another body or cross a wall is cut back). The loop functions' figures (digest 4.1): the searchers'
energy per tick (one unit per searcher not resting, K-7), each target's discovery time, the targets found.

The range-and-bearing model (``RabModel``): every robot hears every other robot within ``range_m`` (3 m, ARGoS's
foot-bot default) whose line of sight no third body crosses (ARGoS checks occlusions by embodied entities), once per
tick (the board's update is the control step), the payload the sender set by the end of the previous tick; range and
bearing are exact and nothing is lost by default (ARGoS's noise and packet-drop defaults are 0); noise, loss and the
update period are parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bridge.core.rng import stream
from swarm_logic.clock import SteppedClock
from swarm_logic.controller import Controller
from swarm_logic.families.pfsm import messages as msg
from swarm_logic.families.pfsm.searcher import PfsmSearcher
from swarm_logic.families.pfsm.target import PfsmTarget
from swarm_logic.robot import Robot
from swarm_logic.robots.footbot.interfaces import (
    BASE_GROUND,
    BASE_GROUND_OFFSETS_M,
    BODY_RADIUS_M,
    LEDS,
    LIGHT,
    LIGHT_COUNT,
    MOTOR_GROUND,
    MOTOR_GROUND_OFFSETS_M,
    PROXIMITY,
    PROXIMITY_COUNT,
    PROXIMITY_RANGE_M,
    RAB_PAYLOAD_BYTES,
    RAB_RANGE_M,
    RANGE_AND_BEARING,
    WHEEL_BASE_M,
    WHEELS,
    GroundReading,
    RabPacket,
    RingReading,
    check_payload,
    ring_angles,
)

TICK_S = 0.1  # ARGoS's examples: 10 ticks per second
PROX_ANGLES = ring_angles(PROXIMITY_COUNT)
LIGHT_ANGLES = ring_angles(LIGHT_COUNT)
NO_PROXIMITY = tuple(RingReading(0.0, a) for a in PROX_ANGLES)
WHITE, GREY = 1.0, 0.5  # the floor and the base patch, as the motor-ground sensors read them


@dataclass(frozen=True)
class RabModel:
    """The range-and-bearing board's figures."""

    range_m: float = RAB_RANGE_M  # ARGoS foot-bot default
    occlusion: bool = True  # a third body on the line of sight blocks it (ARGoS checks occlusions)
    range_noise_m: float = 0.0  # std of a Gaussian error on the range (ARGoS default 0)
    bearing_noise_rad: float = 0.0  # std of a Gaussian error on the bearing (ARGoS default 0)
    loss: float = 0.0  # probability a reading is dropped (ARGoS packet_drop_prob default 0)
    period_ticks: int = 1  # the board's update: every control step (ARGoS); k > 1 holds the readings k ticks

    def __post_init__(self) -> None:
        if self.period_ticks < 1 or not 0.0 <= self.loss <= 1.0 or self.range_m <= 0:
            raise ValueError(f"range-and-bearing model: range > 0, loss in [0, 1], period_ticks >= 1; got {self}")


@dataclass(frozen=True)
class Arena:
    """A closed square of side ``side_m`` (K-10: walls, no interior obstacles), the base the strip x < ``base_depth_m``
    along the west wall (K-6, K-8) with the light above its centre."""

    side_m: float
    base_depth_m: float = 1.0  # an assumption: the document's maps are lost
    light_height_m: float = 1.0  # ARGoS foraging's light: 1 m up, intensity 3
    light_intensity: float = 3.0

    @property
    def area_m2(self) -> float:
        return self.side_m * self.side_m

    @property
    def light(self) -> tuple[float, float]:
        return self.base_depth_m / 2, self.side_m / 2

    def in_base(self, x: float, y: float) -> bool:
        return 0.0 <= x < self.base_depth_m and 0.0 <= y <= self.side_m


def place(n: int, lo: tuple[float, float], hi: tuple[float, float], min_sep: float, rng: np.random.Generator,
          avoid: np.ndarray | None = None, what: str = "robots", attempts: int = 200) -> np.ndarray:
    """``n`` points uniform in the rectangle lo..hi, at least ``min_sep`` apart and from ``avoid``; ValueError when
    they cannot fit (more than random placement can pack: half the rectangle covered by their discs)."""
    w, h = hi[0] - lo[0], hi[1] - lo[1]
    cover = n * math.pi * (min_sep / 2) ** 2
    if w <= 0 or h <= 0 or cover > 0.45 * w * h:
        raise ValueError(f"{n} {what} at least {min_sep:.3f} m apart do not fit in a {max(w, 0):.2f} x "
                         f"{max(h, 0):.2f} m region (their discs would cover {cover:.2f} m^2, random placement packs "
                         f"at most {0.45 * max(w, 0) * max(h, 0):.2f}); enlarge the region or place fewer")
    others = np.zeros((0, 2)) if avoid is None else np.asarray(avoid, float).reshape(-1, 2)
    out = np.zeros((n, 2))
    k = 0
    tries = 0
    while k < n:
        q = rng.uniform(lo, hi)
        taken = np.vstack([others, out[:k]])
        if not len(taken) or np.min(np.hypot(taken[:, 0] - q[0], taken[:, 1] - q[1])) >= min_sep:
            out[k] = q
            k += 1
            tries = 0
        else:
            tries += 1
            if tries > attempts * n:
                raise ValueError(f"could not place {what} {k + 1} of {n} at least {min_sep:.3f} m apart in the region")
    return out


@dataclass
class Deployment:
    """Where the searchers start (random in the base, K-8) and where the targets wait (random outside it)."""

    searchers: np.ndarray
    headings: np.ndarray
    targets: np.ndarray


def deploy(arena: Arena, n_searchers: int, n_targets: int, seed: int, gap_m: float = 0.02) -> Deployment:
    """Searchers uniform in the base, targets uniform in the rest of the arena, bodies ``gap_m`` apart at least, all
    from ``stream(seed, "deploy")``; ValueError naming the base when the searchers do not fit in it."""
    rng = stream(seed, "deploy")
    r, s = BODY_RADIUS_M, 2 * BODY_RADIUS_M + gap_m
    if arena.base_depth_m >= arena.side_m:
        raise ValueError(f"base depth {arena.base_depth_m} m leaves no arena to search (side {arena.side_m} m)")
    try:
        sp = place(n_searchers, (r, r), (arena.base_depth_m - r, arena.side_m - r), s, rng, what="searchers")
    except ValueError as e:
        raise ValueError(f"the base region ({arena.base_depth_m} x {arena.side_m} m) cannot hold {n_searchers} "
                         f"searchers: {e}") from None
    tp = place(n_targets, (arena.base_depth_m + r, r), (arena.side_m - r, arena.side_m - r), s, rng,
               avoid=sp, what="targets")
    return Deployment(sp, rng.uniform(-math.pi, math.pi, n_searchers), tp)


class FootbotWorld:
    """Bodies (searchers first, then targets), their wheel commands and payloads, and what each sensor reads."""

    def __init__(self, arena: Arena, dep: Deployment, rab: RabModel, seed: int, max_wheel_mps: float) -> None:
        self.arena, self.rab_model = arena, rab
        self.ns, self.nt = len(dep.searchers), len(dep.targets)
        self.n = self.ns + self.nt
        self.pos = np.vstack([dep.searchers, dep.targets]).astype(float).reshape(-1, 2)
        self.h = np.concatenate([dep.headings, np.zeros(self.nt)])
        self.wheels = np.zeros((self.n, 2))
        self.max_wheel = max_wheel_mps
        self.payload: list[bytes] = [b""] * self.n
        self.sent: list[bytes] = [b""] * self.n  # what the boards carry this tick (last tick's payloads)
        self.rng = stream(seed, "rab")
        self.tick = 0
        self._rab: list[list[RabPacket] | None] = [None] * self.n
        self.sense()

    def sense(self) -> None:
        """The snapshot this tick's readings come from: positions, and on the board's update ticks what it hears
        (last tick's payloads, ranges and bearings), held until its next update."""
        x, y = self.pos[:, 0], self.pos[:, 1]
        self.dx = x[None, :] - x[:, None]
        self.dy = y[None, :] - y[:, None]
        self.d = np.hypot(self.dx, self.dy)
        if self.tick % self.rab_model.period_ticks:
            return
        self.sent = list(self.payload)
        b = np.arctan2(self.dy, self.dx) - self.h[:, None]
        self.rab_d = self.d
        self.rab_b = np.arctan2(np.sin(b), np.cos(b))  # bearing of j from i, in i's frame
        self.hear = self.links()
        self._rab = [None] * self.n

    def links(self) -> np.ndarray:
        """hear[i, j]: i reads j this tick (in range, line of sight clear, not lost)."""
        m = self.rab_model
        hear = self.d <= m.range_m
        np.fill_diagonal(hear, False)
        if m.occlusion and self.n > 2:
            iu, ju = np.nonzero(np.triu(hear, 1))
            if len(iu):
                p = self.pos
                sx, sy = p[ju, 0] - p[iu, 0], p[ju, 1] - p[iu, 1]  # (m,)
                ll = sx * sx + sy * sy
                kx = p[None, :, 0] - p[iu, 0][:, None]  # (m, n): every body from the pair's first end
                ky = p[None, :, 1] - p[iu, 1][:, None]
                dot = kx * sx[:, None] + ky * sy[:, None]
                cross = kx * sy[:, None] - ky * sx[:, None]
                lc = ll[:, None]
                # a body strictly between the ends whose centre lies within a radius of the line of sight
                blocked = (dot > 0) & (dot < lc) & (cross * cross < (BODY_RADIUS_M * BODY_RADIUS_M) * lc)
                rows = np.arange(len(iu))
                blocked[rows, iu] = False
                blocked[rows, ju] = False
                bad = blocked.any(axis=1)
                hear[iu[bad], ju[bad]] = False
                hear[ju[bad], iu[bad]] = False
        if m.loss > 0:
            hear &= self.rng.random(hear.shape) >= m.loss
        return hear

    def rab_readings(self, i: int) -> list[RabPacket]:
        cached = self._rab[i]
        if cached is not None:
            return cached
        m = self.rab_model
        js = np.nonzero(self.hear[i])[0]
        rs, bs, sent = self.rab_d[i, js].tolist(), self.rab_b[i, js].tolist(), self.sent
        noisy = m.range_noise_m > 0 or m.bearing_noise_rad > 0
        out = []
        for j, r, b in zip(js.tolist(), rs, bs, strict=True):
            data = sent[j]
            if not data:
                continue
            if noisy:
                r = max(0.0, r + float(self.rng.normal(0.0, m.range_noise_m))) if m.range_noise_m > 0 else r
                if m.bearing_noise_rad > 0:
                    b += float(self.rng.normal(0.0, m.bearing_noise_rad))
                    b = math.atan2(math.sin(b), math.cos(b))
            out.append(RabPacket(r, b, data))
        self._rab[i] = out
        return out

    def proximity(self, i: int) -> list[RingReading] | tuple[RingReading, ...]:
        """Each sensor is a ray from the body's surface along its angle, reading 1 - distance / range to the first
        wall or body it meets within ``PROXIMITY_RANGE_M`` (0 beyond): a wall ahead lights a fan of sensors, as
        ARGoS's ray-cast sensors do (the linear fall-off is an assumption; ARGoS's curve is not modelled)."""
        a = self.arena
        x, y, h = float(self.pos[i, 0]), float(self.pos[i, 1]), float(self.h[i])
        reach = BODY_RADIUS_M + PROXIMITY_RANGE_M
        walls = [(gap, normal) for gap, normal in ((x, math.pi), (a.side_m - x, 0.0), (y, -math.pi / 2),
                                                  (a.side_m - y, math.pi / 2)) if gap < reach]
        near = [j for j in np.nonzero(self.d[i] < 2 * BODY_RADIUS_M + PROXIMITY_RANGE_M)[0].tolist() if j != i]
        if not walls and not near:
            return NO_PROXIMITY
        bodies = [(float(self.dx[i, j]), float(self.dy[i, j])) for j in near]
        out = []
        r2 = BODY_RADIUS_M * BODY_RADIUS_M
        for ang in PROX_ANGLES:
            wa = h + ang
            c, s = math.cos(wa), math.sin(wa)
            best = PROXIMITY_RANGE_M
            for gap, normal in walls:  # the ray from the surface point to the wall's plane
                cn = math.cos(wa - normal)
                if cn > 1e-9:
                    best = min(best, (gap - BODY_RADIUS_M * cn) / cn)
            for bx, by in bodies:  # the ray from the centre meets the other body's circle
                t = bx * c + by * s
                q = bx * bx + by * by - t * t
                if t > 0 and q < r2:
                    best = min(best, t - math.sqrt(r2 - q) - BODY_RADIUS_M)
            out.append(RingReading(min(1.0, max(0.0, 1.0 - best / PROXIMITY_RANGE_M)), ang))
        return out

    def light(self, i: int) -> list[RingReading]:
        """The light above the base: each sensor reads (I / distance)^2 x cos of its angle off the light's direction
        (0 facing away); no occlusion."""
        a = self.arena
        lx, ly = a.light
        x, y = float(self.pos[i, 0]), float(self.pos[i, 1])
        dist2 = (lx - x) ** 2 + (ly - y) ** 2 + a.light_height_m ** 2
        b = math.atan2(ly - y, lx - x) - float(self.h[i])
        k = a.light_intensity ** 2 / dist2
        return [RingReading(max(0.0, math.cos(ang - b)) * k, ang) for ang in LIGHT_ANGLES]

    def ground(self, i: int) -> list[GroundReading]:
        x, y, h = float(self.pos[i, 0]), float(self.pos[i, 1]), float(self.h[i])
        c, s = math.cos(h), math.sin(h)
        return [GroundReading(GREY if self.arena.in_base(x + ox * c - oy * s, y + ox * s + oy * c) else WHITE, (ox, oy))
                for ox, oy in MOTOR_GROUND_OFFSETS_M]

    def move(self, dt: float) -> None:
        """Unicycle from the wheels (midpoint heading); a move into a wall or onto another body is not taken."""
        w = np.clip(self.wheels, -self.max_wheel, self.max_wheel)
        v = (w[:, 0] + w[:, 1]) / 2
        om = (w[:, 1] - w[:, 0]) / WHEEL_BASE_M
        hm = self.h + om * dt / 2
        new = self.pos + np.column_stack([v * np.cos(hm), v * np.sin(hm)]) * dt
        self.h = np.arctan2(np.sin(self.h + om * dt), np.cos(self.h + om * dt))
        r, side = BODY_RADIUS_M, self.arena.side_m
        new = np.clip(new, r, side - r)
        moving = np.nonzero(v != 0)[0]
        for i in moving.tolist():
            dd = np.hypot(self.pos[:, 0] - new[i, 0], self.pos[:, 1] - new[i, 1])
            dd[i] = np.inf
            if dd.min() >= 2 * r:
                self.pos[i] = new[i]
        self.tick += 1


    def rescue(self, i: int) -> None:
        """Body ``i`` (a target home in the base) is lifted out of the arena, as ARGoS foraging's loop functions take
        the items dropped in the nest: it no longer blocks the base's entrance, is heard or occludes (an assumption:
        the document says only that found targets return to the base)."""
        self.pos[i] = (-1000.0 - 10.0 * i, -1000.0)
        self.wheels[i] = 0.0
        self.sense()


class PointRab:
    """``RangeAndBearing``: the world's readings of this robot; ``send`` sets what it carries from the next tick."""

    max_payload = RAB_PAYLOAD_BYTES

    def __init__(self, world: FootbotWorld, i: int) -> None:
        self.w, self.i = world, i
        self.range_m = world.rab_model.range_m
        self.bytes_sent = 0
        self.sends = 0  # payloads set: one broadcast each (the board carries it from the next tick)

    def readings(self) -> list[RabPacket]:
        return self.w.rab_readings(self.i)

    def send(self, data: bytes) -> None:
        b = check_payload(data, self.max_payload)
        self.w.payload[self.i] = b
        self.bytes_sent += len(b)
        self.sends += 1


class PointProximity:
    def __init__(self, world: FootbotWorld, i: int) -> None:
        self.w, self.i = world, i

    def readings(self) -> list[RingReading]:
        return list(self.w.proximity(self.i))


class PointLight:
    def __init__(self, world: FootbotWorld, i: int) -> None:
        self.w, self.i = world, i

    def readings(self) -> list[RingReading]:
        return self.w.light(self.i)


class PointGround:
    def __init__(self, world: FootbotWorld, i: int) -> None:
        self.w, self.i = world, i

    def readings(self) -> list[GroundReading]:
        return self.w.ground(self.i)


class PointBaseGround:
    """The 8 black-or-white sensors: 1 where the floor's grey level is 0.5 or more."""

    def __init__(self, world: FootbotWorld, i: int) -> None:
        self.w, self.i = world, i

    def readings(self) -> list[GroundReading]:
        w, i = self.w, self.i
        x, y, h = float(w.pos[i, 0]), float(w.pos[i, 1]), float(w.h[i])
        c, s = math.cos(h), math.sin(h)
        return [GroundReading(float((GREY if w.arena.in_base(x + ox * c - oy * s, y + ox * s + oy * c) else WHITE)
                                    >= 0.5), (ox, oy)) for ox, oy in BASE_GROUND_OFFSETS_M]


class PointWheels:
    """``DifferentialSteering``: the speeds hold until changed; the world moves the body at the end of the tick."""

    def __init__(self, world: FootbotWorld, i: int) -> None:
        self.w, self.i = world, i
        self.max_speed_mps = world.max_wheel

    def set_speeds(self, left_mps: float, right_mps: float) -> None:
        self.w.wheels[self.i] = (left_mps, right_mps)


class PointLeds:
    def __init__(self) -> None:
        self.rgb = (0, 0, 0)

    def set_all_colors(self, rgb: tuple[int, int, int]) -> None:
        self.rgb = rgb


def p_sta(e_total: float, t_total: float, n_found: int, n_targets: int, area_m2: float, n_searchers: int,
          a1_m2: float = 1.0) -> float:
    """Khan's eq. 2: P_STA = 1000 / (E_total T_total) x N_T,found^2 / N_T,total x (A / A_1) / N_S,total (NaN when
    E or T is 0)."""
    if e_total <= 0 or t_total <= 0:
        return math.nan
    return 1000.0 / (e_total * t_total) * (n_found ** 2 / n_targets) * ((area_m2 / a1_m2) / n_searchers)


# -- a run -------------------------------------------------------------------------------------------------------

@dataclass
class SearchRun:
    """The loop functions' figures of one run."""

    ticks: int
    found_s: list[float | None]  # per target: when it was given energy (s), None never
    energy: list[int]  # per tick: searchers not resting (K-7)
    energy_all: list[int]  # per tick: searchers not resting + targets driving home
    home: int  # targets that reached the base
    bytes_sent: int
    searcher_sends: int = 0  # range-and-bearing broadcasts the searchers sent (``PointRab.sends``)
    search_ticks: int = 0  # searcher-ticks in SEARCH out of the base
    still_ticks: int = 0  # of those, with both wheels stopped (no target heard, LJ at rest: K-S5's stall)
    logs: list[dict[str, Any]] = field(default_factory=list)

    @property
    def n_found(self) -> int:
        return sum(t is not None for t in self.found_s)

    @property
    def t_last_s(self) -> float:
        """T_total: when the last target was found, or the run's length when some never were."""
        if self.found_s and self.n_found == len(self.found_s):
            return max(t for t in self.found_s if t is not None)
        return self.ticks * TICK_S

    def energy_until(self, t_s: float, all_robots: bool = False) -> int:
        """E_total: the energy spent up to ``t_s``."""
        k = round(t_s / TICK_S)
        return int(sum((self.energy_all if all_robots else self.energy)[:k]))


class Swarm:
    """The world and one started controller per robot, their devices the point robot's."""

    def __init__(self, arena: Arena, dep: Deployment, seed: int, params: dict[str, Any] | None = None,
                 target_params: dict[str, Any] | None = None, rab: RabModel | None = None,
                 searcher: type[Controller] = PfsmSearcher, target: type[Controller] = PfsmTarget,
                 keep_logs: bool = False, max_wheel_mps: float = 0.3) -> None:
        self.world = w = FootbotWorld(arena, dep, rab or RabModel(), seed, max_wheel_mps)
        self.clock = SteppedClock("the foot-bot model drives controllers by ticks; they must not sleep")
        self.logs: list[dict[str, Any]] = []
        self.ctls: list[Controller] = []
        self.rabs: list[PointRab] = []
        self.leds: list[PointLeds] = []
        for i in range(w.n):
            def sink(topic: str, values: dict[str, Any], i: int = i) -> None:
                if keep_logs:
                    self.logs.append({"tick": w.tick, "robot": i, "topic": topic, **values})
            is_s = i < w.ns
            rab_dev, leds = PointRab(w, i), PointLeds()
            devs = {RANGE_AND_BEARING: rab_dev, PROXIMITY: PointProximity(w, i), LIGHT: PointLight(w, i),
                    MOTOR_GROUND: PointGround(w, i), BASE_GROUND: PointBaseGround(w, i), WHEELS: PointWheels(w, i),
                    LEDS: leds}
            own = dict((params if is_s else target_params) or {})
            robot = Robot(i, self.clock, None, stream(seed, "robot", i), own, log_sink=sink, devices=devs)
            c = (searcher if is_s else target)()
            c.init(robot)
            self.ctls.append(c)
            self.rabs.append(rab_dev)
            self.leds.append(leds)
        w.sense()
        self.found_s: list[float | None] = [None] * w.nt
        self.energy: list[int] = []
        self.energy_all: list[int] = []
        self.search_ticks = self.still_ticks = 0

    def tick(self) -> None:
        w = self.world
        self.clock.t = w.tick * TICK_S
        for c in self.ctls:
            c.step()
        w.move(TICK_S)
        w.sense()
        states = [getattr(c, "state", None) for c in self.ctls[:w.ns]]
        resting = states.count(msg.TIMEOUT)
        base = self.world.arena.base_depth_m
        searching = [i for i, st in enumerate(states) if st == msg.SEARCH and w.pos[i, 0] >= base]
        self.search_ticks += len(searching)
        if searching:
            self.still_ticks += int(np.count_nonzero(np.abs(w.wheels[searching]).max(axis=1) < 1e-3))
        homing = 0
        for k, c in enumerate(self.ctls[w.ns:]):
            st = getattr(c, "state", msg.WAITING)
            if st != msg.WAITING and self.found_s[k] is None:
                self.found_s[k] = w.tick * TICK_S
            homing += st == msg.HOMING
            if st == msg.HOME and w.pos[w.ns + k, 0] >= 0:
                w.rescue(w.ns + k)
        self.energy.append(w.ns - resting)
        self.energy_all.append(w.ns - resting + homing)

    def all_found(self) -> bool:
        return all(t is not None for t in self.found_s)

    def run(self, max_s: float, until_all_found: bool = True) -> SearchRun:
        """Tick until every target is found (``until_all_found``) or ``max_s`` of simulated time."""
        while self.world.tick * TICK_S < max_s - 1e-9:
            self.tick()
            if until_all_found and self.all_found():
                break
        for c in self.ctls:
            c.destroy()
        home = sum(1 for c in self.ctls[self.world.ns:] if getattr(c, "state", None) == msg.HOME)
        return SearchRun(self.world.tick, list(self.found_s), self.energy, self.energy_all, home,
                         sum(r.bytes_sent for r in self.rabs), sum(r.sends for r in self.rabs[:self.world.ns]),
                         self.search_ticks, self.still_ticks, self.logs)
