"""``roy-apf``: chapter 3's simulation results (digest 001 §4.1, targets B1, B2, C1-C3 of §6) in the numerical
model (``bridge.studies.roy.numerical``): Table 3.4 (the gains' mean and sd), Table 3.5 (CI mean and COV, success,
path length) for BAT, PSO, BFO ("BG"), BGPSO, PSOABG and the fixed-gain baseline over seeded runs of
``roy-ch3-v2``, the formation in open space (B1), the gap (B2) and Table 3.6's scaling against circle-based
gathering (C3).

A cell names its ``kind`` of scenario: "numerical" (point agents, ``BatchSwarm``: one cell's trials stepped
together, each run's numbers its own) or "cosim" (``cosim``: sessions of SonPIs, chapter 7's hardware cases in a
"simulation" and a "hardware" profile, target D2; each trial one session). The methods share their deployments, and
a co-simulated case's two profiles too (``seed_ignores``): the comparisons are paired.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import mean, ok, pooled_mean_sd, values
from bridge.studies.roy import cosim
from bridge.studies.roy.numerical import SCENARIOS, TRACE, Ch3Run, Ch3Scenario, Swarm, ch3_batch, deploy
from swarm_logic.families.roy.gathering import CircleGathering

METHODS = ("bat", "pso", "bfo", "bgpso", "psoabg", "fixed")
NAMES = {"bat": "BAT", "pso": "PSO", "bfo": "BG (BFO)", "bgpso": "BGPSO", "psoabg": "PSOABG", "fixed": "fixed gains",
         "gathering": "circle gathering"}
GAINS = ("k_a", "k_v", "k_r", "k_oa")
# the BFO family at BAT's budget (Table 3.2's setting costs ~600 x BAT per step: see docs/roy.md)
BFO_BUDGET = {"bfo_bacteria": 20, "bfo_nre": 2, "bfo_ned": 1}
TABLE_3_4 = {  # (k_a, k_r, k_v, k_OA) mean, sd
    "bfo": ((8.8, 0.22), (8.97, 0.48), (0.36, 1.03), (0.19, 0.43)),
    "pso": ((3.03, 0.5), (4.95, 2.26), (1.05, 1.20), (4.6, 7.09)),
    "bat": ((4.4, 0.09), (6.64, 0.42), (0.31, 0.52), (2.5, 0.87)),
    "bgpso": ((3.8, 0.5), (2.75, 2.71), (2.41, 2.63), (6.37, 9.91)),
    "psoabg": ((8.02, 1.42), (8.20, 1.83), (0.99, 2.15), (1.68, 4.52)),
}
TABLE_3_5 = {  # CI mean, CI COV, success, path length
    "bfo": (0.97, 0.01, 0.52, 67.94), "pso": (0.57, 0.21, 1.0, 53.97), "bat": (0.95, 0.02, 0.993, 55.82),
    "bgpso": (0.53, 0.21, 1.0, 54.73), "psoabg": (0.82, 0.08, 0.985, 63.75),
}
TABLE_3_6 = {6: (357, 200), 12: (698, 386), 30: (1225, 812)}  # N: (gathering, BAT) s
SCALING_N = (6, 12, 30)
SCALING_TRIALS = {6: 20, 12: 6, 30: 2}  # the open-space cells cost ~N^2 per tick: fewer runs at large N
BFO_TRIALS = 100  # the BFO family's cells: as many runs as the others
GATHERING_TRIALS = 5  # gathering in roy-ch3-v2: its controllers run one by one (no batch), to the timeout
FORMED = 0.9  # B1: nearest-neighbour distances >= 2 r_s within 10 %
SMOKE_S = 20.0  # smoke runs: this much simulated time


def scenario(name: str, n: int) -> Ch3Scenario:
    """A named world: "roy-ch3-v2" (or another ``SCENARIOS`` layout) or "open" (its walls, start and target, no
    obstacle), with ``n`` agents; the timeout 3 x Table 3.6's BAT time for ``n`` (600 s at 6)."""
    base = SCENARIOS["roy-ch3-v2" if name == "open" else name].with_agents(n)
    if name == "open":
        base = replace(base, version="open", lines=(), movers=())
    return replace(base, timeout_s=3.0 * TABLE_3_6.get(n, (0, 200))[1])


def method_params(method: str) -> dict[str, Any]:
    """The controller's parameters for a method: ``RoyApf``'s defaults (Tables 3.1-3.3, our resolutions), the BFO
    family at BAT's budget."""
    if method in ("bfo", "bgpso", "psoabg"):
        return {"optimiser": method, **BFO_BUDGET}
    return {"optimiser": method}


def formation_metrics(run: Ch3Run, r_s: float = 1.0) -> dict[str, Any]:
    """B1 from the 1 s trace: when the nearest-neighbour distances first all reach ``FORMED`` x 2 r_s, the share of
    later samples (before arrival) that keep it, the last obstacle contact and whether the formation is whole again
    after it, and the gap (x + y = 40) passed or not."""
    tr = run.trace
    if not len(tr):
        return {}
    col = {k: i for i, k in enumerate(TRACE)}
    t, nn = tr[:, col["t"]], tr[:, col["nn_min"]]
    good = nn >= FORMED * 2 * r_s
    formed = np.flatnonzero(good)
    first = float(t[formed[0]]) if len(formed) else None
    kept = float(good[formed[0]:].mean()) if len(formed) else None
    oa = np.flatnonzero(tr[:, col["oa"]] > 0)
    last_oa = float(t[oa[-1]]) if len(oa) else None
    after = good[oa[-1] + 1:] if len(oa) else good
    side = tr[:, col["cx"]] + tr[:, col["cy"]]
    return {"formed_s": first, "formed_kept": kept, "last_contact_s": last_oa,
            "recovered": bool(after.any()) if len(oa) and len(after) else None,
            "nn_min_end": float(nn[-1]), "at_gap": bool((side >= 36.0).any()), "past_gap": bool((side >= 42.0).any())}


def run_metrics(run: Ch3Run) -> dict[str, Any]:
    """One run's trials.csv row: Table 3.5's figures, the gains' moments (Table 3.4), B1's and B2's."""
    m: dict[str, Any] = {"success": run.success, "mission_s": run.mission_s, "path_length": round(run.path_length, 4),
                         "ci_mean": run.ci_mean, "ci_cov": run.ci_cov, "collisions": run.collisions,
                         "sim_s": round(run.ticks * 0.05, 2), "pso_share": run.pso_share}
    n = run.gain_n
    for g, mu, sd in zip(GAINS, run.gain_mean, run.gain_std, strict=True):
        m[f"{g}_mean"] = float(mu)
        m[f"{g}_sd"] = float(sd * math.sqrt(n / (n - 1))) if n > 1 else 0.0  # the sample sd (``pooled_mean_sd``)
        m[f"{g}_n"] = n
    return {**m, **formation_metrics(run)}


def numerical_trials(cell: dict[str, Any], trials: list[Trial]) -> list[TrialResult]:
    """A cell's trials in the point model, stepped together; gathering runs through its controllers."""
    sc = scenario(cell["scenario"], int(cell["n"]))
    max_s = SMOKE_S if trials and trials[0].smoke else None
    if cell["method"] == "gathering":
        runs = [Swarm(sc, deploy(sc, t.seed), t.seed, {}, controller=CircleGathering).run(max_s) for t in trials]
    else:
        runs = ch3_batch([t.seed for t in trials], method_params(cell["method"]), sc, max_s)
    return [TrialResult(run_metrics(r)) for r in runs]


def cosim_trials(cell: dict[str, Any], trials: list[Trial]) -> list[TrialResult]:
    """A cell's sessions of SonPIs (``cosim``), one per trial, the deployment from the trial's seed (the same in
    both profiles); smoke runs stop at ``SMOKE_S``."""
    out = []
    for t in trials:
        wd = Path(t.workdir)
        wd.mkdir(parents=True, exist_ok=True)
        cfg = cosim.session_config(cell["scenario"], int(cell["n"]), cell["profile"], t.seed % (1 << 31), wd,
                                   SMOKE_S if t.smoke else None, method=cell["method"])
        out.append(TrialResult(cosim.session_metrics(cosim.run_session(cfg, wd))))
    return out


# the scenario kinds a cell can name, each a function running a cell's trials
SCENARIO_KINDS: dict[str, Callable[[dict[str, Any], list[Trial]], list[TrialResult]]] = {
    "numerical": numerical_trials,
    "cosim": cosim_trials,
}
COSIM_TRIALS = 5  # sessions per co-simulated cell
# chapter 7's hardware cases (Tables 7.1-7.3): (scenario, robots), the thesis' S/W and H/W time (s), FE mean (sd),
# path (S/W unit, H/W "cm": digest §4.5.1 doubts the unit)
COSIM_CASES = (("ch7-open", 3), ("ch7-static", 3), ("ch7-static", 4), ("ch7-moving-low", 4), ("ch7-moving-high", 4))
TABLES_7 = {
    ("ch7-open", 3): {"table": "7.1", "time": (35, 71), "fe": ((0.09, 0.01), (0.21, 0.05)), "path": (50.5, 51.2)},
    ("ch7-static", 3): {"table": "7.2", "time": (98, 249), "fe": ((0.13, 0.2), (0.25, 0.19)), "path": (51.82, 53.07)},
    ("ch7-static", 4): {"table": "7.2", "time": (100, 245), "fe": ((0.26, 0.2), (0.32, 0.21)), "path": (54.41, 57.93)},
    ("ch7-moving-low", 4): {"table": "7.3", "time": (None, 304), "fe": (None, (0.37, 0.25)), "path": (None, 62.11)},
    ("ch7-moving-high", 4): {"table": "7.3", "time": (None, 575), "fe": (None, (0.47, 0.41)), "path": (None, 69.5)},
}


def cosim_cell(outcomes: list[Outcome], scenario: str, n: int, profile: str) -> list[TrialResult]:
    return ok(outcomes, kind="cosim", scenario=scenario, n=n, profile=profile)


def _pct(x: float) -> str:
    return "-" if math.isnan(x) else f"{100 * x:.1f} %"


def _f(x: float, nd: int = 2) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{nd}f}"


def grid(outcomes: list[Outcome], method: str) -> list[TrialResult]:
    """A method's runs in roy-ch3-v2 with 6 agents."""
    return ok(outcomes, kind="numerical", scenario="roy-ch3-v2", n=6, method=method)


def table_3_5_row(res: list[TrialResult]) -> tuple[float, float, float, float]:
    """CI mean, CI COV, success rate, mean path length (of the runs that arrived, as the thesis' path of a mission)
    over a cell's runs."""
    paths = [r.metrics["path_length"] for r in res if r.metrics.get("success")]
    return (mean(res, "ci_mean"), mean(res, "ci_cov"), mean(res, "success"),
            float(np.mean(paths)) if paths else math.nan)


def ordering(vals: dict[str, float], reverse: bool) -> list[str]:
    return sorted(vals, key=lambda k: vals[k], reverse=reverse)


@register
class RoyApfExperiment(Experiment):
    name = "roy-apf"
    title = "Roy ch.3: potential-field formation control with metaheuristic gain tuning"
    description = (
        "Chapter 3's simulation (digest 001 §4.1) in the numerical model: 6 point double-integrator agents, "
        "RoyApf unchanged (eqs. 3.3-3.5, 3.20-3.22), every agent re-tuning its four gains at every 0.05 s step; "
        "scenario roy-ch3-v2 (ours: a baffle, a wall with a 3-unit gap, a moving circle; T = (35, 35)), "
        "random starts in [2, 8]^2, timeout 600 s. Our resolutions (docs/roy.md): eq. 3.21's bounded reading, "
        "the look-ahead objective over 1 s with the swarm's progress counted in full, a saturated target term, "
        "v_max = 0.25 unit/s (calibrated: BAT arrives near the thesis' 200 s). BAT 25 bats x 50 iterations, PSO "
        "Table 3.1 (50 x 50), the BFO family (BG, BGPSO, PSOABG) at BAT's budget (20 bacteria, N_re 2, N_ed 1; the "
        "rest Table 3.2); fixed = Table 3.4's BAT means. The methods share their deployments (paired). Open-space "
        "cells: the same world without obstacles (B1, and C3 against circle-based gathering at 6, 12, 30 agents). "
        "Gains: mean and sd over all agents and steps of all runs (Table 3.4); CI, success and path: Table 3.5's "
        "definitions (§5.5)."
    )
    trials = 100
    smoke_trials = 2
    batch = 50
    seed_ignores = ("method", "profile")
    boxes = (("mission_s", "mission time (s)"), ("path_length", "mean path length (unit)"),
             ("ci_mean", "cohesion index, mean over the run"))

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        main = [{"kind": "numerical", "scenario": "roy-ch3-v2", "n": 6, "method": m} for m in METHODS]
        main.append({"kind": "numerical", "scenario": "roy-ch3-v2", "n": 6, "method": "gathering"})
        sizes = SCALING_N[:1] if smoke else SCALING_N
        scaling = [{"kind": "numerical", "scenario": "open", "n": n, "method": m} for n in sizes
                   for m in ("bat", "gathering")]
        hardware = [{"kind": "cosim", "scenario": sc, "n": n, "method": "bat", "profile": p}
                    for sc, n in (COSIM_CASES[:1] if smoke else COSIM_CASES) for p in cosim.PROFILES]
        return main + scaling + hardware

    def cell_trials(self, cell: dict[str, Any], n: int) -> int:
        if cell["kind"] == "cosim":
            return min(n, COSIM_TRIALS)
        if cell["scenario"] == "open":
            return min(n, SCALING_TRIALS[int(cell["n"])])
        if cell["method"] == "gathering":
            return min(n, GATHERING_TRIALS)
        if cell["method"] in ("bfo", "bgpso", "psoabg"):
            return min(n, BFO_TRIALS)
        return n

    def cell_batch(self, cell: dict[str, Any]) -> int:
        return 1 if cell["kind"] == "cosim" else self.batch  # sessions spread over the workers

    def run(self, trial: Trial) -> TrialResult:
        return self.run_batch([trial])[0]

    def run_batch(self, trials: list[Trial]) -> list[TrialResult]:
        cell = trials[0].cell
        if cell.get("kind") not in SCENARIO_KINDS:
            raise ValueError(f"kind: no scenario kind {cell.get('kind')!r}; known: {', '.join(SCENARIO_KINDS)}")
        return SCENARIO_KINDS[cell["kind"]](cell, trials)

    def targets(self) -> list[Target]:
        return [
            Target("cal", "BAT's mission time (v_max calibration, §5.3)", "200 s", "+-20 %", self._calibration),
            Target("B1", "formation without obstacles: nearest neighbours >= 2 r_s (-10 %), kept; recovered after "
                   "the obstacles", "pentagon at 15.5 s, again at 149.21 s", "every run", self._b1),
            Target("B2", "BG deadlocks in a gap narrower than its formation, PSOABG passes", "BG 52 %, PSOABG "
                   "98.5 % success", "BG passes the gap less often than PSOABG by >= 20 points; PSOABG >= 90 %",
                   self._b2),
            Target("C1-success", "success rate ordering", "BG 52 < PSOABG 98.5 < BAT 99.3 <= PSO = BGPSO 100 %",
                   "ordering; +-10 points", lambda o: self._c1(o, 2, "success")),
            Target("C1-path", "mean path length ordering", "PSO 53.97 < BGPSO 54.73 < BAT 55.82 < PSOABG 63.75 < "
                   "BG 67.94", "ordering; +-15 %", lambda o: self._c1(o, 3, "path")),
            Target("C1-CI", "CI mean ordering", "BG 0.97 > BAT 0.95 > PSOABG 0.82 > PSO 0.57 > BGPSO 0.53",
                   "ordering; +-0.10", lambda o: self._c1(o, 0, "ci")),
            Target("C1-COV", "CI COV ordering", "BG 0.01, BAT 0.02 < PSOABG 0.08 < PSO = BGPSO 0.21",
                   "ordering (ties as printed)", lambda o: self._c1(o, 1, "cov")),
            Target("C2", "gain spreads (Table 3.4)", "BAT's k_a, k_r sd smallest; BG's k_OA mean << its k_a, k_r; "
                   "PSO, BGPSO largest k_OA sd", "all three", self._c2),
            Target("C3", "mission time vs N against circle gathering (Table 3.6)", "BAT 200/386/812 s, gathering "
                   "357/698/1225 s", "BAT faster at every N; BAT's 30/6 ratio < 5", self._c3),
            Target("D2-FE", "SonPIs: formation error (eq. 7.1) hardware > simulation (Tables 7.1, 7.2)",
                   "3 robots open 0.21 vs 0.09; static 3 robots 0.25 vs 0.13, 4 robots 0.32 vs 0.26",
                   "hardware's mean FE above simulation's in every case", _d2_fe),
            Target("D2-time", "SonPIs: hardware missions longer than simulation's (Tables 7.1, 7.2)",
                   "x 2.0 (71/35), 2.5 (249/98), 2.5 (245/100)", "ratio of mean mission times 1.5-3 in every case",
                   _d2_time),
            Target("D2-dyn", "SonPIs, hardware: low < high complexity in time, FE and path (Table 7.3)",
                   "304 < 575 s, FE 0.37 < 0.47, path 62.11 < 69.5", "all three orderings", _d2_dyn),
        ]

    @staticmethod
    def _calibration(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        res = grid(outcomes, "bat")
        t = values(res, "mission_s")
        if not len(t):
            return "no arrival", None if not res else False, f"{len(res)} runs"
        m = float(np.mean(t))
        return f"{m:.0f} s (median {np.median(t):.0f}, {len(t)} arrivals)", abs(m - 200) <= 40, "mean over arrivals"

    @staticmethod
    def _b1(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        open_ = ok(outcomes, scenario="open", n=6, method="bat")
        main = grid(outcomes, "bat")
        if not open_ and not main:
            return "no runs", None, ""
        formed = values(open_, "formed_kept")
        when = values(open_, "formed_s")
        rec = [r.metrics.get("recovered") for r in main if r.metrics.get("recovered") is not None]
        ours = (f"open space: formed in {len(formed)}/{len(open_)} runs (median at {_f(np.median(when), 1)} s), "
                f"kept {_pct(float(np.mean(formed)) if len(formed) else math.nan)} of the later samples; "
                f"roy-ch3-v2: recovered after the last contact in {sum(rec)}/{len(rec)}")
        good = len(formed) == len(open_) and (not len(formed) or float(np.min(formed)) >= 0.9) and all(rec)
        return ours, bool(good) if open_ else None, "the thesis shows one run (figures)"

    @staticmethod
    def _b2(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        bg, pa = grid(outcomes, "bfo"), grid(outcomes, "psoabg")
        if not bg or not pa:
            return "no runs", None, ""
        bg_pass, pa_pass = mean(bg, "past_gap"), mean(pa, "past_gap")
        bg_stuck = mean([r for r in bg if r.metrics.get("at_gap")], "past_gap")
        ours = (f"past the gap: BG {_pct(bg_pass)}, PSOABG {_pct(pa_pass)} (PSO share of PSOABG's steps "
                f"{_pct(mean(pa, 'pso_share'))}); BG runs that reached the gap and passed it: {_pct(bg_stuck)}")
        return ours, bool(pa_pass - bg_pass >= 0.2 and pa_pass >= 0.9), ""

    @staticmethod
    def _c1(outcomes: list[Outcome], col: int, what: str) -> tuple[str, bool | None, str]:
        rows = {m: table_3_5_row(grid(outcomes, m)) for m in TABLE_3_5 if grid(outcomes, m)}
        if len(rows) < 2:
            return "no runs", None, ""
        ours = {m: r[col] for m, r in rows.items()}
        thesis = {m: TABLE_3_5[m][col] for m in rows}
        fmt = {2: _pct, 3: lambda x: _f(x, 1)}.get(col, _f)
        text = ", ".join(f"{NAMES[m]} {fmt(ours[m])}" for m in ordering(ours, col in (0,)))
        if any(math.isnan(v) for v in ours.values()):
            return text, False, "a method has no value (no arrival)"
        if what == "success":
            order_ok = all(ours["bfo"] <= ours[m] for m in ours if m != "bfo") if "bfo" in ours else True
            mag = all(abs(ours[m] - thesis[m]) <= 0.10 for m in ours)
        elif what == "path":
            order_ok = ordering(ours, False) == ordering(thesis, False)
            mag = all(abs(ours[m] - thesis[m]) <= 0.15 * thesis[m] for m in ours)
        elif what == "ci":
            order_ok = ordering(ours, True) == ordering(thesis, True)
            mag = all(abs(ours[m] - thesis[m]) <= 0.10 for m in ours)
        else:
            low = [m for m in ("bfo", "bat") if m in ours]
            high = [m for m in ("pso", "bgpso") if m in ours]
            order_ok = all(ours[a] < ours[b] for a in low for b in high) and (
                "psoabg" not in ours or all(ours[a] < ours["psoabg"] < ours[b] for a in low for b in high))
            mag = True
        return text, bool(order_ok and mag), f"ordering {'holds' if order_ok else 'differs'}; magnitudes " \
                                             f"{'within' if mag else 'outside'} the tolerance"

    @staticmethod
    def _c2(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        stats = {m: {g: pooled_mean_sd(grid(outcomes, m), g) for g in GAINS} for m in TABLE_3_4 if grid(outcomes, m)}
        if "bat" not in stats:
            return "no runs", None, ""
        sd = {m: {g: s[g][1] for g in GAINS} for m, s in stats.items()}
        bat_smallest = all(sd["bat"][g] <= min(sd[m][g] for m in sd) for g in ("k_a", "k_r"))
        bg = stats.get("bfo")
        bg_low = bg is not None and bg["k_oa"][0] < 0.5 * min(bg["k_a"][0], bg["k_r"][0])
        others = [m for m in sd if m not in ("pso", "bgpso")]
        pso_wide = all(m in sd for m in ("pso", "bgpso")) and min(sd["pso"]["k_oa"], sd["bgpso"]["k_oa"]) >= max(
            sd[m]["k_oa"] for m in others)
        ours = (f"BAT k_a sd {_f(sd['bat']['k_a'])}, k_r sd {_f(sd['bat']['k_r'])} (smallest: "
                f"{'yes' if bat_smallest else 'no'}); BG k_OA mean "
                f"{_f(bg['k_oa'][0]) if bg else '-'} vs k_a {_f(bg['k_a'][0]) if bg else '-'}; PSO/BGPSO largest "
                f"k_OA sd: {'yes' if pso_wide else 'no'}")
        return ours, bool(bat_smallest and bg_low and pso_wide), "see the Table 3.4 comparison below"

    @staticmethod
    def _c3(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        rows = []
        faster, have = True, {}
        for n in SCALING_N:
            b = values(ok(outcomes, scenario="open", n=n, method="bat"), "mission_s")
            g = values(ok(outcomes, scenario="open", n=n, method="gathering"), "mission_s")
            if not len(b) and not len(g):
                continue
            bm, gm = (float(np.mean(b)) if len(b) else math.nan), (float(np.mean(g)) if len(g) else math.nan)
            have[n] = bm
            faster = faster and not math.isnan(bm) and (math.isnan(gm) or bm < gm)
            rows.append(f"N={n}: BAT {_f(bm, 0)} s, gathering {_f(gm, 0)} s")
        if not rows:
            return "no runs", None, ""
        sub = 30 in have and 6 in have and have[30] / have[6] < 5
        return "; ".join(rows), bool(faster and (sub or 30 not in have)), "open space, means over arrivals"

    def sections(self, outcomes: list[Outcome]) -> list[str]:
        lines = ["", "## Table 3.4: gains (mean / sd over all agents, steps and runs), thesis beside ours", "",
                 "| method | k_a thesis | k_a ours | k_r thesis | k_r ours | k_v thesis | k_v ours | k_OA thesis | "
                 "k_OA ours |", "|---|---|---|---|---|---|---|---|---|"]
        order = ("k_a", "k_r", "k_v", "k_oa")
        for m in ("bfo", "pso", "bat", "bgpso", "psoabg", "fixed"):
            res = grid(outcomes, m)
            if not res:
                continue
            cells = []
            for k, g in enumerate(order):
                th = TABLE_3_4.get(m)
                mu, sd, _ = pooled_mean_sd(res, g)
                cells += [f"{th[k][0]} / {th[k][1]}" if th else "-", f"{mu:.2f} / {sd:.2f}"]
            lines.append(f"| {NAMES[m]} | " + " | ".join(cells) + " |")
        lines += ["", "## Table 3.5: cohesion, success, path, thesis beside ours", "",
                  "| method | runs | CI mean thesis | ours | CI COV thesis | ours | success thesis | ours | "
                  "path thesis | ours (arrivals) | mission time (s, arrivals) | collisions (mean) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for m in (*METHODS, "gathering"):
            res = grid(outcomes, m)
            if not res:
                continue
            ci, cov, succ, path = table_3_5_row(res)
            th = TABLE_3_5.get(m)
            t = values(res, "mission_s")
            lines.append(f"| {NAMES[m]} | {len(res)} | {th[0] if th else '-'} | {_f(ci)} | {th[1] if th else '-'} | "
                         f"{_f(cov, 3)} | {_pct(th[2]) if th else '-'} | {_pct(succ)} | {th[3] if th else '-'} | "
                         f"{_f(path, 1)} | {_f(float(np.mean(t)), 0) if len(t) else '-'} | "
                         f"{_f(mean(res, 'collisions'), 1)} |")
        lines += ["", "## Table 3.6: mission time against agent count (open space), thesis beside ours", "",
                  "| N | gathering thesis | gathering ours (runs, arrivals) | BAT thesis | BAT ours (runs, arrivals) |",
                  "|---|---|---|---|---|"]
        for n in SCALING_N:
            cells = []
            for m in ("gathering", "bat"):
                res = ok(outcomes, scenario="open", n=n, method=m)
                t = values(res, "mission_s")
                cells.append(f"{_f(float(np.mean(t)), 0) if len(t) else '-'} ({len(res)}, {len(t)})")
            if any(not c.startswith("- (0") for c in cells):
                lines.append(f"| {n} | {TABLE_3_6[n][0]} | {cells[0]} | {TABLE_3_6[n][1]} | {cells[1]} |")
        return lines + cosim_sections(outcomes)


# -- the co-simulated hardware cases (target D2) --------------------------------------------------------------------
def _cosim_means(res: list[TrialResult]) -> dict[str, float]:
    """A cell's means: mission time and path over the arrivals, FE (the runs' mission means, and their sd's mean)."""
    arr = [r for r in res if r.metrics.get("success")]
    return {"time": mean(arr, "mission_s"), "fe": mean(res, "fe_mean"), "fe_sd": mean(res, "fe_sd"),
            "path": mean(arr, "path_m"), "success": mean(res, "success"), "n": len(res), "arrived": len(arr)}


def _cases(outcomes: list[Outcome]) -> dict[tuple[str, int], dict[str, dict[str, float]]]:
    out = {}
    for sc, n in COSIM_CASES:
        cells = {p: _cosim_means(cosim_cell(outcomes, sc, n, p)) for p in cosim.PROFILES}
        if any(c["n"] for c in cells.values()):
            out[(sc, n)] = cells
    return out


def _d2_fe(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    cases = {k: v for k, v in _cases(outcomes).items() if TABLES_7[k]["fe"][0] is not None}
    both = {k: v for k, v in cases.items() if v["simulation"]["n"] and v["hardware"]["n"]}
    if not both:
        return "no runs", None, ""
    text = "; ".join(f"{sc} N={n}: {_f(v['hardware']['fe'])} vs {_f(v['simulation']['fe'])}"
                     for (sc, n), v in both.items())
    return text, all(v["hardware"]["fe"] > v["simulation"]["fe"] for v in both.values()), "hardware vs simulation"


def _d2_time(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    cases = {k: v for k, v in _cases(outcomes).items() if TABLES_7[k]["time"][0] is not None}
    both = {k: v for k, v in cases.items() if v["simulation"]["n"] and v["hardware"]["n"]}
    if not both:
        return "no runs", None, ""
    ratios = {k: v["hardware"]["time"] / v["simulation"]["time"] for k, v in both.items()}
    text = "; ".join(f"{sc} N={n}: x {_f(r)} ({_f(both[(sc, n)]['hardware']['time'], 0)} / "
                     f"{_f(both[(sc, n)]['simulation']['time'], 0)} s)" for (sc, n), r in ratios.items())
    if all(math.isnan(r) for r in ratios.values()):
        return text, None, "no case arrived in both profiles"
    good = all(not math.isnan(r) and 1.5 <= r <= 3.0 for r in ratios.values())
    return text, good, "means over the arrivals; a case without arrivals in a profile fails"


def _d2_dyn(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    cases = _cases(outcomes)
    lo, hi = cases.get(("ch7-moving-low", 4)), cases.get(("ch7-moving-high", 4))
    if not lo or not hi or not lo["hardware"]["n"] or not hi["hardware"]["n"]:
        return "no runs", None, ""
    a, b = lo["hardware"], hi["hardware"]
    text = (f"time {_f(a['time'], 0)} vs {_f(b['time'], 0)} s, FE {_f(a['fe'])} vs {_f(b['fe'])}, path "
            f"{_f(100 * a['path'], 1)} vs {_f(100 * b['path'], 1)} cm (arrivals {a['arrived']}/{a['n']}, "
            f"{b['arrived']}/{b['n']})")
    return text, bool(a["time"] < b["time"] and a["fe"] < b["fe"] and a["path"] < b["path"]), "hardware profile"


def _th(v: Any, nd: int = 2) -> str:
    return "-" if v is None else (f"{v[0]} +- {v[1]}" if isinstance(v, tuple) else f"{v:g}" if nd else f"{v}")


def cosim_sections(outcomes: list[Outcome]) -> list[str]:
    """Tables 7.1-7.3 with ours beside, the localisation's and the sonars' errors, the runs that did not arrive."""
    cases = _cases(outcomes)
    if not cases:
        return []
    lines = ["", "## Tables 7.1-7.3: SonPIs in co-simulation, thesis beside ours", "",
             "Ours: sessions of SonPIs (`bridge/studies/roy/cosim.py`), the thesis' S/W column beside our "
             "\"simulation\" profile, its H/W column beside our \"hardware\" profile. Time and path: means over the "
             "sessions that arrived; FE: the mean over sessions of each session's mean over its mission (1 s samples), "
             "and the mean of their sd's. Paths: the thesis' S/W in units, H/W in \"cm\" (the digest doubts that "
             "unit); ours in units of 0.1 m and in cm.", "",
             "| table | case | N | time S/W thesis | ours sim (arrived/runs) | time H/W thesis | "
             "ours hw (arrived/runs) | hw/sim | FE S/W thesis | ours sim | FE H/W thesis | ours hw | "
             "path S/W thesis | ours sim (unit) | path H/W thesis | ours hw (cm) |", "|" + "---|" * 16]
    for (sc, n), v in cases.items():
        th = TABLES_7[(sc, n)]
        s, h = v["simulation"], v["hardware"]
        ratio = h["time"] / s["time"] if s["n"] and h["n"] else math.nan
        lines.append(
            f"| {th['table']} | {sc} | {n} | {_th(th['time'][0])} | {_f(s['time'], 0)} ({s['arrived']}/{s['n']}) | "
            f"{_th(th['time'][1])} | {_f(h['time'], 0)} ({h['arrived']}/{h['n']}) | {_f(ratio)} | "
            f"{_th(th['fe'][0])} | {_f(s['fe'])} +- {_f(s['fe_sd'])} | {_th(th['fe'][1])} | "
            f"{_f(h['fe'])} +- {_f(h['fe_sd'])} | {_th(th['path'][0])} | {_f(10 * s['path'], 1)} | "
            f"{_th(th['path'][1])} | {_f(100 * h['path'], 1)} |")
    lines += ["", "## Localisation and sonars per cell (means over the sessions)", "",
              "Broadcast: the poses the robots got (the camera's fix fused with odometry, or the exact pose in the "
              "simulation profile), against the ground truth at the frame; fix: the camera's own, before the "
              "comparator. Sonar: each board's 250 ms windows' nearest echo against the nearest true surface "
              "(`per_robot[].firmware.arduino.sonar_windows`).", "",
              "| case | N | profile | broadcast error mm (p95) | heading deg | fix error mm | fix heading deg | "
              "frames without pose | sonar Hz | sonar mean error mm | RMS mm | valid | Wi-Fi lost / sent | "
              "closest pair m | sim s per session | CPU s per session |", "|" + "---|" * 16]
    for (sc, n), _v in cases.items():
        for p in cosim.PROFILES:
            res = cosim_cell(outcomes, sc, n, p)
            if not res:
                continue
            lines.append(
                f"| {sc} | {n} | {p} | {_f(mean(res, 'loc_err_mm'))} ({_f(mean(res, 'loc_err_p95_mm'))}) | "
                f"{_f(mean(res, 'loc_head_deg'))} | {_f(mean(res, 'fix_err_mm'))} | {_f(mean(res, 'fix_head_deg'))} | "
                f"{_f(mean(res, 'frames_without_pose'), 1)} | {_f(mean(res, 'sonar_hz'), 1)} | "
                f"{_f(mean(res, 'sonar_err_mm'))} | {_f(mean(res, 'sonar_rms_mm'))} | "
                f"{_f(mean(res, 'sonar_valid'), 3)} | "
                f"{_f(mean(res, 'wifi_lost'), 0)} / {_f(mean(res, 'wifi_sent'), 0)} | {_f(mean(res, 'nn_min_m'), 3)} | "
                f"{_f(mean(res, 'sim_s'), 0)} | {_f(mean(res, 'cpu_s'), 0)} |")
    lines += ["", "## The formation error's parts per cell", "",
              "FE = the share of robot pairs closer than 2 r_s + the share farther than 3 r_s (means over each "
              "session's mission, then over the sessions).", "",
              "| case | N | profile | FE | pairs < 2 r_s | pairs > 3 r_s | closest pair (m, mean of the sessions' "
              "minima) |", "|---|---|---|---|---|---|---|"]
    for (sc, n), _v in cases.items():
        for p in cosim.PROFILES:
            res = cosim_cell(outcomes, sc, n, p)
            if res:
                lines.append(f"| {sc} | {n} | {p} | {_f(mean(res, 'fe_mean'))} | {_f(mean(res, 'fe_close'))} | "
                             f"{_f(mean(res, 'fe_far'))} | {_f(mean(res, 'nn_min_m'), 3)} |")
    missed = [(o.trial, o.result) for o in outcomes if o.trial.cell.get("kind") == "cosim"
              and (o.result is None or not o.result.metrics.get("success"))]
    lines += ["", "## Sessions that did not arrive", ""]
    if not missed:
        lines.append("None: every session's swarm reached T.")
    for t, r in missed:
        c = t.cell
        what = ("raised (see the errors above)" if r is None else
                f"ended at {_f(r.metrics.get('sim_s'), 0)} s without arriving; FE {_f(r.metrics.get('fe_mean'))}, "
                f"path {_f(r.metrics.get('path_m'))} m, closest pair {_f(r.metrics.get('nn_min_m'), 3)} m, "
                f"{r.metrics.get('alive')} robots alive")
        lines.append(f"- {c['scenario']} N={c['n']} {c['profile']}, trial {t.index} (seed {t.seed}): {what}")
    return lines
