"""The numerical runner: the thesis' MATLAB-style studies, with the co-simulation's controllers unchanged.

Point robots in a plane (no firmware, no physics), all in one process, the thesis' own link model (a packet
reaches every robot within ``range_m``, or whose received power is above the sensitivity), an objective field
sensed at the robot's position, and random rectangular obstacles. Each robot gets a ``swarm_logic.robot.Robot``
whose devices are the point robot's: ``PointLlc`` (the ``LowLevel`` protocol: telemetry, rotate-then-go moves
executed at once) and ``PointRadio`` (the ``Radio`` protocol). The controller cannot tell this from the
co-simulation: it sees the same device protocols, clock and parameters.

Time is event-driven: the runner calls every controller due at the earliest wake-up time, then delivers the
packets sent in that round and applies the moves commanded, then senses at the new positions.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse.csgraph import connected_components

from bridge.numerical.objectives import Field, obstacle_distance, segment_entry
from swarm_logic.behaviours import load_behaviour
from swarm_logic.clock import SteppedClock
from swarm_logic.controller import Controller
from swarm_logic.drivers.llc_client import LlcState
from swarm_logic.robot import Robot


@dataclass(slots=True, frozen=True)
class PointTxStatus:
    """A unicast's delivery report (``Radio.tx_result``): ok when the destination was in range."""

    ok: bool

    @property
    def status(self) -> int:
        return 0 if self.ok else 0x21  # the Series 2 codes: success, network ACK failure


@dataclass(slots=True)
class Packet:
    src64: int
    data: bytes
    rssi_dbm: float | None
    broadcast: bool = True


class PointLlc:
    """A point robot's low-level controller: moves happen at once when the round ends."""

    def __init__(self, world: NumericalWorld, i: int) -> None:
        self.world = world
        self.i = i
        self.state = LlcState()
        self.led = (0, 0, 0)

    def poll(self) -> int:
        return 0

    def drive(self, v: float, w: float) -> None:
        raise NotImplementedError("point robots move by move(rot, dist), not by wheel speeds")

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        self.world.pending[self.i] = (rot_rad, dist_m)
        return 0

    def stop(self) -> None:
        self.world.pending.pop(self.i, None)

    def set_led(self, r: int, g: int, b: int) -> None:
        self.led = (r, g, b)

    def set_odometry(self, x: float, y: float, theta: float) -> None:
        """Odometry of a point robot is its true pose; the start pose it is told is where it was put."""


class PointRadio:
    def __init__(self, world: NumericalWorld, i: int) -> None:
        self.world = world
        self.i = i
        self.inbox: deque[Packet] = deque()
        self.fid = 0
        self.done: dict[int, PointTxStatus] = {}

    def send_nowait(self, dest64: int | None, data: bytes, *, options: int = 0, radius: int = 0) -> int:
        self.fid = self.fid % 255 + 1
        self.world.outbox.append((self.i, dest64, bytes(data), self.fid))
        return self.fid

    def tx_result(self, frame_id: int) -> PointTxStatus | None:
        """The report of a ``send_nowait``, once the round that carried it has ended (taken: returned once)."""
        return self.done.pop(frame_id, None)

    def recv(self, timeout: float | None = 0.0) -> Packet | None:
        return self.inbox.popleft() if self.inbox else None

    def poll(self) -> None:
        pass


@dataclass
class LinkModel:
    """The thesis' numerical link: within ``range_m`` (distance), or log-distance power above ``sensitivity``."""

    mode: str = "distance"  # distance | rssi
    range_m: float = math.inf
    tx_dbm: float = 3.0
    pl0_db: float = 47.4  # path loss at 1 m (MRSim's l_c)
    exponent: float = 6.0  # the eSwarBot floor profile (digest 3.7)
    sensitivity_dbm: float = -94.0

    def rssi(self, d: np.ndarray) -> np.ndarray:
        return self.tx_dbm - (self.pl0_db + 10 * self.exponent * np.log10(np.maximum(d, 0.1)))


@dataclass
class NumericalWorld:
    """Positions, headings, obstacles and the objective; what the point robots sense."""

    size: tuple[float, float]
    objective: Field
    obstacles: np.ndarray
    link: LinkModel
    pos: np.ndarray
    theta: np.ndarray
    pending: dict[int, tuple[float, float]] = field(default_factory=dict)
    outbox: list[tuple[int, int | None, bytes, int]] = field(default_factory=list)  # (sender, dest, data, frame id)
    collisions: int = 0
    packets: int = 0
    deliveries: int = 0


@dataclass
class RunResult:
    iterations: int
    best: np.ndarray  # best objective value found so far by the population, per iteration
    current: np.ndarray  # best objective value at the robots' positions, per iteration
    mean: np.ndarray
    subgroups: np.ndarray  # active subgroups per iteration
    excluded: np.ndarray  # excluded robots per iteration
    ruptures: np.ndarray  # active subgroups whose members are not connected (within the link range), per iteration
    collisions: int
    packets: int
    deliveries: int
    improvements: int  # personal-best improvements, all robots
    robot_iterations: int
    final_positions: np.ndarray
    logs: list[dict[str, Any]]


def chain_deployment(n: int, groups: list[list[int]], size: tuple[float, float], d_link: float,
                     obstacles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A31: each subgroup's robots one after the other, each uniformly within ``d_link`` of the previous one (the
    first anywhere), inside the arena and off obstacles, so each subgroup starts chain-connected."""
    w, h = size
    pos = np.zeros((n, 2))
    free = obstacles if len(obstacles) else np.zeros((0, 4))

    def ok(p: np.ndarray) -> bool:
        return 0 <= p[0] <= w and 0 <= p[1] <= h and (not len(free) or obstacle_distance(
            p[:1], p[1:], free)[0] > 0.0)

    for members in groups:
        prev = None
        for i in members:
            for _ in range(10000):
                if prev is None or not math.isfinite(d_link):
                    p = rng.uniform((0, 0), (w, h))
                else:
                    r = d_link * math.sqrt(rng.random())
                    a = rng.uniform(-math.pi, math.pi)
                    p = prev + r * np.array([math.cos(a), math.sin(a)])
                if ok(p):
                    break
            else:
                raise RuntimeError("no free place to deploy a robot: too many obstacles?")
            pos[i] = p
            prev = p
    return pos


def _fill_gaps(arr: np.ndarray, world: NumericalWorld) -> None:
    for k in range(len(arr)):
        if np.isnan(arr[k]):
            arr[k] = arr[k - 1] if k else float(np.max(_f_at(world)))


def _iteration_stats(per_iter: dict[int, list[tuple[int, int, bool, float, float]]], k0: int, iterations: int,
                     link: LinkModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """From the controllers' iteration records: subgroups and excluded robots per iteration, subgroup ruptures (a
    subgroup whose members are out of each other's reach), improvements and robot-iterations in all."""
    subgroups = np.zeros(iterations, int)
    excluded = np.zeros(iterations, int)
    ruptures = np.zeros(iterations, int)
    improvements = 0
    robot_iters = 0
    reach = link.range_m if link.mode == "distance" else 10 ** (
        (link.tx_dbm - link.pl0_db - link.sensitivity_dbm) / (10 * link.exponent))
    for kk, rows in per_iter.items():
        k = kk - k0
        if not 0 <= k < iterations:
            continue
        sids = [row[1] for row in rows]
        improvements += sum(1 for row in rows if row[2])
        robot_iters += len(rows)
        subgroups[k] = len({s for s in sids if s})
        excluded[k] = sum(1 for s in sids if s == 0)
        if math.isfinite(reach):
            ruptures[k] = subgroup_ruptures(np.array([(row[3], row[4]) for row in rows]), sids, reach)
    return subgroups, excluded, ruptures, improvements, robot_iters


def run(behaviour: str | type[Controller], params: dict[str, Any], n: int, iterations: int,
        objective: Field, size: tuple[float, float], obstacles: np.ndarray | None = None,
        link: LinkModel | None = None, seed: int = 0, start: np.ndarray | None = None,
        keep_logs: bool = False, deaths: dict[int, float] | None = None,
        until: Callable[[], bool] | None = None) -> RunResult:
    """Run ``n`` robots of ``behaviour`` for ``iterations`` iterations of their schedule; score them against
    ``objective``.

    ``deaths``: robot -> simulated time from which it is dead (stops, says nothing: a battery death).
    ``until``: asked after every round whose moves were applied (and the field observed); the run ends early when it
    says True (a search that ends when every target is found)."""
    cls = load_behaviour(behaviour) if isinstance(behaviour, str) else behaviour
    rng = np.random.default_rng(seed)
    obstacles = np.zeros((0, 4)) if obstacles is None else np.asarray(obstacles, float)
    link = link or LinkModel()
    p = {**params, "n_total": n}
    if n > 255 and "id_width" in getattr(cls, "defaults", {}):
        p.setdefault("id_width", 2)  # no radio frames here: a swarm beyond one-byte ids takes the wide message format
    it_s = float(p.get("iteration_s", 1.0))
    if start is None:
        g_init = int(p.get("subgroups_init", 1)) or 1
        groups = [[i for i in range(n) if i * g_init // n == g] for g in range(g_init)]
        start = chain_deployment(n, groups, size, float(p.get("d_max_m", link.range_m)), obstacles, rng)
    theta = rng.uniform(-math.pi, math.pi, n)
    world = NumericalWorld(size, objective, obstacles, link, np.array(start, float), theta)
    clock = SteppedClock("the numerical runner drives controllers by their period; they must not sleep")
    logs: list[dict[str, Any]] = []
    per_iter: dict[int, list[tuple[int, int, bool, float, float]]] = {}

    iteration_log = getattr(cls, "iteration_log", None)

    def sink_for(i: int):
        def sink(topic: str, values: dict[str, Any]) -> None:
            if topic == iteration_log:
                per_iter.setdefault(values["k"], []).append((i, values["sid"], values["improved"], values["x"],
                                                             values["y"]))
            if keep_logs:
                logs.append({"robot": i, "topic": topic, **values})
        return sink

    robots: list[Robot] = []
    ctls: list[Controller] = []
    for i in range(n):
        llc = PointLlc(world, i)
        robot = Robot(i, clock, llc, np.random.Generator(np.random.PCG64([seed, i])), dict(p),
                      xbee=PointRadio(world, i), log_sink=sink_for(i),
                      start_pose=(float(start[i][0]), float(start[i][1]), float(theta[i])))
        robots.append(robot)
    observe = getattr(objective, "observe", None)  # a map the robots build: they scan, then sense
    if observe is not None:
        observe(world.pos[:, 0], world.pos[:, 1], 0)
    _sense(world, robots)
    t_next = np.zeros(n)
    for i, robot in enumerate(robots):
        c = cls()
        c.init(robot)
        ctls.append(c)
        t_next[i] = c.period_s
    k0 = None
    t_end = None
    best = np.full(iterations, np.nan)
    cur = np.full(iterations, np.nan)
    mean = np.full(iterations, np.nan)
    running_best = -math.inf
    k_done = 0
    while True:
        t = float(t_next.min())
        if t_end is not None and t >= t_end:
            break
        clock.t = t
        due = np.flatnonzero(t_next <= t + 1e-9)
        if k0 is None:
            k0 = round(t / it_s)
            t_end = (k0 + iterations) * it_s
            objective.advance(0)
        elif objective.dynamic and abs(t / it_s - round(t / it_s)) < 1e-9:
            objective.advance(round(t / it_s) - k0)
        for i in due:
            if deaths and t >= deaths.get(int(i), math.inf):
                t_next[i] = math.inf
                continue
            robots[i].poll()
            ctls[i].step()
            t_next[i] = t + ctls[i].period_s
        _deliver(world, robots, deaths, t)
        if world.pending:
            _apply_moves(world)
            k = round((t - it_s * k0) / it_s - 0.5) if it_s else 0
            if observe is not None and 0 <= k < iterations:
                observe(world.pos[:, 0], world.pos[:, 1], k + 1)
            f = _sense(world, robots)
            if 0 <= k < iterations:
                running_best = max(running_best, float(f.max()))
                best[k], cur[k], mean[k] = running_best, f.max(), f.mean()
                k_done = max(k_done, k + 1)
            if until is not None and until():
                break
    for c in ctls:
        c.destroy()
    for arr in (best, cur, mean):  # iterations where nobody moved keep the last values
        _fill_gaps(arr, world)
    subgroups, excluded, ruptures, improvements, robot_iters = _iteration_stats(per_iter, k0 or 0, iterations, link)
    return RunResult(iterations, best, cur, mean, subgroups, excluded, ruptures, world.collisions, world.packets,
                     world.deliveries, improvements, robot_iters, world.pos.copy(), logs)


def _f_at(world: NumericalWorld) -> np.ndarray:
    return world.objective.value(world.pos[:, 0], world.pos[:, 1])


def _sense(world: NumericalWorld, robots: list[Robot]) -> np.ndarray:
    """Put what each point robot senses at its position into its LLC state; returns the objective values."""
    f = _f_at(world)
    if len(world.obstacles):
        g = obstacle_distance(world.pos[:, 0], world.pos[:, 1], world.obstacles)
    else:
        g = np.full(len(robots), math.inf)
    for i, r in enumerate(robots):
        st = r.llc.state
        st.x, st.y, st.theta = float(world.pos[i, 0]), float(world.pos[i, 1]), float(world.theta[i])
        st.odom_t = 0.0
        st.light_raw = float(f[i])
        st.sonar_m = float(g[i])
        st.sonar_valid = math.isfinite(st.sonar_m)
    return f


def _deliver(world: NumericalWorld, robots: list[Robot], deaths: dict[int, float] | None, t: float) -> None:
    """The round's packets to every robot in reach, in the order they were sent; each sender gets its report."""
    if not world.outbox:
        return
    pos = world.pos
    link = world.link
    senders = np.array([s for s, _, _, _ in world.outbox])
    rows, cols, rssi = _reach(pos, senders, link)
    starts = np.searchsorted(rows, np.arange(len(senders) + 1)).tolist()
    cols = cols.tolist()
    rssi = None if rssi is None else rssi.tolist()
    dead = None if not deaths else {j for j, t_dead in deaths.items() if t >= t_dead}
    inboxes: dict[int, list[Packet]] = {}  # receiver -> its packets of this round, in sending order
    for row, (s, dest, data, fid) in enumerate(world.outbox):
        world.packets += 1
        lo, hi = starts[row], starts[row + 1]
        if dest is None:
            span = range(lo, hi)
            ok = True  # a broadcast always goes out
        else:  # a unicast is acknowledged by a live destination in range
            at = bisect.bisect_left(cols, dest, lo, hi)
            span = range(at, at + 1) if at < hi and cols[at] == dest else range(0)
            ok = bool(span) and not (dead and dest in dead)
        robots[s].xbee.done[fid] = PointTxStatus(ok)
        shared = Packet(s, data, None) if rssi is None else None  # one object for every receiver: they only read it
        for q in span:
            j = cols[q]
            if j == s or (dead and j in dead):
                continue
            pkt = shared if rssi is None else Packet(s, data, rssi[q])
            if (box := inboxes.get(j)) is None:
                inboxes[j] = [pkt]
            else:
                box.append(pkt)
    for j, pkts in inboxes.items():
        robots[j].xbee.inbox.extend(pkts)
        world.deliveries += len(pkts)
    world.outbox.clear()


def _reach(pos: np.ndarray, senders: np.ndarray, link: LinkModel) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Who hears whom: (row, robot) pairs, sorted, of the senders' rows (indices into ``senders``) and the robots in
    their reach, and the received power of each pair (None in distance mode).

    Distance and power are ``np.hypot`` of the coordinate differences, the same numbers as a dense sender x robot
    matrix; a k-d tree only picks the candidate pairs (within the reach plus a margin far above rounding), so a large
    swarm costs its neighbours, not its square."""
    if link.mode == "distance":
        reach = link.range_m
    else:
        reach = 10 ** ((link.tx_dbm - link.pl0_db - link.sensitivity_dbm) / (10 * link.exponent))
    n = len(pos)
    if not math.isfinite(reach) or len(senders) * n <= 250_000:  # small swarms (and no range): the dense matrix
        d = np.hypot(pos[senders, None, 0] - pos[None, :, 0], pos[senders, None, 1] - pos[None, :, 1])
        rows, cols = np.nonzero(d <= reach if link.mode == "distance" else link.rssi(d) >= link.sensitivity_dbm)
        dist = d[rows, cols]
    else:
        from scipy.spatial import cKDTree

        pairs = cKDTree(pos).query_ball_point(pos[senders], reach * (1 + 1e-9) + 1e-9)
        rows = np.repeat(np.arange(len(senders)), [len(p) for p in pairs])
        cols = np.fromiter((j for p in pairs for j in p), int, len(rows))
        order = np.lexsort((cols, rows))
        rows, cols = rows[order], cols[order]
        dist = np.hypot(pos[senders[rows], 0] - pos[cols, 0], pos[senders[rows], 1] - pos[cols, 1])
        keep = dist <= reach if link.mode == "distance" else link.rssi(dist) >= link.sensitivity_dbm
        rows, cols, dist = rows[keep], cols[keep], dist[keep]
    return rows, cols, None if link.mode == "distance" else link.rssi(dist)


def _apply_moves(world: NumericalWorld) -> None:
    w, h = world.size
    idx = np.fromiter(world.pending.keys(), int)
    rot = np.array([v[0] for v in world.pending.values()])
    dist = np.array([v[1] for v in world.pending.values()])
    world.pending.clear()
    th = world.theta[idx] + rot
    th = np.arctan2(np.sin(th), np.cos(th))
    x0, y0 = world.pos[idx, 0], world.pos[idx, 1]
    x1 = np.clip(x0 + dist * np.cos(th), 0.0, w)
    y1 = np.clip(y0 + dist * np.sin(th), 0.0, h)
    if len(world.obstacles):
        t = segment_entry(x0, y0, x1, y1, world.obstacles)
        hit = np.isfinite(t)
        world.collisions += int(hit.sum())
        # a point robot that runs into an obstacle stops just short of it (a collision)
        length = np.maximum(np.hypot(x1 - x0, y1 - y0), 1e-12)
        f = np.where(hit, np.maximum(0.0, t - 1e-3 / length), 1.0)
        x1, y1 = x0 + f * (x1 - x0), y0 + f * (y1 - y0)
    world.pos[idx, 0], world.pos[idx, 1] = x1, y1
    world.theta[idx] = th


def subgroup_ruptures(positions: np.ndarray, sids: list[int], range_m: float) -> int:
    """Active subgroups whose members are not all connected (multi-hop, within ``range_m``)."""
    out = 0
    for s in set(sids) - {0}:
        members = [i for i, v in enumerate(sids) if v == s]
        if len(members) < 2:
            continue
        p = positions[members]
        d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
        n_comp, _ = connected_components(d <= range_m, directed=False)
        out += n_comp > 1
    return out
