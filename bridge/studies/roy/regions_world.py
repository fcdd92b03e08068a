"""The numerical model of Roy's chapters 4-6 (digest 001 §4.2-4.4, §5.3-5.4): single-integrator point agents
(x' = u, eq. 4.1, as the thesis' MATLAB model) in thesis units, stepped at the controller's dt (0.05 s, erratum 1)
with each velocity saturated at the scenario's v_max, among line, polygon, circle and moving-circle obstacles, and a
mission runner that lets a chapter's ``RegionPlanner`` steer them.

Tick semantics: every ``dt`` each working agent takes the velocity the current plan's law gives it
(``planner.velocities``) and moves x <- x + u dt. A move that would cross an obstacle's edge slides along that edge
(its component along the edge is kept when that part is free; otherwise the agent stays) and counts as a contact; a
move into a circle or a mover is refused unless it leaves it. Agents are points: they neither block nor echo each
other (the planner's eclipse filter still drops points near teammates). An agent whose actuator fails (the
scenario's schedule) stops for good but keeps reporting its pose and sonars. Headings follow the velocity (the last
one when stopped). Sonars (m beams at the scenario's angles from the heading) are cast only at the planner's period,
from the poses of that tick: range to the nearest obstacle, NaN beyond the window's far end.

Speed: obstacle edges are bucketed once into two grids: a beam is tested only against the edges near its pieces
(each quarter of it: the edges within d_max / 8 of the quarter's midpoint's cell; every point of the quarter is that
close to its midpoint), a move only against the edges within one tick's travel of its start's cell; so one cast is
a few numpy operations over the (beam, edge) pairs that can meet, and one tick over (N, K) with K the few edges near
a cell (padded to the fullest cell), not over every edge of the map. The candidates are a superset of the edges a
beam or move can meet, in edge order, so the result is the same as testing every edge.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bridge.core.rng import stream
from bridge.studies.roy.metrics import region_statistics, structural_density, travel_variance_index
from bridge.studies.roy.numerical import Mover, crosses, ray_circle, ray_segments, scatter
from bridge.studies.roy.regions_scenarios import RegionScenario
from swarm_logic.families.roy.regions.formation import shape_name
from swarm_logic.families.roy.regions.laws import unique_rows
from swarm_logic.families.roy.regions.planner import Observation, Plan, RegionPlanner, velocities
from swarm_logic.families.roy.regions.sensing import beam_points
from swarm_logic.log import plain

FAR = 1e9  # where the padding edge lies (degenerate, never hit)
BEAM_PIECES = 4  # a beam's edges are looked up per quarter of its length
MAX_CELLS = 1 << 16  # the most cells an edge grid has


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point p (P, 2) to each segment ab (G, 2) -> (P, G)."""
    e = b - a
    ll = np.maximum(np.sum(e * e, axis=1), 1e-300)
    w = p[:, None, :] - a[None]
    s = np.clip(np.sum(w * e[None], axis=2) / ll, 0.0, 1.0)
    c = a[None] + s[..., None] * e[None]
    return np.hypot(p[:, None, 0] - c[..., 0], p[:, None, 1] - c[..., 1])


class EdgeGrid:
    """The obstacle edges (G, 2, 2) bucketed by cell: cell (i, j) of side ``cell`` lists every edge within ``reach``
    of any point of the cell, padded with a far-away degenerate edge to the fullest cell's count."""

    def __init__(self, edges: np.ndarray, lo: np.ndarray, hi: np.ndarray, cell: float, reach: float) -> None:
        self.lo, self.cell = np.asarray(lo, float), float(cell)
        self.shape = (max(1, math.ceil((hi[0] - lo[0]) / cell)), max(1, math.ceil((hi[1] - lo[1]) / cell)))
        pad = np.full((1, 2, 2), FAR)
        self.a = np.concatenate([edges[:, 0], pad[:, 0]]) if len(edges) else pad[:, 0]
        self.b = np.concatenate([edges[:, 1], pad[:, 1] + 1e-6]) if len(edges) else pad[:, 1] + 1e-6
        gi, gj = np.meshgrid(np.arange(self.shape[0]), np.arange(self.shape[1]), indexing="ij")
        centres = self.lo + (np.stack([gi.ravel(), gj.ravel()], axis=1) + 0.5) * cell
        if len(edges):
            near = np.concatenate(
                [  # in blocks of cells: the distances of a block to every edge at a time
                    point_segment_distance(c, edges[:, 0], edges[:, 1]) <= reach + cell * math.sqrt(0.5)
                    for c in np.array_split(centres, max(1, len(centres) // 4096))
                ]
            )
        else:
            near = np.zeros((len(centres), 1), bool)
        self.pad = len(self.a) - 1  # the far-away edge's index
        k = max(1, int(near.sum(axis=1).max(initial=0)))
        first = np.argsort(~near, axis=1, kind="stable")[:, :k]  # each cell's near edges first, in edge order
        self.table = np.where(np.take_along_axis(near, first, axis=1), first, self.pad)

    def candidates(self, p: np.ndarray) -> np.ndarray:
        """The candidate edges' indices (N, K) of each point p (N, 2) (points off the grid take the nearest cell)."""
        ij = np.floor((p - self.lo) / self.cell).astype(int)
        i = np.clip(ij[:, 0], 0, self.shape[0] - 1)
        j = np.clip(ij[:, 1], 0, self.shape[1] - 1)
        return self.table[i * self.shape[1] + j]


class RegionsWorld:
    """N point agents in a ``RegionScenario``'s world from ``seed``: positions, headings, the failure schedule."""

    def __init__(self, scenario: RegionScenario, seed: int) -> None:
        sc = self.sc = scenario
        self.seed = seed
        self.dt = sc.mission.dt
        self.v_max = sc.agents.v_max
        start = sc.agents
        self.pos = scatter(stream(seed, "regions", "deploy"), start.n, start.start_lo, start.start_hi, start.min_sep)
        self.n = start.n
        tgt = np.asarray(sc.mission.targets[0], float)
        self.heading = np.arctan2(tgt[1] - self.pos[:, 1], tgt[0] - self.pos[:, 0])
        self.vel = np.zeros_like(self.pos)
        self.tick = 0
        self.contacts = 0
        self.fail_at = self._failure_schedule()
        self.angles = sc.sensing.angles()
        self.d_max = sc.sensing.d_max
        edges = sc.world.edges()
        size = np.asarray(sc.world.size, float)
        self.edges = edges
        # beams by their pieces' midpoints (the grid reaches d_max + 1 beyond the map: the beams of an agent up to 1
        # unit outside it are still covered), moves by their start (a tick's travel is at most v_max dt); on a large
        # map the cells grow so that a grid has at most MAX_CELLS of them
        piece = self.d_max / BEAM_PIECES
        out = self.d_max + 1.0
        cell = max(piece / 4, 0.25, math.sqrt(float(np.prod(size + 2 * out)) / MAX_CELLS))
        self.beam_grid = EdgeGrid(edges, np.full(2, -out), size + out, cell, piece / 2 + 0.01)
        cell = max(1.0, math.sqrt(float(np.prod(size + 2.0)) / MAX_CELLS))
        self.move_grid = EdgeGrid(edges, np.full(2, -1.0), size + 1.0, cell, self.v_max * self.dt + 0.01)
        self.circles = np.asarray([c for c in sc.world.circles], float).reshape(-1, 3)
        self.movers = tuple(Mover(tuple(m.a), tuple(m.b), m.radius, m.speed) for m in sc.world.movers)

    def _failure_schedule(self) -> np.ndarray:
        """Each agent's failure time (inf: never): round(fraction N) agents drawn from the seed's "failures" stream,
        spread over the scheduled times in turn."""
        f = self.sc.failures
        out = np.full(self.n, math.inf)
        k = round(f.fraction * self.n)
        if k and f.times:
            who = stream(self.seed, "regions", "failures").choice(self.n, size=k, replace=False)
            out[who] = np.asarray(f.times, float)[np.arange(k) % len(f.times)]
        return out

    @property
    def t(self) -> float:
        return self.tick * self.dt

    @property
    def failed(self) -> np.ndarray:
        """The agents whose actuator has failed by now (N,)."""
        return self.fail_at <= self.t + 1e-9

    def discs(self) -> np.ndarray:
        """The circular obstacles now, fixed and moving, as rows (x, y, r)."""
        mv = [(*m.centre(self.t), m.radius) for m in self.movers]
        return np.concatenate([self.circles, np.asarray(mv, float).reshape(-1, 3)])

    def cast(self) -> np.ndarray:
        """The sonar ranges (N, m) from the current poses: the nearest obstacle along each beam, NaN beyond d_max
        (agents on one spot with one heading read the same: cast once, copied)."""
        first, same = unique_rows(np.column_stack([self.pos, self.heading]))
        a = self.heading[first, None] + self.angles[None]
        d = np.stack([np.cos(a), np.sin(a)], axis=-1)
        o = np.broadcast_to(self.pos[first, None, :], d.shape)
        g = self.beam_grid
        ob, db = o.reshape(-1, 2), d.reshape(-1, 2)
        at = (np.arange(BEAM_PIECES) + 0.5) * (self.d_max / BEAM_PIECES)  # the pieces' midpoints along a beam
        cand = g.candidates((ob[:, None] + db[:, None] * at[None, :, None]).reshape(-1, 2))
        piece, k = np.nonzero(cand != g.pad)  # only the real (piece, edge) pairs, by beam
        e = cand[piece, k]
        ray = piece // BEAM_PIECES
        s = ray_segments(ob[ray], db[ray], g.a[e][:, None], g.b[e][:, None])[:, 0]
        flat = np.full(len(ob), np.inf)
        if len(ray):
            start = np.concatenate([[True], ray[1:] != ray[:-1]])  # each beam's first pair
            flat[ray[start]] = np.minimum.reduceat(s, np.nonzero(start)[0])
        best = flat.reshape(d.shape[:2])
        for cx, cy, r in self.discs():
            best = np.minimum(best, ray_circle(o, d, np.array([cx, cy]), r))
        return np.where(best <= self.d_max, best, np.nan)[same]

    def step(self, u: np.ndarray) -> None:
        """One tick: the commanded velocities (N, 2), saturated at v_max, zero for failed agents, integrated with
        the obstacles' slide/refuse rules."""
        v = np.asarray(u, float).copy()
        v[~np.isfinite(v).all(axis=1)] = 0.0
        s = np.hypot(v[:, 0], v[:, 1])
        v *= np.where(s > self.v_max, self.v_max / np.maximum(s, 1e-300), 1.0)[:, None]
        v[self.failed] = 0.0
        p = self.pos
        q = p + v * self.dt
        cand = self.move_grid.candidates(p)
        ga, gb = self.move_grid.a[cand], self.move_grid.b[cand]
        hit = crosses(p, q, ga, gb) if len(p) else np.zeros(0, bool)
        if hit.any():
            q = self._slide(p, q, hit, ga, gb)
        circ = self.discs()
        if len(circ):
            c, r = circ[:, :2], circ[:, 2]
            dq = np.hypot(q[:, None, 0] - c[None, :, 0], q[:, None, 1] - c[None, :, 1])
            dp = np.hypot(p[:, None, 0] - c[None, :, 0], p[:, None, 1] - c[None, :, 1])
            into = np.any((dq < r) & (dq <= dp), axis=1)
            q = np.where(into[:, None], p, q)
            hit = hit | into
        self.contacts += int(np.count_nonzero(hit & (s > 0)))
        self.vel = (q - p) / self.dt
        moved = np.hypot(*(q - p).T) > 1e-12
        self.heading = np.where(moved, np.arctan2(q[:, 1] - p[:, 1], q[:, 0] - p[:, 0]), self.heading)
        self.pos = q
        self.tick += 1

    @staticmethod
    def _slide(p: np.ndarray, q: np.ndarray, hit: np.ndarray, ga: np.ndarray, gb: np.ndarray) -> np.ndarray:
        """For the blocked moves: keep the component along the first edge crossed when that slide crosses nothing,
        else stay."""
        rows = np.nonzero(hit)[0]
        pr, qr, a, b = p[rows], q[rows], ga[rows], gb[rows]
        pk, qk = (np.broadcast_to(v[:, None], a.shape) for v in (pr, qr))
        each = crosses(pk, qk, a[:, :, None], b[:, :, None])  # (R, K): which candidate edge each move crosses
        k = np.argmax(each, axis=1)
        e = b[np.arange(len(rows)), k] - a[np.arange(len(rows)), k]
        e /= np.maximum(np.hypot(e[:, 0], e[:, 1]), 1e-300)[:, None]
        slid = pr + np.sum((qr - pr) * e, axis=1)[:, None] * e
        again = crosses(pr, slid, a, b)
        out = q.copy()
        out[rows] = np.where(again[:, None], pr, slid)
        return out


@dataclass
class MissionResult:
    """A mission's record: ``summary`` (JSON values, the same bytes for the same scenario, planner and seed),
    ``series`` (one row per planner period), ``plans`` (every plan's ``as_dict`` when asked) and ``perf`` (wall
    clock seconds: never part of the summary)."""

    summary: dict[str, Any]
    series: dict[str, list[Any]]
    plans: list[dict[str, Any]] = field(default_factory=list)
    perf: dict[str, float] = field(default_factory=dict)

    def summary_json(self) -> str:
        return json.dumps(plain(self.summary), sort_keys=True, separators=(",", ":"), allow_nan=False)


def arrived(pos: np.ndarray, working: np.ndarray, targets: np.ndarray, radius: float) -> bool:
    """Every working agent within ``radius`` of a target (its nearest); False with no working agent."""
    if not working.any():
        return False
    x = pos[working]
    d = np.hypot(x[:, None, 0] - targets[None, :, 0], x[:, None, 1] - targets[None, :, 1]).min(axis=1)
    return bool(np.all(d <= radius))


def _formation_sequence(times: list[float], names: list[str], hold_s: float) -> list[dict[str, Any]]:
    """The shapes a run went through, each kept for at least ``hold_s`` (shorter flickers are left out), with the
    time each started."""
    seq: list[dict[str, Any]] = []
    i = 0
    while i < len(names):
        j = i
        while j + 1 < len(names) and names[j + 1] == names[i]:
            j += 1
        if times[j] - times[i] >= hold_s - 1e-9 and (not seq or seq[-1]["shape"] != names[i]):
            seq.append({"shape": names[i], "t": round(times[i], 3)})
        i = j + 1
    return seq


def run_mission(
    scenario: RegionScenario,
    planner: RegionPlanner,
    seed: int,
    max_time_s: float | None = None,
    keep_plans: bool = False,
    shape_hold_s: float = 2.0,
) -> MissionResult:
    """Step ``scenario``'s world from ``seed`` under ``planner`` until every working agent has arrived or the
    scenario's timeout (or ``max_time_s``) passes: an Observation and a plan every planner period (the sonars are
    cast then), the plan's law every tick. Records per period: the regions' area and axes, the working agents'
    shape name (N <= 10), the structural density by the scenario's rule, the plan's events."""
    wall0 = time.perf_counter()
    world = RegionsWorld(scenario, seed)
    sc = scenario
    targets = np.asarray(sc.mission.targets, float)
    period = max(1, round(planner.period_s / world.dt))
    timeout = sc.mission.timeout_s if max_time_s is None else min(max_time_s, sc.mission.timeout_s)
    n_ticks = math.ceil(timeout / world.dt - 1e-9)
    ids = np.arange(world.n)
    series: dict[str, list[Any]] = {
        k: [] for k in ("t", "area", "a", "b", "theta", "circle", "shape", "density", "n_failed", "law")
    }
    plans: list[dict[str, Any]] = []
    events: list[dict[str, Any]] = []
    track_len = np.zeros(world.n)
    plan: Plan | None = None
    obstacles = np.zeros((0, 2))
    arrival = math.nan
    t_plan = t_world = t_cast = 0.0
    for tick in range(n_ticks + 1):
        if tick % period == 0:
            c0 = time.perf_counter()
            ranges = world.cast()
            t_cast += time.perf_counter() - c0
            obs = Observation(world.t, ids, world.pos.copy(), world.heading.copy(), ranges, world.angles, targets[0])
            owner, beam = np.nonzero(np.isfinite(ranges))
            obstacles = beam_points(world.pos, world.heading, world.angles, owner, beam, ranges[owner, beam])
            p0 = time.perf_counter()
            plan = planner.plan(obs)
            t_plan += time.perf_counter() - p0
            _record(series, world, plan, sc)
            events.extend({"t": round(world.t, 6), **e} for e in plan.events)
            if keep_plans:
                plans.append(plan.as_dict())
        working = ~world.failed
        if arrived(world.pos, working, targets, sc.mission.arrival_radius) or (plan is not None and plan.done):
            arrival = world.t
            break
        if tick == n_ticks:
            break
        w0 = time.perf_counter()
        u = velocities(plan, world.pos, obstacles, world.v_max)
        before = world.pos.copy()
        world.step(u)
        track_len += np.hypot(*(world.pos - before).T)
        t_world += time.perf_counter() - w0
    area = np.asarray(series["area"], float)
    stats = region_statistics(np.asarray(series["a"], float), np.asarray(series["b"], float))
    working = ~world.failed
    kinds: dict[str, int] = {}
    for e in events:
        kinds[e.get("kind", "?")] = kinds.get(e.get("kind", "?"), 0) + 1
    summary = {
        "scenario": sc.name,
        "version": sc.version,
        "seed": seed,
        "n": world.n,
        "v_max": world.v_max,
        "arrived": math.isfinite(arrival),
        "arrival_s": None if math.isnan(arrival) else round(arrival, 6),
        "t_end_s": round(world.t, 6),
        "failed_true": int(world.failed.sum()),
        "failure_times": sorted(float(t) for t in world.fail_at[np.isfinite(world.fail_at)]),
        "final_area": float(area[-1]) if len(area) else None,
        "final_axes": [series["a"][-1], series["b"][-1]] if len(area) else None,
        "final_circle": bool(series["circle"][-1]) if len(area) else None,
        "region": {k: v.as_dict() for k, v in stats.items()},
        "density": _mean_sd(series["density"]),
        "path_mean": float(track_len[working].mean()) if working.any() else None,
        "tvi": travel_variance_index(track_len[working]) if working.any() else None,
        "contacts": world.contacts,
        "formations": _formation_sequence(series["t"], series["shape"], shape_hold_s) if world.n <= 10 else [],
        "formation_plan": _changes(events, "formation"),
        "region_switches": _changes(events, "region"),
        "event_counts": dict(sorted(kinds.items())),
        "events": events,
        "planner": planner.summary(),
    }
    perf = {
        "wall_s": time.perf_counter() - wall0,
        "plan_s": t_plan,
        "world_s": t_world,
        "cast_s": t_cast,
        "sim_s": world.t,
        "ticks": world.tick,
    }
    return MissionResult(plain(summary), series, plans, perf)


def _changes(events: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    """The planner's ``kind`` events as a sequence of (t, what it changed to), the first row what it started with."""
    rows = [e for e in events if e.get("kind") == kind]
    out = [{"t": 0.0, "to": rows[0].get("from", "circle")}] if rows and kind == "formation" else []
    return out + [{"t": e["t"], "to": e.get("to")} for e in rows]


def _mean_sd(values: list[float]) -> dict[str, float | None]:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return {"mean": float(v.mean()) if len(v) else None, "sd": float(v.std()) if len(v) else None}


def _record(series: dict[str, list[Any]], world: RegionsWorld, plan: Plan, sc: RegionScenario) -> None:
    """One period's row: the first region's geometry, the working agents' shape, D(t) by the scenario's rule."""
    series["t"].append(round(world.t, 6))
    reg = plan.regions[0] if plan.regions else None
    e = reg.ellipse if reg is not None else None
    series["area"].append(reg.area if reg is not None else math.nan)
    series["a"].append(e.a if e is not None else math.nan)
    series["b"].append(e.b if e is not None else math.nan)
    series["theta"].append(e.theta if e is not None else math.nan)
    series["circle"].append(bool(e.is_circle) if e is not None else False)
    working = ~world.failed
    x = world.pos[working]
    tgt = np.asarray(sc.mission.targets[0], float)
    c = x.mean(axis=0) if len(x) else tgt
    series["shape"].append(shape_name(x, math.atan2(tgt[1] - c[1], tgt[0] - c[0])) if world.n <= 10 else "")
    rule = sc.metrics.density_rule
    if rule == "ch4":
        scale = math.sqrt(reg.area / math.pi / max(len(x), 1)) if reg is not None else math.nan
    else:
        scale = sc.metrics.r_s
    groups = None
    if sc.metrics.density_pairs == "sub_swarms" and plan.groups is not None:
        groups = np.full(world.n, -1)
        groups[np.asarray(plan.ids, int)] = np.asarray(plan.groups, int)  # the observation's ids are the world's rows
        groups = groups[working]
    ok = math.isfinite(scale) and scale > 0
    series["density"].append(structural_density(x, scale, rule, groups) if ok else math.nan)
    series["n_failed"].append(int((~working).sum()))
    series["law"].append(plan.law)


def main(argv: list[str] | None = None) -> int:
    """``python -m bridge.studies.roy.regions_world SCENARIO [--seed S] [--failures F] [--v-max V] [--agents N]
    [--events]``:
    run one mission and print its summary as JSON (the events only with ``--events``)."""
    import argparse
    import sys

    from bridge.core.config import ConfigError
    from bridge.studies.roy.regions_scenarios import load_scenario, make_planner

    ap = argparse.ArgumentParser(prog="python -m bridge.studies.roy.regions_world", description=main.__doc__)
    ap.add_argument("scenario", help="a scenario file, or the name of a shipped one (hil_configs/roy/NAME.toml)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--failures", type=float, default=None, help="the fraction of agents that fail (0..1)")
    ap.add_argument("--v-max", type=float, default=None, help="the agents' speed limit (units/s)")
    ap.add_argument("--agents", type=int, default=None, help="the same map with this many agents (r_s scaled)")
    ap.add_argument("--events", action="store_true", help="include every plan event in the summary")
    a = ap.parse_args(argv)
    try:
        sc = load_scenario(a.scenario)
        if a.failures is not None:
            sc = sc.with_failures(a.failures)
        if a.v_max is not None:
            sc = sc.with_v_max(a.v_max)
        if a.agents is not None:
            sc = sc.with_agents(a.agents)
        planner = make_planner(sc)
    except (ConfigError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    res = run_mission(sc, planner, a.seed)
    out = dict(res.summary)
    if not a.events:
        out.pop("events")
    out["perf"] = {k: round(v, 3) for k, v in res.perf.items()}
    print(json.dumps(out, indent=1, allow_nan=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
