"""Chapter 6's planner (``Ch6Planner``, region planner ``ch6``) on synthetic sonar: point agents with eight beams
(ranges ray-cast against a corridor with a wall across it) follow the plan's law in an Euler loop; the swarm splits
at two lanes into sub-swarms sized by the lanes' widths, goes through and merges behind the wall; one lane causes
no split; a missing leader is replaced; bad input never crashes. The session of six SonPIs at a wall with two lanes
is tests/services/test_region_ch6_session.py.

The agents are points: under eq. 6.5 with the nearest-only repulsion (the default) they collapse onto their goal
(the kernel vanishes between coincident points), so most tests use the "sum" mode, which keeps them apart."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bridge.studies.roy.numerical import ray_segments
from swarm_logic.families.roy.regions.ch6 import Ch6Params, Ch6Planner
from swarm_logic.families.roy.regions.planner import PLANNERS, Observation, velocities
from swarm_logic.families.roy.regions.sensing import SensingParams, ring_angles, sense

ROOT = Path(__file__).resolve().parents[4]
ANGLES = ring_angles(8)
REACH = 10.0  # the synthetic sonar's range: beyond it, no echo (NaN)
TARGET = np.array([35.0, 0.0])
TWO_LANES = [(0.75, 3.0), (-2.75, -0.75)]  # 2.25 and 2.0 wide: 17 agents split 9 and 8


def walls(lanes: list[tuple[float, float]], x0: float = 15.0, thick: float = 1.0, half: float = 6.0) -> np.ndarray:
    """Segments (G, 2, 2): a corridor |y| <= ``half`` and a wall x0..x0 + thick across it, open at ``lanes`` (y)."""
    segs = [((-10.0, half), (60.0, half)), ((-10.0, -half), (60.0, -half))]
    ys = [-half, *[v for lane in sorted(lanes) for v in lane], half]
    for lo, hi in zip(ys[0::2], ys[1::2], strict=True):
        x1 = x0 + thick
        segs += [((x0, lo), (x0, hi)), ((x1, lo), (x1, hi)), ((x0, lo), (x1, lo)), ((x0, hi), (x1, hi))]
    return np.array(segs, float)


def ranges(x: np.ndarray, headings: np.ndarray, segs: np.ndarray) -> np.ndarray:
    th = headings[:, None] + ANGLES[None, :]
    d = np.stack([np.cos(th), np.sin(th)], axis=-1)
    r = ray_segments(x[:, None, :], d, segs[:, 0], segs[:, 1]).min(axis=-1)
    return np.where(r <= REACH, r, np.nan)


def start(n: int = 17) -> tuple[np.ndarray, np.ndarray]:
    k = math.ceil(math.sqrt(n))
    g = np.array([(i % k, i // k) for i in range(n)], float)
    return np.arange(n) + 10, g - g.mean(axis=0) + np.array([2.0, 0.0])


def planner(**kw: object) -> Ch6Planner:
    return Ch6Planner(**{"r_s": 0.5, "r_robot": 0.3, "v_region": 1.0, "free_reach": REACH, "law_mode": "sum", **kw})


def run(p: Ch6Planner, lanes: list[tuple[float, float]], seconds: float, drop: dict | None = None, seed: int = 0):
    """The swarm under the planner: every 0.25 s an observation (headings jittered +-0.3 rad, a seeded stream), the
    plan; every 0.05 s each agent moves by the plan's law with its own sonar points as the obstacles (v_max 2).
    ``drop``: {"id": agent, "at": "split"}: that agent is left out of every observation from the period whose plan
    would split (found by a first run with the same seed). Returns the positions, the ids, and per plan (t, the plan,
    the observed positions)."""
    rng = np.random.default_rng(seed)
    segs = walls(lanes)
    ids, x = start()
    plans = []
    plan = None
    pts = np.zeros((0, 2))
    dt = 0.05
    for step in range(round(seconds / dt)):
        t = step * dt
        if step % 5 == 0:
            h = rng.uniform(-0.3, 0.3, len(ids))
            rr = ranges(x, h, segs)
            keep = np.ones(len(ids), bool)
            if drop is not None and t >= drop["t"]:
                keep = ids != drop["id"]
            plan = p.plan(Observation(t, ids[keep], x[keep], h[keep], rr[keep], ANGLES, TARGET))
            plans.append((t, plan, x[keep].copy(), ids[keep].copy()))
            pts = sense(x[keep], h[keep], rr[keep], ANGLES, SensingParams(d_max=5.0)).points
            if plan.done:
                break
        x[keep] = x[keep] + dt * velocities(plan, x[keep], pts, v_max=2.0)
    return x, ids, plans


def events(plans: list, kind: str) -> list[dict]:
    return [e for _, plan, _, _ in plans for e in plan.events if e["kind"] == kind]


@pytest.mark.parametrize("mode", ["sum", "nearest"])
def test_two_lanes_split_by_width_go_through_and_merge_into_one_swarm(mode: str) -> None:
    p = planner(law_mode=mode)
    x, _, plans = run(p, TWO_LANES, 60.0)
    (split,) = events(plans, "split")
    assert split["sizes"] == [9, 8]  # SG^i = b_fs^i / sum b_fs N (eq. 6.11), the wider lane the larger
    assert split["b_fs"] == pytest.approx([2.25, 2.0], abs=0.45)  # the edges are the bins nearest the feet
    assert sum(split["areas"]) == pytest.approx(split["parent_area"])  # sum A_e^i = A_e (eq. 6.8)
    # B9: each sub-swarm led by its member nearest its sub-region's centre (eq. 6.14), at the split's positions
    t_split, plan_split, xs, ids_s = next(item for item in plans if any(e["kind"] == "split" for e in item[1].events))
    for sid, leader, centre in zip(split["swarms"], split["leaders"], split["centres"], strict=True):
        rows = np.flatnonzero(plan_split.groups == sid)
        nearest = ids_s[rows[np.argmin(np.hypot(*(xs[rows] - centre).T))]]
        assert leader == nearest
    assert len(plan_split.leaders) == 2 and len(plan_split.regions) == 2
    if mode == "sum":  # (nearest-only repulsion lets point agents collapse onto their goal: no side to compare)
        # each sub-swarm's members are the agents nearest its lane (the upper lane takes the upper agents)
        upper = np.flatnonzero(plan_split.groups == split["swarms"][0])
        assert xs[upper, 1].mean() > xs[np.flatnonzero(plan_split.groups == split["swarms"][1]), 1].mean()
    # through the lanes, then the next regions intersect: one merge, area the sum (B10), one leader
    assert len(events(plans, "passed")) == 2
    (merge,) = events(plans, "merge")
    assert merge["t"] > t_split
    assert sorted(merge["merged"]) == sorted(split["swarms"])
    assert merge["area"] == pytest.approx(sum(merge["areas"])) and merge["theorem1"]
    assert merge["area"] == pytest.approx(17 * math.pi * 0.25)
    t_end, last, _, _ = plans[-1]
    assert last.done and len(last.leaders) == 1 and len(last.regions) == 1 and len(set(last.groups)) == 1
    assert last.regions[0].area == pytest.approx(merge["area"])
    assert np.all(x[:, 0] > 16.0) and np.all(np.hypot(*(x - TARGET).T) <= math.sqrt(merge["area"] / math.pi))
    s = p.summary()
    assert (s["splits"], s["merges"], s["done_t"]) == (1, 1, t_end)


def test_the_regions_keep_their_area_while_the_axes_follow_the_gap() -> None:
    p = planner()
    _, _, plans = run(p, TWO_LANES, 60.0)
    split = events(plans, "split")[0]
    areas: dict[int, set[float]] = {}
    shapes: dict[int, set[tuple[float, float]]] = {}
    for _, plan, _, _ in plans:
        for r in plan.regions:
            areas.setdefault(r.group, set()).add(round(r.area, 9))
            shapes.setdefault(r.group, set()).add((round(r.ellipse.a, 6), round(r.ellipse.b, 6)))
    for sid, area in zip(split["swarms"], split["areas"], strict=True):
        assert areas[sid] == {round(area, 9)}  # B11: the area does not change...
        assert len(shapes[sid]) > 1  # ... while the axes do (the lane, then a circle)


def test_a_single_corridor_causes_no_split() -> None:
    p = planner()
    x, _, plans = run(p, [(-1.5, 1.5)], 60.0)
    assert events(plans, "split") == [] and events(plans, "merge") == []
    assert plans[-1][1].done and len(plans[-1][1].leaders) == 1
    assert np.all(x[:, 0] > 16.0)


def test_a_leader_missing_at_the_split_is_replaced_and_logged() -> None:
    _, _, plans = run(planner(), TWO_LANES, 20.0)
    t_split = events(plans, "split")[0]["t"]
    p = planner()
    _, _, plans = run(p, TWO_LANES, 20.0, drop={"id": 10, "t": t_split})
    (split,) = events(plans, "split")
    assert split["t"] == t_split and 10 not in split["leaders"]
    (promo,) = events(plans, "promotion")
    assert (promo["dead"], promo["during"], promo["t"]) == (10, "split", t_split)
    assert promo["promoted"] not in (-1, 10) and "missing" in promo["reason"]
    assert p.summary()["promotions"] == 1 and p.summary()["decisions"][0]["kind"] == "promotion"


def test_a_sub_swarm_leader_lost_in_its_lane_is_replaced_by_the_member_nearest_its_centre() -> None:
    _, _, plans = run(planner(), TWO_LANES, 20.0)
    split = events(plans, "split")[0]
    dead = split["leaders"][1]
    p = planner()
    _, _, plans = run(p, TWO_LANES, 60.0, drop={"id": dead, "t": split["t"] + 1.0})
    promo = next(e for e in events(plans, "promotion") if e["dead"] == dead)
    assert promo["during"] == "period" and promo["swarm"] == split["swarms"][1]
    _, plan, xs, ids = next(item for item in plans if item[0] == promo["t"])
    rows = np.flatnonzero(plan.groups == promo["swarm"])
    centre = next(r.ellipse.centre for r in plan.regions if r.group == promo["swarm"])
    assert promo["promoted"] == ids[rows[np.argmin(np.hypot(*(xs[rows] - centre).T))]]
    assert plans[-1][1].done  # the rest still merge and arrive


def test_lanes_take_the_targets_of_a_multi_target_map() -> None:
    _, _, plans = run(planner(targets=[[35.0, 5.0], [35.0, -5.0]]), TWO_LANES, 20.0)
    assert events(plans, "split")[0]["targets"] == [0, 1]  # by bearing (erratum 25)
    _, _, plans = run(planner(targets=[[35.0, 5.0], [35.0, -5.0]], lane_map=[1, 0]), TWO_LANES, 20.0)
    assert events(plans, "split")[0]["targets"] == [1, 0]  # as the scenario maps them


def test_bad_input_never_crashes_and_is_logged() -> None:
    p = planner()
    empty = Observation(0.0, np.zeros(0, int), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 8)), ANGLES, TARGET)
    plan = p.plan(empty)
    assert plan.goals.shape == (0, 2) and plan.events[0]["kind"] == "held" and not plan.done
    ids, x = start()
    n = len(ids)
    rng = np.random.default_rng(3)
    for k in range(1, 30):
        r = rng.uniform(0, 6, (n, 8))
        r[rng.random((n, 8)) < 0.3] = np.nan
        r[rng.random((n, 8)) < 0.1] = np.inf
        r[rng.random((n, 8)) < 0.1] = -4.0
        r[0] = 1e300
        xs = x.copy()
        xs[1] = np.nan  # one agent's pose is garbage every period
        target = TARGET if k % 5 else np.array([np.nan, 1.0])
        obs = Observation(0.25 * k, ids, xs, rng.uniform(-3, 3, n), r, ANGLES, target)
        plan = p.plan(empty if k == 7 else obs)
        assert np.isfinite(plan.goals).all()
        v = velocities(plan, np.where(np.isfinite(xs), xs, 0.0)[: len(plan.ids)] if k != 7 else np.zeros((0, 2)))
        assert np.isfinite(v).all()
    kinds = [e.get("reason") for e in plan.events if e["kind"] == "input"]
    assert "pose" in kinds and "readings" in kinds
    s = p.summary()
    assert s["dropped_readings"]["garbage"] > 0 and s["bad_poses"] > 0


def test_law_min_sep_reaches_the_plan_and_keeps_the_sub_swarm_apart() -> None:
    ids, x = start()
    rr = ranges(x, np.zeros(len(ids)), walls(TWO_LANES))
    for sep, want in ((0.0, None), (1.0, 1.0)):
        plan = planner(law_min_sep=sep).plan(Observation(0.0, ids, x, np.zeros(len(ids)), rr, ANGLES, TARGET))
        assert plan.params.get("min_sep") == want
    p = planner(law_min_sep=1.0, v_region=0.01)
    x, _, _ = run(p, TWO_LANES, 8.0)
    d = np.hypot(x[:, None, 0] - x[None, :, 0], x[:, None, 1] - x[None, :, 1]) + np.eye(len(x)) * 1e9
    assert np.median(d.min(axis=1)) > 0.85 * 0.5  # r_s = 0.5 kept (0.45 measured; the sum law alone: 0.14)


def test_registered_and_parameters_validated() -> None:
    assert PLANNERS.get("ch6") is Ch6Planner
    assert Ch6Params().k_c == 12.0 and Ch6Params().k_f == 2.5 and (Ch6Params().d_min, Ch6Params().d_max) == (2, 5)
    for bad, field in (
        ({"r_s": -1.0}, "r_s"),
        ({"memory": 0}, "memory"),
        ({"law_mode": "all"}, "law_mode"),
        ({"law_min_sep": -1.0}, "law_min_sep"),
        ({"semi_minor": "quarter"}, "semi_minor"),
        ({"d_min": 6.0}, "d_max"),
        ({"lane_map": [0]}, "lane_map"),
        ({"targets": [[1.0]]}, "targets"),
        ({"detector": {"profile": "spiral"}}, "detector"),
        ({"detector": {"nope": 1}}, "detector"),
    ):
        with pytest.raises(ValueError, match=field):
            Ch6Planner(**bad)


def test_face_asks_the_robots_to_face_the_way_until_the_split() -> None:
    x0, _, off = run(planner(), TWO_LANES, 16.0)
    x1, _, on = run(planner(face=True), TWO_LANES, 16.0)
    assert all(plan.face is None for _, plan, _, _ in off)
    (split,) = events(on, "split")
    assert events(off, "split")[0]["t"] == split["t"] and np.array_equal(x0, x1)  # point agents ignore it
    faced = [t for t, plan, _, _ in on if plan.face is not None]
    # from the first region step (the region advancing) through the hold at the wall, never after the split
    assert faced[0] == 0.25 and max(faced) < split["t"] and len(faced) >= 0.8 * split["t"] / 0.25
    assert all(plan.face == pytest.approx(0.0, abs=0.3) for _, plan, _, _ in on if plan.face is not None)


def test_a_wall_ahead_is_across_the_way_ahead_of_every_robot_not_beside_or_among_them() -> None:
    p = planner(face=True)  # r_s 0.5, r_robot 0.3
    xs = np.array([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0]])
    c, h = np.zeros(2), np.array([1.0, 0.0])
    assert p._wall_ahead(np.array([[3.0, 0.5]]), xs, c, h)  # the wall in front
    assert not p._wall_ahead(np.array([[3.0, 4.0], [3.0, -4.0]]), xs, c, h)  # side walls beside the swarm
    assert not p._wall_ahead(np.array([[1.2, 0.0], [0.5, 0.5]]), xs, c, h)  # among the robots, or a teammate's back
    assert not p._wall_ahead(np.zeros((0, 2)), xs, c, h)
