"""The PFSM search (Khan, section 4.4-5; digest 4, 6.2): 3 arenas x 3 swarm sizes x 3 target counts, searchers
deployed at random in the base, 10 seeds per scenario, in the point-robot model (``bridge.studies.pfsm.numerical``)
with the family's controllers unchanged. The targets K-S1 ... K-S5 compare trends, not values: the document's
figures are lost and gave one run per scenario.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import mean, ok
from bridge.studies.pfsm.numerical import TICK_S, Arena, Swarm, deploy, p_sta

SIDES = (5.0, 7.5, 10.0)  # m: 25, 56.25, 100 m^2
SEARCHERS = (10, 20, 30)
TARGETS = (10, 20, 30)
MAX_S = 600.0  # the global time boundary (s): "sufficient" for K-S1 (runs end when every target is found)
# the grid's readings where they differ from the controller's defaults, and why
GRID_PARAMS: dict[str, Any] = {
    # K-4: straight ahead when no target is heard (ARGoS foraging's exploration), a deviation: with the literal zero
    # vector the searchers stall out of every target's range (K-S5) and K-S1 cannot hold
    "search_vector": "diffusion",
    # MaxTime_SEARCH,RETURN: ARGoS foraging's 60 s lets a searcher reach 6 m at 0.1 m/s, short of the 10 m arena's
    # far side (the document gives no value); 150 s crosses it 1.5 times
    "max_search_s": 150.0,
}
STALL_S = 300.0  # K-S5's runs: the literal zero search vector, to this time
CURVE_EVERY = 10  # ticks per point of the energy curve (1 s)


def search_trial(side: float, ns: int, nt: int, seed: int, params: dict[str, Any], max_s: float = MAX_S,
                 until_all_found: bool = True) -> TrialResult:
    """One run: deploy, search until every target is found or ``max_s``, and the loop functions' figures."""
    arena = Arena(side)
    dep = deploy(arena, ns, nt, seed)
    run = Swarm(arena, dep, seed, params).run(max_s, until_all_found)
    t = run.t_last_s
    e, e_all = run.energy_until(t), run.energy_until(t, all_robots=True)
    found = [f for f in run.found_s if f is not None]
    structural = 1000.0 * (run.n_found ** 2 / nt) * arena.area_m2 / ns  # eq. 2 without 1 / (E T)
    metrics: dict[str, Any] = {
        "found": run.n_found,
        "all_found": run.n_found == nt,
        "t_total_s": round(t, 1),
        "e_total": e,
        "e_total_all": e_all,
        "p_sta": p_sta(e, t, run.n_found, nt, arena.area_m2, ns),
        "p_sta_all": p_sta(e_all, t, run.n_found, nt, arena.area_m2, ns),
        "structural": structural,
        "inv_et": 1.0 / (e * t) if e and t else math.nan,
        "first_found_s": min(found) if found else None,
        "mean_found_s": sum(found) / len(found) if found else None,
        "home": run.home,
        "walking_frac": e / (ns * max(1, round(t / TICK_S))),
        "still_frac": run.still_ticks / run.search_ticks if run.search_ticks else None,
        "bytes_per_tick": round(run.bytes_sent / max(1, run.ticks), 1),
    }
    energy = [sum(run.energy[k:k + CURVE_EVERY]) for k in range(0, len(run.energy), CURVE_EVERY)]
    xs = [TICK_S * (k + CURVE_EVERY) for k in range(0, len(run.energy), CURVE_EVERY)]
    return TrialResult(metrics, {"energy": energy}, {"energy": xs})


def level_means(outcomes: list[Outcome], key: str, levels: tuple[Any, ...], metric: str) -> list[float]:
    """The mean of ``metric`` over the grid's trials at each level of factor ``key`` (each over its 9 scenarios)."""
    return [mean(ok(outcomes, variant="grid", **{key: v}), metric) for v in levels]


def formula_note(outcomes: list[Outcome], key: str, levels: tuple[Any, ...]) -> str:
    """Digest 4.2: how much of the level-to-level change of mean P_STA eq. 2's N_T^2/N_T x A/N_S factor makes by
    itself (at equal E x T), and what the measured 1/(E T) adds."""
    p = level_means(outcomes, key, levels, "p_sta")
    s = level_means(outcomes, key, levels, "structural")
    inv = level_means(outcomes, key, levels, "inv_et")
    if any(math.isnan(v) or v == 0 for v in p + s + inv):
        return "-"
    parts = [f"{lv:g}: x{p[k] / p[0]:.2f} (formula x{s[k] / s[0]:.2f}, 1/(E T) x{inv[k] / inv[0]:.2f})"
             for k, lv in enumerate(levels) if k]
    return f"mean P_STA relative to {levels[0]:g}: " + "; ".join(parts)


def _fmt(vs: list[float]) -> str:
    return "/".join("-" if math.isnan(v) else f"{v:.3g}" for v in vs)


@register
class PfsmSearch(Experiment):
    name = "pfsm-search"
    title = "PFSM-LJ search: 3 arenas x 3 swarm sizes x 3 target counts (Khan, section 5), numerical"
    description = (
        "Khan's 27 scenarios (digest 4.1): square arenas of side 5, 7.5 and 10 m, closed walls, no obstacles "
        "(K-10); 10, 20 or 30 searchers uniform at random in the base, the 1 m strip along the west wall, a grey "
        "floor under a light 1 m above its centre (K-6, K-8); 10, 20 or 30 targets uniform in the rest. Point "
        "foot-bots (radius 0.085 m, unicycle from the wheel speeds), 10 ticks/s; the range-and-bearing board hears "
        "every robot in line of sight within 3 m each tick, exact, no loss. The family's controllers unchanged, "
        "every reading the default of docs/pfsm.md (K-1 literal guards, U(0,1) P_T, K-2 foraging social rule "
        "Delta 0.01, K-3 generalised LJ k = 6, delta 0.75 m, G 0.1 m^2/s, K-5 near = 0.30 m, max speed 0.1 m/s, "
        "MaxTime_TIMEOUT 5 s) except search_vector = diffusion (K-4) and MaxTime_SEARCH = 150 s, as the grid's "
        "comments say why. A run ends when every target has been found or at 600 s. E_total: searcher-ticks not "
        "resting up to the last discovery (K-7; p_sta_all adds the targets driving home), T_total its time in "
        "seconds, P_STA eq. 2 with A_1 = 1 m^2. K-S5's cells: 10 searchers in the 10 m arena with the literal zero "
        "search vector for 300 s, against the grid's reading.")
    trials = 10
    smoke_trials = 2
    x_label = "time (s)"
    curves = (("energy", "searcher energy per second (robot-ticks not resting)"),)
    boxes = (("p_sta", "P_STA (eq. 2)"), ("t_total_s", "T_total (s)"))
    means = tuple((f, ("p_sta",), "P_STA (eq. 2)", {"variant": "grid"}) for f in ("side", "searchers", "targets"))

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        grid = itertools.product(SIDES, SEARCHERS, TARGETS)
        if smoke:
            grid = ((5.0, 10, 10), (5.0, 10, 30), (10.0, 30, 10))  # type: ignore[assignment]
        cells = [{"variant": "grid", "side": s, "searchers": n, "targets": t} for s, n, t in grid]
        stall = ((10, 10), (10, 30)) if not smoke else ((10, 10),)
        cells += [{"variant": v, "side": 10.0, "searchers": n, "targets": t} for v in ("zero", "diffusion")
                  for n, t in stall]
        return cells

    def run(self, trial: Trial) -> TrialResult:
        c = trial.cell
        if c["variant"] == "grid":
            return search_trial(c["side"], c["searchers"], c["targets"], trial.seed, GRID_PARAMS)
        params = {**GRID_PARAMS, "search_vector": c["variant"]}
        return search_trial(c["side"], c["searchers"], c["targets"], trial.seed, params, STALL_S,
                            until_all_found=False)

    def targets(self) -> list[Target]:
        return [
            Target("K-S1", "all targets found", "every target discovered (the scalability runs)",
                   "every grid run finds every target within 600 s", ks1),
            Target("K-S2", "flexibility: mean P_STA per area (25 / 56.25 / 100 m^2)", "highest at 25, dip at 56.25, "
                   "rise at 100", "P(25) highest, P(56.25) lowest, P(100) > P(56.25)", ks2),
            Target("K-S3", "scalability: mean P_STA per swarm size (10 / 20 / 30)", "best at 10, dip at 20, "
                   "plateau or slight rise at 30", "P(10) highest, P(20) lowest, P(30) >= P(20)", ks3),
            Target("K-S4", "robustness: mean P_STA per target count (10 / 20 / 30)", "clear positive slope",
                   "P(10) < P(20) < P(30)", ks4),
            Target("K-S5", "sub-optima: literal zero search vector", "searchers settle into a static formation out of "
                   "the targets' reach; more targets break the stall", "zero vector: searchers still for a larger "
                   "share of their SEARCH time than with the diffusion reading, and less so with 30 targets than 10",
                   ks5),
        ]


def ks1(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    rs = ok(outcomes, variant="grid")
    if not rs:
        return "no runs", None, ""
    missed = [r for r in rs if not r.metrics["all_found"]]
    return (f"{len(rs) - len(missed)} of {len(rs)} runs found every target", not missed,
            f"mean T_total {mean(rs, 't_total_s'):.0f} s")


def _trend(outcomes: list[Outcome], key: str, levels: tuple[Any, ...], judge: Any) -> tuple[str, bool | None, str]:
    p = level_means(outcomes, key, levels, "p_sta")
    if any(math.isnan(v) for v in p):
        return f"P_STA {_fmt(p)}", None, "needs every level"
    return f"P_STA {_fmt(p)}", bool(judge(*p)), formula_note(outcomes, key, levels)


def ks2(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    return _trend(outcomes, "side", SIDES, lambda a, b, c: a > c > b)


def ks3(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    return _trend(outcomes, "searchers", SEARCHERS, lambda a, b, c: a > b and a > c and c >= b)


def ks4(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    return _trend(outcomes, "targets", TARGETS, lambda a, b, c: a < b < c)


def ks5(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    def still(v: str, t: int) -> float:
        return mean(ok(outcomes, variant=v, targets=t), "still_frac")

    def found(v: str, t: int) -> float:
        return mean(ok(outcomes, variant=v, targets=t), "found")

    z10, z30, d10 = still("zero", 10), still("zero", 30), still("diffusion", 10)
    if math.isnan(z10) or math.isnan(d10):
        return "no stall runs", None, ""
    good = z10 > d10 and (math.isnan(z30) or z30 < z10)
    ours = f"still share of SEARCH time: zero {z10:.2f} (10 targets), {z30:.2f} (30); diffusion {d10:.2f}"
    note = (f"targets found in 300 s: zero {found('zero', 10):.1f}/10, {found('zero', 30):.1f}/30; diffusion "
            f"{found('diffusion', 10):.1f}/10, {found('diffusion', 30):.1f}/30")
    return ours, good, note
