"""The benchmark Khan's Table 1 only tabulates (digest 003, item 6): PFSM-LJ, RDPSO and GSO on the same 27 scenarios,
deployments, run-end rule and metric, so its complexity claims meet measured numbers.

PFSM-LJ runs in the point foot-bot model (``numerical``) with the pfsm-search grid's readings (``GRID_PARAMS``).
RDPSO (``swarm_logic.families.rdpso``) and GSO (``swarm_logic.families.baselines.gso``) run unchanged in the
numerical runner (``bridge.numerical.runner``: ``PointLlc`` / ``PointRadio`` behind their ``LowLevel`` and ``Radio``
protocols, the XBee-like log-distance link) on the same arenas and ``deploy()`` draws: the searchers start where the
foot-bots start and the targets wait where the target foot-bots wait. What they climb is ``TargetField``: a peak at
every target not yet found, sensed from as far as a foot-bot hears a target (the range-and-bearing range), removed
once a searcher comes within the foot-bot's "near target" distance (K-5). The trials of one scenario share their
seeds across the three algorithms (``seed_ignores``), so the comparison is paired.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from scipy import stats as sps

from bridge.core.rng import stream
from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import mean, ok
from bridge.numerical import runner as numerical
from bridge.studies.pfsm.experiments import GRID_PARAMS, MAX_S, SEARCHERS, SIDES, TARGETS
from bridge.studies.pfsm.numerical import TICK_S, Arena, Deployment, Swarm, deploy, p_sta
from bridge.studies.rdpso.parameter_sets import SETS
from swarm_logic.families.baselines.gso import Gso
from swarm_logic.families.pfsm.searcher import PfsmSearcher
from swarm_logic.families.rdpso.controller import Rdpso
from swarm_logic.robots.footbot.interfaces import RAB_RANGE_M

ALGORITHMS = ("pfsm", "rdpso", "gso")
NAMES = {"pfsm": "PFSM-LJ", "rdpso": "RDPSO", "gso": "GSO"}
NEAR_M = float(PfsmSearcher.defaults["near_target_m"])  # K-5: a target is found within this centre distance
REACH_M = RAB_RANGE_M  # a target's peak reaches as far as a foot-bot hears a target (3 m)
ITERATION_S = 1.0  # RDPSO's and GSO's iteration (A13)
STEP_M = 0.1  # their largest move per iteration: 0.1 m/s, the foot-bots' top speed
D_MAX_M = RAB_RANGE_M  # RDPSO's connectivity distance and GSO's sensor range r_s: the foot-bots' hearing range


class TargetField:
    """The targets as an objective field (``bridge.numerical.objectives.Field`` with ``observe``): f = max over the
    targets not yet found of max(0, 1 - d / ``reach_m``), a cone 1 at the target and 0 beyond ``reach_m`` (the
    victims' "sensed intensity" of the RDPSO thesis, as far as a foot-bot senses a target). ``observe`` (the runner
    calls it with the start positions, 0, then after every round of moves k with k + 1) marks a target found when a
    robot is within ``near_m`` of it (its peak goes from the next sensing on) and counts the robots that moved."""

    dynamic = False

    def __init__(self, side_m: float, targets: np.ndarray, reach_m: float = REACH_M, near_m: float = NEAR_M) -> None:
        self.bounds = (0.0, 0.0, float(side_m), float(side_m))
        self.targets = np.asarray(targets, float).reshape(-1, 2)
        self.reach_m, self.near_m = float(reach_m), float(near_m)
        self.live = np.ones(len(self.targets), bool)
        self.found_at: list[int | None] = [None] * len(self.targets)  # the round (iteration) each was found in
        self.moved: dict[int, int] = {}  # round -> robots whose position changed in it
        self._prev: np.ndarray | None = None

    def value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x, y = np.asarray(x, float), np.asarray(y, float)
        if not self.live.any():
            return np.zeros(np.broadcast(x, y).shape)
        t = self.targets[self.live]
        d = np.hypot(x[..., None] - t[:, 0], y[..., None] - t[:, 1]).min(axis=-1)
        return np.maximum(0.0, 1.0 - d / self.reach_m)

    def optimum(self) -> tuple[float, float]:
        live = self.targets[self.live]
        return (float(live[0, 0]), float(live[0, 1])) if len(live) else (0.0, 0.0)

    def advance(self, iteration: int) -> None:
        """The field changes by discovery only (``observe``)."""

    def observe(self, x: np.ndarray, y: np.ndarray, iteration: int) -> None:
        p = np.column_stack([x, y]).astype(float)
        if self._prev is not None:
            self.moved[iteration] = int(np.count_nonzero(np.any(p != self._prev, axis=1)))
        self._prev = p
        if self.live.any():
            d = np.hypot(p[:, None, 0] - self.targets[:, 0], p[:, None, 1] - self.targets[:, 1]).min(axis=0)
            for j in np.nonzero(self.live & (d < self.near_m))[0].tolist():
                self.found_at[j] = iteration
                self.live[j] = False

    def all_found(self) -> bool:
        return not self.live.any()


def algorithm_params(alg: str, n: int, swarm_seed: int) -> dict[str, Any]:
    """RDPSO's and GSO's readings in the benchmark (both: 1 s iterations, 0.1 m per iteration, no send jitter)."""
    common = {"iteration_s": ITERATION_S, "comm_window_s": 0.25, "send_jitter_s": 0.0, "dx_max_m": STEP_M,
              "log_every": 0}
    if alg == "rdpso":
        g = max(1, n // 5)  # subgroups of 5, as in the benchmark chapter's runs (b13-benchmark)
        return {**common, **SETS["S1"], "d_max_m": D_MAX_M, "subgroups_min": 0, "subgroups_init": g,
                "subgroups_max": 2 * g, "sc_max": 30, "swarm_seed": swarm_seed}
    if alg == "gso":
        return {**common, "step_m": STEP_M, "r_s_m": D_MAX_M, "beta": 0.08}
    raise ValueError(f"no numerical-runner reading for {alg!r}; known: rdpso, gso")


def _found_metrics(found_s: list[float | None], nt: int) -> dict[str, Any]:
    found = [f for f in found_s if f is not None]
    return {"found": len(found), "all_found": len(found) == nt,
            "first_found_s": round(min(found), 1) if found else None,
            "mean_found_s": round(sum(found) / len(found), 2) if found else None}


def pfsm_trial(arena: Arena, dep: Deployment, seed: int) -> dict[str, Any]:
    """PFSM-LJ as pfsm-search runs its grid; messages: the searchers' range-and-bearing broadcasts."""
    ns, nt = len(dep.searchers), len(dep.targets)
    sw = Swarm(arena, dep, seed, GRID_PARAMS)
    heard = 0
    w = sw.world
    while w.tick * TICK_S < MAX_S - 1e-9:
        sw.tick()
        heard += int(w.hear[:ns].sum())  # readings the searchers' boards took this tick
        if sw.all_found():
            break
    for c in sw.ctls:
        c.destroy()
    t_run = w.tick * TICK_S
    found_s = list(sw.found_s)
    t = max(f for f in found_s if f is not None) if found_s and all(f is not None for f in found_s) else t_run
    e = int(sum(sw.energy[:round(t / TICK_S)]))
    sends = sum(r.sends for r in sw.rabs[:ns])
    return {**_found_metrics(found_s, nt), "t_total_s": round(t, 1), "e_total": e, "e_moving": None,
            "p_sta": p_sta(e, t, len([f for f in found_s if f is not None]), nt, arena.area_m2, ns),
            "run_s": round(t_run, 1), "msgs_per_robot": round(sends / ns, 2),
            "msgs_per_robot_s": round(sends / ns / t_run, 4), "heard_per_robot_s": round(heard / ns / t_run, 3)}


def swarm_trial(alg: str, arena: Arena, dep: Deployment, seed: int) -> dict[str, Any]:
    """RDPSO or GSO from the same deployment: the searchers' start positions, the targets' peaks; the run ends in the
    round the last target is found, or at ``MAX_S``. Every searcher spends one unit per tick (neither algorithm has
    a resting state: every robot senses, broadcasts and decides every iteration); ``e_moving`` counts only the
    robot-ticks of iterations in which it moved."""
    ns, nt = len(dep.searchers), len(dep.targets)
    field = TargetField(arena.side_m, dep.targets)
    rng = stream(seed, "benchmark", alg)
    params = algorithm_params(alg, ns, int(rng.integers(1 << 31)))
    cls = Rdpso if alg == "rdpso" else Gso
    iterations = math.ceil(MAX_S / ITERATION_S)
    res = numerical.run(cls, params, ns, iterations, field, (arena.side_m, arena.side_m),
                        link=numerical.LinkModel(mode="rssi"), seed=int(rng.integers(1 << 31)),
                        start=dep.searchers, until=field.all_found)
    # a move of up to 0.1 m at 0.1 m/s takes the iteration: a target found in round k is found at k iterations
    found_s = [None if k is None else k * ITERATION_S for k in field.found_at]
    # the run: to the round of the last discovery, or all its iterations (rounds nobody moved in are not observed)
    t = max(f for f in found_s if f is not None) if field.all_found() else MAX_S
    t = t_run = max(t, ITERATION_S)
    ticks_per_round = round(ITERATION_S / TICK_S)
    e = ns * round(t / TICK_S)
    e_moving = ticks_per_round * sum(m for k, m in field.moved.items() if k * ITERATION_S <= t + 1e-9)
    return {**_found_metrics(found_s, nt), "t_total_s": round(t, 1), "e_total": e, "e_moving": e_moving,
            "p_sta": p_sta(e, t, sum(f is not None for f in found_s), nt, arena.area_m2, ns),
            "run_s": round(t_run, 1), "msgs_per_robot": round(res.packets / ns, 2),
            "msgs_per_robot_s": round(res.packets / ns / t_run, 4),
            "heard_per_robot_s": round(res.deliveries / ns / t_run, 3)}


def benchmark_trial(alg: str, side: float, ns: int, nt: int, seed: int) -> dict[str, Any]:
    """One run of ``alg`` on scenario (side, ns, nt) from ``deploy(seed)``: the metrics every algorithm reports."""
    arena = Arena(side)
    dep = deploy(arena, ns, nt, seed)
    return pfsm_trial(arena, dep, seed) if alg == "pfsm" else swarm_trial(alg, arena, dep, seed)


def ci95(v: np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95 % confidence interval (Student's t; NaN half-width below 2 values)."""
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    if not len(v):
        return math.nan, math.nan
    if len(v) < 2:
        return float(v.mean()), math.nan
    return float(v.mean()), float(sps.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / math.sqrt(len(v)))


def _ci(results: list[TrialResult], metric: str, digits: str = ".3g") -> str:
    m, h = ci95(np.array([r.metrics.get(metric) for r in results if r.metrics.get(metric) is not None], float))
    if math.isnan(m):
        return "-"
    return f"{m:{digits}}" if math.isnan(h) else f"{m:{digits}} ± {h:{digits}}"


COLUMNS = (("found", "found"), ("t_total_s", "T_total (s)"), ("e_total", "E_total"), ("p_sta", "P_STA"),
           ("msgs_per_robot", "messages / robot"), ("msgs_per_robot_s", "messages / robot / s"),
           ("heard_per_robot_s", "heard / robot / s"))


def level_mean(outcomes: list[Outcome], alg: str, metric: str, **cell: Any) -> float:
    return mean(ok(outcomes, alg=alg, **cell), metric)


@register
class SearchBenchmark(Experiment):
    name = "search-benchmark"
    title = "Search benchmark: PFSM-LJ vs RDPSO vs GSO on Khan's 27 scenarios (Table 1 measured), numerical"
    description = (
        "Khan's 27 scenarios as pfsm-search runs them (arena side 5 / 7.5 / 10 m, 10 / 20 / 30 searchers, 10 / 20 / "
        "30 targets, searchers uniform in the 1 m base strip along the west wall, targets uniform outside it, "
        "deploy() of the pfsm study), 10 seeds per scenario shared by the three algorithms (same seed: same "
        "searcher starts, same targets). A run ends when every target has been found or at 600 s. PFSM-LJ: the "
        "point foot-bot model with the pfsm-search grid's readings (diffusion search vector, MaxTime_SEARCH 150 s, "
        "0.1 m/s), bodies and walls; messages = the searchers' range-and-bearing broadcasts (one per tick). RDPSO "
        "and GSO: their controllers unchanged in the numerical runner (point robots behind LowLevel and Radio, no "
        "bodies; the arena's walls clip moves; the XBee-like log-distance link, -94 dBm sensitivity, about 6.7 m), "
        "1 s iterations, at most 0.1 m per iteration (the foot-bots' 0.1 m/s); they climb a field with a cone "
        "1 - d / 3 m at every target not yet found (sensed as far as a foot-bot hears a target, 3 m), and a target "
        "is found when a searcher comes within 0.30 m of it (PFSM's K-5 near distance), its peak then removed; a "
        "target found in iteration k counts as found at k s. RDPSO: S1 (alpha 0.632, rho 0.1 / 0.3 / 0.79 / 0.79), "
        "N_s / 5 subgroups (at most twice that), SC_max 30, d_max 3 m, gossip hellos. GSO: step 0.1 m, r_s 3 m, "
        "beta 0.08, rho 0.4, gamma 0.6, n_t 5. Messages = frames each searcher sent (one per iteration). Energy "
        "(K-7): searcher-ticks not resting (0.1 s ticks) up to T_total; PFSM rests in TIMEOUT, RDPSO and GSO have "
        "no resting state (every robot senses, broadcasts and decides every iteration), so every searcher counts "
        "every tick (e_moving: only the ticks of iterations it moved in). P_STA eq. 2 with A_1 = 1 m^2, T_total "
        "the last discovery (600 s when some target was never found).")
    trials = 10
    smoke_trials = 2
    seed_ignores = ("alg",)
    # no box plots: 81 cells make an unreadable strip; the comparison section's tables carry the figures

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        grid: Any = itertools.product(SIDES, SEARCHERS, TARGETS)
        if smoke:
            grid = ((5.0, 10, 10), (5.0, 30, 10), (10.0, 10, 10))
        return [{"alg": a, "side": s, "searchers": n, "targets": t} for s, n, t in grid for a in ALGORITHMS]

    def run(self, trial: Trial) -> TrialResult:
        c = trial.cell
        return TrialResult(benchmark_trial(c["alg"], c["side"], c["searchers"], c["targets"], trial.seed))

    def sections(self, outcomes: list[Outcome]) -> list[str]:
        lines = ["", "## Comparison (mean ± 95 % CI half-width over the trials)", "",
                 "### Every scenario run, pooled", "", "| algorithm | " + " | ".join(h for _, h in COLUMNS) + " |",
                 "|---|" + "---|" * len(COLUMNS)]
        for a in ALGORITHMS:
            rs = ok(outcomes, alg=a)
            if rs:
                lines.append(f"| {NAMES[a]} | " + " | ".join(_ci(rs, m) for m, _ in COLUMNS) + " |")
        scenarios = list(dict.fromkeys((o.trial.cell["side"], o.trial.cell["searchers"], o.trial.cell["targets"])
                                       for o in outcomes))
        lines += ["", "### Per scenario", "", "| side (m) | searchers | targets | algorithm | "
                  + " | ".join(h for _, h in COLUMNS) + " |", "|---|---|---|---|" + "---|" * len(COLUMNS)]
        for s, n, t in scenarios:
            for a in ALGORITHMS:
                rs = ok(outcomes, alg=a, side=s, searchers=n, targets=t)
                if rs:
                    lines.append(f"| {s:g} | {n} | {t} | {NAMES[a]} | "
                                 + " | ".join(_ci(rs, m) for m, _ in COLUMNS) + " |")
        return lines

    def targets(self) -> list[Target]:
        return [
            Target("T1-comm", "messages sent per robot and second, N_s = 30 vs 10 (each over its 9 scenarios)",
                   "Table 1: communication O(N_s) for PFSM-LJ, RDPSO and GSO (the swarm's messages grow "
                   "linearly with the searchers)", "for every algorithm, the per-robot rate at 30 within 0.8 to 1.25 "
                   "of that at 10 (total messages about proportional to N_s)", comm_sent),
            Target("T2-heard", "messages heard per robot and second, N_s = 30 vs 10", "Table 1: communication O(N_s) "
                   "(each robot hears at most its N_s neighbours)", "for every algorithm, the per-robot rate at 30 "
                   "at most 1.05 x 29 / 9 = 3.38 x that at 10 (no faster than linear in the others heard)",
                   comm_heard),
            Target("T3-search", "search performance (no claim: the document ran no head-to-head)", "-",
                   "reported, not judged", performance),
        ]


def _ratio_by(outcomes: list[Outcome], metric: str, key: str, lo: Any, hi: Any,
              algs: tuple[str, ...] = ALGORITHMS) -> dict[str, float]:
    out = {}
    for a in algs:
        m_lo, m_hi = level_mean(outcomes, a, metric, **{key: lo}), level_mean(outcomes, a, metric, **{key: hi})
        if not (math.isnan(m_lo) or math.isnan(m_hi)) and m_lo > 0:
            out[a] = m_hi / m_lo
    return out


def _judge_ratios(r: dict[str, float], need: tuple[str, ...], good: Any, what: str) -> tuple[str, bool | None, str]:
    if any(a not in r for a in need):
        return "needs every algorithm at both levels", None, ""
    return ", ".join(f"{NAMES[a]} x{v:.2f}" for a, v in r.items()), all(good(r[a]) for a in need), what


def comm_sent(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    r = _ratio_by(outcomes, "msgs_per_robot_s", "searchers", 10, 30)
    return _judge_ratios(r, ALGORITHMS, lambda v: 0.8 <= v <= 1.25, "ratio of mean per-robot send rates, 30 / 10")


def comm_heard(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    r = _ratio_by(outcomes, "heard_per_robot_s", "searchers", 10, 30)
    return _judge_ratios(r, ALGORITHMS, lambda v: v <= 1.05 * 29 / 9, "ratio of mean per-robot receive rates, 30 / "
                         "10; one frame per robot and step, so only extra traffic (relays, replies) could break it; "
                         "PFSM's readings include the targets' broadcasts")


def performance(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    parts, notes = [], []
    for a in ALGORITHMS:
        rs = ok(outcomes, alg=a)
        if not rs:
            continue
        all_found = sum(bool(r.metrics["all_found"]) for r in rs)
        parts.append(f"{NAMES[a]}: P_STA {mean(rs, 'p_sta'):.3g}, found {mean(rs, 'found'):.1f}, "
                     f"T_total {mean(rs, 't_total_s'):.0f} s")
        notes.append(f"{NAMES[a]} found every target in {all_found}/{len(rs)} runs")
    return "; ".join(parts) or "no runs", None, "; ".join(notes)
