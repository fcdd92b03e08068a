"""Chapter 7's comparisons of the BAT approach on SonPIs (C11, C12; digest 001 §4.5.1, Tables 7.4 and 7.5): chapter
3's method (``roy_apf``, BAT) against circle gathering (``roy_gathering``, Sharma et al. 2017) and against the binary
cooperative bat algorithm (``roy_apf`` with ``optimiser = "binary_bat"``, Zhang 2020) in the dynamic cases 3 (low
complexity: one toy car) and 4 (high: two walls, three cars), in co-simulation with the hardware profile (the tables
are the thesis' hardware runs).

The sessions are ``cosim.py``'s cases (350 x 175 cm, r_s 11.3 cm, the robots deployed from the seed in the west end,
the same deployment for every method: ``seed_ignores``), scored by the study's loop functions from the true poses:
mission time, eq. 7.1's formation error, path, and the FE and duration of each of the case's route phases (Table 7.5's
"before changing initial formation", "avoiding the 1st moving obstacle", ...: ``cosim.CASES[..].phases``).

C11 (Table 7.4): the proposed method is faster than circle gathering in every cell (case 3 and 4, N = 3 and 4),
circle gathering keeps the lower FE in case 3, and it fails (never arrives) with 4 robots in case 4.
C12 (Table 7.5, 4 robots): the proposed method's phase FE at or below binary bat's in every phase but the first
(about equal there) and its mission shorter in both cases.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from bridge.experiments.runner import Outcome, Trial, TrialResult
from bridge.experiments.stats import mean, mean_pm_sd, values
from bridge.studies.roy import cosim
from bridge.studies.roy.regions_judging import Verdict, fmt, no_runs, whole

KIND = "ch7"
PROFILE = "hardware"
PROPOSED, CG, BINARY_BAT = "bat", cosim.GATHERING, "binary_bat"
METHOD_NAMES = {PROPOSED: "proposed (BAT)", CG: "circle gathering", BINARY_BAT: "binary bat"}
CASES = {"ch7-moving-low": "low", "ch7-moving-high": "high"}  # case -> Table 7.4's environment complexity
C11_N = (3, 4)
C12_N = 4
TRIALS = 3  # sessions per cell (a case-4 session that never arrives runs 360 s of simulated time)
SMOKE_S = 10.0  # smoke trials: this much simulated time (the first phase of every case lasts longer)
FIRST_PHASE_TOL = 0.05  # C12: "about equal" FE before the initial formation changes (0.37 vs 0.36, 0.28 vs 0.30)

# Table 7.4: (case, N) -> CG (time s, FE mean, sd, path), proposed (time s, FE mean, sd, path); None: CG failed
TABLE_7_4: dict[tuple[str, int], tuple[tuple[float, float, float, float] | None, tuple[float, float, float, float]]] = {
    ("ch7-moving-low", 3): ((451, 0.10, 0.05, 60.03), (260, 0.27, 0.22, 59.27)),
    ("ch7-moving-low", 4): ((612, 0.17, 0.12, 61.85), (304, 0.37, 0.25, 62.11)),
    ("ch7-moving-high", 3): ((1169, 0.22, 0.04, 68.34), (466, 0.37, 0.32, 67.03)),
    ("ch7-moving-high", 4): (None, (575, 0.47, 0.41, 69.5)),
}
# Table 7.5 (4 robots): case -> per phase (FE binary bat mean, sd, FE proposed mean, sd); total durations (s)
TABLE_7_5_FE = {
    "ch7-moving-low": ((0.36, 0.21, 0.37, 0.20), (0.59, 0.30, 0.52, 0.27), (0.25, 0.10, 0.18, 0.05)),
    "ch7-moving-high": ((0.30, 0.27, 0.28, 0.25), (0.79, 0.20, 0.73, 0.26), (0.57, 0.31, 0.45, 0.22),
                        (0.24, 0.19, 0.13, 0.049)),
}
TABLE_7_5_S = {"ch7-moving-low": (345.0, 304.0), "ch7-moving-high": (725.0, 575.0)}  # (binary bat, proposed)


def cells() -> list[dict[str, Any]]:
    """C11's cells (both cases, N = 3 and 4, proposed and circle gathering) and C12's binary bat at N = 4."""
    out = [{"kind": KIND, "scenario": c, "agents": n, "method": m}
           for c in CASES for n in C11_N for m in (PROPOSED, CG)]
    return out + [{"kind": KIND, "scenario": c, "agents": C12_N, "method": BINARY_BAT} for c in CASES]


def trial(cell: dict[str, Any], t: Trial) -> TrialResult:
    """One session of the cell's case, method and robots in the hardware profile (``SMOKE_S`` of it when smoke)."""
    wd = Path(t.workdir)
    wd.mkdir(parents=True, exist_ok=True)
    cfg = cosim.session_config(cell["scenario"], int(cell["agents"]), PROFILE, t.seed % (1 << 31), wd,
                               SMOKE_S if t.smoke else None, method=cell["method"])
    s = cosim.run_session(cfg, wd)
    m = cosim.session_metrics(s)
    timings = {"session_wall_s": float(s["wall_time_s"]), "cpu_s": float(m.pop("cpu_s") or 0.0)}
    m.pop("rtf", None)  # wall-clock figures belong in timings.csv
    return TrialResult(m, timings=timings)


# -- judging ---------------------------------------------------------------------------------------------------------


def runs(outcomes: list[Outcome], case: str, n: int, method: str) -> list[TrialResult]:
    return whole(outcomes, case, kind=KIND, agents=n, method=method)


def mission(res: list[TrialResult]) -> tuple[float, int]:
    """The mean mission time with a run that never arrived counted at its session's end (a lower bound on its time),
    and how many arrived."""
    t = [float(r.metrics["mission_s"]) if r.metrics.get("success") else float(r.metrics["sim_s"]) for r in res]
    return (float(np.mean(t)) if t else math.nan), sum(bool(r.metrics.get("success")) for r in res)


def _time(res: list[TrialResult]) -> str:
    t, k = mission(res)
    return f"{'>=' if k < len(res) else ''}{fmt(t, 0)} s ({k}/{len(res)})"


def judge_c11(outcomes: list[Outcome]) -> Verdict:
    """Proposed faster than CG in every (case, N); CG's FE lower in case 3; CG never arrives with 4 robots in case 4."""
    parts, good = [], True
    for (case, n), _ in TABLE_7_4.items():
        p, g = runs(outcomes, case, n, PROPOSED), runs(outcomes, case, n, CG)
        if not p or not g:
            return no_runs(outcomes, f"needs both methods' sessions in {case} N={n}",
                           f"smoke run: the sessions stop at {SMOKE_S:g} s")
        (tp, kp), (tg, _kg) = mission(p), mission(g)
        faster = kp > 0 and tp < tg
        text = f"{CASES[case]} N={n}: time {_time(p)} vs CG {_time(g)}"
        good &= faster
        if CASES[case] == "low":
            fp, fg = mean(p, "fe_mean"), mean(g, "fe_mean")
            text += f", FE {fmt(fp)} vs CG {fmt(fg)}"
            good &= fg < fp
        if (case, n) == ("ch7-moving-high", 4):
            good &= not any(r.metrics.get("success") for r in g)
        parts.append(text)
    return "; ".join(parts), good, ("times: means with a run that never arrived counted at its session's end (>=), "
                                    "arrivals k/n; CG must arrive in no high N=4 run")


def judge_c12(outcomes: list[Outcome]) -> Verdict:
    """Per case (4 robots): the proposed method's phase FE <= binary bat's in every phase but the first (within
    ``FIRST_PHASE_TOL`` there), and its mission shorter."""
    parts, good = [], True
    for case, phases in TABLE_7_5_FE.items():
        p, b = runs(outcomes, case, C12_N, PROPOSED), runs(outcomes, case, C12_N, BINARY_BAT)
        if not p or not b:
            return no_runs(outcomes, f"needs both methods' sessions in {case} N={C12_N}",
                           f"smoke run: the sessions stop at {SMOKE_S:g} s")
        fe = []
        for k in range(1, len(phases) + 1):
            fp, fb = mean(p, f"ph{k}_fe"), mean(b, f"ph{k}_fe")
            fe.append(f"{fmt(fp)}/{fmt(fb)}")
            if k == 1:
                good &= math.isfinite(fp) and math.isfinite(fb) and abs(fp - fb) <= FIRST_PHASE_TOL
            else:
                good &= math.isfinite(fp) and math.isfinite(fb) and fp <= fb
        (tp, kp), (tb, _) = mission(p), mission(b)
        good &= kp > 0 and tp < tb
        parts.append(f"{CASES[case]}: phase FE proposed/binary bat {', '.join(fe)}; time {_time(p)} vs {_time(b)}")
    return "; ".join(parts), good, (f"phase FE: means over the runs that reached the phase; the first within "
                                    f"{FIRST_PHASE_TOL}, the others at or below; '-': no run reached it")


# -- the report's tables ---------------------------------------------------------------------------------------------


def _pm(res: list[TrialResult], key: str, nd: int = 2) -> str:
    v = values(res, key)
    return mean_pm_sd(v, nd) if len(v) else "-"


def sections(outcomes: list[Outcome]) -> list[str]:
    """Table 7.4 and Table 7.5, thesis beside ours."""
    if not any(o.trial.cell.get("kind") == KIND and o.result is not None for o in outcomes):
        return []
    lines = ["", "## Chapter 7's comparisons (C11, C12): the BAT approach, circle gathering, binary bat", "",
             f"SonPI sessions, hardware profile (tracking camera, sequential sonars, lossy Wi-Fi), {TRIALS} per cell, "
             "the same deployments for every method. Time: mean, a run that did not arrive counted at its session's "
             "end (>=), arrivals k/n. FE: eq. 7.1 (mean +- sd over the runs). Path: mean per robot (cm; the thesis' "
             "hardware 'cm' are doubtful, digest §4.5.1).", "",
             "**Table 7.4** (thesis: CG / proposed; ours beside)", "",
             "| case | N | time CG thesis | ours | time proposed thesis | ours | FE CG thesis | ours | "
             "FE proposed thesis | ours | path CG thesis | ours (cm) | path proposed thesis | ours (cm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (case, n), (cg, pr) in TABLE_7_4.items():
        p, g = runs(outcomes, case, n, PROPOSED), runs(outcomes, case, n, CG)
        if not p and not g:
            continue
        path_g, path_p = values(g, "path_m"), values(p, "path_m")
        lines.append(
            f"| {CASES[case]} | {n} | {cg[0] if cg else 'Fail'} | {_time(g) if g else '-'} | {pr[0]:g} | "
            f"{_time(p) if p else '-'} | {f'{cg[1]} +- {cg[2]}' if cg else 'Fail'} | {_pm(g, 'fe_mean')} | "
            f"{pr[1]} +- {pr[2]} | {_pm(p, 'fe_mean')} | {cg[3] if cg else 'Fail'} | "
            f"{fmt(100 * float(np.mean(path_g)), 1) if len(path_g) else '-'} | {pr[3]} | "
            f"{fmt(100 * float(np.mean(path_p)), 1) if len(path_p) else '-'} |")
    lines += ["", f"**Table 7.5** ({C12_N} robots; phase FE binary bat / proposed, thesis beside ours; the phases end "
                  "where the centroid first comes within a distance of T: cosim.CASES)", "",
              "| case | phase | FE binary bat thesis | ours | FE proposed thesis | ours | "
              "duration binary bat ours (s) | duration proposed ours (s) |", "|---|---|---|---|---|---|---|---|"]
    for case, phases in TABLE_7_5_FE.items():
        p, b = runs(outcomes, case, C12_N, PROPOSED), runs(outcomes, case, C12_N, BINARY_BAT)
        if not p and not b:
            continue
        names = [ph["name"] for ph in cosim.CASES[case].phases]
        for k, (th, name) in enumerate(zip(phases, names, strict=True), 1):
            lines.append(f"| {CASES[case]} | {name} | {th[0]} +- {th[1]} | {_pm(b, f'ph{k}_fe')} | {th[2]} +- {th[3]} "
                         f"| {_pm(p, f'ph{k}_fe')} | {_pm(b, f'ph{k}_s', 1)} | {_pm(p, f'ph{k}_s', 1)} |")
        bb_s, pr_s = TABLE_7_5_S[case]
        lines.append(f"| {CASES[case]} | whole mission (s) | {bb_s:g} | {_time(b) if b else '-'} | {pr_s:g} | "
                     f"{_time(p) if p else '-'} | | |")
    return lines
