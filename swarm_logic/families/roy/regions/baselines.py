"""The methods Roy (2022) compares chapters 4 and 7 against, as region planners for the point model (digest 001
§4.6), and the host a chapter 4 controller runs on (Table 7.6).

- ``AggregationPlanner`` (planner ``aggregation``): the no-communication aggregation baseline of Fig. 4.15 (Shah &
  Vachhani 2019, the thesis' [96]: "a decentralized controller inspired by APF for aggregation ... using only a
  local sensing scheme with no inter-agent communication", "does not require the global positioning information").
  Each agent, on its own, every sensing period: a pull toward the target's bearing (a beacon it senses) plus an
  attraction to the centroid of the teammates within its sensing range; every step, an exponential repulsion from
  its nearest teammates and sonar points (eq. 6.5's kernel, law ``split_merge`` in "knn" mode). No region, no
  shared plan: the "planner" is N independent controllers evaluated together, each from its own row's data.
- ``VisionLeaderFollowerPlanner`` (planner ``vision_lf``): the vision leader-follower baseline of Table 7.6 (Wang et
  al. 2016, the thesis' [103]). The leader moves along a predefined trajectory (the thesis' own account of
  leader-follower, §2.2: "a particular robot ... will move along a predefined trajectory ... the followers will
  accompany the lead agent by keeping a certain distance"), here a route of waypoints at ``leader_speed`` x v_max.
  The followers form a chain, each keeping ``follow_distance`` behind its predecessor, which it measures only with
  its camera, once per frame (the planner's period): within ``camera_range`` and within the field of view
  ``camera_fov_deg`` about the bearing where it last saw it (the camera keeps its target centred, as Wang's visual
  servoing does; a point agent cannot turn in place); out of view it goes to where it last saw it. A follower
  whose predecessor is home (within ``home_radius`` of the target) goes home too.
- ``HostedCh4Planner`` (planner ``ch4_hosted``): chapter 4's planner on a host that takes time (Table 7.6's
  "proposed scheme with centralized controller" on the i7 PC, "with L-F" on the leader's Raspberry Pi). An update
  takes ``window_s`` (the sonar window, §7.4.1: 250 ms) plus the region computation, ``compute_s_per_agent`` x N x
  ``host_factor`` (§7.4.1: the k-means over the robots' windows "typically consumes 50 msec" for the six-robot
  runs on the PC: 50/6 ms per robot; the Pi's factor is ours, the thesis gives none). The region advances one step
  (the planner's period of its dynamics) per update, and the plan of an update is published when it ends: a slower
  host moves the region less often.

Every choice the thesis leaves open is a field of the planner's ``Params`` with its reason in the docs page
(docs/roy-ch4.md for the aggregation baseline, docs/roy-baselines.md for the rest).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from swarm_logic.families.roy.regions.ch4 import Ch4Params, Ch4Planner
from swarm_logic.families.roy.regions.planner import Observation, Plan, RegionPlanner
from swarm_logic.families.roy.regions.records import check_fields, require

HOSTS = ("pc", "rpi")


def toward(x: np.ndarray, points: np.ndarray, speed: np.ndarray | float, k_c: float) -> np.ndarray:
    """The goals (N, 2) that make the pull -k_c (x - g) a velocity of length ``speed`` from each x (N, 2) toward its
    point (N, 2), or the point itself when it is nearer than that (the pull then brings the agent onto it)."""
    d = np.asarray(points, float) - x
    r = np.hypot(d[:, 0], d[:, 1])
    reach = np.broadcast_to(np.asarray(speed, float), r.shape) / k_c
    f = np.where(r > reach, reach / np.maximum(r, 1e-300), 1.0)
    return x + d * f[:, None]


def local_centroids(x: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Each agent's view of its teammates within ``radius`` (a range-and-bearing sensor, no message): their centroid
    (N, 2) (its own position when it sees none) and how many it sees (N,)."""
    n = len(x)
    if n < 2:
        return x.copy(), np.zeros(n, int)
    pairs = cKDTree(x).query_pairs(radius, output_type="ndarray")
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    count = np.bincount(i, minlength=n)
    sx = np.bincount(i, x[j, 0], n)
    sy = np.bincount(i, x[j, 1], n)
    seen = count > 0
    c = x.copy()
    c[seen] = np.stack([sx[seen], sy[seen]], axis=1) / count[seen, None]
    return c, count


@dataclass(frozen=True)
class KnnLawParams:
    """The baselines' local law: eq. 6.5 in its "knn" mode, the pull ``k_c`` toward each agent's goal and the
    repulsion ``k_f`` exp(-d / ``r_s``) from its ``neighbours`` nearest teammates and sonar points within
    ``radius_scales`` r_s (the same kernel as the proposed method's chapter 6 law); ``period_s`` the planner's."""

    k_c: float = 0.5
    k_f: float = 1.0
    r_s: float = 0.5
    radius_scales: float = 3.0
    neighbours: int = 8
    period_s: float = 0.25

    def __post_init__(self) -> None:
        check_fields(self, ("k_c", "k_f", "r_s", "radius_scales", "period_s"))
        k = self.neighbours
        require(isinstance(k, int) and k >= 1, "neighbours", "must be an integer >= 1", k)

    def law_params(self) -> dict[str, Any]:
        """The plan's ``params`` for the law ``split_merge``."""
        return {
            "mode": "knn",
            "k_c": self.k_c,
            "k_f": self.k_f,
            "r_s": self.r_s,
            "radius_scales": self.radius_scales,
            "neighbours": self.neighbours,
        }


def _sorted(obs: Observation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The observation's ids, positions and headings in id order (the plan's row order)."""
    order = np.argsort(obs.ids, kind="stable")
    return (
        np.asarray(obs.ids, int)[order],
        np.asarray(obs.positions, float)[order],
        np.asarray(obs.headings, float)[order],
    )


# -- the no-communication aggregation baseline (Fig. 4.15) ----------------------------------------------------------


@dataclass(frozen=True)
class AggregationParams(KnnLawParams):
    """The aggregation baseline's settings, in thesis units. Each agent's desired velocity is ``goal_speed`` x v_max
    along its bearing to the target plus ``cohesion`` x (c_i - x_i), c_i the centroid of the teammates within
    ``sense_range`` (the aggregating attraction: Gazi-Passino's linear term, averaged over the neighbours seen),
    capped at v_max; the law (``KnnLawParams``) realises it and keeps agents off each other and the walls. ``r_s``
    is scaled with N like every scenario's (``with_agents``)."""

    r_s: float = 0.606
    v_max: float = 0.3
    goal_speed: float = 0.8
    cohesion: float = 0.2
    sense_range: float = 5.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_fields(self, ("v_max", "goal_speed", "sense_range"))
        check_fields(self, ("cohesion",), positive=False)
        require(self.goal_speed <= 1.0, "goal_speed", "must be at most 1 (a fraction of v_max)", self.goal_speed)


class AggregationPlanner(RegionPlanner):
    """N independent agents aggregating without communication while they seek the target (``AggregationParams``).
    Its plan has no region; its events: ``input`` for rows dropped (non-finite poses)."""

    Params = AggregationParams

    def __init__(self, **params: Any) -> None:
        self.p = AggregationParams(**params)
        self.period_s = self.p.period_s
        self.plans = 0
        self.alone = 0  # agent-periods with no teammate in sensing range
        self.dropped = 0

    def plan(self, obs: Observation) -> Plan:
        p = self.p
        ids, x, _ = _sorted(obs)
        good = np.isfinite(x).all(axis=1)
        events: tuple[dict[str, Any], ...] = ()
        if not good.all():
            self.dropped += int((~good).sum())
            events = ({"kind": "input", "dropped": int((~good).sum()), "reason": "garbage"},)
        xg = np.where(good[:, None], x, 0.0)
        c, count = local_centroids(xg[good], p.sense_range)
        coh = np.zeros_like(xg)
        coh[good] = p.cohesion * (c - xg[good])
        self.alone += int(np.count_nonzero(count == 0))
        target = np.asarray(obs.target, float)
        to = target - xg
        r = np.hypot(to[:, 0], to[:, 1])
        w = p.goal_speed * p.v_max * to / np.maximum(r, 1e-300)[:, None] + coh
        s = np.hypot(w[:, 0], w[:, 1])
        w *= np.where(s > p.v_max, p.v_max / np.maximum(s, 1e-300), 1.0)[:, None]
        goals = xg + w / p.k_c
        near = r * p.k_c <= p.goal_speed * p.v_max  # at the target: hold it
        goals[near] = target
        goals[~good] = xg[~good]
        self.plans += 1
        params = p.law_params()
        return Plan(obs.t, ids, goals, "split_merge", params, groups=np.zeros(len(ids), int), events=events)

    def summary(self) -> dict[str, Any]:
        return {"params": asdict(self.p), "plans": self.plans, "alone": self.alone, "dropped": self.dropped}


# -- the vision leader-follower baseline (Table 7.6) ----------------------------------------------------------------


@dataclass(frozen=True)
class VisionLFParams(KnnLawParams):
    """The vision leader-follower baseline's settings, in thesis units. ``route``: the leader's predefined trajectory
    (waypoints, the target appended), taken at ``leader_speed`` x v_max; a waypoint is passed within
    ``waypoint_tol``. Followers: ``follow_distance`` behind the predecessor along its heading (a camera's working
    distance: not scaled with N), seen within ``camera_range`` and ``camera_fov_deg`` (the Pi camera's 62 degrees);
    ``home_radius`` the target's zone. The law: ``KnnLawParams``."""

    route: tuple[tuple[float, float], ...] = ()
    v_max: float = 0.3
    leader_speed: float = 0.8
    waypoint_tol: float = 0.5
    follow_distance: float = 1.0
    camera_range: float = 3.0
    camera_fov_deg: float = 62.0
    home_radius: float = 2.0

    def __post_init__(self) -> None:
        super().__post_init__()
        names = ("v_max", "leader_speed", "waypoint_tol", "follow_distance", "camera_range", "camera_fov_deg")
        check_fields(self, (*names, "home_radius"))
        require(self.leader_speed <= 1.0, "leader_speed", "must be at most 1 (a fraction of v_max)", self.leader_speed)
        require(self.camera_fov_deg <= 360.0, "camera_fov_deg", "must be at most 360", self.camera_fov_deg)
        for k, w in enumerate(self.route):
            require(
                len(w) == 2 and all(math.isfinite(float(c)) for c in w),
                "route",
                f"waypoint {k} must be two finite numbers",
                w,
            )


def chain_order(x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The chain's rows, leader first: the agent nearest the target leads, each next one is the unassigned agent
    nearest the last assigned (set up once, at deployment)."""
    n = len(x)
    left = np.ones(n, bool)
    k = int(np.argmin(np.hypot(*(x - target).T)))
    order = [k]
    left[k] = False
    for _ in range(n - 1):
        d = np.hypot(*(x - x[order[-1]]).T)
        d[~left] = np.inf
        k = int(np.argmin(d))
        order.append(k)
        left[k] = False
    return np.asarray(order, int)


def in_view(x: np.ndarray, heading: np.ndarray, other: np.ndarray, reach: float, fov: float) -> np.ndarray:
    """Whether each camera at x (N, 2) facing ``heading`` (N,) sees the point ``other`` (N, 2): within ``reach`` and
    within half the field of view ``fov`` (rad) of its heading."""
    d = other - x
    r = np.hypot(d[:, 0], d[:, 1])
    off = np.abs(np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - heading))))
    return (r <= reach) & ((off <= fov / 2) | (r < 1e-9))


class VisionLeaderFollowerPlanner(RegionPlanner):
    """A chain of followers behind a leader on a route (``VisionLFParams``). The chain is set up at the first
    observation (``chain_order``); its events: ``chain`` once, ``lost`` / ``found`` when a follower's predecessor
    leaves or re-enters its camera's view, ``waypoint`` when the leader passes one, ``home`` the first time every
    agent is in the target's zone."""

    Params = VisionLFParams

    def __init__(self, **params: Any) -> None:
        if "route" in params:
            params["route"] = tuple(tuple(float(c) for c in w) for w in params["route"])
        self.p = VisionLFParams(**params)
        self.period_s = self.p.period_s
        self.ids: np.ndarray | None = None
        self.pred: np.ndarray | None = None  # each row's predecessor row (-1: the leader)
        self.seen_at: np.ndarray | None = None  # where each follower last saw its predecessor (N, 2)
        self.seen_heading: np.ndarray | None = None
        self.visible: np.ndarray | None = None
        self.wp = 0
        self.plans = 0
        self.lost_periods = 0
        self.home_t: float | None = None

    def _setup(self, ids: np.ndarray, x: np.ndarray, target: np.ndarray) -> list[dict[str, Any]]:
        self.ids = ids
        order = chain_order(x, target)
        pred = np.full(len(ids), -1)
        pred[order[1:]] = order[:-1]
        self.pred = pred
        self.order = order
        self.route = np.array([*self.p.route, tuple(target)], float).reshape(-1, 2)
        self.seen_at = np.where(pred[:, None] >= 0, x[np.maximum(pred, 0)], x)
        self.seen_heading = np.zeros(len(ids))
        self.visible = np.ones(len(ids), bool)
        return [{"kind": "chain", "leader": int(ids[order[0]]), "order": ids[order].tolist()}]

    def plan(self, obs: Observation) -> Plan:
        p = self.p
        ids, x, heading = _sorted(obs)
        target = np.asarray(obs.target, float)
        events: list[dict[str, Any]] = []
        if self.ids is None:
            if len(ids) == 0:
                raise ValueError("the first observation has no agent: the chain is built from it")
            events += self._setup(ids, x, target)
        if not np.array_equal(ids, self.ids):
            raise ValueError(f"ids: the chain's agents are {self.ids.tolist()}, got {ids.tolist()}")
        assert self.pred is not None and self.seen_at is not None and self.seen_heading is not None
        lead = self.order[0]
        while self.wp < len(self.route) - 1 and np.hypot(*(x[lead] - self.route[self.wp])) <= p.waypoint_tol:
            self.wp += 1
            events.append({"kind": "waypoint", "index": self.wp})
        f = self.pred >= 0
        pr = np.maximum(self.pred, 0)
        # the camera keeps its predecessor centred (Wang's visual servoing): it looks where it last saw it
        look = self.seen_at - x
        camera = np.where(np.hypot(look[:, 0], look[:, 1]) > 1e-9, np.arctan2(look[:, 1], look[:, 0]), heading)
        sees = f & in_view(x, camera, x[pr], p.camera_range, math.radians(p.camera_fov_deg))
        self.seen_at[sees] = x[pr][sees]
        self.seen_heading[sees] = heading[pr][sees]
        assert self.visible is not None
        for k in np.nonzero(f & (sees != self.visible))[0]:
            events.append({"kind": "found" if sees[k] else "lost", "agent": int(ids[k])})
        self.visible = np.where(f, sees, True)
        self.lost_periods += int(np.count_nonzero(f & ~sees))
        home = np.hypot(*(x - target).T) <= p.home_radius
        slot = self.seen_at - p.follow_distance * np.stack([np.cos(self.seen_heading), np.sin(self.seen_heading)], 1)
        goals = toward(x, slot, p.v_max, p.k_c)
        goals[lead] = toward(x[lead : lead + 1], self.route[self.wp : self.wp + 1], p.leader_speed * p.v_max, p.k_c)[0]
        go_home = home | (f & home[pr])
        goals[go_home] = toward(x[go_home], np.broadcast_to(target, (int(go_home.sum()), 2)), p.v_max, p.k_c)
        if self.home_t is None and home.all():
            self.home_t = obs.t
            events.append({"kind": "home", "t": obs.t})
        self.plans += 1
        params = p.law_params()
        return Plan(
            obs.t,
            ids,
            goals,
            "split_merge",
            params,
            groups=np.zeros(len(ids), int),
            leaders=(int(ids[lead]),),
            events=tuple(events),
        )

    def summary(self) -> dict[str, Any]:
        return {
            "params": asdict(self.p),
            "plans": self.plans,
            "leader": None if self.ids is None else int(self.ids[self.order[0]]),
            "waypoints_passed": self.wp,
            "lost_periods": self.lost_periods,
            "home_t": self.home_t,
        }


# -- chapter 4's planner on a host that takes time (Table 7.6) ------------------------------------------------------


@dataclass(frozen=True)
class HostedCh4Params(Ch4Params):
    """``Ch4Params`` and the host: ``host`` "pc" (the centralised global controller, an i7) or "rpi" (the leader's
    Raspberry Pi, "proposed with L-F"), ``window_s`` the sonar window an update waits for, ``compute_s_per_agent``
    the PC's region computation per robot (§7.4.1: 50 ms for six robots), ``rpi_factor`` the Pi's slowness against
    the PC (4: the single-core ratio of a Pi 4 to a desktop i7, ours; the thesis gives none). ``poll_s``: how often
    the model asks whether the host is done (the point model's dt: an update ends within a tick of its cycle); the
    region's step per update stays ``period_s`` (the thesis' 250 ms global period)."""

    host: str = "pc"
    window_s: float = 0.25
    compute_s_per_agent: float = 0.05 / 6
    rpi_factor: float = 4.0
    poll_s: float = 0.05

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.host in HOSTS, "host", f"expected one of {', '.join(HOSTS)}", self.host)
        check_fields(self, ("window_s", "rpi_factor", "poll_s"))
        check_fields(self, ("compute_s_per_agent",), positive=False)
        require(
            self.rpi_factor >= 1.0, "rpi_factor", "must be >= 1 (the Pi is not faster than the PC)", self.rpi_factor
        )

    def cycle_s(self, n: int) -> float:
        """An update's duration with ``n`` robots: the window, then the host's computation."""
        factor = self.rpi_factor if self.host == "rpi" else 1.0
        return self.window_s + factor * self.compute_s_per_agent * n


HOST_FIELDS = tuple(f.name for f in fields(HostedCh4Params) if f.name not in {g.name for g in fields(Ch4Params)})


class HostedCh4Planner(Ch4Planner):
    """``Ch4Planner`` updating at its host's pace (``HostedCh4Params.cycle_s``): an update observes at its start and
    publishes its plan at its end (the plan before it holds meanwhile, events once); the region advances one step of
    its dynamics per update. Its summary adds the host, the cycle and the updates."""

    Params = HostedCh4Params

    def __init__(self, **params: Any) -> None:
        host = {k: params.pop(k) for k in HOST_FIELDS if k in params}
        super().__init__(**params)
        self.host = HostedCh4Params(**{**{f.name: getattr(self.p, f.name) for f in fields(Ch4Params)}, **host})
        self.pending: Plan | None = None
        self.current: Plan | None = None
        self.ready_at = -math.inf
        self.updates = 0
        self.cycle: float | None = None
        self.last_out: Plan | None = None
        self.step_s = Ch4Planner.period_s
        self.period_s = self.host.poll_s  # the caller polls the host this often

    def plan(self, obs: Observation) -> Plan:
        if obs.t + 1e-9 >= self.ready_at:
            if self.pending is not None:
                self.current = self.pending
            self.period_s = self.step_s  # the region moves one step of its dynamics per update
            try:
                new = super().plan(obs)
            finally:
                self.period_s = self.host.poll_s
            self.updates += 1
            self.cycle = self.host.cycle_s(self.n)
            self.ready_at = obs.t + self.cycle
            if self.current is None:  # the first update: the agents wait for it (nothing to follow before)
                self.current = new
            else:
                self.pending = new
        out = self.current
        assert out is not None
        fresh = out is not self.last_out
        self.last_out = out
        return Plan(
            obs.t,
            out.ids,
            out.goals,
            out.law,
            out.params,
            groups=out.groups,
            leaders=out.leaders,
            regions=out.regions,
            events=out.events if fresh else (),
            done=out.done,
        )

    def summary(self) -> dict[str, Any]:
        return {
            **super().summary(),
            "host": self.host.host,
            "cycle_s": self.cycle,
            "updates": self.updates,
        }
