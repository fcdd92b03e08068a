"""``roy-regions``, chapters 5 and 6 (digest 001 §4.5-4.6): what a mission of the ``ch5`` or ``ch6`` planner is
judged on (targets B7-B12, C6-C9), and the report's figures of chapter 6.

A ``Recorder`` wraps the scenario's planner in the point model and passes every plan through unchanged; it keeps, per
planner period, each region's area, axes and centre, and checks at the moments that matter, on the plans and the
poses the planner saw:

- chapter 5, at every region update (B7): the N circles the agents were assigned (each agent's goal, of the radius
  the packing used) do not overlap and lie inside the polygon Φ, at r_s or shrunk; the lattice's own count; the
  unused area UA = A_Φ - N π r_s² (eq. 5.12) against the gap b_fs sensed then;
- chapter 5, the barrier (B8): at every "all in circles" release, how far the agents were from their circles (in
  units of the circle radius; the planner's tolerance is 0.1), whether the goals ever changed between region
  updates, and whether a region update came without a release since the last;
- chapter 6, at every split (B9): whether each sub-swarm's leader is its member nearest its sub-region's centre
  (eq. 6.14), from the poses of that period; at every merge (B10): whether the merged sub-regions already
  intersected in the period before.

The rest comes from the mission's summary (the planners' ``split``, ``merge``, ``barrier`` and ``region`` events)
and its series (D(t), eq. 6.25). The thesis' scaling "scenario 1" (Tables 6.2, Figs. 6.13, 6.15, 6.17: "splitting
and rejoining ... with only static obstacles (Fig. 6.9)") is case 2, ``ch6-case2``; its "scenario 2" (Table 6.3,
Figs. 6.14, 6.16, 6.18: "splitting ... with static and dynamic obstacles (Fig. 6.11)") is case 3, ``ch6-case3``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from scipy.stats import spearmanr
from shapely.geometry import Polygon

from bridge.experiments.runner import Outcome, TrialResult
from bridge.studies.roy.metrics import linear_fit, unused_area
from bridge.studies.roy.numerical import Mover
from bridge.studies.roy.regions_judging import Verdict, whole
from bridge.studies.roy.regions_judging import fmt as _f
from bridge.studies.roy.regions_judging import no_runs as _none
from bridge.studies.roy.regions_plots import exec_plot, finish
from bridge.studies.roy.regions_scenarios import RegionScenario
from bridge.studies.roy.regions_world import MissionResult
from swarm_logic.families.roy.regions.planner import Observation, Plan, RegionPlanner
from swarm_logic.families.roy.regions.shapes import Ellipse

CH5 = "ch5-a"
CH6_CASES = ("ch6-case1", "ch6-case2", "ch6-case3")
# the thesis' scaling scenarios (Tables 6.2, 6.3) -> our case files, and the N of their rows
SCALING = {"scenario 1": "ch6-case2", "scenario 2": "ch6-case3"}
SCALING_N = (50, 100, 250, 500, 1000)
SCALING_TRIALS = {1000: 10}  # the big cells' cap on trials (the rest run the experiment's count)
TIME_TOL = 0.2  # C6, C9: +-20 % on times
# C6: 14 agents at T after about 250 s; the "all agents in circles" events of Fig. 5.8
THESIS_CH5_ARRIVAL = 250.0
THESIS_CIRCLE_EVENTS = (12.0, 29.0, 60.2, 94.0, 153.2)
# C7: the mean structural density (eq. 6.25) by (case file, N): §6.5's 0.55 (100 agents, scenario 1) and 0.6 (50,
# scenario 2), Figs. 6.15-6.16's 0.43, 0.4 (scenario 1) and 0.325, 0.31 (scenario 2) at 500 and 1000
THESIS_D = {
    ("ch6-case2", 100): 0.55,
    ("ch6-case2", 500): 0.43,
    ("ch6-case2", 1000): 0.40,
    ("ch6-case3", 50): 0.60,
    ("ch6-case3", 500): 0.325,
    ("ch6-case3", 1000): 0.31,
}
D_TOL = 0.1
# C8: Tables 6.2 and 6.3 (mean execution time against N: slopes and COV)
THESIS_EXEC = {"ch6-case2": "0.444 s/agent, COV 0.164 -> 0.002", "ch6-case3": "5.56 s/agent, COV 0.034 -> 0.0004"}
R2_MIN = 0.99
# C8's execution time: the mission's CPU seconds (``cpu_s``, the process time of ``run_mission``): the compute time
# of erratum 29, which the wall-clock ``exec_s`` measures too but inflated by whatever else shares the cores
EXEC = "cpu_s"
# C9: §6.5's times (s): case 2 split 10, merge 45, arrival 60; case 1 split 16, arrival 82; case 3 split 35, arrival 85
THESIS_CH6_TIMES = {
    "ch6-case1": {"split": 16.0, "arrival": 82.0},
    "ch6-case2": {"split": 10.0, "merge": 45.0, "arrival": 60.0},
    "ch6-case3": {"split": 35.0, "arrival": 85.0},
}
START_S = 5.0  # B12: D while converging = its mean over the first seconds; "before the split" the same span before
REL = 1e-9  # B9, B10, B11: areas equal to this relative tolerance
# B7: a circle is inside the region when its centre is at least (1 - CLEAR_TOL) radii from the boundary: the
# packing erodes the region with arcs drawn as chords (0.0012 r_s), so 1e-3 r is its own accuracy
CLEAR_TOL = 1e-3


# -- recording -------------------------------------------------------------------------------------------------------


class Recorder(RegionPlanner):
    """A chapter 5 or 6 planner with its plans recorded (module docstring); ``plan`` returns the planner's plan
    unchanged, ``summary`` the planner's. Its own work is a few appends a period, and a check at the rare periods of
    a region update, a release, a split or a merge."""

    def __init__(self, planner: RegionPlanner, r_s: float) -> None:
        self.planner = planner
        self.period_s = planner.period_s
        self.r_s = float(r_s)
        self.regions: list[tuple[float, int, float, float, float, float, float]] = []  # t, group, area, a, b, x, y
        self.updates: list[dict[str, Any]] = []  # ch5: B7 per region update
        self.releases: list[float] = []  # ch5: max distance to the circles / radius at each "all in circles"
        self.goal_changes = 0  # ch5: periods whose goals changed without a region update
        self.leaders: list[bool] = []  # ch6: per sub-swarm of every split, its leader the member nearest its centre
        self.merge_overlap: list[bool] = []  # ch6: per merge, its parts intersected the period before
        self.prev: Plan | None = None
        self.prev_regions: dict[int, Ellipse] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self.__dict__["planner"], name)

    def summary(self) -> dict[str, Any]:
        return self.planner.summary()

    def plan(self, obs: Observation) -> Plan:
        plan = self.planner.plan(obs)
        kinds = {e.get("kind") for e in plan.events}
        now: dict[int, Ellipse] = {}
        for r in plan.regions:
            if r.ellipse is not None:
                e = r.ellipse
                now[r.group] = e
                self.regions.append((plan.t, r.group, e.area, e.a, e.b, e.x, e.y))
        if plan.law == "packing":
            self._ch5(obs, plan, kinds)
        elif kinds & {"split", "merge"}:
            self._ch6(obs, plan)
        self.prev, self.prev_regions = plan, now
        return plan

    def _ch5(self, obs: Observation, plan: Plan, kinds: set[Any]) -> None:
        """B7 at a region update; B8: the goals held between updates, the agents in their circles at a release."""
        prev = self.prev
        if "region" in kinds and plan.regions and plan.regions[0].vertices is not None:
            self.updates.append(self._circles(plan))
        elif prev is not None and "region" not in kinds and not _same(prev.goals, plan.goals):
            self.goal_changes += 1
        for e in plan.events:
            if e.get("kind") == "barrier" and e.get("reason") == "all in circles" and prev is not None:
                radius = float(prev.params.get("r_s", self.r_s))
                d = np.hypot(*(_rows(obs, plan.ids) - _rows_of(prev, plan.ids)).T)
                self.releases.append(float(np.nanmax(d)) / radius if len(d) else math.nan)

    def _ch6(self, obs: Observation, plan: Plan) -> None:
        """B9: each new sub-swarm's leader against its member nearest its centre; B10: the merged parts' regions of
        the period before."""
        x = _rows(obs, plan.ids)
        groups = np.asarray(plan.groups) if plan.groups is not None else np.full(len(plan.ids), -1)
        for e in plan.events:
            if e.get("kind") == "split":
                for sid, lead, c in zip(e["swarms"], e["leaders"], e["centres"], strict=True):
                    members = np.nonzero(groups == sid)[0]
                    ok_x = members[np.isfinite(x[members]).all(axis=1)]
                    if not len(ok_x):
                        continue
                    near = ok_x[int(np.argmin(np.hypot(*(x[ok_x] - np.asarray(c, float)).T)))]
                    self.leaders.append(int(plan.ids[near]) == int(lead))
            elif e.get("kind") == "merge":
                parts = [self.prev_regions.get(int(g)) for g in e["merged"]]
                known = [p for p in parts if p is not None]
                self.merge_overlap.append(
                    len(known) == len(parts)
                    and any(known[i].intersects(known[j]) for i in range(len(known)) for j in range(i + 1, len(known)))
                )

    def _circles(self, plan: Plan) -> dict[str, Any]:
        """B7 at a region update: the assigned circles (the goals, of the packing's radius) against Φ."""
        g = np.asarray(plan.goals, float)
        radius = float(plan.params.get("r_s", self.r_s))
        poly = Polygon(np.asarray(plan.regions[0].vertices, float))
        if len(g) > 1:
            d = np.hypot(g[:, None, 0] - g[None, :, 0], g[:, None, 1] - g[None, :, 1])
            gap = float(d[np.triu_indices(len(g), 1)].min())
        else:
            gap = math.inf
        inside = shapely.contains_xy(poly, g[:, 0], g[:, 1])
        edge = shapely.distance(poly.exterior, shapely.points(g))
        clearance = float(edge.min()) / radius if len(g) else math.inf
        fits = bool(inside.all() and clearance >= 1 - CLEAR_TOL)
        event = next(e for e in plan.events if e.get("kind") == "region")
        return {
            "t": plan.t,
            "n": len(g),
            "radius": radius,
            "disjoint": gap >= 2 * radius * (1 - 1e-9),
            "inside": fits,
            "clearance": clearance,
            "at_r_s": radius >= self.r_s * (1 - 1e-9),
            "method": event.get("method"),
            "lattice_count": event.get("lattice_count"),
            "area": event.get("area"),
            "b_fs": event.get("b_fs"),
        }


def _rows(obs: Observation, ids: np.ndarray) -> np.ndarray:
    """The observation's positions in the order of ``ids`` (NaN for an id it lacks)."""
    where = {int(i): k for k, i in enumerate(np.asarray(obs.ids).tolist())}
    x = np.asarray(obs.positions, float)
    return np.array([x[where[int(i)]] if int(i) in where else (np.nan, np.nan) for i in ids]).reshape(-1, 2)


def _rows_of(plan: Plan, ids: np.ndarray) -> np.ndarray:
    """A plan's goals in the order of ``ids`` (NaN for an id it lacks)."""
    where = {int(i): k for k, i in enumerate(np.asarray(plan.ids).tolist())}
    g = np.asarray(plan.goals, float)
    return np.array([g[where[int(i)]] if int(i) in where else (np.nan, np.nan) for i in ids]).reshape(-1, 2)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return np.shape(a) == np.shape(b) and bool(np.array_equal(np.asarray(a), np.asarray(b)))


def recorder_for(sc: RegionScenario, planner: RegionPlanner) -> Recorder | None:
    """A ``Recorder`` around the planner of a chapter 5 or 6 scenario, None for another."""
    return Recorder(planner, sc.metrics.r_s) if sc.planner.name in ("ch5", "ch6") else None


# -- per-trial metrics -----------------------------------------------------------------------------------------------


def _times(events: list[dict[str, Any]], kind: str) -> list[float]:
    return [float(e["t"]) for e in events if e.get("kind") == kind]


def _join(v: list[float]) -> str:
    return " ".join(f"{x:g}" for x in v)


def ch5_metrics(res: MissionResult, rec: Recorder) -> dict[str, Any]:
    """B7, B8 and C6's figures of a chapter 5 mission (module docstring)."""
    s = res.summary
    p = s["planner"]
    up = rec.updates
    short = [u for u in up if u["lattice_count"] is not None and u["lattice_count"] < u["n"]]
    ua = [(u["b_fs"], unused_area(u["area"], u["n"], rec.r_s)) for u in up if u["b_fs"] is not None]
    rho = math.nan
    ua_at_min = ua_rank = None
    if len(ua) >= 3:
        b, a = np.array(ua).T
        rho = float(spearmanr(b, a).statistic) if np.ptp(b) > 0 and np.ptp(a) > 0 else math.nan
        ua_at_min = float(a[int(np.argmin(b))])
        ua_rank = float(np.mean(a < ua_at_min))  # the share of updates with less UA than at the narrowest gap
    # B8: region updates (after the first) with no release since the update before
    unreleased, released = 0, False
    for e in s["events"]:
        if e.get("kind") == "barrier":
            released = True
        elif e.get("kind") == "region":
            if e.get("why") not in ("start", "membership") and not released:
                unreleased += 1
            released = False
    circles = [float(r["t"]) for r in p.get("releases", []) if r["reason"] == "all in circles"]
    return {
        "region_updates": len(up),
        "b7_held": sum(u["disjoint"] and u["inside"] and u["at_r_s"] for u in up),
        "b7_overlap_or_out": sum(not (u["disjoint"] and u["inside"]) for u in up),
        "b7_shrunk": sum(not u["at_r_s"] for u in up),
        "b7_min_clearance": min((u["clearance"] for u in up), default=None),
        "b7_lattice_short": len(short),
        "b7_fallback_held": sum(u["disjoint"] and u["inside"] and u["at_r_s"] for u in short),
        "ua_bfs_rho": rho,
        "ua_at_min_bfs": ua_at_min,
        "ua_rank_at_min_bfs": ua_rank,
        "b8_releases": len(rec.releases),
        "b8_timeouts": len(p.get("timeouts", [])),
        "b8_max_off": max(rec.releases) if rec.releases else None,
        "b8_goal_changes": rec.goal_changes,
        "b8_unreleased_updates": unreleased,
        "circle_events": len(circles),
        "circle_events_s": _join(circles),
    }


def _groups(rec: Recorder) -> dict[int, np.ndarray]:
    """Each region's rows (t, group, area, a, b, x, y) by group."""
    if not rec.regions:
        return {}
    rows = np.asarray(rec.regions, float)
    return {int(g): rows[rows[:, 1] == g] for g in np.unique(rows[:, 1])}


def _mean_in(t: np.ndarray, d: np.ndarray, lo: float, hi: float) -> float | None:
    m = (t >= lo) & (t < hi) & np.isfinite(d)
    return float(d[m].mean()) if m.any() else None


def ch6_metrics(res: MissionResult, rec: Recorder, sc: RegionScenario) -> dict[str, Any]:
    """B9-B12 and C9's figures of a chapter 6 mission (module docstring)."""
    ev = res.summary["events"]
    splits = [e for e in ev if e.get("kind") == "split"]
    merges = [e for e in ev if e.get("kind") == "merge"]
    out: dict[str, Any] = {
        "splits": len(splits),
        "merges": len(merges),
        "split_s": float(splits[0]["t"]) if splits else None,
        "merge_s": float(merges[0]["t"]) if merges else None,
        "split_times": _join(_times(ev, "split")),
        "merge_times": _join(_times(ev, "merge")),
        "split_sizes": " / ".join("+".join(str(k) for k in e["sizes"]) for e in splits),
        "split_b_fs": " / ".join(" ".join(f"{b:.2f}" for b in e["b_fs"]) for e in splits),
    }
    scans = [e for e in ev if e.get("kind") == "scan"]
    out["scan_last"] = scans[-1]["reason"] if scans else ""
    out["scans_two_plus"] = sum(len(e.get("b_fs", [])) >= 2 for e in scans)
    out["scan_max_openings"] = max((len(e.get("b_fs", [])) for e in scans), default=0)
    if splits:
        out["split_min_openings"] = min(len(e["b_fs"]) for e in splits)
        out["split_area_err"] = max(abs(sum(e["areas"]) - e["parent_area"]) / e["parent_area"] for e in splits)
        out["split_widest_most"] = all(e["sizes"][int(np.argmax(e["areas"]))] == max(e["sizes"]) for e in splits)
        out["split_leaders_nearest"] = bool(rec.leaders) and all(rec.leaders)
    if merges:
        out["merge_area_err"] = max(abs(e["area"] - sum(e["areas"])) / sum(e["areas"]) for e in merges)
        out["merge_one_leader"] = all(isinstance(e.get("leader"), int) and e["leader"] >= 0 for e in merges)
        out["merge_theorem1"] = all(bool(e.get("theorem1")) for e in merges)
        out["merge_overlapped"] = sum(rec.merge_overlap)
    # B11: every region's area over its life, its axes' change, and (with movers) the periods a sub-swarm born of a
    # split changed its axes with a mover within its reach
    groups = _groups(rec)
    dev = axes = 0.0
    moved = 0
    movers = [Mover(tuple(m.a), tuple(m.b), m.radius, m.speed) for m in sc.world.movers]
    born = {int(i) for e in splits for i in e["swarms"]}
    for g, rows in groups.items():
        area, a, b = rows[:, 2], rows[:, 3], rows[:, 4]
        dev = max(dev, float(np.max(np.abs(area - area[0])) / area[0]))
        axes = max(axes, float(np.ptp(a)), float(np.ptp(b)))
        if movers and g in born and len(rows) > 1:
            change = (np.abs(np.diff(a)) > 1e-9) | (np.abs(np.diff(b)) > 1e-9)
            for k in np.nonzero(change)[0] + 1:
                t, c, reach = rows[k, 0], rows[k, 5:7], max(rows[k, 3], rows[k, 4])
                moved += any(np.hypot(*(m.centre(t) - c)) <= reach + m.radius for m in movers)
    out["sub_area_dev"] = dev
    out["sub_axes_range"] = axes
    out["mover_axes_periods"] = moved if movers else None
    # B12: D(t) while converging, before the first split, between it and the first merge, after that merge
    t = np.asarray(res.series["t"], float)
    d = np.asarray(res.series["density"], float)
    out["d_start"] = _mean_in(t, d, 0.0, START_S)
    if splits:
        ts = out["split_s"]
        tm = out["merge_s"] if merges and out["merge_s"] > ts else math.inf
        out["d_pre_split"] = _mean_in(t, d, ts - START_S, ts)
        out["d_split"] = _mean_in(t, d, ts, tm)
        out["d_merge"] = _mean_in(t, d, tm, math.inf) if math.isfinite(tm) else None
    return out


def ch56_metrics(res: MissionResult, rec: Recorder, sc: RegionScenario) -> dict[str, Any]:
    """The chapter's figures of a mission run with ``rec`` (``recorder_for``)."""
    return ch5_metrics(res, rec) if sc.planner.name == "ch5" else ch6_metrics(res, rec, sc)


def ch56_curves(rec: Recorder) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Each sub-swarm's region area and semi-axes over its life (``sub<group>_area``, ``_a``, ``_b``) and their
    times, for a chapter 6 mission (none for chapter 5's polygon)."""
    curves: dict[str, list[float]] = {}
    xs: dict[str, list[float]] = {}
    for g, rows in _groups(rec).items():
        for k, name in ((2, "area"), (3, "a"), (4, "b")):
            curves[f"sub{g}_{name}"] = [float(v) for v in rows[:, k]]
            xs[f"sub{g}_{name}"] = [float(v) for v in rows[:, 0]]
    return curves, xs


# -- judging ---------------------------------------------------------------------------------------------------------


def _sum(res: list[TrialResult], key: str) -> int:
    return int(sum(r.metrics.get(key) or 0 for r in res))


def judge_b7(outcomes: list[Outcome]) -> Verdict:
    res = whole(outcomes, CH5)
    if not res:
        return _none(outcomes, f"needs {CH5}")
    n_up, held = _sum(res, "region_updates"), _sum(res, "b7_held")
    short, fb = _sum(res, "b7_lattice_short"), _sum(res, "b7_fallback_held")
    bad, shrunk = _sum(res, "b7_overlap_or_out"), _sum(res, "b7_shrunk")
    clear = [r.metrics["b7_min_clearance"] for r in res if r.metrics.get("b7_min_clearance") is not None]
    nearest = _f(min(clear) if clear else None, 4)
    rho = [r.metrics["ua_bfs_rho"] for r in res if r.metrics.get("ua_bfs_rho") is not None]
    rho = [v for v in rho if math.isfinite(v)]
    rank = [r.metrics["ua_rank_at_min_bfs"] for r in res if r.metrics.get("ua_rank_at_min_bfs") is not None]
    ours = (
        f"{held}/{n_up} updates with N disjoint r_s circles inside the region ({bad} overlapping or outside, "
        f"{shrunk} at a shrunk radius; the nearest a centre came to the boundary: {nearest} "
        f"radii); lattice short of N in {short}, the fallback held N at r_s in {fb}; "
        f"UA against b_fs: Spearman {_f(float(np.mean(rho)) if rho else None)} (mean of {len(rho)} runs), at the "
        f"narrowest b_fs {_f(100 * float(np.mean(rank)) if rank else None, 0)} % of the updates had less UA"
    )
    good = n_up > 0 and held == n_up
    return ours, good, "every update of every run: the assigned circles, disjoint and inside; UA is reported"


def judge_b8(outcomes: list[Outcome]) -> Verdict:
    res = whole(outcomes, CH5)
    if not res:
        return _none(outcomes, f"needs {CH5}")
    rel, tout = _sum(res, "b8_releases"), _sum(res, "b8_timeouts")
    off = [r.metrics["b8_max_off"] for r in res if r.metrics.get("b8_max_off") is not None]
    moved, unrel = _sum(res, "b8_goal_changes"), _sum(res, "b8_unreleased_updates")
    worst = max(off) if off else None
    ours = (
        f"{rel} 'all in circles' releases (agents at most {_f(worst, 3)} radii from their circles), {tout} by the "
        f"timeout; goals changed between updates {moved} times; updates without a release {unrel}"
    )
    good = rel > 0 and moved == 0 and unrel == 0 and tout == 0 and worst is not None and worst <= 0.1 + 1e-9
    return ours, good, "every update: released with every agent within 0.1 r of its circle, goals held till then"


def judge_c6(outcomes: list[Outcome]) -> Verdict:
    res = whole(outcomes, CH5)
    if not res:
        return _none(outcomes, f"needs {CH5}")
    arr = [r.metrics["arrival_s"] for r in res if r.metrics.get("arrived")]
    m = float(np.mean(arr)) if arr else math.nan
    counts = [int(r.metrics.get("circle_events") or 0) for r in res]
    first = str(res[0].metrics.get("circle_events_s") or "").split()[: len(THESIS_CIRCLE_EVENTS)]
    ours = (
        f"arrival {_f(m, 1)} s ({len(arr)}/{len(res)} arrived); 'all in circles' events {min(counts)}-{max(counts)} "
        f"per run (thesis {len(THESIS_CIRCLE_EVENTS)}), the first run's first: {', '.join(first) or '-'} s"
    )
    t_ok = bool(arr) and len(arr) == len(res) and abs(m - THESIS_CH5_ARRIVAL) <= TIME_TOL * THESIS_CH5_ARRIVAL
    n_ok = all(c == len(THESIS_CIRCLE_EVENTS) for c in counts)
    return ours, t_ok and n_ok, f"time {'ok' if t_ok else 'off'}; count {'ok' if n_ok else 'off'} (events in order)"


def _case_parts(
    outcomes: list[Outcome], part: Callable[[str, list[TrialResult]], tuple[str, bool | None]], note: str
) -> Verdict:
    """A target over chapter 6's three cases: each case's text and verdict (None: not judged there), joined, with
    ``note``."""
    parts, verdicts = [], []
    for case in CH6_CASES:
        res = whole(outcomes, case, agents=None)
        if not res:
            continue
        text, v = part(case, res)
        parts.append(f"{case}: {text}")
        verdicts.append(v)
    if not parts:
        return _none(outcomes, "needs the ch6 cells")
    judged = [v for v in verdicts if v is not None]
    return "; ".join(parts), (all(judged) if judged else None), note


def _split_part(case: str, res: list[TrialResult]) -> tuple[str, bool | None]:
    split = [r for r in res if r.metrics.get("splits")]
    if not split:
        seen = max(int(r.metrics.get("scan_max_openings") or 0) for r in res)
        why = "the packed swarm's sonar never saw two lanes at once" if seen < 2 else "2+ openings never confirmed"
        return f"no split in {len(res)} runs: at most {seen} opening(s) in a scan ({why})", False
    ok_ = [
        r
        for r in split
        if r.metrics["split_min_openings"] >= 2
        and r.metrics["split_area_err"] <= REL
        and r.metrics["split_widest_most"]
        and r.metrics["split_leaders_nearest"]
    ]
    err = max(r.metrics["split_area_err"] for r in split)
    sizes = sorted({str(r.metrics["split_sizes"]) for r in split})[:3]
    text = (
        f"split {len(split)}/{len(res)} (sizes {', '.join(sizes)}), >= 2 openings, area sum err <= {err:.1e}, widest "
        f"most, leaders nearest: {len(ok_)}/{len(split)}"
    )
    return text, len(ok_) == len(split) and len(split) == len(res)


def judge_b9(outcomes: list[Outcome]) -> Verdict:
    return _case_parts(
        outcomes, _split_part, "every split; a case whose runs never split fails (the thesis splits all three)"
    )


def _merge_part(case: str, res: list[TrialResult]) -> tuple[str, bool | None]:
    merged = [r for r in res if r.metrics.get("merges")]
    if not merged:
        split = sum(bool(r.metrics.get("splits")) for r in res)
        return f"no merge in {len(res)} runs ({split} split)", (False if case == "ch6-case2" else None)
    good = [
        r
        for r in merged
        if r.metrics["merge_area_err"] <= REL and r.metrics["merge_one_leader"] and r.metrics["merge_theorem1"]
    ]
    over = _sum(merged, "merge_overlapped")
    n_m = _sum(merged, "merges")
    text = (
        f"merged in {len(merged)}/{len(res)}: area = sum, one leader, Theorem 1 in {len(good)}/{len(merged)}; "
        f"{over}/{n_m} merges' sub-regions already intersected the period before"
    )
    expected = case == "ch6-case2"  # the thesis merges in case 2 only; cases 1 and 3 head for three targets
    return text, len(good) == len(merged) and (len(merged) == len(res) if expected else True)


def judge_b10(outcomes: list[Outcome]) -> Verdict:
    return _case_parts(outcomes, _merge_part, "every merge; case 2 must merge (cases 1 and 3: three targets, no merge)")


def judge_b11(outcomes: list[Outcome]) -> Verdict:
    res = whole(outcomes, "ch6-case3", agents=None)
    if not res:
        return _none(outcomes, "needs ch6-case3")
    dev = max(float(r.metrics.get("sub_area_dev") or 0.0) for r in res)
    axes = max(float(r.metrics.get("sub_axes_range") or 0.0) for r in res)
    moved = [int(r.metrics.get("mover_axes_periods") or 0) for r in res]
    split = sum(bool(r.metrics.get("splits")) for r in res)
    ours = (
        f"areas constant to {dev:.1e} (relative) while the axes moved by up to {_f(axes)}; sub-swarms in a lane with "
        f"a mover near and their axes changing: {sum(m > 0 for m in moved)}/{len(res)} runs ({split} split)"
    )
    good = dev <= REL and all(m > 0 for m in moved)
    why = "" if split else "no split in case 3: no sub-swarm ever meets the movers (see B9)"
    return ours, good, why or "every region of every run; movers near a sub-swarm born of a split"


def _d_part(case: str, res: list[TrialResult]) -> tuple[str, bool | None]:
    split = [r for r in res if r.metrics.get("d_split") is not None]
    start = [r.metrics["d_start"] for r in res if r.metrics.get("d_start") is not None]
    if not split:
        return f"D start {_f(float(np.mean(start)) if start else None, 3)}, no split", None
    pre = [r.metrics["d_pre_split"] for r in split if r.metrics.get("d_pre_split") is not None]
    mid = [r.metrics["d_split"] for r in split]
    post = [r.metrics["d_merge"] for r in split if r.metrics.get("d_merge") is not None]

    def m(v: list[float]) -> float | None:
        return float(np.mean(v)) if v else None

    def below(r: TrialResult, lo: str, hi: str) -> bool:
        return r.metrics.get(lo) is not None and r.metrics.get(hi) is not None and r.metrics[lo] < r.metrics[hi]

    up = [r for r in split if below(r, "d_pre_split", "d_split")]
    low = [r for r in split if below(r, "d_start", "d_split")]
    down = [r for r in split if below(r, "d_merge", "d_split")]
    n_post = sum(r.metrics.get("d_merge") is not None for r in split)
    text = (
        f"D start {_f(m(start), 3)}, before the split {_f(m(pre), 3)}, split to merge {_f(m(mid), 3)}, after the "
        f"merge {_f(m(post), 3)}; start lower {len(low)}/{len(split)}, up after the split {len(up)}/{len(split)}, "
        f"down after the merge {len(down)}/{n_post}"
    )
    return text, len(low) == len(up) == len(split) and len(down) == n_post


def judge_b12(outcomes: list[Outcome]) -> Verdict:
    return _case_parts(
        outcomes,
        _d_part,
        f"means of D(t) (eq. 6.25) over the first {START_S:g} s, the {START_S:g} s before the split, ...",
    )


def scaling(outcomes: list[Outcome], scenario: str, metric: str, timing: bool = False) -> dict[int, np.ndarray]:
    """A metric's values (a timing's, with ``timing``) per agent count over a scenario's missions (its file's N and
    its ``agents`` cells): whole missions, or a smoke run's when it has only those (for its plots)."""
    done = [o for o in outcomes if o.result is not None and o.trial.cell.get("scenario") == scenario]
    use = [o for o in done if not o.trial.smoke] or done
    out: dict[int, list[float]] = {}
    for o in use:
        v = (o.result.timings if timing else o.result.metrics).get(metric)
        n = o.result.metrics.get("n")
        if v is not None and n is not None:
            out.setdefault(int(n), []).append(float(v))
    return {k: np.asarray(v, float) for k, v in sorted(out.items())}


def judge_c7(outcomes: list[Outcome]) -> Verdict:
    if all(o.trial.smoke for o in outcomes):
        return _none(outcomes, "")
    parts, good, judged = [], True, 0
    for name, case in SCALING.items():
        by_n = {n: v for n, v in scaling([o for o in outcomes if not o.trial.smoke], case, "density_mean").items()}
        if not by_n:
            continue
        means = {n: float(np.mean(v)) for n, v in by_n.items()}
        falls = all(b <= a for a, b in itertools.pairwise(means.values()))
        near = []
        for n, m in means.items():
            th = THESIS_D.get((case, n))
            if th is not None:
                judged += 1
                near.append(abs(m - th) <= D_TOL)
        good = good and falls and all(near)
        text = ", ".join(
            f"{n}: {m:.3f}" + (f" (thesis {THESIS_D[(case, n)]})" if (case, n) in THESIS_D else "")
            for n, m in means.items()
        )
        parts.append(f"{name} ({case}): {text}; falling {'yes' if falls else 'no'}")
    if not parts:
        return _none(outcomes, "needs chapter 6's scaling cells")
    return "; ".join(parts), good and judged > 0, f"+-{D_TOL} at the thesis' N, means falling with N"


def exec_scaling(outcomes: list[Outcome], scenario: str, key: str = EXEC) -> tuple[dict[int, np.ndarray], Any]:
    """A scenario's execution time (the timing ``key``) per N and the least-squares line through the means (None
    with fewer than two N)."""
    by_n = scaling(outcomes, scenario, key, timing=True)
    if len(by_n) < 2:
        return by_n, None
    return by_n, linear_fit(list(by_n), [float(np.mean(v)) for v in by_n.values()])


def _cov(v: np.ndarray) -> float:
    return float(np.std(v, ddof=1) / np.mean(v)) if len(v) > 1 and np.mean(v) > 0 else math.nan


def _falling(ns: list[int], covs: list[float]) -> tuple[bool, str]:
    """Whether the COV falls with N: lower at the largest N than at the smallest and negatively rank-correlated with
    N (the trend: a few trials per N leave each COV noisy); and whether it falls at every step ("yes"/"no")."""
    if len(covs) < 2 or not all(math.isfinite(c) for c in covs):
        return False, "no"
    rho = float(spearmanr(ns, covs).statistic) if np.ptp(covs) > 0 else 0.0
    monotone = "yes" if all(b < a for a, b in itertools.pairwise(covs)) else "no"
    return covs[-1] < covs[0] and rho < 0, monotone


def judge_c8(outcomes: list[Outcome]) -> Verdict:
    if all(o.trial.smoke for o in outcomes):
        return _none(outcomes, "")
    parts, good, fits = [], True, 0
    real = [o for o in outcomes if not o.trial.smoke]
    for name, case in SCALING.items():
        by_n, fit = exec_scaling(real, case)
        if not by_n:
            continue
        covs = [_cov(v) for v in by_n.values()]
        falls, monotone = _falling(list(by_n), covs)
        rows = zip(by_n.items(), covs, strict=True)
        text = ", ".join(f"{n}: {float(np.mean(v)):.2f} s (COV {_f(c, 3)})" for (n, v), c in rows)
        if fit is not None:
            fits += 1
            text += f"; fit {fit.intercept:.3f} + {fit.slope:.4f} N s, R^2 {fit.r2:.4f}"
            good = good and fit.r2 > R2_MIN and fit.slope > 0 and falls
            _, wall = exec_scaling(real, case, "exec_s")
            if wall is not None:
                text += f" (wall-clock exec_s: {wall.slope:.4f} N s, R^2 {wall.r2:.4f})"
        trend = "yes" if falls else "no"
        parts.append(f"{name} ({case}, thesis {THESIS_EXEC[case]}): {text}; COV falling {trend} (monotone {monotone})")
    if not parts:
        return _none(outcomes, "needs chapter 6's scaling cells")
    return "; ".join(parts), (good if fits else None), "CPU seconds per mission (cpu_s; erratum 29: compute time)"


def _time_part(case: str, res: list[TrialResult]) -> tuple[str, bool | None]:
    th = THESIS_CH6_TIMES[case]
    out, good = [], True
    for what, key in (("split", "split_s"), ("merge", "merge_s"), ("arrival", "arrival_s")):
        if what not in th:
            continue
        v = [float(r.metrics[key]) for r in res if r.metrics.get(key) is not None]
        if not v:
            out.append(f"{what} never (thesis {th[what]:g})")
            good = False
            continue
        m = float(np.mean(v))
        ok_ = len(v) == len(res) and abs(m - th[what]) <= TIME_TOL * th[what]
        good = good and ok_
        out.append(f"{what} {m:.1f} s in {len(v)}/{len(res)} (thesis {th[what]:g})")
    return ", ".join(out), good


def judge_c9(outcomes: list[Outcome]) -> Verdict:
    return _case_parts(outcomes, _time_part, "means over the runs; a run without the event fails it")


# -- figures ---------------------------------------------------------------------------------------------------------


def _first(outcomes: list[Outcome], case: str) -> TrialResult | None:
    best = None
    for o in outcomes:
        c = o.trial.cell
        mine = o.result is not None and c.get("scenario") == case and c.get("agents") is None
        if mine and (best is None or o.trial.index < best[0]):
            best = (o.trial.index, o.result)
    return None if best is None else best[1]


def _events(ax: Any, res: TrialResult) -> None:
    for key, colour, label in (("split_times", "C3", "split"), ("merge_times", "C2", "merge")):
        for k, t in enumerate(str(res.metrics.get(key) or "").split()):
            ax.axvline(float(t), color=colour, ls="--", lw=0.9, label=label if k == 0 else None)


def subswarm_plot(case: str, res: TrialResult, path: Path) -> list[str]:
    """Each sub-swarm's region area (top) and semi-axes (bottom) over a chapter 6 mission, splits and merges
    marked (Figs. 6.8, 6.10)."""
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.0, 5.0), dpi=110, sharex=True)
    groups = sorted({k[3:].split("_")[0] for k in res.curves if k.startswith("sub")}, key=int)
    for k, g in enumerate(groups):
        ax1.plot(res.curve_x[f"sub{g}_area"], res.curves[f"sub{g}_area"], lw=1.2, color=f"C{k % 10}", label=f"#{g}")
        ax2.plot(res.curve_x[f"sub{g}_a"], res.curves[f"sub{g}_a"], lw=1.2, color=f"C{k % 10}", label=f"a #{g}")
        ax2.plot(res.curve_x[f"sub{g}_b"], res.curves[f"sub{g}_b"], lw=1.0, ls=":", color=f"C{k % 10}", label=f"b #{g}")
    for ax in (ax1, ax2):
        _events(ax, res)
    ax1.set_ylabel("area pi a b (unit^2)")
    ax2.set_ylabel("semi-axes (unit)")
    ax2.set_yscale("log")
    ax2.set_xlabel("t (s)")
    return finish(fig, [ax1, ax2], f"sub-swarms of {case}", path, f"sub-swarms, {case}")


def density_events_plot(runs: dict[str, TrialResult], path: Path) -> list[str]:
    """D(t) (eq. 6.25) over a chapter 6 mission per case, splits and merges marked (Figs. 6.13, 6.14)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(runs), 1, figsize=(7.0, 2.4 * len(runs)), dpi=110, squeeze=False)
    for ax, (case, res) in zip(axes[:, 0], runs.items(), strict=True):
        ax.plot(res.curve_x["density"], res.curves["density"], lw=1.0, label=case)
        _events(ax, res)
        ax.set_ylabel("D(t)")
    axes[-1, 0].set_xlabel("t (s)")
    return finish(fig, list(axes[:, 0]), "D(t) with splits and merges", path, "D(t), chapter 6")


def ch6_figures(outcomes: list[Outcome], plots: Path) -> list[str]:
    """The report's chapter 6 figures: each case's sub-swarms, D(t) with the events, execution time against N per
    scaling scenario with its fit."""

    lines: list[str] = []
    reps = {c: r for c in CH6_CASES if (r := _first(outcomes, c)) is not None}
    for case, res in reps.items():
        if any(k.startswith("sub") for k in res.curves):
            lines += subswarm_plot(case, res, plots / f"subswarms-{case}.png")
    dens = {c: r for c, r in reps.items() if "density" in r.curves}
    if dens:
        lines += density_events_plot(dens, plots / "density-ch6.png")
    for name, case in SCALING.items():
        by_n, fit = exec_scaling(outcomes, case)
        if by_n:
            by_f = {float(n): v for n, v in by_n.items()}
            label, ylabel = f"{name} ({case})", "execution time (CPU s of the mission)"
            lines += exec_plot(by_f, fit, plots / f"exec-time-{case}.png", label=label, ylabel=ylabel)
    return lines
