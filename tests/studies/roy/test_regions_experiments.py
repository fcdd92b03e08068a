"""The roy-regions experiment: its cells (one per scenario file, failure fractions, trial caps), smoke trials' metrics
in the point model, the targets' judgement on synthetic outcomes both ways, and a smoke run's report and plots."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.experiments import runner as ex
from bridge.experiments.runner import Outcome, Trial, TrialResult, get_experiment
from bridge.studies.roy import regions_experiments as rx
from bridge.studies.roy.regions_baselines import C10_VARIANTS, TVI_BASELINE, TVI_PROPOSED
from bridge.studies.roy.regions_cosim import COSIM
from bridge.studies.roy.regions_experiments import CELLS, SCENARIO_KINDS, CellSpec, RoyRegionsExperiment

TARGETS = ["B3", "B4", "B5", "B6", "B7", "B8", "B9", "B10", "B11", "B12", "C4-6", "C4-50", "C4-fail", "C4-COV"]
TARGETS += ["C5-TVI", "C5-D", "C6", "C7", "C8", "C9", "C10", "C11", "C12", "D1", "D3", "D4", "D5"]


def test_the_cells_are_the_scenario_files_with_their_kind_and_failure_fractions(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    exp = get_experiment("roy-regions")()
    every = exp.cells(smoke=False)
    cells = [c for c in every if c["kind"] == "numerical"]
    assert {c["scenario"] for c in cells} == {"ch4-a", "ch4-maze-50", "ch4-failures-50", "ch4-mover"} | {
        "ch5-a",
        "ch6-case1",
        "ch6-case2",
        "ch6-case3",
    } | {TVI_PROPOSED, TVI_BASELINE, *C10_VARIANTS.values()}
    assert {c["scenario"] for c in every if c["kind"] == "cosim"} == set(COSIM)  # SonPI sessions, few trials each
    assert all(exp.cell_trials(c, 20) <= 3 for c in every if c["kind"] == "cosim")
    assert sorted(c["failures"] for c in cells if "failures" in c) == [0.05, 0.10, 0.20]
    assert all(c["kind"] in SCENARIO_KINDS for c in every) and exp.cells(smoke=True) == every
    for c in cells:
        assert rx.scenario_of(c).name == c["scenario"]
        assert rx.scenario_of(c).agents.n == c.get("agents", rx.scenario_of(c).agents.n)
        cap = next(s.max_trials for s in CELLS if s.cell() == c)
        assert exp.cell_trials(c, 7) == min(7, cap or 7)
    assert rx.scenario_of({"scenario": "ch4-failures-50", "failures": 0.2}).failures.fraction == 0.2
    # a new scenario is one line, with a cap on its trials when its runs are dear
    monkeypatch.setattr(rx, "CELLS", (*CELLS, CellSpec("ch4-a", failures=0.5, max_trials=3)))
    dear = {"kind": "numerical", "scenario": "ch4-a", "failures": 0.5}
    assert dear in exp.cells(smoke=False) and exp.cell_trials(dear, 20) == 3 and exp.cell_trials(dear, 2) == 2


def test_smoke_trials_record_the_region_formation_failures_and_the_mover() -> None:
    exp = RoyRegionsExperiment()
    a = exp.run_batch([Trial("roy-regions", {"kind": "numerical", "scenario": "ch4-a"}, 0, 5, True, "")])[0]
    m = a.metrics
    assert m["sim_s"] == pytest.approx(rx.SMOKE_S) and not m["arrived"] and m["arrival_s"] is None
    assert m["n"] == 6 and "exec_s" not in m and 0 < a.timings["plan_s"] <= a.timings["exec_s"]
    assert m["circle_start"] is True and m["formation_first"] == "triangle"
    assert m["final_area"] == pytest.approx(3.14159265 * 2.5**2) and m["area_cov"] == pytest.approx(0.0, abs=1e-12)
    assert 0 < m["density_mean"] <= 1 and m["n_failed"] == 0 and "mover_in_periods" not in m
    assert len(a.curves["area"]) == len(a.curve_x["area"]) == 81  # every 0.25 s over 20 s
    assert set(a.curves) == {"area", "a", "b", "density", "formation", "shape"}
    again = exp.run_batch([Trial("roy-regions", {"kind": "numerical", "scenario": "ch4-a"}, 0, 5, True, "")])[0]
    assert again.metrics == m  # the same seed, the same row (the wall-clock figures are timings, apart)
    fail = {"kind": "numerical", "scenario": "ch4-failures-50", "failures": 0.2}
    f = exp.run_batch([Trial("roy-regions", fail, 0, 5, True, "")])[0].metrics
    assert f["n"] == 50 and f["n_failed"] == 5 and "formation_first" not in f  # 10 fail: 5 at 14 s, 5 at 80 s
    assert f["area_formula"] == pytest.approx(3.14159265 * 4.284**2 * 45 / 50)
    mv = exp.run_batch([Trial("roy-regions", {"kind": "numerical", "scenario": "ch4-mover"}, 0, 5, True, "")])[0]
    assert mv.metrics["mover_in_periods"] + mv.metrics["mover_out_periods"] == 81
    with pytest.raises(ValueError, match="kind: no scenario kind 'bench'; known: numerical, cosim, ch7"):
        exp.run_batch([Trial("roy-regions", {"kind": "bench", "scenario": "ch4-a"}, 0, 5, True, "")])


def outcome(i: int, smoke: bool = False, **cell_and_metrics: object) -> Outcome:
    cell = {k: cell_and_metrics.pop(k) for k in ("scenario", "failures") if k in cell_and_metrics}
    return Outcome(
        Trial("roy-regions", {"kind": "numerical", **cell}, i, i, smoke, ""), TrialResult(dict(cell_and_metrics)), None
    )


def test_targets_pass_and_fail_on_synthetic_outcomes_and_none_passes_without_runs() -> None:
    targets = {t.id: t for t in RoyRegionsExperiment().targets()}
    assert list(targets) == TARGETS
    for t in targets.values():  # no runs: nothing is judged, whatever the target
        assert t.evaluate([])[1] is None, t.id
    assert (
        targets["B5"].evaluate([outcome(0, True, scenario="ch4-failures-50", failures=0.1)])[2].startswith("smoke run")
    )

    def c4(times: list[float | None]) -> list[Outcome]:
        return [outcome(i, scenario="ch4-a", arrived=t is not None, arrival_s=t) for i, t in enumerate(times)]

    assert targets["C4-6"].evaluate(c4([170.0, 180.0]))[1] is True
    assert targets["C4-6"].evaluate(c4([220.0, 215.0]))[1] is False  # 28 % late
    assert targets["C4-6"].evaluate(c4([170.0, None]))[1] is False  # a run that never arrives

    def b5(area: float, detected: int) -> list[Outcome]:
        return [
            outcome(
                i,
                scenario="ch4-failures-50",
                failures=0.2,
                final_area=area,
                area_formula=46.12,
                n_failed=10,
                n_detected=detected,
                arrived=True,
            )
            for i in range(3)
        ]

    assert targets["B5"].evaluate(b5(47.5, 10))[1] is True  # within 2 % of the thesis' 47.80
    assert targets["B5"].evaluate(b5(46.12, 10))[1] is True  # exactly pi r_c^2 (N - N') / N
    assert targets["B5"].evaluate(b5(44.0, 10))[1] is False
    assert targets["B5"].evaluate(b5(47.5, 9))[1] is False  # a failure never detected

    def b6(held_in: int, held_out: int, crossed: bool = False) -> list[Outcome]:
        return [
            outcome(
                0,
                scenario="ch4-mover",
                mover_in_periods=100,
                mover_out_periods=100,
                arrived=True,
                blocked_mover_in=held_in,
                blocked_mover_out=held_out,
                crossed_with_mover_in=crossed,
            )
        ]

    assert targets["B6"].evaluate(b6(10, 2))[1] is True
    assert targets["B6"].evaluate(b6(10, 8))[1] is False  # holds as often with the mover away
    assert targets["B6"].evaluate(b6(10, 2, crossed=True))[1] is False
    b3 = [outcome(0, scenario="ch4-maze-50", circle_start=True, ellipse_seen=True, final_circle=True)]
    assert targets["B3"].evaluate(b3)[1] is True
    b3.append(outcome(1, scenario="ch4-maze-50", circle_start=True, ellipse_seen=False, final_circle=True))
    assert targets["B3"].evaluate(b3)[1] is False
    assert targets["C7"].evaluate(b3)[1] is None and "chapter 6" in targets["C7"].evaluate(b3)[2]


def test_a_smoke_run_reports_every_target_and_draws_the_plots(tmp_path: Path) -> None:
    run = ex.execute_experiment(
        "roy-regions", smoke=True, jobs=1, out=tmp_path, progress=False, only={"scenario": ["ch4-a", "ch4-maze-50"]}
    )
    assert run.failed == 0 and len(run.outcomes) == 2
    report = (tmp_path / "report.md").read_text()
    for tid in TARGETS:
        assert f"| {tid} |" in report
    assert all(ok is None for _, _, ok, _ in run.verdicts)  # a smoke run judges nothing
    for png in ("region-ch4-a.png", "region-ch4-maze-50.png", "formations.png", "density.png", "exec-time-vs-n.png"):
        assert (tmp_path / "plots" / png).stat().st_size > 1000 and f"(plots/{png})" in report
