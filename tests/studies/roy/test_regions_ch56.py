"""Chapters 5 and 6 in roy-regions: the scaling cells, the judges of B7-B12 and C6-C9 on hand-made outcomes both
ways, and short real missions of ch5-a and ch6-case2 with their recorded metrics."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from bridge.experiments.runner import Outcome, Trial, TrialResult
from bridge.studies.roy import regions_ch56 as c56
from bridge.studies.roy.regions_experiments import CELLS, RoyRegionsExperiment, numerical_trial, scenario_of
from bridge.studies.roy.regions_scenarios import load_scenario, make_planner
from bridge.studies.roy.regions_world import run_mission


def outcome(
    i: int, scenario: str, agents: int | None = None, smoke: bool = False, exec_s: float | None = None, **metrics: Any
) -> Outcome:
    cell: dict[str, Any] = {"kind": "numerical", "scenario": scenario}
    if agents is not None:
        cell["agents"] = agents
    timings = {} if exec_s is None else {"exec_s": 2 * exec_s, "cpu_s": exec_s}
    return Outcome(Trial("roy-regions", cell, i, i, smoke, ""), TrialResult(dict(metrics), timings=timings), None)


def test_the_scaling_cells_cover_both_scenarios_at_every_n_once() -> None:
    exp = RoyRegionsExperiment()
    for case, own in (("ch6-case2", 100), ("ch6-case3", 50)):
        ns = sorted(c.agents or own for c in CELLS if c.scenario == case)
        assert ns == list(c56.SCALING_N)  # the file's own N is its case cell, not a second one
    big = {"kind": "numerical", "scenario": "ch6-case3", "agents": 1000}
    assert exp.cell_trials(big, 20) == c56.SCALING_TRIALS[1000] and exp.cell_trials(big, 3) == 3
    sc = scenario_of(big)
    assert sc.agents.n == 1000 and sc.metrics.r_s == pytest.approx(3.2 * math.sqrt(50 / 1000))
    assert c56.SCALING == {"scenario 1": "ch6-case2", "scenario 2": "ch6-case3"}


def ch5(**m: Any) -> list[Outcome]:
    base = dict(
        region_updates=40,
        b7_held=40,
        b7_overlap_or_out=0,
        b7_shrunk=0,
        b7_lattice_short=30,
        b7_fallback_held=30,
        ua_bfs_rho=0.3,
        ua_rank_at_min_bfs=0.1,
        b8_releases=39,
        b8_timeouts=0,
        b8_max_off=0.09,
        b8_goal_changes=0,
        b8_unreleased_updates=0,
        arrived=True,
        arrival_s=240.0,
        circle_events=5,
        circle_events_s="12 29 60 94 153",
    )
    base.update(m)
    return [outcome(0, "ch5-a", **base), outcome(1, "ch5-a", **base)]


def test_chapter_5_judges_pass_and_fail() -> None:
    assert c56.judge_b7(ch5())[1] is True
    assert c56.judge_b7(ch5(b7_held=38, b7_shrunk=2))[1] is False  # two updates at a shrunk radius
    assert c56.judge_b7(ch5(b7_held=39, b7_overlap_or_out=1))[1] is False
    assert "Spearman 0.30" in c56.judge_b7(ch5())[0]
    assert c56.judge_b8(ch5())[1] is True
    assert c56.judge_b8(ch5(b8_max_off=0.3))[1] is False  # released with an agent out of its circle
    assert c56.judge_b8(ch5(b8_goal_changes=1))[1] is False  # the region moved before the release
    assert c56.judge_b8(ch5(b8_unreleased_updates=2))[1] is False
    assert c56.judge_b8(ch5(b8_timeouts=1))[1] is False
    assert c56.judge_c6(ch5())[1] is True
    assert c56.judge_c6(ch5(arrival_s=320.0))[1] is False  # 28 % late
    assert c56.judge_c6(ch5(circle_events=44))[1] is False  # the events' count
    assert c56.judge_c6(ch5(arrived=False))[1] is False
    for judge in (c56.judge_b7, c56.judge_b8, c56.judge_c6):
        assert judge([])[1] is None
        assert judge([outcome(0, "ch5-a", smoke=True)])[2].startswith("smoke run")


def split_run(i: int, case: str, **m: Any) -> Outcome:
    base = dict(
        splits=1,
        merges=1,
        split_s=10.0,
        merge_s=45.0,
        arrival_s=60.0,
        arrived=True,
        split_sizes="55+45",
        split_min_openings=2,
        split_area_err=1e-16,
        split_widest_most=True,
        split_leaders_nearest=True,
        merge_area_err=0.0,
        merge_one_leader=True,
        merge_theorem1=True,
        merge_overlapped=1,
        merge_times="45",
        split_times="10",
        sub_area_dev=1e-15,
        sub_axes_range=2.0,
        mover_axes_periods=None,
        d_start=0.3,
        d_pre_split=0.5,
        d_split=0.7,
        d_merge=0.5,
        scan_last="one opening",
    )
    base.update(m)
    return outcome(i, case, **base)


def test_chapter_6_judges_pass_and_fail() -> None:
    good = [split_run(0, "ch6-case2"), split_run(1, "ch6-case2")]
    for judge in (c56.judge_b9, c56.judge_b10, c56.judge_b12, c56.judge_c9):
        assert judge(good)[1] is True, judge.__name__
        assert judge([])[1] is None
    assert c56.judge_b9([*good, split_run(2, "ch6-case2", split_widest_most=False)])[1] is False
    assert c56.judge_b9([*good, split_run(2, "ch6-case2", split_area_err=1e-3)])[1] is False
    assert c56.judge_b9([*good, split_run(2, "ch6-case2", split_leaders_nearest=False)])[1] is False
    never = c56.judge_b9([*good, split_run(2, "ch6-case1", splits=0, scan_max_openings=1)])
    assert never[1] is False and "ch6-case1: no split in 1 runs: at most 1 opening(s) in a scan" in never[0]
    assert c56.judge_b10([*good, split_run(2, "ch6-case2", merge_theorem1=False)])[1] is False
    assert c56.judge_b10([*good, split_run(2, "ch6-case2", merges=0)])[1] is False  # case 2 must merge
    assert c56.judge_b10([*good, split_run(2, "ch6-case1", merges=0)])[1] is True  # case 1 need not
    # B12: the thesis' order (low, up after the split, down after the merge) and ours reversed
    assert c56.judge_b12([split_run(0, "ch6-case2", d_pre_split=0.99, d_split=0.58, d_merge=0.95)])[1] is False
    assert c56.judge_b12([split_run(0, "ch6-case1", splits=0, d_split=None)])[1] is None  # nothing to order
    assert c56.judge_c9([split_run(0, "ch6-case2", split_s=22.0)])[1] is False  # 120 % late
    assert c56.judge_c9([split_run(0, "ch6-case3", split_s=None, splits=0, arrival_s=85.0)])[1] is False
    b11 = [split_run(0, "ch6-case3", mover_axes_periods=12), split_run(1, "ch6-case3", mover_axes_periods=3)]
    assert c56.judge_b11(b11)[1] is True
    assert c56.judge_b11([*b11, split_run(2, "ch6-case3", sub_area_dev=1e-6, mover_axes_periods=4)])[1] is False
    nosplit = c56.judge_b11([split_run(0, "ch6-case3", splits=0, mover_axes_periods=0)])
    assert nosplit[1] is False and "no split in case 3" in nosplit[2]


def scaling(case: str, d: dict[int, float], exec_s: dict[int, list[float]]) -> list[Outcome]:
    own = {"ch6-case2": 100, "ch6-case3": 50}[case]
    out = []
    for n, times in exec_s.items():
        for k, t in enumerate(times):
            out.append(outcome(k, case, None if n == own else n, exec_s=t, n=n, density_mean=d[n]))
    return out


def test_scaling_judges_c7_and_c8() -> None:
    d1 = {50: 0.6, 100: 0.55, 250: 0.5, 500: 0.45, 1000: 0.41}
    linear = {n: [0.01 * n * (1 + e * math.log(n) / 20) for e in (-1, 0, 1)] for n in d1}  # the COV rises with N
    falling = {n: [0.01 * n + e / math.sqrt(n) for e in (-0.05, 0.0, 0.05)] for n in d1}
    assert c56.judge_c7(scaling("ch6-case2", d1, falling))[1] is True
    assert c56.judge_c7(scaling("ch6-case2", {**d1, 1000: 0.2}, falling))[1] is False  # 0.2 off the thesis' 0.40
    assert c56.judge_c7(scaling("ch6-case2", {**d1, 250: 0.7}, falling))[1] is False  # not falling with N
    c8 = c56.judge_c8(scaling("ch6-case2", d1, falling))
    assert c8[1] is True and "R^2 1.0000" in c8[0]
    assert c56.judge_c8(scaling("ch6-case2", d1, linear))[1] is False  # the COV does not fall
    bent = {n: [v * (1 + 3 * (n == 1000)) for v in vs] for n, vs in falling.items()}
    assert c56.judge_c8(scaling("ch6-case2", d1, bent))[1] is False  # R^2 < 0.99
    assert c56.judge_c7([])[1] is None and c56.judge_c8([])[1] is None
    smoke = [outcome(0, "ch6-case2", smoke=True, exec_s=1.0, n=100, density_mean=0.5)]
    assert c56.judge_c8(smoke)[1] is None and c56.judge_c7(smoke)[2].startswith("smoke run")


def test_short_real_missions_record_the_chapters_metrics() -> None:
    t5 = numerical_trial({"kind": "numerical", "scenario": "ch5-a"}, Trial("roy-regions", {}, 0, 1, True, ""))
    m = t5.metrics
    assert m["region_updates"] >= 2 and m["b7_held"] + m["b7_shrunk"] == m["region_updates"]
    assert m["b7_overlap_or_out"] == 0 and m["b8_goal_changes"] == 0 and m["b8_unreleased_updates"] == 0
    assert m["circle_events"] == m["b8_releases"] >= 1 and 0 <= m["b8_max_off"] <= 0.1 + 1e-9
    assert float(m["circle_events_s"].split()[0]) <= 20.0
    t6 = numerical_trial({"kind": "numerical", "scenario": "ch6-case2"}, Trial("roy-regions", {}, 0, 1, True, ""))
    m6 = t6.metrics
    assert m6["splits"] == 0 and m6["sub_area_dev"] <= 1e-9 and 0 < m6["d_start"] < 1  # the split comes at 22 s
    assert len(t6.curves["sub0_area"]) == len(t6.curve_x["sub0_area"]) == 81
    # the split and the merge of the same mission, run on to 30 s
    sc = load_scenario("ch6-case2")
    rec = c56.recorder_for(sc, make_planner(sc))
    res = run_mission(sc, rec, 1, max_time_s=30.0)
    m = c56.ch56_metrics(res, rec, sc)
    assert m["splits"] == 1 and m["split_s"] == 22.0 and m["split_sizes"] == "45+55"
    assert m["split_area_err"] <= 1e-9 and m["split_widest_most"] and m["split_leaders_nearest"]
    assert m["merges"] == 1 and m["merge_area_err"] <= 1e-9 and m["merge_one_leader"] and m["merge_theorem1"]
    # B12: D within the sub-swarms (the file's density_pairs) rises after the split; over the whole swarm it falls
    assert m["sub_area_dev"] <= 1e-9 and m["d_split"] > m["d_pre_split"] - 1e-9 and m["d_split"] == 1.0
    whole = sc.model_copy(update={"metrics": sc.metrics.model_copy(update={"density_pairs": "swarm"})})
    rec = c56.recorder_for(whole, make_planner(whole))
    mw = c56.ch56_metrics(run_mission(whole, rec, 1, max_time_s=30.0), rec, whole)
    assert mw["d_split"] < 0.7 < mw["d_pre_split"] and mw["split_s"] == 22.0
    assert res.summary == run_mission(sc, make_planner(sc), 1, max_time_s=30.0).summary  # the recorder changes nothing


def test_chapter_6_figures_draw_the_sub_swarms_d_and_the_execution_time(tmp_path: Path) -> None:
    t = [0.25 * k for k in range(40)]
    curves = {"density": [0.3 + 0.01 * k for k in range(40)], "sub0_area": [78.5] * 20, "sub0_a": [5.0] * 20}
    curves |= {"sub0_b": [5.0] * 20, "sub1_area": [35.0] * 20, "sub1_a": [3.0] * 20, "sub1_b": [2.8] * 20}
    xs = {k: (t[:20] if k.startswith("sub0") else t[20:]) for k in curves} | {"density": t}
    res = TrialResult({"split_times": "5", "merge_times": "", "n": 100}, curves, xs, {"cpu_s": 1.0})
    outcomes = [
        Outcome(Trial("roy-regions", {"kind": "numerical", "scenario": "ch6-case2"}, 0, 0, False, ""), res, None)
    ]
    outcomes += scaling("ch6-case2", dict.fromkeys((50, 250), 0.5), {50: [0.5, 0.6], 250: [2.5, 2.6]})
    lines = c56.ch6_figures(outcomes, tmp_path)
    for png in ("subswarms-ch6-case2.png", "density-ch6.png", "exec-time-ch6-case2.png"):
        assert (tmp_path / png).stat().st_size > 1000 and any(f"(plots/{png})" in line for line in lines)
    assert "![execution time against N, scenario 1 (ch6-case2)](plots/exec-time-ch6-case2.png)" in lines
