"""``Ch5Planner`` (region planner ``ch5``): chapter 5's global controller (Roy 2022 §5.2-5.3, digest 001 §2.3.7).
Every period it senses (the window [d_thre-, d_thre+] of Table 5.1, erratum 18); when the barrier is released (every
agent within ``tolerance`` r_s of its circle's centre, or the barrier's timeout) it makes the next region Φ (the EFA
of the sensed points, advanced one step toward T, erratum 19), packs N circles in it (the lattice, then the fallback,
erratum 20) and assigns them (Hungarian, or the literal argmax, erratum 21); until the next release it holds that
plan, so the region never advances while an agent is out of its circle (B8). Each agent's goal is its circle's
centre and the law is eq. 5.2 ("packing", Table 5.1's gains).

Repairs of ours beyond the digest's errata, each a parameter:

- ``repulsion_cutoff`` (default 0.5). Eq. 5.2 as printed sums the repulsion over every pair; with Table 5.1's gains
  (k_r / k_a = 8.5) the agents settle 3 to 6 r_s away from their circles' centres, so the barrier would only ever
  release by its timeout. We keep the repulsion to pairs closer than 0.5 x 2 r_s = r_s (the bodies' contact
  distance for r_robot = r_s / 2): the thesis' "avoiding inter-agent collision with its nearby agents". At their
  centres (>= 2 r_s apart) the agents feel none, and an agent can pass between two settled neighbours to a hole of
  the packing (at 0.9 x 2 r_s it cannot, and waits for the timeout). ``None``: every pair, as printed.
- ``frontier`` (default True). The EFA of the echoes alone describes what they surround: inside a corridor only the
  side beams echo, so Φ never reaches past the swarm's front and the region stops advancing. With ``frontier`` every
  beam with no echo inside the window adds its point at d_thre+ (free that far), and Φ's outline is, per bearing
  about the swarm, the nearest echo or else the farthest free point: the free space the swarm sees.
- ``fallback`` (default "circle"): an EFA region that cannot hold the swarm is replaced by rule (a)'s circle (cut
  about the echoes) before the last feasible plan is kept; "keep": only keep it.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from swarm_logic.families.roy.regions.efa import (
    ADVANCES,
    ORDERINGS,
    SORT_CENTRES,
    EfaParams,
    PolygonRegion,
    RegionParams,
    polygon_region,
    require,
)
from swarm_logic.families.roy.regions.ellipse import free_space
from swarm_logic.families.roy.regions.packing import (
    ASSIGNMENTS,
    SELECTIONS,
    BarrierParams,
    CirclePlan,
    PackingParams,
    barrier,
    plan_circles,
)
from swarm_logic.families.roy.regions.planner import Observation, Plan, Region, RegionPlanner
from swarm_logic.families.roy.regions.records import check_fields
from swarm_logic.families.roy.regions.sensing import SensingParams, beam_points, sense

DONE_RULES = ("region", "agents")
STEP_RULES = ("fixed", "horizon")
FALLBACKS = ("circle", "keep")
RELEASES = ("all in circles", "timeout")


@dataclass(frozen=True)
class Ch5Params:
    """Chapter 5's global controller, in thesis units and seconds of the caller's clock. "T": Table 5.1; "R": our
    resolution, erratum number of the digest's §5.2.

    - Law (eq. 5.2): ``k_a`` 22.4, ``k_r`` 190.45, ``r_s`` 1 (T); ``repulsion_cutoff`` (R, ours) 0.5: only pairs
      closer than 0.5 x 2 r_s repel, None: every pair, as printed (agents then settle off their circles).
    - Sensing: the window ``d_min`` 0.5, ``d_max`` 5 (T, erratum 18: below the thesis' own d_thre- > 2 r_s, used as
      printed); ``r_robot`` and ``eclipse_eps``, a reading this close to a teammate is the teammate.
    - Region (erratum 19): ``step`` 1 toward T per update, ``step_rule`` "fixed" (Φ's centre moves ``step``) or
      "horizon" (thesis §5.4.1-5.4.2: Φ is fitted "inside the sensed space", eq. 5.5's points within d_thre+ of the
      agents: its centre moves toward T until its far edge, N π r_s² / η's radius ahead of it, reaches the front
      agent's sensing horizon d_thre+, never less than ``step``), ``packing_density`` 0.7, ``grow`` True (False: the
      disc is exactly ``d_max``), ``min_points`` 3, ``advance`` "shift_clip" ("efa": the reconstruction as is),
      ``sort_about`` "points" ("swarm"), ``ordering`` "polar" ("given": literal), ``clearance`` 1 r_s,
      ``harmonics`` 14 and ``samples`` 100 (T).
    - Packing (erratum 20): ``select`` "central" ("all"), ``relax`` True (False: the lattice and shrinking only).
    - Assignment (erratum 21): ``assignment`` "hungarian" ("bottleneck", "literal": the printed argmax).
    - Barrier (§2.3.5, R): ``tolerance`` 0.1 r, ``timeout`` 30 s; ``retry_s`` 5: after a region that cannot hold
      the swarm, how long the last feasible plan is kept before the next try.
    - End: ``goal_radius`` 1; ``done_rule`` "region" (the thesis' end: the region has reached T, its centre within
      ``goal_radius``, and every agent is in its circle) or "agents" (every agent within ``goal_radius`` of T).
    - Ours (module docstring): ``frontier`` True and ``frontier_bins`` 72 (Φ's outline: the free space seen; False:
      the echoes alone), ``fallback`` "circle" ("keep").
    - ``seed`` of the packing fallback's random stream; ``period_s`` 0.25 s."""

    r_s: float = 1.0
    k_a: float = 22.4
    k_r: float = 190.45
    repulsion_cutoff: float | None = 0.5
    d_min: float = 0.5
    d_max: float = 5.0
    r_robot: float = 0.5
    eclipse_eps: float = 0.1
    step: float = 1.0
    step_rule: str = "fixed"
    packing_density: float = 0.7
    grow: bool = True
    min_points: int = 3
    advance: str = "shift_clip"
    sort_about: str = "points"
    ordering: str = "polar"
    clearance: float = 1.0
    harmonics: int = 14
    samples: int = 100
    select: str = "central"
    relax: bool = True
    assignment: str = "hungarian"
    tolerance: float = 0.1
    timeout: float = 30.0
    retry_s: float = 5.0
    fallback: str = "circle"
    frontier: bool = True
    frontier_bins: int = 72
    goal_radius: float = 1.0
    done_rule: str = "region"
    seed: int = 0
    period_s: float = 0.25

    def __post_init__(self) -> None:
        check_fields(self, ("r_s", "k_a", "retry_s", "goal_radius", "period_s"))
        check_fields(self, ("k_r",), positive=False)
        require(
            self.repulsion_cutoff is None or (math.isfinite(self.repulsion_cutoff) and self.repulsion_cutoff > 0),
            "repulsion_cutoff",
            "must be finite and > 0 (or None: every pair, as printed)",
            self.repulsion_cutoff,
        )
        require(self.advance in ADVANCES, "advance", f"expected one of {', '.join(ADVANCES)}", self.advance)
        require(
            self.sort_about in SORT_CENTRES, "sort_about", f"expected one of {', '.join(SORT_CENTRES)}", self.sort_about
        )
        require(self.ordering in ORDERINGS, "ordering", f"expected one of {', '.join(ORDERINGS)}", self.ordering)
        require(self.select in SELECTIONS, "select", f"expected one of {', '.join(SELECTIONS)}", self.select)
        require(
            self.assignment in ASSIGNMENTS, "assignment", f"expected one of {', '.join(ASSIGNMENTS)}", self.assignment
        )
        require(self.fallback in FALLBACKS, "fallback", f"expected one of {', '.join(FALLBACKS)}", self.fallback)
        require(self.step_rule in STEP_RULES, "step_rule", f"expected one of {', '.join(STEP_RULES)}", self.step_rule)
        require(self.done_rule in DONE_RULES, "done_rule", f"expected one of {', '.join(DONE_RULES)}", self.done_rule)
        require(
            isinstance(self.frontier_bins, int) and self.frontier_bins >= 8,
            "frontier_bins",
            "must be an int >= 8",
            self.frontier_bins,
        )
        require(isinstance(self.seed, int), "seed", "must be an int", self.seed)
        self.sensing()
        self.region()
        self.packing()
        self.barrier()

    def sensing(self) -> SensingParams:
        return SensingParams(self.d_min, self.d_max, self.r_robot, self.eclipse_eps)

    def region(self) -> RegionParams:
        efa = EfaParams(self.harmonics, self.samples, ordering=self.ordering)
        return RegionParams(
            self.step,
            self.packing_density,
            self.d_max,
            self.grow,
            self.min_points,
            self.advance,
            self.sort_about,
            self.clearance,
            efa,
        )

    def packing(self) -> PackingParams:
        """Erratum 20's packing; r_s shrinks only while the circles still hold a robot (r >= ``r_robot``)."""
        base = PackingParams(select=self.select, relax=self.relax)
        ratio = self.r_robot / self.r_s
        floor = math.floor(math.log(ratio) / math.log(1.0 - base.shrink)) if ratio < 1.0 else 0
        return replace(base, max_shrinks=max(0, min(base.max_shrinks, floor)))

    def barrier(self) -> BarrierParams:
        return BarrierParams(self.tolerance, self.timeout)


def _pose_ok(x: np.ndarray) -> np.ndarray:
    return np.isfinite(x).all(axis=1)


class Ch5Planner(RegionPlanner):
    """The loop of digest §2.3.7, one ``plan`` per period. Its events (each a dict with ``kind`` and ``t``):

    - ``region``: a region update: ``update`` (its number), ``why`` ("start", "released", "retry", "fallback",
      "membership"), the region's ``rule`` and ``reason``, ``area`` A_Φ, ``n`` agents packed, ``b_fs`` the gap
      sensed then (None: none), the packing ``method`` (lattice/relaxed/shrunk), ``lattice_count`` and
      ``lattice_holds`` (count >= N, B7), ``radius``, ``circles``, ``points`` sensed, the assignment's
      ``one_to_one``;
    - ``barrier``: the barrier released, ``reason`` "all in circles" (the thesis' timeline events, C6) or
      "timeout", with ``waiting`` (the ids not in their circles) and ``held_s``;
    - ``infeasible``: a region that cannot hold the swarm (``why_not``: less area than N robots, the packing failed,
      circles smaller than the robots, an agent without a circle), with the ``region`` fields and the ``decision``:
      "circle rule" (``fallback``), "last plan" (``kept``: its time) or "hold where they are" (none yet);
    - ``input``: ``reason`` "garbage" (readings not finite or negative, by agent), "no_pose" (agents with no finite
      position: not packed, never arrived), "absent" (planned agents missing from the observation: not waited for),
      each when its set of agents changes;
    - ``done``: the end (``done_rule``), once.
    """

    Params = Ch5Params

    def __init__(self, **params: Any) -> None:
        self.p = Ch5Params(**params)
        self.period_s = self.p.period_s
        self.rng = np.random.default_rng(self.p.seed)
        self.region: PolygonRegion | None = None
        self.targets: dict[int, np.ndarray] = {}
        self.radius = self.p.r_s
        self.since = 0.0
        self.kept: float | None = None  # when the plan in force was made
        self.released_at: float | None = None
        self.tried_at: float | None = None
        self.done_t: float | None = None
        self.plans = 0
        self.updates: list[dict[str, Any]] = []
        self.releases: list[dict[str, Any]] = []
        self.infeasible: list[dict[str, Any]] = []
        self.dropped: Counter[str] = Counter()
        self.flagged: dict[str, tuple[int, ...]] = {}
        self.last_distances: list[float] = []

    # --- one period -------------------------------------------------------------------------------------------------

    def plan(self, obs: Observation) -> Plan:
        order = np.argsort(obs.ids, kind="stable")
        ids = np.asarray(obs.ids)[order].astype(int)
        x = np.asarray(obs.positions, float)[order]
        heads = np.asarray(obs.headings, float)[order]
        ranges = np.asarray(obs.ranges, float)[order]
        target = np.asarray(obs.target, float)
        t = float(obs.t)
        self.plans += 1
        events: list[dict[str, Any]] = []
        if len(ids) == 0:
            return Plan(t, ids, np.zeros((0, 2)), "packing", self.law(), events=({"kind": "held", "t": t},))
        sensed = sense(x, heads, ranges, np.asarray(obs.angles, float), self.p.sensing())
        self.dropped.update(sensed.dropped)
        ok = _pose_ok(x)
        bad = ~np.isnan(ranges) & (~np.isfinite(ranges) | (ranges < 0) | ~ok[:, None])
        self.flag(events, t, "garbage", ids[bad.any(axis=1)], readings=int(bad.sum()))
        self.flag(events, t, "no_pose", ids[~ok])
        present = {int(i) for i in ids}
        self.flag(events, t, "absent", np.array(sorted(set(self.targets) - present), int))
        points = sensed.points
        outline = self.outline(points, x, heads, ranges, np.asarray(obs.angles, float)) if self.p.frontier else points
        new = {int(i) for i in ids[ok]} - set(self.targets)
        waiting = self.tried_at is not None and t - self.tried_at < self.p.retry_s
        if self.done_t is not None or not ok.any():
            pass  # the end; or nobody to pack or wait for (``no_pose`` says so): the plan in force stands
        elif self.region is None or new:
            if not waiting:
                why = "start" if self.region is None else "membership"
                self.build(events, t, ids, x, (points, outline), target, why, repack=self.region is not None)
        else:
            self.step(events, t, ids, x, (points, outline), target)
        if self.done_t is None and self.finished(ids, x, target):
            self.done_t = t
            events.append({"kind": "done", "t": t, "rule": self.p.done_rule, "updates": len(self.updates)})
        self.last_distances = [float(d) for d in np.hypot(*(x - target).T)]
        return Plan(
            t,
            ids,
            self.goals(ids, x),
            "packing",
            self.law(),
            groups=np.zeros(len(ids), int),
            regions=self.drawn(),
            events=tuple(events),
            done=self.done_t is not None,
        )

    def step(
        self,
        events: list[dict[str, Any]],
        t: float,
        ids: np.ndarray,
        x: np.ndarray,
        points: tuple[np.ndarray, np.ndarray],
        target: np.ndarray,
    ) -> None:
        """The barrier over the planned agents present; on its release, the next region (B8)."""
        planned = np.array([int(i) in self.targets for i in ids])
        goals = np.array([self.targets.get(int(i), np.full(2, np.nan)) for i in ids]).reshape(-1, 2)
        status = barrier(x[planned], goals[planned], self.radius, self.since, t, self.p.barrier())
        if self.released_at is None and status.released:
            self.released_at = t
            reason = RELEASES[0] if status.all_arrived else RELEASES[1]
            waiting = [int(i) for i in ids[planned][status.waiting]]
            record = {"t": t, "reason": reason, "update": len(self.updates), "held_s": t - self.since}
            self.releases.append(record)
            events.append({"kind": "barrier", **record, "waiting": waiting})
            if reason == RELEASES[0] and self.region_at_target(target):
                return  # the end: ``finished`` says so
        if self.released_at is None:
            return
        if self.tried_at is not None and t - self.tried_at < self.p.retry_s:
            return
        self.build(events, t, ids, x, points, target, "released" if self.tried_at is None else "retry")

    def build(
        self,
        events: list[dict[str, Any]],
        t: float,
        ids: np.ndarray,
        x: np.ndarray,
        sensed: tuple[np.ndarray, np.ndarray],
        target: np.ndarray,
        why: str,
        repack: bool = False,
    ) -> None:
        """Make (or, with ``repack``, re-pack the current) region for the agents with a position and assign it; a
        region that cannot hold them is logged and the last feasible plan kept. ``sensed``: the echoes' points and
        the outline the EFA reads (the same points, or with ``frontier`` the free-space outline)."""
        points, outline = sensed
        ok = _pose_ok(x)
        pos, pids = x[ok], ids[ok]
        region = self.region if repack and self.region is not None else self.make_region(outline, pos, target)
        circles, why_not = self.pack(region, pos)
        centre = pos.mean(axis=0) if len(pos) else region.centre
        toward = target - centre
        heading = math.atan2(toward[1], toward[0]) if np.isfinite(toward).all() and np.hypot(*toward) > 0 else 0.0
        gap = free_space(points, centre, "closest", heading=heading, split="sides")
        b_fs = gap.b_fs if gap.sensed else None
        self.tried_at = t
        if why_not and self.p.fallback == "circle" and not repack and region.rule != "circle":
            record = self.record(t, why, region, circles, len(pos), b_fs, len(points), repack)
            events.append({**record, "kind": "infeasible", "why_not": why_not, "decision": "circle rule"})
            self.infeasible.append({**record, "kept": None, "decision": "circle rule"})
            region = self.make_region(points, pos, target, circle=True)
            circles, why_not = self.pack(region, pos)
            why = "fallback"
        record = self.record(t, why, region, circles, len(pos), b_fs, len(points), repack)
        if why_not:
            kept = "last plan" if self.region is not None else "hold where they are"
            events.append({**record, "kind": "infeasible", "why_not": why_not, "decision": kept, "kept": self.kept})
            self.infeasible.append({**record, "kept": self.kept, "decision": kept})
            if self.region is None:  # nothing feasible yet: every agent holds where it is
                self.targets = {int(i): p.copy() for i, p in zip(pids, pos, strict=True)}
                self.since = t
            return
        asg = circles.assignment
        self.region = region
        self.targets = {int(i): asg.targets[k].copy() for k, i in enumerate(pids)}
        self.radius = circles.packing.radius
        self.since = t
        self.kept = t
        self.released_at = None
        self.tried_at = None
        self.updates.append(record)
        events.append({"kind": "region", **record})

    def outline(
        self, echoes: np.ndarray, x: np.ndarray, heads: np.ndarray, ranges: np.ndarray, angles: np.ndarray
    ) -> np.ndarray:
        """The free space the swarm sees, as the points the EFA reads (``frontier``): every beam with no echo inside
        the window adds the point at d_thre+ along it (free that far), then, in each of ``frontier_bins`` bearings
        about the swarm's centroid, the nearest echo is kept, or, where there is none, the farthest free point."""
        ok = _pose_ok(x) & np.isfinite(heads)
        if not ok.any():
            return echoes
        with np.errstate(invalid="ignore"):
            free = ok[:, None] & (np.isnan(ranges) | (ranges > self.p.d_max))
        owner, beam = np.nonzero(free)
        frontier = beam_points(x, heads, angles, owner, beam, self.p.d_max)
        pts = np.vstack([echoes.reshape(-1, 2), frontier])
        is_echo = np.arange(len(pts)) < len(echoes.reshape(-1, 2))
        if len(pts) == 0:
            return pts
        d = pts - x[ok].mean(axis=0)
        dist = np.hypot(d[:, 0], d[:, 1])
        b = self.p.frontier_bins
        bins = np.floor((np.arctan2(d[:, 1], d[:, 0]) + math.pi) / (2 * math.pi) * b).astype(int) % b
        # per bin: echoes first, nearest first; then free points, farthest first; keep each bin's first
        key = np.where(is_echo, dist, 1e12 - dist)
        order = np.lexsort((key, bins))
        first = np.ones(len(order), bool)
        first[1:] = bins[order][1:] != bins[order][:-1]
        return pts[order[first]]

    def make_region(
        self, points: np.ndarray, pos: np.ndarray, target: np.ndarray, circle: bool = False
    ) -> PolygonRegion:
        """Φ by the region rule; ``circle``: rule (a) whatever was sensed (the circle one step ahead, cut about the
        sensed points)."""
        params = self.p.region()
        if self.p.frontier and not circle:
            params = replace(params, sort_about="swarm")  # the outline is a star about the swarm's centroid
        if circle:
            params = replace(params, min_points=max(params.min_points, len(points) + 1))
        if self.p.step_rule == "horizon" and not circle:  # the fallback's circle keeps ``step``
            params = replace(params, step=self.horizon_step(pos, target))
        return polygon_region(points, pos, target, self.p.r_s, params)

    def horizon_step(self, pos: np.ndarray, target: np.ndarray) -> float:
        """``step_rule`` "horizon": how far Φ's centre moves toward T so that its far edge (the radius of the area
        N π r_s² / η ahead of the centre) lies on the front agent's sensing horizon, d_thre+ beyond the agent
        farthest along the direction to T; at least ``step``."""
        if not len(pos) or not np.isfinite(target).all():
            return self.p.step
        centre = pos.mean(axis=0)
        toward = target - centre
        dist = float(np.hypot(*toward))
        if dist <= 0.0:
            return self.p.step
        front = float(((pos - centre) @ (toward / dist)).max())
        reach = math.sqrt(len(pos) * self.p.r_s**2 / self.p.packing_density)
        return max(self.p.step, front + self.p.d_max - reach)

    def pack(self, region: PolygonRegion, pos: np.ndarray) -> tuple[CirclePlan | None, str]:
        """The circles and their assignment, and why they cannot hold the swarm ("" when they can): a region with
        less area than N circles (not packed at all), a failed packing, circles smaller than the robots."""
        n = len(pos)
        if region.area < n * math.pi * self.p.r_robot**2:
            return None, f"A_phi {region.area:.3g} is less than {n} robots' area"
        circles = plan_circles(region.polygon, pos, self.p.r_s, self.p.packing(), self.p.assignment, self.rng)
        if circles.packing.method == "failed":
            return circles, f"the packing failed ({len(circles.packing.centres)} circles for {n})"
        if circles.packing.radius < self.p.r_robot:
            return circles, f"the circles ({circles.packing.radius:.3g}) are smaller than the robots ({self.p.r_robot})"
        if (circles.assignment.index < 0).any():
            return circles, "an agent got no circle"
        return circles, ""

    def record(
        self,
        t: float,
        why: str,
        region: PolygonRegion,
        circles: CirclePlan | None,
        n: int,
        b_fs: float | None,
        points: int,
        repack: bool,
    ) -> dict[str, Any]:
        """A region update's figures (the ``region`` and ``infeasible`` events)."""
        pk = None if circles is None else circles.packing
        return {
            "t": t,
            "update": len(self.updates) + 1,
            "why": why,
            "rule": "repack" if repack else region.rule,
            "reason": region.reason,
            "area": region.area,
            "n": n,
            "b_fs": b_fs,
            "centre": [float(c) for c in region.centre],
            "method": "failed" if pk is None else pk.method,
            "lattice_count": None if pk is None else pk.lattice_count,
            "lattice_holds": pk is not None and pk.lattice_count >= n,
            "radius": None if pk is None else pk.radius,
            "circles": 0 if pk is None else len(pk.centres),
            "points": points,
            "one_to_one": circles is not None and circles.assignment.one_to_one,
        }

    # --- helpers ----------------------------------------------------------------------------------------------------

    def flag(self, events: list[dict[str, Any]], t: float, reason: str, agents: np.ndarray, **extra: Any) -> None:
        """An ``input`` event when the set of agents with this problem changes."""
        now = tuple(int(i) for i in agents)
        if now != self.flagged.get(reason, ()):
            events.append({"kind": "input", "t": t, "reason": reason, "agents": list(now), **extra})
            self.flagged[reason] = now

    def region_at_target(self, target: np.ndarray) -> bool:
        return self.region is not None and bool(np.hypot(*(self.region.centre - target)) <= self.p.goal_radius)

    def finished(self, ids: np.ndarray, x: np.ndarray, target: np.ndarray) -> bool:
        if self.p.done_rule == "agents":
            return bool(len(x) and (np.hypot(*(x - target).T) <= self.p.goal_radius).all())
        arrived = bool(self.releases) and self.releases[-1]["reason"] == RELEASES[0]
        return arrived and self.released_at is not None and self.region_at_target(target)

    def goals(self, ids: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Each agent's circle centre; an agent with none yet holds where it is (or, with no position either, goes
        to the region's centre): goals are always finite, as the wire needs."""
        fallback = self.region.centre if self.region is not None else np.zeros(2)
        out = np.empty((len(ids), 2))
        for k, i in enumerate(ids):
            g = self.targets.get(int(i))
            out[k] = g if g is not None and np.isfinite(g).all() else (x[k] if _pose_ok(x[k : k + 1])[0] else fallback)
        return out

    def law(self) -> dict[str, Any]:
        """Eq. 5.2's parameters; the kernel's scale is the radius the packing used."""
        return {"k_a": self.p.k_a, "k_r": self.p.k_r, "r_s": self.radius, "cutoff_scales": self.p.repulsion_cutoff}

    def drawn(self) -> tuple[Region, ...]:
        if self.region is None:
            return ()
        return (Region(0, vertices=np.asarray(self.region.polygon.exterior.coords)[:-1]),)

    def summary(self) -> dict[str, Any]:
        """The report's figures: the region updates (each with A_Φ, b_fs, N and r_s for UA = A_Φ - N π r_s², eq.
        5.12), the packing methods used, the barrier's releases with their times, the infeasible regions, the readings
        dropped by reason, the end."""
        return {
            "params": asdict(self.p),
            "plans": self.plans,
            "updates": len(self.updates),
            "regions": [
                {k: u[k] for k in ("t", "why", "rule", "area", "b_fs", "n", "method", "lattice_count", "radius")}
                for u in self.updates
            ],
            "methods": dict(Counter(u["method"] for u in self.updates)),
            "releases": [{"t": r["t"], "reason": r["reason"]} for r in self.releases],
            "arrivals": [r["t"] for r in self.releases if r["reason"] == RELEASES[0]],
            "timeouts": [r["t"] for r in self.releases if r["reason"] == RELEASES[1]],
            "infeasible": [{"t": r["t"], "area": r["area"], "n": r["n"], "kept": r["kept"]} for r in self.infeasible],
            "dropped": dict(self.dropped),
            "done_t": self.done_t,
            "distances_to_target": self.last_distances,
        }
