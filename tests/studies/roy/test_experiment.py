"""The roy-apf experiment: its cells (every method, the scenario kinds, fewer trials where runs are dear), a batch
of trials run through the numerical kind, and the targets' judgement on known figures."""

from __future__ import annotations

import pytest

from bridge.experiments.runner import Outcome, Trial, TrialResult, get_experiment
from bridge.studies.roy.experiments import METHODS, SCENARIO_KINDS, TABLE_3_5, RoyApfExperiment, scenario


def test_the_experiment_is_registered_with_every_method_and_its_scenario_kinds() -> None:
    exp = get_experiment("roy-apf")()
    cells = exp.cells(smoke=False)
    main = {c["method"] for c in cells if c["scenario"] == "roy-ch3-v2"}
    assert set(METHODS) <= main and "gathering" in main
    assert {c["n"] for c in cells if c["scenario"] == "open"} == {6, 12, 30}
    assert all(c["kind"] in SCENARIO_KINDS for c in cells)
    bat = {"kind": "numerical", "scenario": "roy-ch3-v2", "n": 6, "method": "bat"}
    assert exp.cell_trials(bat, 100) == 100
    assert exp.cell_trials({**bat, "scenario": "open", "n": 30}, 100) < 10
    assert scenario("open", 12).lines == () and scenario("open", 12).n == 12
    assert scenario("roy-ch3-v2", 6).timeout_s == 600.0


def test_a_batch_of_trials_runs_in_the_numerical_kind_with_its_metrics() -> None:
    """Two smoke trials of the fixed gains stepped together, and one of circle gathering."""
    exp = RoyApfExperiment()
    cell = {"kind": "numerical", "scenario": "roy-ch3-v2", "n": 6, "method": "fixed"}
    res = exp.run_batch([Trial("roy-apf", cell, i, 11 + i, True, "") for i in range(2)])
    assert len(res) == 2 and res[0].metrics != res[1].metrics
    m = res[0].metrics
    assert m["sim_s"] == pytest.approx(20.0) and not m["success"] and m["k_a_mean"] == pytest.approx(4.4)
    assert m["k_a_sd"] == pytest.approx(0.0, abs=1e-5) and m["k_a_n"] == 6 * 400  # from sums of squares
    assert 0.0 < m["ci_mean"] <= 1.0 and (m["formed_s"] is None or m["formed_s"] >= 0.0)
    g = exp.run_batch([Trial("roy-apf", {**cell, "method": "gathering"}, 0, 11, True, "")])[0].metrics
    assert g["sim_s"] == pytest.approx(20.0) and g["collisions"] == 0
    with pytest.raises(ValueError, match="kind"):
        exp.run_batch([Trial("roy-apf", {**cell, "kind": "hil"}, 0, 1, True, "")])


def outcome(method: str, i: int, **metrics: object) -> Outcome:
    cell = {"kind": "numerical", "scenario": "roy-ch3-v2", "n": 6, "method": method}
    return Outcome(Trial("roy-apf", cell, i, i, False, ""), TrialResult(dict(metrics)), None)


def test_c1_judges_the_thesis_figures_as_passing_and_a_swapped_ordering_as_failing() -> None:
    exp = RoyApfExperiment()
    c1 = {t.id: t for t in exp.targets()}

    def table(swap: bool) -> list[Outcome]:
        out = []
        for m, (ci, cov, succ, path) in TABLE_3_5.items():
            if swap and m == "bfo":
                ci = 0.5
            for i in range(10):
                out.append(outcome(m, i, ci_mean=ci, ci_cov=cov, success=i < round(10 * succ), path_length=path))
        return out

    for tid in ("C1-CI", "C1-path", "C1-COV"):
        assert c1[tid].evaluate(table(False))[1] is True, tid
    assert c1["C1-CI"].evaluate(table(True))[1] is False
    text, verdict, _ = c1["C1-success"].evaluate(table(False))
    assert verdict is True and "50.0 %" in text  # BG: 5 of 10
    assert c1["C3"].evaluate(table(False))[1] is None  # no open-space runs: not judged
