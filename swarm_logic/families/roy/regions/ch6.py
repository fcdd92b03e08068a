"""``Ch6Planner`` (region planner ``ch6``): chapter 6's split and merge of leader-follower sub-swarms (Roy 2022
§6.2-6.4). Every period each sub-swarm's leader gathers its members' sonar points (Table 6.1's window [2, 5],
kept for the last ``memory`` periods, with the free ends of the beams that returned nothing) and looks for openings
ahead (``split_merge.detect_openings``). Two or more, seen in ``confirm`` scans running: the central controller
splits the sub-swarm (``split_swarm``: sizes, allocation, leaders, sub-regions, lane targets). Otherwise the leader
steps its ellipse toward its target by chapter 4's update (``ellipse.step_region``: the area kept, the axes
following the gap). When the next regions of two or more sub-swarms intersect, they merge (``merge_all``).

Each agent's goal is its sub-swarm's region centre and its law eq. 6.5 (``split_merge``, Table 6.1's gains); the
law repels from the nearest agent or obstacle point, and the obstacle points are the caller's: ``velocities(plan, x,
obstacles)`` with the points each agent senses (the robots pass their own sonar points, the numerical model its
sensed points). The plan carries which law and its gains, never the points.

Our resolutions beyond the library's: a sub-swarm born of a split first takes its region through its lane to a
waypoint ``pass_depth`` beyond the lane's mouth along the passage, and until then neither scans for openings (it
would see its neighbour's lane again) nor merges (sub-regions sized by eq. 6.9 overlap at the mouths); then it heads
for its target. A sub-swarm whose leader is missing from the observation gets the surviving member nearest its
region's centre (eq. 6.14's rule), a logged promotion.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from swarm_logic.families.roy.regions.ellipse import RegionParams, RegionState, free_space, step_region
from swarm_logic.families.roy.regions.laws import CH6_MODES
from swarm_logic.families.roy.regions.planner import Observation, Plan, Region, RegionPlanner
from swarm_logic.families.roy.regions.records import check_fields
from swarm_logic.families.roy.regions.sensing import DROP_REASONS, SensingParams, beam_points, sense
from swarm_logic.families.roy.regions.shapes import Ellipse
from swarm_logic.families.roy.regions.split_merge import (
    SplitMergeParams,
    SubSwarm,
    detect_openings,
    ensure_leader,
    merge_all,
    split_swarm,
)

CHOICES = {
    "law_mode": CH6_MODES,
    "semi_minor": ("literal", "half"),
    "allocation": ("nearest", "assignment"),
    "merge_centre": ("area_weighted", "mean"),
    "dynamics": ("repaired", "literal"),
    "axes": ("geometric", "literal"),
    "gap_mode": ("closest", "centroid"),
    "gap_split": ("sides", "kmeans"),
    "passage": ("bearing", "normal"),
}


@dataclass(frozen=True)
class Ch6Params:
    """Chapter 6's planner settings, in thesis units (Table 6.1 where it gives them, the chapter 6 page's
    recommendations elsewhere).

    - Law (eq. 6.5): ``k_c`` 12, ``k_f`` 2.5, ``r_s`` (3.2 and 0.5 in Table 6.1's cases; 1.13 on the SonPI),
      ``law_mode`` "nearest" (erratum 22; "sum": every agent and point within ``radius_scales`` r_s; "knn": the
      ``law_neighbours`` nearest of those, the sum's spacing at a cost linear in N for large swarms),
      ``law_min_sep`` (erratum 22: r_s as §6.2.3's kept minimum distance; an agent nearer than ``law_min_sep`` r_s
      to another moves only away from it; 0 the printed law, which packs the swarm far tighter than r_s).
    - Sensing: the window [``d_min``, ``d_max``] = [2, 5] (eqs. 6.1-6.4); ``r_robot``, ``eclipse_eps`` the teammate
      filter; the points of the last ``memory`` periods are kept (the thesis' R~(t + tau); one period of eight beams
      per agent misses most of a wall); a beam clear beyond ``d_max`` gives a free end for the detector, at its echo's
      range or, with no echo, at ``free_reach`` (None: 2 ``d_max``), and never farther (what a beam meets far
      beyond a lane, the arena's far wall, says nothing of the lane).
    - Detection: ``bin_width`` (None: r_s, the page's figure for sonar input), ``detector`` any other
      ``SplitMergeParams`` field (default ``{"profile": "range"}``: eq. 6.5's gains pack the swarm into a clump a
      few r_s wide, so the lanes fan out from its centre and a beam clear through a lane ends far to its side in the
      depth profile); a split needs ``confirm`` scans running that say so, with every opening's centre within
      ``opening_reach`` of the region's centre (None: ``d_max`` plus its larger semi-axis; a lane farther than the
      window reaches is made of far echoes).
    - Split and merge: ``semi_minor`` (erratum 11: "literal" b^i = b_fs^i, "half"), ``allocation`` (eq. 6.13:
      "nearest", "assignment"), ``merge_centre`` (erratum 24: "area_weighted", "mean").
    - Lanes (erratum 25): ``targets`` the map's targets (None: the observation's target for every sub-swarm),
      ``lane_map`` lane k (left to right) -> target index (None: the target nearest the lane's bearing);
      ``pass_depth`` (None: ``d_max``) how far beyond its lane's mouth a new sub-swarm's region goes before heading for
      its target, along ``passage``: "bearing" (from the parent region's centre to the lane's centre: sparse sonar
      tilts the mouth) or "normal" (the opening's ``theta``, the normal of l1 -> l2).
    - Region (chapter 4's update, ``RegionParams``): ``area`` the first region's (None: N pi r_s^2, eq. 6.8's A_e),
      ``centre`` (None: the first centroid), ``leader`` the first leader (None: the lowest id, the user's arbitrary
      pick), ``dynamics`` (erratum 10), ``axes`` and ``clearance`` (erratum 11), ``v_region`` the region's top speed,
      ``k_vcir``, ``k_theta``, ``barrier``; the gap by ``free_space`` with ``gap_mode`` (erratum 12) and ``gap_split``
      ("sides" of the line toward the target, the corridor reading; "kmeans" as printed), on the points ahead of the
      region's centre by at most its larger semi-axis plus ``gap_ahead`` along the heading (a wall across the way
      is not a gap: the region holds when it reaches it, and the detector decides; a wall just passed is behind).
    - ``face`` (default False, the plan as before): while the swarm, before its first split, advances (its region
      not waiting for its robots) or has obstacle points within its reach ahead and across its way
      (``_wall_ahead``: the wall it holds before), the plan asks the robots to face its heading (``Plan.face``;
      the SonPI's ``roy_region`` turns in place toward it, ``face_tol_deg``): robots drawn to one centre end up
      facing it, and five fixed front sonars then read their teammates, not the wall and its lanes.
    - ``goal_radius`` (None: the equal-area radius of each sub-swarm's region): done when every agent is this close to
      its sub-swarm's target.
    """

    r_s: float = 3.2
    k_c: float = 12.0
    k_f: float = 2.5
    law_mode: str = "nearest"
    radius_scales: float = 3.0
    law_neighbours: int = 8
    law_min_sep: float = 0.0
    d_min: float = 2.0
    d_max: float = 5.0
    r_robot: float = 0.5
    eclipse_eps: float = 0.1
    memory: int = 4
    free_reach: float | None = None
    bin_width: float | None = None
    detector: dict[str, Any] = field(default_factory=lambda: {"profile": "range"})
    confirm: int = 2
    opening_reach: float | None = None
    semi_minor: str = "literal"
    allocation: str = "nearest"
    merge_centre: str = "area_weighted"
    targets: tuple[tuple[float, float], ...] | None = None
    lane_map: tuple[int, ...] | None = None
    pass_depth: float | None = None
    passage: str = "bearing"
    area: float | None = None
    centre: tuple[float, float] | None = None
    leader: int | None = None
    dynamics: str = "repaired"
    axes: str = "geometric"
    clearance: float = 0.5
    v_region: float = 0.3
    k_vcir: float = 10.0
    k_theta: float = 2.0
    barrier: bool = True
    gap_mode: str = "closest"
    gap_split: str = "sides"
    gap_ahead: float = 0.0
    face: bool = False
    goal_radius: float | None = None
    period_s: float = 0.25

    def __post_init__(self) -> None:
        check_fields(self, ("r_s", "k_c", "radius_scales", "d_max", "v_region", "k_vcir", "k_theta", "period_s"))
        check_fields(self, ("k_f", "d_min", "r_robot", "eclipse_eps", "clearance", "gap_ahead"), positive=False)
        check_fields(self, ("law_min_sep",), positive=False)
        for name in ("bin_width", "free_reach", "opening_reach", "pass_depth", "area", "goal_radius"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be finite and > 0 (or None for the default), got {v!r}")
        for name in ("memory", "confirm", "law_neighbours"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise ValueError(f"{name}: must be an integer >= 1, got {getattr(self, name)!r}")
        for name, allowed in CHOICES.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}: expected one of {', '.join(allowed)}, got {getattr(self, name)!r}")
        if self.d_max <= self.d_min:
            raise ValueError(f"d_max: must exceed d_min ({self.d_min}), got {self.d_max}")
        if self.centre is not None and (len(self.centre) != 2 or not all(math.isfinite(c) for c in self.centre)):
            raise ValueError(f"centre: expected two finite coordinates, got {self.centre}")
        if self.targets is not None:
            t = np.asarray(self.targets, dtype=float)
            if t.ndim != 2 or t.shape[1] != 2 or not len(t) or not np.isfinite(t).all():
                raise ValueError(f"targets: expected a list of finite (x, y) points, got {self.targets!r}")
        if self.lane_map is not None:
            n = 0 if self.targets is None else len(self.targets)
            if any(not (isinstance(k, int) and 0 <= k < n) for k in self.lane_map):
                raise ValueError(f"lane_map: every entry must be a target index in 0..{n - 1}, got {self.lane_map!r}")
        try:
            self.split_params()
        except (TypeError, ValueError) as e:
            raise ValueError(f"detector: {e}") from None

    def split_params(self) -> SplitMergeParams:
        kw: dict[str, Any] = {"bin_width": self.bin_width if self.bin_width is not None else self.r_s}
        kw.update(self.detector)
        return SplitMergeParams(
            r_s=self.r_s,
            semi_minor=self.semi_minor,
            allocation=self.allocation,
            merge_centre=self.merge_centre,
            **kw,
        )

    def region_params(self, area: float) -> RegionParams:
        """Chapter 4's update for a sub-swarm of region area ``area`` (kept: r_c = sqrt(area / pi))."""
        return RegionParams(
            r_c=math.sqrt(area / math.pi),
            k_vcir=self.k_vcir,
            v_max=self.v_region,
            k_theta=self.k_theta,
            dynamics=self.dynamics,
            axes=self.axes,
            clearance=self.clearance,
            barrier=self.barrier,
            r_robot=self.r_robot,
        )


@dataclass
class _Swarm:
    """A sub-swarm's planner state: the split/merge record (members, leader, region, target), chapter 4's region
    state, the sensed points of the last periods, the lane waypoint and mouth while it is in transit, the split scans
    running."""

    sub: SubSwarm
    state: RegionState
    area: float
    hits: deque[np.ndarray]
    free: deque[np.ndarray]
    waypoint: np.ndarray | None = None
    mouth: np.ndarray | None = None
    confirm: int = 0
    held: str = ""
    facing: float | None = None
    scan: str = ""
    arrived: bool = False


class Ch6Planner(RegionPlanner):
    """Every period: the sonar points per sub-swarm, then for each sub-swarm the split, or a missing leader's
    promotion and the region step, then the merge check, then the plan (goals: the sub-region centres; law
    ``split_merge``; groups, leaders, regions). Events: ``region`` (the first), ``scan`` (the detector's verdict, on
    change), ``split``, ``merge``, ``promotion``, ``passed`` (a sub-swarm out of its lane), ``held`` (a region step
    refused, on change), ``input`` (dropped readings or poses, new agents, a bad target), ``arrived`` (a sub-swarm at
    its target) and ``done``."""

    Params = Ch6Params

    def __init__(self, **params: Any) -> None:
        for k in ("centre",):
            if isinstance(params.get(k), list):
                params[k] = tuple(params[k])
        if params.get("targets") is not None:
            params["targets"] = tuple(tuple(float(c) for c in t) for t in params["targets"])
        if params.get("lane_map") is not None:
            params["lane_map"] = tuple(params["lane_map"])
        self.p = Ch6Params(**params)
        self.period_s = self.p.period_s
        self.smp = self.p.split_params()
        self.sensing = SensingParams(self.p.d_min, self.p.d_max, self.p.r_robot, self.p.eclipse_eps)
        self.targets = None if self.p.targets is None else np.array(self.p.targets, dtype=float)
        self.swarms: list[_Swarm] = []
        self.group_of: dict[int, int] = {}
        self.next_id = 0
        self.mission: np.ndarray | None = None
        self.plans = 0
        self.counts = {"splits": 0, "merges": 0, "promotions": 0, "joined": 0, "bad_poses": 0}
        self.dropped = dict.fromkeys(DROP_REASONS, 0)
        self.done_t: float | None = None
        self.log: list[dict[str, Any]] = []  # splits, merges and promotions, for the summary

    # --- helpers -----------------------------------------------------------------------------------------------------

    def _new_swarm(self, sub: SubSwarm, waypoint: np.ndarray | None = None) -> _Swarm:
        m = self.p.memory
        return _Swarm(sub, RegionState(sub.region), sub.region.area, deque(maxlen=m), deque(maxlen=m), waypoint)

    def _final_target(self, s: _Swarm) -> np.ndarray | None:
        if s.sub.target is not None and self.targets is not None:
            return self.targets[s.sub.target]
        return self.mission

    def _goal_radius(self, s: _Swarm) -> float:
        return self.p.goal_radius if self.p.goal_radius is not None else math.sqrt(s.area / math.pi)

    def _groups(self, ids: np.ndarray) -> np.ndarray:
        """Each of ``ids``' sub-swarm (-1: none) by ``group_of``, looked up in one sorted array."""
        if not self.group_of:
            return np.full(len(ids), -1, dtype=int)
        keys = np.fromiter(self.group_of.keys(), dtype=int, count=len(self.group_of))
        vals = np.fromiter(self.group_of.values(), dtype=int, count=len(self.group_of))
        order = np.argsort(keys)
        keys, vals = keys[order], vals[order]
        at = np.minimum(np.searchsorted(keys, ids), len(keys) - 1)
        return np.where(keys[at] == ids, vals[at], -1)

    def _record(self, events: list[dict[str, Any]], e: dict[str, Any]) -> None:
        events.append(e)
        if e["kind"] in ("split", "merge", "promotion"):
            self.log.append(e)

    def _promotions(self, events: list, t: float, during: str, promos: Any) -> None:
        for pr in promos:
            self.counts["promotions"] += 1
            self._record(events, {"kind": "promotion", "t": t, "during": during, **pr.as_dict()})

    # --- the period --------------------------------------------------------------------------------------------------

    def plan(self, obs: Observation) -> Plan:
        self.plans += 1
        events: list[dict[str, Any]] = []
        order = np.argsort(np.asarray(obs.ids), kind="stable")
        ids = np.asarray(obs.ids, dtype=int)[order]
        x = np.asarray(obs.positions, dtype=float)[order].reshape(-1, 2)
        hd = np.asarray(obs.headings, dtype=float)[order]
        rng = np.asarray(obs.ranges, dtype=float)[order].reshape(len(ids), len(obs.angles))
        ang = np.asarray(obs.angles, dtype=float)
        n = len(ids)
        ok = np.isfinite(x).all(axis=1) & np.isfinite(hd)
        if n and not ok.all():
            self.counts["bad_poses"] += int((~ok).sum())
            events.append({"kind": "input", "reason": "pose", "agents": ids[~ok].tolist()})
        tg = np.asarray(obs.target, dtype=float)
        if tg.shape == (2,) and np.isfinite(tg).all():
            self.mission = tg
        elif self.mission is None and self.targets is None:
            events.append({"kind": "input", "reason": "target", "target": np.asarray(obs.target).tolist()})
        live_ids, live_x = ids[ok], x[ok]
        row = dict(zip(ids[ok].tolist(), np.nonzero(ok)[0].tolist(), strict=True))

        if not self.swarms:
            if not len(live_ids):
                return self._plan(obs.t, ids, x, [*events, {"kind": "held", "reason": "no agent with a pose"}])
            self._first(obs.t, live_ids, live_x, events)
        self._join(live_ids, live_x, events)

        # the sonar points (eqs. 6.1-6.4) and the free ends of the beams with no echo in the window
        pts = sense(x, hd, rng, ang, self.sensing) if n and len(ang) else None
        if pts is not None:
            for k_, v in pts.dropped.items():
                self.dropped[k_] += v
            if pts.dropped["garbage"]:
                events.append({"kind": "input", "reason": "readings", "dropped": dict(pts.dropped)})
        group_row = np.where(ok, self._groups(ids), -1)
        free_pts, free_row = self._free_ends(x, hd, rng, ang, ok)
        for s in self.swarms:
            mine = group_row == s.sub.id
            if pts is not None:
                s.hits.append(pts.points[mine[pts.owner]])
            s.free.append(free_pts[mine[free_row]] if len(free_row) else np.zeros((0, 2)))

        # each sub-swarm: split, or step its region
        live_group = group_row[ok]
        out: list[_Swarm] = []
        for s in self.swarms:
            out.extend(self._decide(obs.t, s, live_x[live_group == s.sub.id], live_ids, live_x, events))
        self.swarms = out
        self._merge(obs.t, live_ids, live_x, events)
        return self._plan(obs.t, ids, x, events, row)

    def _first(self, t: float, ids: np.ndarray, x: np.ndarray, events: list) -> None:
        n = len(ids)
        area = self.p.area if self.p.area is not None else n * math.pi * self.p.r_s**2
        c = np.array(self.p.centre) if self.p.centre is not None else x.mean(axis=0)
        r = math.sqrt(area / math.pi)
        lead = self.p.leader if self.p.leader is not None and self.p.leader in set(ids.tolist()) else int(ids.min())
        sub = SubSwarm(self.next_id, tuple(int(i) for i in ids), lead, Ellipse.circle(float(c[0]), float(c[1]), r))
        self.next_id += 1
        self.swarms = [self._new_swarm(sub)]
        self.group_of = {int(i): sub.id for i in ids}
        events.append({"kind": "region", "t": t, "swarm": sub.id, "leader": lead, "area": area, **sub.region.as_dict()})

    def _join(self, ids: np.ndarray, x: np.ndarray, events: list) -> None:
        """Agents seen for the first time join the sub-swarm whose region centre is nearest."""
        new = [r for r, i in enumerate(ids.tolist()) if i not in self.group_of]
        for i, p in zip(ids[new].tolist(), x[new], strict=True):
            if i in self.group_of:  # an id given twice
                continue
            k = int(np.argmin([np.hypot(*(p - s.sub.region.centre)) for s in self.swarms]))
            s = self.swarms[k]
            s.sub = replace(s.sub, members=(*s.sub.members, i))
            self.group_of[i] = s.sub.id
            self.counts["joined"] += 1
            events.append({"kind": "input", "reason": "joined", "agent": i, "swarm": s.sub.id})

    def _free_ends(
        self, x: np.ndarray, hd: np.ndarray, rng: np.ndarray, ang: np.ndarray, ok: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ends of the beams clear beyond the window's top, with the row of the agent whose beam it is: at their
        echo's range (clear that far) or, with no echo, at ``free_reach`` (None: 2 ``d_max``), never beyond it."""
        with np.errstate(invalid="ignore"):
            far = np.isfinite(rng) & (rng > self.p.d_max)
        clear = (np.isnan(rng) | far) & ok[:, None]
        r, b = np.nonzero(clear)
        reach = self.p.free_reach if self.p.free_reach is not None else 2 * self.p.d_max
        d = np.where(far[r, b], np.minimum(rng[r, b], reach), reach)
        return beam_points(x, hd, ang, r, b, d), r

    def _decide(
        self, t: float, s: _Swarm, xs: np.ndarray, ids: np.ndarray, x: np.ndarray, events: list
    ) -> list[_Swarm]:
        """A sub-swarm's period: out of its lane?, a split (``confirm`` scans running), else chapter 4's region step
        toward its waypoint or target. ``xs``: its present members' positions; ``ids``, ``x``: every live agent's."""
        e = s.state.region
        if s.waypoint is not None and self._through(s, xs):
            s.waypoint = None
            events.append({"kind": "passed", "t": t, "swarm": s.sub.id, "centre": e.centre.tolist()})
        goal = s.waypoint if s.waypoint is not None else self._final_target(s)
        if goal is None:
            return [s]
        d = goal - e.centre
        heading = math.atan2(d[1], d[0]) if np.any(d) else e.theta
        hits = np.concatenate(list(s.hits)) if s.hits else np.zeros((0, 2))
        free = np.concatenate(list(s.free)) if s.free else np.zeros((0, 2))
        if s.waypoint is None and len(xs) >= 2 and len(hits):
            scan = detect_openings(hits, e.centre, heading, self.smp, free=free)
            reach = self.p.opening_reach if self.p.opening_reach is not None else self.p.d_max + max(e.a, e.b)
            far = [o for o in scan.openings if np.hypot(*(o.centre - e.centre)) > reach]
            if scan.split and far:  # a lane farther than the window reaches is built of far echoes: not yet a lane
                scan = replace(scan, split=False, reason=f"{scan.reason}, {len(far)} beyond {reach:.3g}: no split")
            s.confirm = s.confirm + 1 if scan.split else 0
            if scan.reason != s.scan:
                s.scan = scan.reason
                b_fs = [round(o.b_fs, 4) for o in scan.openings]
                events.append({"kind": "scan", "t": t, "swarm": s.sub.id, "reason": scan.reason, "b_fs": b_fs})
            if s.confirm >= self.p.confirm:
                children = self._split(t, s, scan, ids, x, events)
                if children:
                    return children
        sub, promo = ensure_leader(s.sub, x, ids)  # a missing leader: the member nearest the centre (eq. 6.14)
        if promo is not None and promo.promoted != -1:
            s.sub = replace(s.sub, leader=sub.leader)
            self._promotions(events, t, "period", (promo,))
        # chapter 4's update: the gap ahead of the region (points within its reach along the heading), the area kept
        c, h = e.centre, np.array([math.cos(heading), math.sin(heading)])
        reach = max(e.a, e.b) + self.p.gap_ahead
        ahead = (hits - c) @ h if len(hits) else np.zeros(0)
        near = hits[(ahead >= 0) & (ahead <= reach)]
        wall = self._wall_ahead(near, xs, c, h)
        gap = free_space(near, c, self.p.gap_mode, heading=heading, split=self.p.gap_split)
        step = step_region(s.state, gap, goal, self.period_s, self.p.region_params(s.area), xs if len(xs) else None)
        if step.held.startswith("infeasible") and not s.held.startswith("infeasible"):
            events.append({"kind": "held", "t": t, "swarm": s.sub.id, "reason": step.held})
        s.held = step.held
        # the robots face the way while the region advances (not while it waits for them) or holds before a wall
        s.facing = heading if s.waypoint is None and (wall or not step.held) else None
        s.state = step.state
        s.sub = replace(s.sub, region=step.state.region)
        return [s]

    def _wall_ahead(self, near: np.ndarray, xs: np.ndarray, c: np.ndarray, h: np.ndarray) -> bool:
        """Whether any of the points ``near`` (within the region's reach ahead) lies across the way: ahead of every
        member by more than ``r_robot`` (not a point among the robots, as a teammate's back can be) and within the
        members' lateral extent widened by r_s (not the arena's side walls beside them)."""
        if not len(near) or not len(xs):
            return False
        side = np.array([-h[1], h[0]])
        along, across = (xs - c) @ h, (xs - c) @ side
        pa, pc = (near - c) @ h, (near - c) @ side
        lo, hi = across.min() - self.p.r_s, across.max() + self.p.r_s
        return bool(np.any((pa > along.max() + self.p.r_robot) & (pc >= lo) & (pc <= hi)))

    def _through(self, s: _Swarm, xs: np.ndarray) -> bool:
        """Whether a sub-swarm in transit is out of its lane: its region's centre at the waypoint, or every present
        member beyond the lane's mouth by 2 r_s along the passage."""
        assert s.waypoint is not None
        if np.hypot(*(s.state.region.centre - s.waypoint)) <= self.p.v_region * self.period_s:
            return True
        along = s.waypoint - s.mouth
        length = float(np.hypot(*along))
        return bool(len(xs)) and length > 0 and bool(np.all((xs - s.mouth) @ (along / length) >= 2 * self.p.r_s))

    def _split(self, t: float, s: _Swarm, scan: Any, ids: np.ndarray, x: np.ndarray, events: list) -> list[_Swarm]:
        d = split_swarm(
            scan, s.sub, x, self.smp, ids=ids, first_id=self.next_id, targets=self.targets, lane_map=self.p.lane_map
        )
        self._promotions(events, t, "split", d.promotions)
        if not d.split:
            if d.promotions and d.swarms[0].leader != -1:
                s.sub = replace(s.sub, leader=d.swarms[0].leader)
            return []
        self.next_id += len(d.swarms)
        self.counts["splits"] += 1
        depth = self.p.pass_depth if self.p.pass_depth is not None else self.p.d_max
        out = []
        for child, op in zip(d.swarms, [o for o in scan.openings if _used(o, d.swarms)], strict=True):
            along = child.region.centre - s.sub.region.centre
            theta = math.atan2(along[1], along[0]) if self.p.passage == "bearing" and np.any(along) else op.theta
            way = child.region.centre + depth * np.array([math.cos(theta), math.sin(theta)])
            c = self._new_swarm(child, way)
            c.mouth = child.region.centre
            c.hits.extend(s.hits)
            c.free.extend(s.free)
            for m in child.members:
                self.group_of[m] = child.id
            out.append(c)
        self._record(
            events,
            {
                "kind": "split",
                "t": t,
                "parent": s.sub.id,
                "swarms": [c.id for c in d.swarms],
                "sizes": [len(c.members) for c in d.swarms],
                "b_fs": [o.b_fs for o in scan.openings],
                "leaders": [c.leader for c in d.swarms],
                "areas": [c.region.area for c in d.swarms],
                "centres": [c.region.centre.tolist() for c in d.swarms],
                "parent_area": s.area,
                "targets": [c.target for c in d.swarms],
                "missing": list(d.missing),
                "reason": d.reason,
            },
        )
        return out

    def _merge(self, t: float, ids: np.ndarray, x: np.ndarray, events: list) -> None:
        free = [s for s in self.swarms if s.waypoint is None]
        if len(free) < 2:
            return
        target = self.mission if self.targets is None else None
        _, decisions = merge_all([s.sub for s in free], [s.sub.region for s in free], x, self.smp, ids, target)
        if not decisions:
            return
        by_id = {s.sub.id: s for s in free}
        gone = {i for dec in decisions for i in dec.merged}
        keep = [s for s in self.swarms if s.sub.id not in gone]
        for dec in decisions:
            parts = [by_id[i] for i in dec.merged]
            new = replace(dec.swarm, id=self.next_id)
            self.next_id += 1
            absent = tuple(a for p in parts for a in p.sub.members if a not in set(new.members))
            new = replace(new, members=new.members + absent)  # an absent member rejoins when it reports again
            m = self._new_swarm(new)
            m.area = dec.area
            for p in parts:
                m.hits.extend(p.hits)
                m.free.extend(p.free)
            self.group_of.update(dict.fromkeys(new.members, new.id))
            keep.append(m)
            self.counts["merges"] += 1
            self._promotions(events, t, "merge", dec.promotions)
            self._record(
                events,
                {
                    "kind": "merge",
                    "t": t,
                    "merged": list(dec.merged),
                    "swarm": new.id,
                    "areas": [p.sub.region.area for p in parts],
                    "area": dec.area,
                    "required_area": dec.required_area,
                    "theorem1": dec.theorem1,
                    "leader": new.leader,
                    "sizes": [len(p.sub.members) for p in parts],
                    **{k: v for k, v in new.region.as_dict().items() if k in ("a", "b")},
                },
            )
        self.swarms = sorted(keep, key=lambda s: s.sub.id)

    def _plan(self, t: float, ids: np.ndarray, x: np.ndarray, events: list, row: dict[int, int] | None = None) -> Plan:
        n = len(ids)
        centre = {s.sub.id: s.sub.region.centre for s in self.swarms}
        groups = self._groups(ids)
        fallback = self.mission if self.mission is not None else np.zeros(2)
        kinds, which = np.unique(groups, return_inverse=True)  # one goal per sub-swarm, copied to its members
        goals = np.array([centre.get(g, fallback) for g in kinds.tolist()]).reshape(-1, 2)[which].reshape(n, 2)
        row = row or {}
        all_in = bool(self.swarms) and bool(row)
        for s in self.swarms:
            tgt = self._final_target(s)
            present = list(map(row.__getitem__, filter(row.__contains__, s.sub.members)))
            there = (
                tgt is not None
                and s.waypoint is None
                and bool(present)
                and bool(np.all(np.hypot(*(x[present] - tgt).T) <= self._goal_radius(s)))
            )
            if there and not s.arrived:
                events.append({"kind": "arrived", "t": t, "swarm": s.sub.id, "members": len(present)})
            s.arrived = s.arrived or there
            all_in = all_in and (there or not present)
        if all_in and self.done_t is None:
            self.done_t = t
            events.append({"kind": "done", "t": t, "swarms": [s.sub.id for s in self.swarms]})
        params = {
            "k_c": self.p.k_c,
            "k_f": self.p.k_f,
            "r_s": self.p.r_s,
            "mode": self.p.law_mode,
            "radius_scales": self.p.radius_scales,
        }
        if self.p.law_mode == "knn":
            params["neighbours"] = self.p.law_neighbours
        if self.p.law_min_sep > 0:
            params["min_sep"] = self.p.law_min_sep
        before = not self.counts["splits"] and not self.counts["merges"]
        face = self.swarms[0].facing if self.p.face and before and len(self.swarms) == 1 else None
        return Plan(
            t,
            ids,
            goals,
            "split_merge",
            params,
            groups=groups,
            leaders=tuple(s.sub.leader for s in self.swarms if s.sub.leader != -1),
            regions=tuple(Region(s.sub.id, s.sub.region) for s in self.swarms),
            events=tuple(events),
            done=self.done_t is not None,
            face=face,
        )

    def summary(self) -> dict[str, Any]:
        return {
            "params": asdict(self.p),
            "plans": self.plans,
            **self.counts,
            "dropped_readings": dict(self.dropped),
            "done_t": self.done_t,
            "swarms": [{**s.sub.as_dict(), "area": s.area, "in_transit": s.waypoint is not None} for s in self.swarms],
            "decisions": self.log,
        }


def _used(opening: Any, swarms: tuple[SubSwarm, ...]) -> bool:
    """Whether a scan's opening got a sub-swarm (``split_swarm`` drops an opening no agent would fill): its centre is
    one of the sub-regions' centres."""
    c = opening.centre
    return any(math.isclose(s.region.x, c[0]) and math.isclose(s.region.y, c[1]) for s in swarms)
