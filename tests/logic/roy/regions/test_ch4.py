"""Chapter 4's planner: its parameters, its initial formation, and a short closed-loop mission through a gap."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from swarm_logic.families.roy.regions import formation as fm
from swarm_logic.families.roy.regions.ch4 import Ch4Params, Ch4Planner, clip_into, lattice_graph
from swarm_logic.families.roy.regions.planner import Observation
from swarm_logic.families.roy.regions.shapes import Ellipse


def test_params_name_the_bad_field() -> None:
    with pytest.raises(ValueError, match="split: expected one of"):
        Ch4Params(split="middle")
    with pytest.raises(ValueError, match="slot_fill: must be finite and > 0"):
        Ch4Params(slot_fill=0.0)
    with pytest.raises(ValueError, match="d_max: must exceed d_min"):
        Ch4Params(d_min=5.0, d_max=4.0)


def test_initial_formation() -> None:
    adj, pos = lattice_graph(6)
    assert np.array_equal(adj, fm.DELTA_TRI)
    adj, pos = lattice_graph(7, 1.0)
    assert adj.sum() == 2 * 12 and np.allclose(pos.mean(axis=0), 0)  # the hexagon and its centre: 12 edges


def test_clip_moves_only_the_points_outside() -> None:
    e = Ellipse(0.0, 0.0, 4.0, 1.0, 0.0)
    g = clip_into(e, np.array([[0.5, 0.2], [8.0, 0.0], [0.0, 3.0]]), 0.5)
    assert np.allclose(g, [[0.5, 0.2], [2.0, 0.0], [0.0, 0.5]])


def test_absent_and_garbage_readings_do_not_crash() -> None:
    pl = Ch4Planner(centre0=[5.0, 5.0])
    ang = np.arange(8) * np.pi / 4
    ids = np.array([3, 5, 8, 13, 21, 34])  # any ids: the plan's rows follow them
    x = fm.tri_coordinates(1.0) + 5.0
    rng = np.array([[np.inf, -1.0, np.nan, 2.0, 2.0, 2.0, 2.0, 2.0]] * 6)
    target = np.array([35.0, 35.0])
    # nobody seen yet (a session before the camera's first frame): it holds, and sizes the swarm later
    empty = pl.plan(Observation(-0.25, np.zeros(0, int), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 8)), ang, target))
    assert empty.goals.shape == (0, 2) and empty.events == ({"kind": "held", "reason": "no agent"},)
    plan = pl.plan(Observation(0.0, ids, x, np.zeros(6), rng, ang, target))
    assert plan.goals.shape == (6, 2) and np.isfinite(plan.goals).all() and list(plan.ids) == list(ids)
    assert {"kind": "input", "dropped": 12, "reason": "garbage"} in plan.events
    # later: two agents absent, one unknown id; the plan still covers the swarm
    plan = pl.plan(Observation(0.25, np.array([3, 5, 8, 99]), x[:4], np.zeros(4), rng[:4], ang, target))
    assert list(plan.ids) == list(ids) and np.isfinite(plan.goals).all()
    assert {"kind": "input", "dropped": 1, "reason": "unknown agent"} in plan.events


def test_a_gap_switches_circle_ellipse_circle(tmp_path: Path) -> None:
    from bridge.studies.roy.regions_scenarios import load_scenario, make_planner
    from bridge.studies.roy.regions_world import run_mission

    p = tmp_path / "gap.toml"
    p.write_text(
        """
name = "gap"
version = "gap-v1"
[world]
size = [36.0, 20.0]
segments = [[[14.0, 0.0], [14.0, 8.2]], [[14.0, 11.8], [14.0, 20.0]]]
[agents]
n = 6
start_lo = [2.5, 7.5]
start_hi = [7.5, 12.5]
v_max = 0.5
[mission]
targets = [[30.0, 10.0]]
arrival_radius = 3.5
timeout_s = 200.0
[planner]
name = "ch4"
params = { centre0 = [5.0, 10.0] }
""",
        encoding="utf-8",
    )
    sc = load_scenario(p)
    res = run_mission(sc, make_planner(sc), seed=1)
    s = res.summary
    switches = [e["to"] for e in s["events"] if e["kind"] == "region"]
    assert switches[:1] == ["ellipse"] and switches[-1] == "circle"
    t_ellipse = [t for t, c in zip(res.series["t"], res.series["circle"], strict=True) if not c]
    xs = [e["t"] for e in s["events"] if e["kind"] == "region" and e["to"] == "ellipse"]
    assert min(t_ellipse) == xs[0]
    assert s["arrived"] and s["final_circle"] and s["contacts"] == 0
    assert s["final_area"] == pytest.approx(np.pi * 2.5**2)
