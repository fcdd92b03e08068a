"""Chapter 4's global controller (Roy 2022 §4.3-4.6) as a ``RegionPlanner``: every period it senses the free space
ahead from the agents' sonars, tests it for a moving obstacle, detects failed agents and shrinks the region for them,
moves the circle/ellipse region toward the target, and picks the formation (Algorithm 1, N <= 10) or the scalable
law (eq. 4.41, N > 10). The plan it returns carries each agent's goal, the law and its gains, the region, and an
event for every decision (formation change, circle/ellipse switch, failure detected, region held, readings dropped).

Every literal/repaired choice of the library is a field of ``Ch4Params``; the defaults are the repaired ones that
the closed-loop missions measured to work (see the chapter's page, "The planner and the numerical missions").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from swarm_logic.families.roy.regions import formation as fm
from swarm_logic.families.roy.regions.ellipse import (
    AXES,
    DYNAMICS,
    GAP_MODES,
    SPLITS,
    FailureDetector,
    FailureParams,
    Gap,
    MovingObstacleTest,
    RegionParams,
    RegionState,
    cohesion_radius,
    free_space,
    step_region,
)
from swarm_logic.families.roy.regions.laws import theorem1_kc
from swarm_logic.families.roy.regions.planner import Observation, Plan, Region, RegionPlanner
from swarm_logic.families.roy.regions.records import check_fields
from swarm_logic.families.roy.regions.sensing import SensingParams, sense
from swarm_logic.families.roy.regions.shapes import Ellipse

AD_MODES = ("always", "off")
GOALS = ("slots", "centre")
ASSIGN = ("hungarian", "index")
SCALABLE_GOALS = ("clip", "centre")


@dataclass(frozen=True)
class Ch4Params:
    """The chapter 4 planner's parameters (Table 4.1, digest §5.3, each erratum's choice, and our repairs).

    Region: ``r_c`` (the no-failure radius: 2.5 for 6 agents, sqrt(57.65 / pi) for 50), ``centre0`` O_c (None: the
    agents' centroid), ``k_vcir``, ``k_theta``, ``dynamics`` (erratum 10), ``axes``, ``clearance`` and ``axes_lag``
    (erratum 11), ``r_robot``; the region moves at ``region_speed`` x the agents' ``v_max``. ``barrier``: the region
    advances only when the share ``barrier_fraction`` (N <= ``max_agents``) or ``barrier_fraction_scalable`` of the
    working agents is inside (ours: 1 is the rule as stated, which 50 agents never meet at once).

    Sensing and free space: ``d_min``, ``d_max``, ``eclipse_eps``, ``boundary`` (eq. 4.26's filter), ``gap_mode``
    (erratum 12), ``split`` ("sides", or "kmeans" as printed), ``side_test`` (both clusters must flank the line toward
    the target), ``ahead_only`` (ours: only the points ahead of the region's centre count; the walls behind the swarm
    are no gap to pass), ``gap_memory_s`` (ours: the narrowest gap committed in this window is used; sparse beams
    make b_fs flicker across the switch threshold). ``ad_test``: "always" (eqs. 4.36-4.37 every window) or "off";
    ``ad_margin`` (ours): blocked only when AD falls by more than this (the swarm's own approach lowers AD too; 0 is
    the test as printed).

    Failures (erratum 17): ``fail_speed_frac``, ``fail_centre_frac``, ``fail_hold_s``, and ``detect_when_held`` (ours:
    an agent stopped outside a region that the barrier holds, for ``fail_hold_s``, has failed too; the detector alone
    needs the centre to move, which the barrier forbids until the failed agents are known: a deadlock).

    Formation (N <= ``max_agents``): ``rho`` (erratum 14), ``k_f`` (Table 4.1) and ``k_c`` (None: Theorem 1's from
    ``k_f``, erratum 13), ``mismatch``, ``mismatch_pad`` (each agent's disc, None: rho / 2) and ``trigger`` (erratum 15
    and ours). ``goals``: "slots" (ours: each agent to its place in the chosen formation, with the repulsion gain
    ``k_f_slots``; ``assign`` "hungarian" gives agents the nearest slots, "index" slot i to agent i) or "centre" (the
    region's centre, as printed, with ``k_f``). ``slot_fill``: the slots are shrunk about the centre to lie within
    this fraction of the region. ``safety_factor``: erratum 16's safety term (0: none). ``research_tol``: a new search
    when an axis changed by this fraction since the last one or an agent is outside; ``formation_hold_s``: never
    sooner than this after the last change.

    Scalable law (N > ``max_agents``, eq. 4.41): ``k_c_scalable``, ``k_f_scalable``, ``neighbours``, ``k_nearest``
    and ``scalable_goals``: "centre" pulls every agent to O_e as printed (the kernel r e^(-r / R_s) vanishes at 0, so
    the swarm collapses to a point); "clip" (ours) pulls each agent only to the nearest point of the region shrunk to
    ``slot_fill`` (an agent inside feels no pull, the repulsion spreads the swarm over the region's shape)."""

    # the region controller's fields take RegionParams' defaults, the sensing ones SensingParams'
    r_c: float = RegionParams.r_c
    centre0: tuple[float, float] | None = None
    v_max: float = RegionParams.v_max
    region_speed: float = 0.8
    k_vcir: float = RegionParams.k_vcir
    k_theta: float = RegionParams.k_theta
    dynamics: str = RegionParams.dynamics
    axes: str = RegionParams.axes
    clearance: float = RegionParams.clearance
    axes_lag: float = RegionParams.axes_lag
    barrier: bool = RegionParams.barrier
    barrier_fraction: float = 1.0
    barrier_fraction_scalable: float = 0.9
    r_robot: float = RegionParams.r_robot
    d_min: float = SensingParams.d_min
    d_max: float = SensingParams.d_max
    eclipse_eps: float = SensingParams.eclipse_eps
    boundary: bool = True
    gap_mode: str = "closest"
    split: str = "sides"
    side_test: bool = True
    ahead_only: bool = True
    ad_test: str = "always"
    ad_margin: float = 0.5
    gap_memory_s: float = 2.0
    fail_speed_frac: float = 0.05
    fail_centre_frac: float = 0.2
    fail_hold_s: float = 2.0
    detect_when_held: bool = True
    max_agents: int = 10
    rho: float = 1.0
    k_f: float = 5.0
    k_f_slots: float = 1.0
    k_c: float | None = None
    mismatch: str = "iou"
    mismatch_pad: float | None = 1.0
    safety_factor: float = 1.2
    trigger: str = "fit"
    goals: str = "slots"
    assign: str = "hungarian"
    research_tol: float = 0.1
    formation_hold_s: float = 5.0
    slot_fill: float = 0.7
    k_c_scalable: float = 2.0
    k_f_scalable: float = 1.0
    scalable_goals: str = "clip"
    neighbours: str = "knn"
    k_nearest: int = 6

    def __post_init__(self) -> None:
        for name, allowed in (
            ("dynamics", DYNAMICS),
            ("axes", AXES),
            ("gap_mode", GAP_MODES),
            ("split", SPLITS),
            ("ad_test", AD_MODES),
            ("mismatch", fm.MISMATCH),
            ("trigger", fm.TRIGGERS),
            ("goals", GOALS),
            ("assign", ASSIGN),
            ("scalable_goals", SCALABLE_GOALS),
            ("neighbours", ("knn", "all")),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}: expected one of {', '.join(allowed)}, got {getattr(self, name)!r}")
        check_fields(
            self,
            (
                "r_c",
                "v_max",
                "region_speed",
                "k_vcir",
                "k_theta",
                "d_max",
                "rho",
                "k_f",
                "fail_speed_frac",
                "fail_centre_frac",
                "fail_hold_s",
                "k_c_scalable",
                "k_f_scalable",
                "k_f_slots",
                "slot_fill",
                "barrier_fraction",
                "barrier_fraction_scalable",
            ),
        )
        check_fields(
            self,
            (
                "clearance",
                "axes_lag",
                "r_robot",
                "d_min",
                "eclipse_eps",
                "research_tol",
                "ad_margin",
                "gap_memory_s",
                "safety_factor",
                "formation_hold_s",
            ),
            positive=False,
        )
        if self.k_c is not None:
            check_fields(self, ("k_c",))
        if self.mismatch_pad is not None:
            check_fields(self, ("mismatch_pad",))
        for name in ("barrier_fraction", "barrier_fraction_scalable", "slot_fill"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"{name}: must lie in (0, 1], got {getattr(self, name)}")
        if self.d_max <= self.d_min:
            raise ValueError(f"d_max: must exceed d_min ({self.d_min}), got {self.d_max}")
        if self.split == "sides" and not self.side_test:
            raise ValueError("split: 'sides' needs side_test (the line toward the target splits the points)")
        if self.centre0 is not None and (len(self.centre0) != 2 or not all(map(math.isfinite, self.centre0))):
            raise ValueError(f"centre0: expected two finite numbers, got {self.centre0!r}")
        if self.max_agents < 1 or self.k_nearest < 1:
            raise ValueError("max_agents, k_nearest: must be >= 1")


def clip_into(region: Ellipse, x: np.ndarray, fill: float) -> np.ndarray:
    """Each point (N, 2) moved radially (in the ellipse's normalised frame) onto the region shrunk to ``fill`` when
    it lies beyond it, else kept: the goals of the scalable law's "clip" mode."""
    lv = np.sqrt(np.maximum(region.level(x), 1e-300))
    f = np.where(lv > fill, fill / lv, 1.0)
    return region.centre + (x - region.centre) * f[:, None]


def lattice_graph(n: int, rho: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The initial formation for ``n`` agents: Delta_tri and its coordinates for 6 (§4.6.1), else the ``n`` points
    of a triangular lattice nearest its origin, linked at distance rho; (adjacency, positions)."""
    if n == 6:
        return fm.DELTA_TRI.copy(), fm.tri_coordinates(rho)
    r = math.ceil(math.sqrt(n)) + 1
    i, j = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing="ij")
    pts = np.stack([i.ravel() + 0.5 * j.ravel(), j.ravel() * math.sqrt(3) / 2], axis=1) * rho
    order = np.lexsort((pts[:, 0], pts[:, 1], np.round(np.hypot(*pts.T), 9)))
    p = pts[order[:n]]
    d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
    adj = (np.abs(d - rho) < 1e-6 * rho).astype(int)
    return adj, p - p.mean(axis=0)


@dataclass
class _Counters:
    periods: int = 0
    held: dict[str, int] = field(default_factory=dict)
    searches: int = 0
    formation_changes: int = 0
    switches: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    detected: list[tuple[float, int]] = field(default_factory=list)


class Ch4Planner(RegionPlanner):
    """Chapter 4's global controller, built with ``Ch4Params``' fields as keyword arguments. Its swarm is the first
    observation's agents (the plan's ``ids``, in id order); an agent absent later keeps its last pose, an unknown
    one is dropped and reported (event ``input``)."""

    Params = Ch4Params
    period_s = 0.25

    def __init__(self, **params: Any) -> None:
        for k in ("centre0",):
            if isinstance(params.get(k), list):
                params[k] = tuple(params[k])
        self.p = Ch4Params(**params)
        self.ids: np.ndarray | None = None
        self.n = 0
        self.c = _Counters()

    def _setup(self, ids: np.ndarray) -> None:
        """The agents are the first observation's (``ids``, sorted); everything sized by N is built here."""
        params = self.p
        self.ids = np.unique(np.asarray(ids, int))
        n = self.n = len(self.ids)
        shared = {f.name: getattr(params, f.name) for f in fields(RegionParams) if f.name != "v_max"}
        self.region_params = RegionParams(**shared, v_max=params.region_speed * params.v_max)
        self.sensing = SensingParams(params.d_min, params.d_max, params.r_robot, params.eclipse_eps)
        self.detector = FailureDetector(
            n, FailureParams(params.v_max, params.fail_speed_frac, params.fail_centre_frac, params.fail_hold_s)
        )
        self.ad = MovingObstacleTest()
        self.scalable = n > params.max_agents
        self.graph, self.base = (None, None) if self.scalable else lattice_graph(n, params.rho)
        self.adjacency = self.graph
        self.embedding = self.base
        self.shape = "" if self.scalable else fm.shape_name(self.base)
        self.k_c = params.k_c if params.k_c is not None else theorem1_kc(n, params.k_f, params.rho, params.r_c)
        self.state: RegionState | None = None
        self.last_search: tuple[float, float] | None = None
        self.last_change = -math.inf
        self.ref_gap: Gap | None = None
        self.recent: list[tuple[float, Gap]] = []
        self.last_x: np.ndarray | None = None
        self.last_t = -math.inf
        self.stall = np.zeros(n)
        self.t = 0.0
        self.held = ""
        self.pos = np.zeros((n, 2))
        self.heading = np.zeros(n)
        self.ranges: np.ndarray | None = None

    def _rows(self, obs: Observation) -> int:
        """Merge the reporting agents' rows into the full (N, ...) arrays, rows in id order (an absent agent keeps
        its last pose and has no readings); returns how many rows came from an agent the planner does not know."""
        ids = np.asarray(obs.ids, int)
        row = np.clip(np.searchsorted(self.ids, ids), 0, self.n - 1)
        ok = self.ids[row] == ids
        good = ok & np.isfinite(obs.positions).all(axis=1)
        self.pos[row[good]] = obs.positions[good]
        self.heading[row[good]] = np.where(np.isfinite(obs.headings[good]), obs.headings[good], self.heading[row[good]])
        if self.ranges is None or self.ranges.shape[1] != len(obs.angles):
            self.ranges = np.full((self.n, len(obs.angles)), np.nan)
        self.ranges[:] = np.nan
        self.ranges[row[ok]] = obs.ranges[ok]
        return int((~ok).sum())

    def plan(self, obs: Observation) -> Plan:
        p = self.p
        events: list[dict[str, Any]] = []
        if self.ids is None:
            if len(obs.ids) == 0:  # nobody seen yet (before the camera's first frame): size the swarm later
                return Plan(
                    obs.t,
                    np.zeros(0, int),
                    np.zeros((0, 2)),
                    "formation",
                    events=({"kind": "held", "reason": "no agent"},),
                )
            self._setup(obs.ids)
        unknown = self._rows(obs)
        if unknown:
            events.append({"kind": "input", "dropped": unknown, "reason": "unknown agent"})
        self.t = obs.t
        x = self.pos
        target = np.asarray(obs.target, float)
        if self.state is None:
            c = np.asarray(p.centre0, float) if p.centre0 is not None else x.mean(axis=0)
            to = target - c
            self.state = RegionState(Ellipse(float(c[0]), float(c[1]), p.r_c, p.r_c, math.atan2(to[1], to[0])))
        region = self.state.region
        bearing = math.atan2(target[1] - region.y, target[0] - region.x)
        # sensing (eqs. 4.26-4.29) and the free space (eq. 4.30)
        pts = sense(
            x,
            self.heading,
            self.ranges,
            obs.angles,
            self.sensing,
            boundary=(region.centre, region.b) if p.boundary else None,
        )
        bad = pts.dropped.get("garbage", 0)
        if bad:
            events.append({"kind": "input", "dropped": bad, "reason": "garbage"})
        for k, v in pts.dropped.items():
            self.c.dropped[k] = self.c.dropped.get(k, 0) + v
        seen = pts.points
        if p.ahead_only:
            seen = seen[(seen - region.centre) @ np.array([math.cos(bearing), math.sin(bearing)]) >= 0]
        gap = free_space(seen, region.centre, p.gap_mode, bearing if p.side_test else None, p.split)
        # the moving-obstacle test (eqs. 4.36-4.37)
        blocked = False
        committed = gap
        if p.ad_test == "always":
            ref = self.ref_gap
            decision = self.ad.feed(seen, gap)
            self.ref_gap = gap
            blocked = decision.status == "blocked" and decision.ad_now < decision.ad_ref - p.ad_margin
            if decision.status == "accepted" and decision.gap is not None:
                committed = decision.gap
            elif decision.status == "blocked" and not blocked and ref is not None:
                committed = ref
            else:
                committed = Gap(math.inf)
        committed = self._narrowest(obs.t, committed)
        # failures (eq. 4.46, erratum 17) and the shrink (eq. 4.47)
        before = self.detector.failed.copy()
        failed = self.detector.update(obs.t, x, region)
        if p.detect_when_held:
            failed = failed | self._stalled(obs.t, x, region)
            self.detector.failed |= failed
        new = np.nonzero(failed & ~before)[0]
        if len(new):
            self.c.detected.append((obs.t, len(new)))
            events.append({"kind": "failure", "agents": new.tolist(), "n_failed": int(failed.sum())})
        frac = p.barrier_fraction_scalable if self.scalable else p.barrier_fraction
        step = step_region(
            self.state, committed, target, self.period_s, self.region_params, x, ~failed, int(failed.sum()), blocked
        )
        if p.barrier and frac < 1.0 and step.held == "barrier":
            inside = float(np.mean(region.contains(x[~failed]))) if (~failed).any() else 1.0
            if inside >= frac:  # enough of the swarm is in: advance as if the barrier were met
                free = replace(self.region_params, barrier=False)
                step = step_region(
                    self.state, committed, target, self.period_s, free, x, ~failed, int(failed.sum()), blocked
                )
        held = step.held.split(":")[0]
        if held:
            self.c.held[held] = self.c.held.get(held, 0) + 1
        if held != self.held and held and held != "barrier":
            events.append({"kind": "held", "reason": step.held})
        self.held = held
        self.last_x, self.last_t = x.copy(), obs.t
        was_circle = region.is_circle
        self.state = step.state
        region = self.state.region
        if region.is_circle != was_circle:
            self.c.switches += 1
            events.append(
                {
                    "kind": "region",
                    "to": "circle" if region.is_circle else "ellipse",
                    "a": region.a,
                    "b": region.b,
                    "b_fs": committed.b_fs,
                }
            )
        self.c.periods += 1
        law, params, goals = self._law(x, failed, region, events)
        return Plan(obs.t, self.ids.copy(), goals, law, params, regions=(Region(0, region),), events=tuple(events))

    def _stalled(self, t: float, x: np.ndarray, region: Ellipse) -> np.ndarray:
        """Agents stopped outside a region the barrier holds, for ``fail_hold_s``: a working agent outside a region
        that waits for it moves toward it at speed, and the library's detector (which needs the centre to move)
        never sees them while the barrier holds the region for them."""
        p = self.p
        if self.last_x is None or t <= self.last_t:
            return np.zeros(self.n, bool)
        dt = t - self.last_t
        speed = np.hypot(*(x - self.last_x).T) / dt
        stuck = (speed < p.fail_speed_frac * p.v_max) & ~region.contains(x) & (self.held == "barrier")
        self.stall = np.where(stuck, self.stall + dt, 0.0)
        return self.stall >= p.fail_hold_s - 1e-9

    def _narrowest(self, t: float, gap: Gap) -> Gap:
        """The narrowest gap committed over the last ``gap_memory_s`` (sparse beams make b_fs flicker around the
        switch threshold; a gap once sensed stays for that long)."""
        self.recent = [(s, g) for s, g in self.recent if t - s < self.p.gap_memory_s - 1e-9]
        if gap.sensed:
            self.recent.append((t, gap))
        return min((g for _, g in self.recent), key=lambda g: g.b_fs, default=gap)

    def _law(
        self, x: np.ndarray, failed: np.ndarray, region: Ellipse, events: list[dict[str, Any]]
    ) -> tuple[str, dict[str, Any], np.ndarray]:
        """The local law, its parameters and the goals: the scalable law toward the centre (N > max_agents), or the
        formation law with Algorithm 1's formation (its slots, or the centre)."""
        p = self.p
        working = ~failed
        if self.scalable:
            r_s = cohesion_radius(region.a, region.b, max(int(working.sum()), 1))
            params = {
                "k_c": p.k_c_scalable,
                "k_f": p.k_f_scalable,
                "r_s": r_s,
                "neighbours": p.neighbours,
                "k": p.k_nearest,
            }
            if p.scalable_goals == "centre":
                return "scalable", params, np.broadcast_to(region.centre, (self.n, 2)).copy()
            return "scalable", params, clip_into(region, x, p.slot_fill)
        if region.is_circle:
            adjacency, emb, shape = self.graph, self.base, fm.shape_name(self.base)
            self.last_search = None
        else:
            adjacency, emb, shape = self.adjacency, self.embedding, self.shape
            axes = (region.a, region.b)
            outside = not bool(np.all(region.contains(x[working])))
            changed = self.last_search is None or (
                (outside or any(abs(u - v) > p.research_tol * v for u, v in zip(axes, self.last_search, strict=True)))
                and self.t - self.last_change >= p.formation_hold_s
            )
            if changed:
                choice = fm.match_formation(
                    x[working] if working.all() else x,
                    self.graph,
                    self.adjacency,
                    p.rho,
                    region,
                    p.mismatch,
                    p.mismatch_pad,
                    p.max_agents,
                    p.trigger,
                )
                if choice.searched:
                    self.c.searches += 1
                    self.last_search = axes
                    adjacency, emb, shape = choice.adjacency, choice.embedding, choice.shape
        if not np.array_equal(adjacency, self.adjacency):
            self.last_change = self.t
            if shape != self.shape:
                self.c.formation_changes += 1
                events.append(
                    {"kind": "formation", "from": self.shape, "to": shape, "edges": int(np.triu(adjacency).sum())}
                )
        self.adjacency, self.embedding, self.shape = adjacency, emb, shape
        if p.goals == "slots":
            goals = fm.formation_slots(emb, region, x)
            reach = float(np.sqrt(np.max(region.level(goals)))) if len(goals) else 0.0
            if reach > p.slot_fill:  # shrink the formation about the centre until it lies inside the region
                goals = region.centre + (goals - region.centre) * (p.slot_fill / reach)
            if p.assign == "hungarian":  # agent i takes slot c[i]; the graph follows its slots
                _, c = linear_sum_assignment(np.sum((x[:, None] - goals[None]) ** 2, axis=2))
                goals, adjacency = goals[c], adjacency[np.ix_(c, c)]
        else:
            goals = np.broadcast_to(region.centre, (self.n, 2)).copy()
        desired = fm.desired_distances(adjacency, p.rho)
        k_f = p.k_f_slots if p.goals == "slots" else p.k_f
        params = {"desired": desired.tolist(), "k_c": self.k_c, "k_f": k_f}
        params["safety"] = {"r_robot": p.r_robot, "factor": p.safety_factor} if p.safety_factor > 0 else None
        return "formation", params, goals

    def summary(self) -> dict[str, Any]:
        return {
            "periods": self.c.periods,
            "held": dict(sorted(self.c.held.items())),
            "searches": self.c.searches,
            "formation_changes": self.c.formation_changes,
            "region_switches": self.c.switches,
            "failures_detected": [{"t": t, "n": k} for t, k in self.c.detected],
            "n_failed_detected": int(self.detector.failed.sum()) if self.ids is not None else 0,
            "dropped": dict(sorted(self.c.dropped.items())),
            "k_c": self.k_c if self.ids is not None else None,
        }
