"""``roy-regions``: chapters 4-6's virtual regions (digest 001 §4.2-4.6) judged against the thesis (targets B3-B12,
C4-C12, D1, D3-D5 of §6).

A cell is a scenario run by its ``kind``: "numerical" (a scenario file of ``hil_configs/roy/``,
``regions_scenarios``, in the point model, ``regions_world.run_mission``: one mission per trial, its planner the
file's), "cosim" (SonPI sessions through the region controller service, ``regions_cosim``: hardware-scale arenas for
D1, D3-D5) or "ch7" (chapter 7's comparisons of the BAT approach on SonPIs, ``regions_ch7``: C11, C12).
``SCENARIO_KINDS`` names the kinds; ``CELLS`` lists the region cells, one ``CellSpec`` a line, with a cap on a cell's
trials when its runs are dear.

Each trial records the mission's figures (arrival, region area and axes, D(t), TVI, formations, failures, the AD
test's holds around a mover) and its execution time: the wall-clock seconds of the planner, the world and the sonar
casts (``exec_s``, erratum 29: the thesis' "execution time" is compute time, not the simulated ``sim_s``; ``plan_s``
the planner's part): the two columns that differ between two runs of the same command. A target whose scenario,
baseline or kind has no runs is "not judged" with the reason; none passes without runs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import mean, ok, values
from bridge.studies.roy import regions_ch7
from bridge.studies.roy import regions_judging as judging
from bridge.studies.roy.metrics import linear_fit
from bridge.studies.roy.numerical import Mover
from bridge.studies.roy.regions_baselines import (
    C10_NS,
    C10_TRIALS,
    C10_VARIANTS,
    TVI_BASELINE,
    TVI_NS,
    TVI_PROPOSED,
    TVI_TRIALS,
    baseline_metrics,
    judge_c5_tvi,
    judge_c10,
)
from bridge.studies.roy.regions_ch56 import (
    SCALING_N,
    SCALING_TRIALS,
    ch6_figures,
    ch56_curves,
    ch56_metrics,
    judge_b7,
    judge_b8,
    judge_b9,
    judge_b10,
    judge_b11,
    judge_b12,
    judge_c6,
    judge_c7,
    judge_c8,
    judge_c9,
    recorder_for,
)
from bridge.studies.roy.regions_cosim import cosim_trial, judge_d1, judge_d3, judge_d4, judge_d5
from bridge.studies.roy.regions_judging import Verdict
from bridge.studies.roy.regions_judging import every as _every
from bridge.studies.roy.regions_judging import fmt as _f
from bridge.studies.roy.regions_judging import whole as runs
from bridge.studies.roy.regions_plots import SHAPES, density_plot, exec_plot, file_name, formation_plot, region_plot
from bridge.studies.roy.regions_scenarios import SCENARIO_DIR, RegionScenario, load_scenario, make_planner
from bridge.studies.roy.regions_world import MissionResult, run_mission

SMOKE_S = 20.0  # smoke trials: this much simulated time per mission
FAILURES = (0.05, 0.10, 0.20)  # scenario C's failure fractions (Fig. 4.13)
AREA_0 = 57.65  # the 50-agent region's area without failures (§4.2: mean 57.65, sd 1.09)
THESIS_FAILURE_AREA = {0.05: 55.19, 0.10: 52.56, 0.20: 47.80}  # §4.2 scenario C's final areas
THESIS_TIMES = {"ch4-a": 171.0, "ch4-maze-50": 150.0, "ch4-failures-50": 250.0}  # C4 (s)
THESIS_AREA_COV = 1.09 / 57.65  # C4: the 50-agent run's area COV (0.019)
TIME_TOL = 0.2  # C4: +-20 % on times
COV_TOL = 0.5  # C4's area COV: within 50 % of the thesis' (ours and theirs come from different region rules)
AREA_TOL = 0.02  # B5 (as A5): the final area within 2 % of the thesis' ...
FORMULA_TOL = 1e-6  # ... or exactly pi r_c^2 (N - N') / N
CONVERGE_S = 10.0  # C5's D comparison leaves out the first seconds (the swarm converging into the first circle)
# B6's scenarios, each with the half-width of the gap its first mover sweeps across (centred on the middle of the
# sweep): ch4-mover's first wall has a 4-unit gap
GAP_MOVERS = {"ch4-mover": 2.0}
SEQUENCES_SHOWN = 3  # the report lists the formation sequences of each cell's first trials


@dataclass(frozen=True)
class CellSpec:
    """One cell: a scenario file's name, its kind, a failure fraction overriding the file's (or None), an agent
    count overriding the file's (``RegionScenario.with_agents``: the same map, r_s scaled; None: the file's) and a
    cap on its trials (None: as many as the experiment runs per cell)."""

    scenario: str
    kind: str = "numerical"
    failures: float | None = None
    max_trials: int | None = None
    agents: int | None = None

    def cell(self) -> dict[str, Any]:
        c: dict[str, Any] = {"kind": self.kind, "scenario": self.scenario}
        if self.failures is not None:
            c["failures"] = self.failures
        if self.agents is not None:
            c["agents"] = self.agents
        return c


CELLS: tuple[CellSpec, ...] = (
    CellSpec("ch4-a"),  # B3, B4, C4 (171 s)
    CellSpec("ch4-maze-50"),  # B3, C4 (150 s, area COV 0.019), C5
    *(CellSpec("ch4-failures-50", failures=f) for f in FAILURES),  # B3, B5, C4 (250 s)
    CellSpec("ch4-mover"),  # B6
    CellSpec("ch5-a"),  # B7, B8, C6 (14 agents, Table 5.1)
    CellSpec("ch6-case1"),  # B9, B10, B12, C9 (50 agents, r_s 3.2, three lanes)
    CellSpec("ch6-case2"),  # B9, B10, B12, C9; C7, C8: scenario 1 at N = 100
    CellSpec("ch6-case3"),  # B9-B12, C9; C7, C8: scenario 2 at N = 50
    # C7, C8: scenario 1 (ch6-case2's map) and scenario 2 (ch6-case3's) at the other N of Tables 6.2 and 6.3
    *(CellSpec("ch6-case2", agents=n, max_trials=SCALING_TRIALS.get(n)) for n in SCALING_N if n != 100),
    *(CellSpec("ch6-case3", agents=n, max_trials=SCALING_TRIALS.get(n)) for n in SCALING_N if n != 50),
    CellSpec("d3-ch4-3", kind="cosim", max_trials=3),  # D1 (noisy, 3), D3 (251 s): SonPI sessions, regions_cosim
    CellSpec("d3-ch4-6", kind="cosim", max_trials=3),  # D1 (noisy, 6), D3 (615 s)
    CellSpec("d1-ch4-3-noiseless", kind="cosim", max_trials=2),  # D1 (noiseless, 3)
    CellSpec("d1-ch4-6-noiseless", kind="cosim", max_trials=2),  # D1 (noiseless, 6)
    *(CellSpec(f"d4-ch6-{n}", kind="cosim", max_trials=3) for n in (4, 5, 6)),  # D4 (two lanes; N = 4, 5, 6)
    CellSpec("d5-ch5-3", kind="cosim", max_trials=3),  # D5 (polygon regions)
    *(CellSpec(TVI_PROPOSED, agents=n, max_trials=TVI_TRIALS) for n in TVI_NS),  # C5-TVI: the proposed method
    *(CellSpec(TVI_BASELINE, agents=n, max_trials=TVI_TRIALS) for n in TVI_NS),  # C5-TVI: the aggregation baseline
    *(CellSpec(sc, agents=n, max_trials=C10_TRIALS[n]) for n in C10_NS for sc in C10_VARIANTS.values()),  # C10
)


def scenario_of(cell: dict[str, Any]) -> RegionScenario:
    """The cell's scenario file, with its failure fraction and its agent count when the cell sets them."""
    sc = load_scenario(cell["scenario"])
    if cell.get("failures") is not None:
        sc = sc.with_failures(float(cell["failures"]))
    if cell.get("agents") is not None:
        sc = sc.with_agents(int(cell["agents"]))
    return sc


def _code(name: str) -> int:
    return SHAPES.index(name) if name in SHAPES else len(SHAPES)


def planned_formation(times: np.ndarray, plan: list[dict[str, Any]]) -> list[str]:
    """The planner's formation in force at each of ``times``, from the mission's ``formation_plan`` (empty names
    without one)."""
    out = [""] * len(times)
    for row in plan:
        for k in np.nonzero(times >= float(row["t"]) - 1e-9)[0]:
            out[k] = str(row["to"])
    return out


def region_metrics(res: MissionResult) -> dict[str, Any]:
    """The region's figures over a mission (B3, C4, C5): its area at the start and end, its mean, sd and COV, the
    narrowest b, whether it started a circle, became an ellipse, ended a circle, and D(t) in both."""
    s, ser = res.summary, res.series
    t = np.asarray(ser["t"], float)
    circle = np.asarray(ser["circle"], bool)
    dens = np.asarray(ser["density"], float)
    b = np.asarray(ser["b"], float)
    area = s["region"]["area"]
    late = t >= CONVERGE_S
    d_ell, d_circ = dens[late & ~circle], dens[late & circle]
    period = float(t[1] - t[0]) if len(t) > 1 else 0.0
    return {
        "final_area": s["final_area"],
        "final_a": s["final_axes"][0] if s["final_axes"] else None,
        "final_b": s["final_axes"][1] if s["final_axes"] else None,
        "final_circle": s["final_circle"],
        "circle_start": bool(circle[0]) if len(circle) else None,
        "ellipse_seen": bool((~circle).any()) if len(circle) else None,
        "ellipse_s": round(float(np.count_nonzero(~circle)) * period, 3),
        "region_switches": len(s["region_switches"]),
        "b_min": float(np.nanmin(b)) if np.isfinite(b).any() else None,
        "area_mean": area["mean"],
        "area_sd": area["sd"],
        "area_cov": area["cov"],
        "density_mean": s["density"]["mean"],
        "density_ellipse": float(np.nanmean(d_ell)) if np.isfinite(d_ell).any() else None,
        "density_circle": float(np.nanmean(d_circ)) if np.isfinite(d_circ).any() else None,
    }


def formation_plan(res: MissionResult, kept: str = "") -> list[dict[str, Any]]:
    """The planner's formations over the mission (``formation_plan``); a mission without a change of formation
    kept its first one all along: ``kept`` (the planner's shape at the end, "" for none) from t = 0."""
    plan = res.summary["formation_plan"]
    return plan if plan or not kept else [{"t": 0.0, "to": kept}]


def formation_metrics(res: MissionResult, plan: list[dict[str, Any]]) -> dict[str, Any]:
    """B4, for a swarm the planner forms (N <= 10; ``plan`` from ``formation_plan``): the planned sequence, its first
    shape, when it first changed, the shape in force where the region was narrowest (the corridor), and the shapes
    the agents made."""
    s, ser = res.summary, res.series
    if not plan:
        return {}
    t = np.asarray(ser["t"], float)
    names = planned_formation(t, plan)
    b = np.asarray(ser["b"], float)
    narrow = int(np.nanargmin(b)) if np.isfinite(b).any() else None
    return {
        "formation_first": plan[0]["to"],
        "formation_sequence": " > ".join(f"{r['to']}@{float(r['t']):g}" for r in plan),
        "formation_changes": len(plan) - 1,
        "formation_change_s": float(plan[1]["t"]) if len(plan) > 1 else None,
        "formation_at_narrowest": names[narrow] if narrow is not None else None,
        "shapes_observed": " > ".join(f"{r['shape']}@{float(r['t']):g}" for r in s["formations"]),
    }


def failure_metrics(res: MissionResult, sc: RegionScenario) -> dict[str, Any]:
    """B5: how many agents failed and were detected, when, and the final area against pi r_c^2 (N - N') / N."""
    s = res.summary
    p = s["planner"]
    det = p.get("failures_detected") or []
    r_c = float(sc.planner.params.get("r_c", math.nan))
    formula = math.pi * r_c**2 * (s["n"] - s["failed_true"]) / s["n"] if math.isfinite(r_c) else math.nan
    return {
        "n_failed": s["failed_true"],
        "n_detected": p.get("n_failed_detected"),
        "detected_first_s": float(det[0]["t"]) if det else None,
        "detected_last_s": float(det[-1]["t"]) if det else None,
        "area_formula": formula,
    }


def mover_metrics(res: MissionResult, sc: RegionScenario) -> dict[str, Any]:
    """B6, in a scenario of ``GAP_MOVERS`` (its first mover sweeps across a gap centred on the middle of its sweep,
    of the half-width given there): over the periods while the region's centre is still on the start's
    side of the mover's line, how often the AD test held the region ("gap blocked") with the mover in the gap and
    with it away, and whether the region's centre crossed the line while the mover was in the gap."""
    half = GAP_MOVERS.get(sc.name)
    if half is None or not sc.world.movers or not res.plans:
        return {}
    m = sc.world.movers[0]
    mv = Mover(tuple(m.a), tuple(m.b), m.radius, m.speed)
    a, b = np.asarray(m.a, float), np.asarray(m.b, float)
    gap, reach = (a + b) / 2, half + m.radius
    start = (np.asarray(sc.agents.start_lo, float) + np.asarray(sc.agents.start_hi, float)) / 2

    def side(p: np.ndarray) -> float:
        return float(np.sign((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])))

    home = side(start)
    blocked = {
        round(float(e["t"]), 6)
        for e in res.summary["events"]
        if e.get("kind") == "held" and e.get("reason") == "gap blocked"
    }
    n_in = n_out = held_in = held_out = 0
    crossed_in: bool | None = None
    for pl in res.plans:
        reg = pl["regions"][0] if pl["regions"] else None
        if reg is None or "x" not in reg:
            continue
        t = float(pl["t"])
        near = bool(np.hypot(*(mv.centre(t) - gap)) <= reach)
        if side(np.array([reg["x"], reg["y"]])) != home:
            crossed_in = near
            break
        held = round(t, 6) in blocked
        n_in, held_in = n_in + near, held_in + (near and held)
        n_out, held_out = n_out + (not near), held_out + (not near and held)
    return {
        "mover_in_periods": n_in,
        "mover_out_periods": n_out,
        "blocked_mover_in": held_in,
        "blocked_mover_out": held_out,
        "crossed_with_mover_in": crossed_in,
    }


def numerical_trial(cell: dict[str, Any], trial: Trial) -> TrialResult:
    """One mission of the cell's scenario in the point model from the trial's seed (``SMOKE_S`` of it in a smoke
    run): its metrics, and per planner period the region's area, a, b, D(t) and (N <= 10) the formation's code."""
    sc = scenario_of(cell)
    planner = make_planner(sc)
    rec = recorder_for(sc, planner)  # chapters 5 and 6: the plans recorded for their targets
    cpu0 = time.process_time()
    res = run_mission(
        sc, rec or planner, trial.seed, max_time_s=SMOKE_S if trial.smoke else None, keep_plans=sc.name in GAP_MOVERS
    )
    cpu_s = time.process_time() - cpu0
    s, perf = res.summary, res.perf
    plan = formation_plan(res, str(getattr(planner, "shape", "") or ""))
    metrics: dict[str, Any] = {
        "n": s["n"],
        "arrived": s["arrived"],
        "arrival_s": s["arrival_s"],
        "sim_s": s["t_end_s"],
        **region_metrics(res),
        "tvi": s["tvi"],
        "path_mean": s["path_mean"],
        "contacts": s["contacts"],
        **{f"held_{k.replace(' ', '_')}": v for k, v in sorted(s["planner"].get("held", {}).items())},
        **formation_metrics(res, plan),
        **failure_metrics(res, sc),
        **mover_metrics(res, sc),
        **(ch56_metrics(res, rec, sc) if rec is not None else {}),
        **baseline_metrics(res),
    }
    ser = res.series
    t = [float(x) for x in ser["t"]]
    curves = {k: [float(v) for v in ser[k]] for k in ("area", "a", "b", "density")}
    if plan:
        curves["formation"] = [float(_code(n)) for n in planned_formation(np.asarray(t), plan)]
        curves["shape"] = [float(_code(n)) for n in ser["shape"]]
    xs = {k: t for k in curves}
    if rec is not None:
        sub, sub_x = ch56_curves(rec)
        curves.update(sub)
        xs.update(sub_x)
    timings = {"exec_s": perf["plan_s"] + perf["world_s"] + perf["cast_s"], "plan_s": perf["plan_s"], "cpu_s": cpu_s}
    return TrialResult(metrics, curves, xs, timings)


# the scenario kinds a cell can name, each a function running one trial of a cell
SCENARIO_KINDS: dict[str, Callable[[dict[str, Any], Trial], TrialResult]] = {
    "numerical": numerical_trial,
    "cosim": cosim_trial,
    regions_ch7.KIND: regions_ch7.trial,
}


# -- judging ---------------------------------------------------------------------------------------------------------


def no_runs(outcomes: list[Outcome], need: str) -> Verdict:
    """Not judged for want of whole missions: a smoke run's stop early, else ``need`` says what is missing."""
    return judging.no_runs(outcomes, need, f"smoke run: the missions stop at {SMOKE_S:g} s")


def missing(scenario: str) -> str | None:
    """Why a scenario cannot be judged yet: no file, or None when it has one."""
    return None if (SCENARIO_DIR / f"{scenario}.toml").exists() else f"no scenario file {scenario} yet"


def judge_b3(outcomes: list[Outcome]) -> Verdict:
    """Circle at the start, an ellipse at the gaps, a circle again at the end, in every mission of chapter 4."""
    parts, good = [], True
    for sc in ("ch4-a", "ch4-maze-50", "ch4-failures-50"):
        res = runs(outcomes, sc)
        if not res:
            continue
        n_ok = sum(
            bool(r.metrics.get("circle_start") and r.metrics.get("ellipse_seen") and r.metrics.get("final_circle"))
            for r in res
        )
        parts.append(f"{sc}: {n_ok}/{len(res)}")
        good = good and n_ok == len(res)
    if not parts:
        return no_runs(outcomes, "needs the chapter 4 cells")
    return "; ".join(parts), good, "runs that start a circle, become an ellipse and end a circle"


def judge_b4(outcomes: list[Outcome]) -> Verdict:
    res = runs(outcomes, "ch4-a")
    if not res:
        return no_runs(outcomes, "needs ch4-a")
    first = sum(r.metrics.get("formation_first") == "triangle" for r in res)
    other = sum(r.metrics.get("formation_at_narrowest") not in (None, "", "triangle") for r in res)
    t = values(res, "formation_change_s")
    seqs = sorted({str(r.metrics.get("formation_sequence")) for r in res})
    ours = (
        f"triangle first {first}/{len(res)}; another shape at the narrowest region {other}/{len(res)}; first "
        f"change {_f(float(np.median(t)) if len(t) else None)} s (median); e.g. {seqs[0]}"
    )
    return ours, first == len(res) and other == len(res), "the planner's formation (formation_plan)"


def judge_b5(outcomes: list[Outcome]) -> Verdict:
    parts, good = [], True
    for f in FAILURES:
        res = runs(outcomes, "ch4-failures-50", failures=f)
        if not res:
            continue
        th = THESIS_FAILURE_AREA[f]
        area, formula = mean(res, "final_area"), mean(res, "area_formula")
        area_ok = all(
            abs(r.metrics["final_area"] - th) <= AREA_TOL * th
            or abs(r.metrics["final_area"] - r.metrics["area_formula"]) <= FORMULA_TOL * th
            for r in res
            if r.metrics.get("final_area") is not None
        )
        detected = _every(res, lambda m: m.get("n_detected") == m.get("n_failed"))
        arrived = _every(res, lambda m: bool(m.get("arrived")))
        good = good and area_ok and detected and arrived and all(r.metrics.get("final_area") is not None for r in res)
        parts.append(
            f"{100 * f:g} %: area {_f(area)} (formula {_f(formula)}, thesis {th}), detected all "
            f"{'yes' if detected else 'no'}, arrived {sum(bool(r.metrics.get('arrived')) for r in res)}"
            f"/{len(res)}"
        )
    if not parts:
        return no_runs(outcomes, "needs the ch4-failures-50 cells")
    return "; ".join(parts), good, "every run"


def judge_b6(outcomes: list[Outcome]) -> Verdict:
    res = [r for r in runs(outcomes, "ch4-mover") if "mover_in_periods" in r.metrics]
    if not res:
        return no_runs(outcomes, "needs ch4-mover")
    n_in, n_out = (int(values(res, k).sum()) for k in ("mover_in_periods", "mover_out_periods"))
    h_in, h_out = (int(values(res, k).sum()) for k in ("blocked_mover_in", "blocked_mover_out"))
    rate_in = h_in / n_in if n_in else math.nan
    rate_out = h_out / n_out if n_out else math.nan
    crossed = sum(bool(r.metrics.get("crossed_with_mover_in")) for r in res)
    arrived = sum(bool(r.metrics.get("arrived")) for r in res)
    ours = (
        f"held 'gap blocked' in {_f(100 * rate_in, 1)} % of the periods with the mover in the gap, "
        f"{_f(100 * rate_out, 1)} % with it away ({h_in}/{n_in}, {h_out}/{n_out}); crossed with the mover in "
        f"the gap {crossed}/{len(res)}; arrived {arrived}/{len(res)}"
    )
    if not n_in or not n_out:
        return ours, None, "the mover never (or always) stood in the gap before the swarm passed"
    good = rate_in > 2 * rate_out and crossed == 0 and arrived == len(res)
    return ours, good, "before the region's centre passes the mover's line, pooled over the runs"


def _time_target(scenario: str, **cell: Any) -> Callable[[list[Outcome]], Verdict]:
    def judge(outcomes: list[Outcome]) -> Verdict:
        res = runs(outcomes, scenario, **cell)
        if not res:
            return no_runs(outcomes, missing(scenario) or f"needs {scenario}")
        t = values([r for r in res if r.metrics.get("arrived")], "arrival_s")
        th = THESIS_TIMES[scenario]
        if not len(t):
            return f"no arrival in {len(res)} runs", False, ""
        m = float(np.mean(t))
        good = abs(m - th) <= TIME_TOL * th and len(t) == len(res)
        return f"{_f(m, 1)} s (mean of {len(t)} arrivals of {len(res)} runs)", good, f"{_f(m / th)} x the thesis'"

    return judge


def judge_c4_cov(outcomes: list[Outcome]) -> Verdict:
    res = runs(outcomes, "ch4-maze-50")
    if not res:
        return no_runs(outcomes, "needs ch4-maze-50")
    cov = mean(res, "area_cov")
    sd, m = mean(res, "area_sd"), mean(res, "area_mean")
    good = abs(cov - THESIS_AREA_COV) <= COV_TOL * THESIS_AREA_COV
    return f"{_f(cov, 4)} (area {_f(m)} +- {_f(sd, 3)})", good, "mean over the runs of each run's COV"


def judge_c5_density(outcomes: list[Outcome]) -> Verdict:
    parts, good = [], True
    for sc in ("ch4-a", "ch4-maze-50"):
        res = [
            r
            for r in runs(outcomes, sc)
            if r.metrics.get("density_ellipse") is not None and r.metrics.get("density_circle") is not None
        ]
        if not res:
            continue
        e, c = mean(res, "density_ellipse"), mean(res, "density_circle")
        parts.append(f"{sc}: D {_f(e, 3)} in the ellipse, {_f(c, 3)} in the circle")
        good = good and e > c
    if not parts:
        return no_runs(outcomes, "needs runs with both an ellipse and a circle after the first 10 s")
    return "; ".join(parts), good, "D(t) eq. 4.50, means over the periods after 10 s; the ellipse = among obstacles"


def _by_n(outcomes: list[Outcome], metric: str, timing: bool = False) -> dict[float, np.ndarray]:
    """A metric's values (a timing's, with ``timing``) per agent count over the numerical trials that ran whole
    missions (a smoke run's own when it has only those, for its plots)."""
    done = [o for o in outcomes if o.result is not None and o.trial.cell.get("kind") == "numerical"]
    whole = [o for o in done if not o.trial.smoke] or done
    out: dict[float, list[float]] = {}
    for o in whole:
        n = o.result.metrics.get("n")
        v = (o.result.timings if timing else o.result.metrics).get(metric)
        if n is not None and v is not None:
            out.setdefault(float(n), []).append(float(v))
    return {k: np.asarray(v) for k, v in sorted(out.items())}


def _mean_timing(res: list[TrialResult], key: str) -> float:
    vals = [r.timings[key] for r in res if key in r.timings]
    return float(np.mean(vals)) if vals else math.nan


def exec_fit(outcomes: list[Outcome]) -> tuple[dict[float, np.ndarray], Any]:
    """Execution time (``exec_s``) per N and the least-squares line through the means (None with fewer than two
    distinct N)."""
    by_n = _by_n(outcomes, "exec_s", timing=True)
    if len(by_n) < 2:
        return by_n, None
    return by_n, linear_fit(list(by_n), [float(np.mean(v)) for v in by_n.values()])


@register
class RoyRegionsExperiment(Experiment):
    name = "roy-regions"
    title = "Roy ch.4-6: formation control by virtual regions"
    description = (
        "Chapters 4-6 (digest 001 §4.2-4.6) in the numerical model (bridge/studies/roy/regions_world.py): "
        "single-integrator point agents (eq. 4.1) in thesis units, dt 0.05 s, the planner every 0.25 s, each "
        "scenario a versioned look-alike of a lost map (hil_configs/roy/), its planner and parameters the file's "
        "(docs/roy-ch4.md: our resolutions, v_max 0.3 units/s frozen for chapter 4). Cells: ch4-a (6 agents, "
        "Table 4.1), ch4-maze-50 (50 agents, the scalable law), ch4-failures-50 at 5, 10 and 20 % actuator "
        "failures, ch4-mover (a circle sweeping across the first gap), ch5-a (14 agents, Table 5.1), ch6-case1..3 "
        "(Table 6.1) and chapter 6's scaling scenarios 1 (ch6-case2's map) and 2 (ch6-case3's) at N = 50-1000 "
        "(r_s scaled to keep N pi r_s^2). Each trial is one mission from its own seed (deployment, failing agents). "
        "timings.csv's exec_s is the wall-clock time of the planner, the world and the sonar casts (the thesis' "
        "execution time, erratum 29), plan_s the planner's part, cpu_s the mission's CPU seconds (C8's measure). "
        "Co-simulated cells (SonPI sessions): D1, D3-D5's region sessions (regions_cosim) and chapter 7's "
        "comparisons of the BAT approach with circle gathering and binary bat in cases 3 and 4 (regions_ch7, C11, "
        "C12; the methods share their deployments)."
    )
    trials = 20
    seed_ignores = ("method",)  # chapter 7's methods share their deployments: the comparisons are paired
    smoke_trials = 1
    boxes = (
        ("arrival_s", "arrival time (s)"),
        ("final_area", "final region area (unit^2)"),
        ("density_mean", "structural density D, mean over the mission"),
    )

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [c.cell() for c in CELLS] + regions_ch7.cells()

    def cell_trials(self, cell: dict[str, Any], n: int) -> int:
        if cell.get("kind") == regions_ch7.KIND:
            return min(n, regions_ch7.TRIALS)
        spec = next((c for c in CELLS if c.cell() == cell), None)
        return min(n, spec.max_trials) if spec is not None and spec.max_trials else n

    def run(self, trial: Trial) -> TrialResult:
        run_kind = SCENARIO_KINDS.get(trial.cell.get("kind"))
        if run_kind is None:
            raise ValueError(f"kind: no scenario kind {trial.cell.get('kind')!r}; known: {', '.join(SCENARIO_KINDS)}")
        return run_kind(trial.cell, trial)

    def targets(self) -> list[Target]:
        return [
            Target(
                "B3",
                "region: a circle in the open, an ellipse in gaps, a circle after the last obstacle",
                "a = b at the end of Figs. 4.10, 4.11",
                "every run",
                judge_b3,
            ),
            Target(
                "B4",
                "formation sequence, 6 agents: a triangle at the start, another shape in the corridor",
                "triangle, new shape 67.31 s, quadrilateral 118.48 s, pentagon at the goal",
                "every run",
                judge_b4,
            ),
            Target(
                "B5",
                "failures detected, area shrunk by (N - N')/N, the rest reach T",
                "final area 55.19 / 52.56 / 47.80 at 5 / 10 / 20 %",
                "every run: all detected, arrived, area within 2 % of the thesis' or = pi r_c^2 (N - N')/N",
                judge_b5,
            ),
            Target(
                "B6",
                "a mover in the gap: the AD test holds the region, no commitment until it passes",
                "AD(t2) < AD(t1): the gap not committed",
                "holds with the mover in the gap > 2 x the rate with it "
                "away; no crossing with the mover in the gap; every run arrives",
                judge_b6,
            ),
            Target(
                "B7",
                "at least N non-overlapping r_s circles in every polygon region; fallback packing",
                "lattice 6, trim-and-pack 8 (Fig. 5.7); UA minimal at minimal b_fs",
                "every update",
                judge_b7,
            ),
            Target(
                "B8",
                "iteration barrier: the region waits until every agent is in its circle",
                "holds",
                "every update",
                judge_b8,
            ),
            Target(
                "B9",
                "split iff >= 2 openings; sub-areas sum to the parent's; widest opening most agents",
                "Fig. 6.7",
                "every split",
                judge_b9,
            ),
            Target(
                "B10",
                "merge iff the next ellipses intersect; area = sum of the sub-areas; one leader",
                "Fig. 6.9",
                "every merge",
                judge_b10,
            ),
            Target(
                "B11",
                "movers in a lane: the sub-swarm's axes change, its area does not",
                "55-70 s, case 3",
                "area constant to 1e-9",
                judge_b11,
            ),
            Target(
                "B12",
                "D(t) low while converging, up after a split, down after a merge",
                "Figs. 6.8, 6.10",
                "the order of the changes",
                judge_b12,
            ),
            Target("C4-6", "6 agents reach T (ch4-a)", "171 s", "+-20 %", _time_target("ch4-a")),
            Target("C4-50", "50 agents through the maze (ch4-maze-50)", "150 s", "+-20 %", _time_target("ch4-maze-50")),
            Target(
                "C4-fail",
                "50 agents with failures (ch4-failures-50, 5/10/20 % pooled)",
                "250 s",
                "+-20 %",
                _time_target("ch4-failures-50"),
            ),
            Target(
                "C4-COV", "region area COV over the 50-agent mission", "0.019 (1.09 / 57.65)", "+-50 %", judge_c4_cov
            ),
            Target(
                "C5-TVI",
                "TVI toward 1 with N, above the aggregation baseline's",
                "Fig. 4.15 (no numbers)",
                "at every N",
                judge_c5_tvi,
            ),
            Target(
                "C5-D",
                "D(t) highest among obstacles",
                "Fig. 4.14 (no numbers)",
                "mean D in the ellipse > in the circle",
                judge_c5_density,
            ),
            Target(
                "C6",
                "14 agents reach T in the 50 x 50 map; 'all in circles' events",
                "250 s; 12, 29, 60.2, 94, 153.2 s",
                "+-20 %; the events' count and order",
                judge_c6,
            ),
            Target(
                "C7",
                "average structural density (eq. 6.25), falling with N",
                "0.55 (100), 0.60 (50); 0.43 / 0.40 (500 / 1000, sc. 1); 0.325 / 0.31 (sc. 2)",
                "+-0.1",
                judge_c7,
            ),
            Target(
                "C8",
                "execution time (compute) linear in N, dispersion falling",
                "0.444 s/agent, 5.56 s/agent, R^2 > 0.999",
                "the shape: R^2 > 0.99, COV falling",
                judge_c8,
            ),
            Target(
                "C9",
                "chapter 6 missions: split, merge, arrival times",
                "case 2: 10 / 45 / 60 s; case 1: 16 / 82 s; case 3: 35 / 85 s",
                "+-20 %",
                judge_c9,
            ),
            Target(
                "C10",
                "running time: centralised < vision L-F < proposed with L-F, at every N",
                "N = 6: 615 < 944 < 1029 s; N = 50: 150 < 192 < 250 s",
                "the ordering",
                judge_c10,
            ),
            Target(
                "C11",
                "against circle gathering in cases 3/4: faster everywhere, CG fails 4 robots high",
                "260 vs 451, 304 vs 612, 466 vs 1169 s",
                "every cell",
                regions_ch7.judge_c11,
            ),
            Target(
                "C12",
                "phase-wise FE at or below binary bat's; shorter missions",
                "304 vs 345 s, 575 vs 725 s",
                "every phase",
                regions_ch7.judge_c12,
            ),
            Target(
                "D1",
                "hardware analog: area COV with noise",
                "0.097 (3 robots), 0.02 (6); noiseless 0.022, 0.001",
                "COV within 50 %, above noiseless, falling with N",
                judge_d1,
            ),
            Target(
                "D3",
                "geometric region on SonPIs: goal times, lines in corridors",
                "3 robots 251 s; 6 robots 615 s",
                "+-20 % after the speed calibration on 3 robots; a line at the narrowest region",
                judge_d3,
            ),
            Target(
                "D4",
                "split/merge on SonPIs, 2-lane arena",
                "pre-split 3120 cm^2; overlap 220 s; goal 385 s; final 2400 cm^2; N = 4, 5, 6: 309.7 / 349.56 / "
                "386.77 s",
                "+-20 % after the speed calibration on N = 6",
                judge_d4,
            ),
            Target(
                "D5",
                "polygon region on SonPIs",
                "'all in circles' 42, 100 s; new boundary 112 s; goal 367 s",
                "+-20 % after the speed calibration on the goal",
                judge_d5,
            ),
        ]

    def sections(self, outcomes: list[Outcome]) -> list[str]:
        lines = [
            "",
            "## Chapter 4's missions, thesis beside ours",
            "",
            "Means over the runs (arrival: over the runs that arrived).",
            "",
            "| cell | runs | arrived | arrival thesis (s) | ours (s) | final area thesis | ours | formula | "
            "area COV | D mean | TVI | contacts | exec s |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for spec in CELLS:
            res = ok(outcomes, **spec.cell())
            if not res:
                continue
            arr = [r for r in res if r.metrics.get("arrived")]
            th_t = THESIS_TIMES.get(spec.scenario)
            th_a = (
                THESIS_FAILURE_AREA.get(spec.failures)
                if spec.failures is not None
                else (AREA_0 if spec.scenario == "ch4-maze-50" else None)
            )
            label = cell_label(spec.cell())
            lines.append(
                f"| {label} | {len(res)} | {len(arr)} | {th_t or '-'} | {_f(mean(arr, 'arrival_s'), 1)} | "
                f"{th_a or '-'} | {_f(mean(res, 'final_area'))} | {_f(mean(res, 'area_formula'))} | "
                f"{_f(mean(res, 'area_cov'), 4)} | {_f(mean(res, 'density_mean'), 3)} | {_f(mean(res, 'tvi'), 3)} | "
                f"{_f(mean(res, 'contacts'), 0)} | {_f(_mean_timing(res, 'exec_s'), 3)} |"
            )
        seqs = [
            (cell_label(o.trial.cell), o.trial.index, o.result.metrics)
            for o in outcomes
            if o.result is not None and o.result.metrics.get("formation_sequence") and o.trial.index < SEQUENCES_SHOWN
        ]
        if seqs:
            lines += [
                "",
                "## Formation sequences (the planner's, shape@time s)",
                "",
                f"The first {SEQUENCES_SHOWN} trials of each cell; every trial's in trials.csv "
                "(`formation_sequence`, `shapes_observed`).",
                "",
            ]
            lines += [
                f"- {label} trial {i}: {m['formation_sequence']}; the agents made: {m.get('shapes_observed') or '-'}"
                for label, i, m in seqs
            ]
        by_n, fit = exec_fit(outcomes)
        if by_n:
            lines += [
                "",
                "## Execution time against N (compute, not simulated time)",
                "",
                "| N | runs | mean (s) | sd | COV | simulated s (mean) |",
                "|---|---|---|---|---|---|",
            ]
            sims = _by_n(outcomes, "sim_s")
            for n, v in by_n.items():
                sd = float(np.std(v, ddof=1)) if len(v) > 1 else math.nan
                lines.append(
                    f"| {n:g} | {len(v)} | {_f(float(np.mean(v)), 3)} | {_f(sd, 3)} | "
                    f"{_f(sd / float(np.mean(v)), 3)} | {_f(float(np.mean(sims.get(n, [math.nan]))), 1)} |"
                )
            if fit is not None:
                lines += [
                    "",
                    f"Fit through the means: {fit.intercept:.4f} + {fit.slope:.5f} N s, R^2 {fit.r2:.4f} "
                    f"({fit.n} values of N).",
                ]
        return lines + regions_ch7.sections(outcomes)

    def figures(self, outcomes: list[Outcome], plots: Path) -> list[str]:
        """The region's area and axes per cell, the formation sequence, D(t) (one trial per cell each) and the
        execution time against N with its linear fit."""
        reps = representatives(outcomes)
        lines: list[str] = []
        for label, res in reps.items():
            if "area" in res.curves:
                lines += region_plot(label, res, plots / f"region-{file_name(label)}.png")
        form = {k: r for k, r in reps.items() if "formation" in r.curves}
        if form:
            lines += formation_plot(form, plots / "formations.png")
        dens = {k: r for k, r in reps.items() if "density" in r.curves}
        if dens:
            lines += density_plot(dens, plots / "density.png")
        by_n, fit = exec_fit(outcomes)
        if by_n:
            lines += exec_plot(by_n, fit, plots / "exec-time-vs-n.png")
        lines += ch6_figures(outcomes, plots)
        return lines


def cell_label(cell: dict[str, Any]) -> str:
    """A cell's name in tables and plots: its scenario, with its failure fraction when it sets one."""
    label = cell["scenario"] + (f" {100 * cell['failures']:g} %" if cell.get("failures") is not None else "")
    return label + (f" N={cell['agents']}" if cell.get("agents") is not None else "")


def representatives(outcomes: list[Outcome]) -> dict[str, TrialResult]:
    """One trial per cell for the time plots: the cell's lowest-numbered trial that ran, by the cell's label."""
    out: dict[str, tuple[int, TrialResult]] = {}
    for o in outcomes:
        label = cell_label(o.trial.cell)
        if o.result is not None and (label not in out or o.trial.index < out[label][0]):
            out[label] = (o.trial.index, o.result)
    return {k: v[1] for k, v in out.items()}
