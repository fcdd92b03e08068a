"""Chapter 7's comparisons in roy-regions (C11, C12): the cells (paired deployments), the judges on synthetic
outcomes both ways, the report's tables, and one short session of each method."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from bridge.experiments.runner import Outcome, Trial, TrialResult, get_experiment, trial_seed
from bridge.studies.roy import regions_ch7 as c7

LOW, HIGH = "ch7-moving-low", "ch7-moving-high"


def test_the_cells_pair_the_methods_on_one_deployment() -> None:
    exp = get_experiment("roy-regions")()
    cells = [c for c in exp.cells(smoke=False) if c["kind"] == c7.KIND]
    assert cells == c7.cells() and len(cells) == 10
    assert {(c["scenario"], c["agents"]) for c in cells if c["method"] == c7.CG} == {
        (s, n) for s in (LOW, HIGH) for n in (3, 4)}
    assert {(c["scenario"], c["agents"]) for c in cells if c["method"] == c7.BINARY_BAT} == {(LOW, 4), (HIGH, 4)}
    assert all(exp.cell_trials(c, 20) == c7.TRIALS for c in cells)
    seeds = {trial_seed(0, "roy-regions", {k: v for k, v in c.items() if k not in exp.seed_ignores}, 0)
             for c in cells if c["scenario"] == LOW and c["agents"] == 4}
    assert len(seeds) == 1  # proposed, CG and binary bat start from the same poses


def run(case: str, n: int, method: str, i: int, **m: Any) -> Outcome:
    cell = {"kind": c7.KIND, "scenario": case, "agents": n, "method": method}
    return Outcome(Trial("roy-regions", cell, i, i, False, ""), TrialResult(dict(m)), None)


def arrived(t: float, fe: float, **m: Any) -> dict[str, Any]:
    return {"success": True, "mission_s": t, "sim_s": t + 0.01, "fe_mean": fe, "path_m": 0.6, **m}


def lost(fe: float, **m: Any) -> dict[str, Any]:
    return {"success": False, "mission_s": None, "sim_s": 360.0, "fe_mean": fe, "path_m": 1.2, **m}


def c11_outcomes(cg_high4_arrives: bool = False, cg_low_fe: float = 0.1, slow: float = 1.0) -> list[Outcome]:
    out = []
    for i in range(2):
        for case, n in c7.TABLE_7_4:
            out.append(run(case, n, c7.PROPOSED, i, **arrived(60.0 * slow, 0.3)))
            if (case, n) == (HIGH, 4) and not cg_high4_arrives:
                out.append(run(case, n, c7.CG, i, **lost(0.2)))
            else:
                out.append(run(case, n, c7.CG, i, **arrived(100.0, cg_low_fe if case == LOW else 0.2)))
    return out


def test_c11_passes_the_thesis_pattern_and_fails_each_break_of_it() -> None:
    text, good, _ = c7.judge_c11(c11_outcomes())
    assert good is True and "high N=4: time 60 s (2/2) vs CG >=360 s (0/2)" in text
    assert c7.judge_c11(c11_outcomes(cg_high4_arrives=True))[1] is False  # CG must fail with 4 robots, case 4
    assert c7.judge_c11(c11_outcomes(cg_low_fe=0.5))[1] is False  # CG keeps the lower FE in case 3
    assert c7.judge_c11(c11_outcomes(slow=2.0))[1] is False  # the proposed method slower than CG
    assert c7.judge_c11([])[1] is None


def c12_outcomes(fe: tuple[float, ...] = (0.3, 0.5, 0.4, 0.1), bb_t: float = 90.0) -> list[Outcome]:
    out = []
    for case, phases in c7.TABLE_7_5_FE.items():
        k = len(phases)
        for i in range(2):
            out.append(run(case, 4, c7.PROPOSED, i, **arrived(60.0, 0.3, **{f"ph{j + 1}_fe": fe[j] for j in range(k)})))
            out.append(run(case, 4, c7.BINARY_BAT, i, **arrived(bb_t, 0.4, **{f"ph{j + 1}_fe": 0.32 if j == 0 else 0.6
                                                                             for j in range(k)})))
    return out


def test_c12_passes_when_the_proposed_phases_are_no_worse_and_fails_otherwise() -> None:
    text, good, _ = c7.judge_c12(c12_outcomes())
    assert good is True and "low: phase FE proposed/binary bat 0.30/0.32, 0.50/0.60, 0.40/0.60" in text
    assert c7.judge_c12(c12_outcomes(fe=(0.2, 0.5, 0.4, 0.1)))[1] is False  # the first phase not about equal
    assert c7.judge_c12(c12_outcomes(fe=(0.3, 0.7, 0.4, 0.1)))[1] is False  # a later phase worse
    assert c7.judge_c12(c12_outcomes(bb_t=50.0))[1] is False  # binary bat the faster
    assert c7.judge_c12(c12_outcomes()[:4])[1] is None  # case 4 did not run


def test_the_report_tables_show_thesis_and_ours() -> None:
    bb = [o for o in c12_outcomes() if o.trial.cell["method"] == c7.BINARY_BAT]
    lines = "\n".join(c7.sections(c11_outcomes() + bb))
    assert "**Table 7.4**" in lines and "| high | 4 | Fail | >=360 s (0/2) | 575 | 60 s (2/2) |" in lines
    assert "| low | before changing initial formation | 0.36 +- 0.21 | 0.32 +- 0.00 | 0.37 +- 0.2 | - |" in lines
    assert c7.sections([]) == []


@pytest.mark.long
@pytest.mark.parametrize("method", [c7.PROPOSED, c7.CG, c7.BINARY_BAT])
def test_a_short_session_of_each_method(tmp_path: Path, method: str) -> None:
    cell = {"kind": c7.KIND, "scenario": LOW, "agents": 3, "method": method}
    res = c7.trial(cell, Trial("roy-regions", cell, 0, 11, True, str(tmp_path)))
    m = res.metrics
    assert m["sim_s"] == pytest.approx(c7.SMOKE_S, abs=0.05) and m["alive"] == 3 and m["path_m"] > 0.05
    assert m["ph1_s"] is None and m["ph1_fe"] is not None  # still in the first phase after SMOKE_S
    assert "rtf" not in m and "cpu_s" not in m and res.timings["cpu_s"] > 0
