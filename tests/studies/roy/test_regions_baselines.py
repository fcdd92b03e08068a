"""The baselines' targets in roy-regions: C5-TVI and C10 judged on hand-made outcomes both ways, each fed one short
real mission of its cells, the baselines' per-trial figures, and the scenario files that must share their maps."""

from __future__ import annotations

import math

import pytest

from bridge.experiments.runner import Outcome, Trial, TrialResult
from bridge.studies.roy import regions_baselines as rb
from bridge.studies.roy.regions_experiments import CELLS, numerical_trial
from bridge.studies.roy.regions_scenarios import load_scenario, make_planner
from bridge.studies.roy.regions_world import run_mission
from swarm_logic.families.roy.regions.planner import PLANNERS


def outcome(scenario: str, smoke: bool = False, **metrics: object) -> Outcome:
    trial = Trial("roy-regions", {"kind": "numerical", "scenario": scenario}, 0, 0, smoke, "")
    return Outcome(trial, TrialResult(metrics), None)


def tvi(n: int, prop: float, base: float) -> list[Outcome]:
    return [
        outcome(rb.TVI_PROPOSED, n=n, tvi=prop, arrived=True),
        outcome(rb.TVI_BASELINE, n=n, tvi=base, arrived=False),
    ]


def test_c5_tvi_judged_both_ways_on_hand_made_outcomes() -> None:
    ours, good, note = rb.judge_c5_tvi([*tvi(20, 0.995, 0.93), *tvi(50, 0.997, 0.97)])
    assert good is True and "N=20: 0.9950 vs 0.9300 (arrived 1/1, 0/1)" in ours and "0.99" in note
    assert rb.judge_c5_tvi([*tvi(20, 0.995, 0.996), *tvi(50, 0.997, 0.97)])[1] is False  # below the baseline once
    assert rb.judge_c5_tvi([*tvi(20, 0.999, 0.93), *tvi(50, 0.990, 0.97)])[1] is False  # falling with N
    assert rb.judge_c5_tvi([*tvi(20, 0.97, 0.93), *tvi(50, 0.98, 0.97)])[1] is False  # not close to 1
    assert rb.judge_c5_tvi(tvi(50, 0.997, 0.97))[1] is None  # one N: no trend to judge
    assert rb.judge_c5_tvi([])[1] is None
    smoke = [outcome(rb.TVI_PROPOSED, smoke=True, n=20, tvi=1.0), outcome(rb.TVI_BASELINE, smoke=True, n=20, tvi=0.5)]
    assert rb.judge_c5_tvi(smoke) == ("no runs", None, "smoke run: the missions stop early")


def c10(n: int, central: float | None, vision: float | None, lf: float | None) -> list[Outcome]:
    return [
        outcome(sc, n=n, arrived=t is not None, arrival_s=t)
        for sc, t in zip(rb.C10_VARIANTS.values(), (central, vision, lf), strict=True)
    ]


def test_c10_judged_both_ways_on_hand_made_outcomes() -> None:
    ours, good, _ = rb.judge_c10([*c10(6, 615.0, 944.0, 1029.0), *c10(50, 150.0, 192.0, 250.0)])
    assert good is True and ours.startswith("N=6: 615.0 < 944.0 < 1029.0 yes (thesis 615 < 944 < 1029")
    assert rb.judge_c10([*c10(6, 615.0, 944.0, 1029.0), *c10(50, 200.0, 192.0, 250.0)])[1] is False
    ours, good, _ = rb.judge_c10(c10(6, 615.0, None, 1029.0))  # a baseline that never arrives takes forever
    assert good is False and "615.0 < never < 1029.0 no" in ours
    assert rb.judge_c10(c10(6, 615.0, 944.0, None))[1] is True  # the slowest may never arrive
    assert rb.judge_c10(c10(6, 615.0, 944.0, 1029.0)[:2])[1] is None  # a variant missing at every N
    assert rb.running_time([]) == (math.inf, 0)


def test_the_baseline_files_share_their_maps() -> None:
    def tables(name: str) -> dict[str, object]:
        sc = load_scenario(name)
        keys = ("world", "agents", "sensing", "mission", "failures", "metrics")
        return {k: getattr(sc, k).model_dump() for k in keys}

    assert tables(rb.TVI_BASELINE) == tables(rb.TVI_PROPOSED) == tables("ch4-maze-50")
    assert load_scenario(rb.TVI_PROPOSED).planner == load_scenario("ch4-maze-50").planner
    central, vision, lf = (tables(s) for s in rb.C10_VARIANTS.values())
    assert central == vision == lf
    assert {load_scenario(s).planner.name for s in rb.C10_VARIANTS.values()} == {"ch4_hosted", "vision_lf"}
    assert PLANNERS.get(load_scenario(rb.TVI_BASELINE).planner.name).__name__ == "AggregationPlanner"


def test_the_cells_of_both_targets() -> None:
    cells = [c.cell() for c in CELLS]
    for n in rb.TVI_NS:
        assert {"kind": "numerical", "scenario": rb.TVI_BASELINE, "agents": n} in cells
        assert {"kind": "numerical", "scenario": rb.TVI_PROPOSED, "agents": n} in cells
    for sc in rb.C10_VARIANTS.values():
        assert {"kind": "numerical", "scenario": sc, "agents": 6} in cells  # the files' own N, named
        assert {"kind": "numerical", "scenario": sc, "agents": 400} in cells


def test_one_short_real_mission_each_feeds_the_judges() -> None:
    """C5-TVI: 10 s of the maze at N = 20 under both methods; C10: the vision leader-follower's whole 6-agent
    mission beside hand-made times of the other two, and 10 s of the centralised host's (its cycle)."""
    outs = []
    for sc in (rb.TVI_PROPOSED, rb.TVI_BASELINE):
        scenario = load_scenario(sc).with_agents(20)
        res = run_mission(scenario, make_planner(scenario), 1, max_time_s=10.0)
        s = res.summary
        assert s["n"] == 20 and 0 < s["tvi"] <= 1
        outs.append(outcome(sc, n=20, tvi=s["tvi"], arrived=s["arrived"]))
    ours, good, _ = rb.judge_c5_tvi(outs)
    assert ours.startswith("N=20: ") and good is None  # one N
    vision = rb.C10_VARIANTS["vision"]
    r = numerical_trial({"kind": "numerical", "scenario": vision}, Trial("roy-regions", {}, 0, 1, False, ""))
    m = r.metrics
    assert m["n"] == 6 and m["arrived"] and 60 < m["arrival_s"] < 600
    assert "lf_lost_periods" in m and "host_cycle_s" not in m
    t = m["arrival_s"]
    real = Outcome(Trial("roy-regions", {"scenario": vision}, 0, 1, False, ""), r, None)
    c, _, lf = c10(6, t - 1.0, None, t + 1.0)
    assert rb.judge_c10([c, real, lf])[1] is True
    c, _, lf = c10(6, t + 1.0, None, t + 2.0)
    assert rb.judge_c10([c, real, lf])[1] is False
    central = load_scenario(rb.C10_VARIANTS["central"])
    host = rb.baseline_metrics(run_mission(central, make_planner(central), 1, max_time_s=10.0))
    assert host["host_cycle_s"] == pytest.approx(0.30) and host["host_updates"] == 34  # 0, 0.3, ..., 9.9 s
