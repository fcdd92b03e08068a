"""The benchmark chapter's mapping study (thesis section 8.2.1, digest E11, target B13) in the numerical runner.

RDPSO and the four baselines (EPSO, PPSO, GSO, AFS) explore a garage with the objective family's ``mapping`` field
(``bridge.numerical.objectives.MappingField`` on ``bridge.numerical.entropy_map``; eq. 8.1 sensed, eq. 8.3's
exploration ratio eta_exp and eq. 8.4's normalised AUC scored). The controllers are the co-simulation's, unchanged;
parameters the thesis does not give are chosen here and in ``docs/baselines.md`` ("Mapping objective (chapter 8)").
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import iqr, median, ok
from bridge.numerical import runner as numerical
from bridge.numerical.entropy_map import normalised_auc
from bridge.numerical.objectives import MappingField
from bridge.studies.rdpso.parameter_sets import SETS

# the ISR-UC garage as we lay it out: 85 x 35 m = 2975 m^2 (the thesis' A), 4 rows x 14 columns of 1.6 m square
# pillars (56 obstacles, 4.8 % of the floor; the thesis counts 56 obstacles and a density of 4.93 %, section 9.2.3)
GARAGE = (85.0, 35.0)
PILLAR_M = 1.6
PILLARS = (14, 4)
R_W_M = 3.0  # sensing radius (Table 9.1)
CELL_M = 0.5
DX_MAX_M = 1.0  # per 1 s iteration: the garage robots' v = 1 m/s (Table 9.1)
MEMORY_ITERATIONS = 10  # EPSO/PPSO forget bests older than this on the changing map (docs/baselines.md)
ALGORITHMS = ("rdpso", "epso", "ppso", "gso", "afs")


def garage_obstacles() -> np.ndarray:
    """The pillars as (x0, y0, x1, y1) rectangles, centred in a regular 14 x 4 grid of bays."""
    w, h = GARAGE
    cols, rows = PILLARS
    half = PILLAR_M / 2
    return np.array([(w / cols * (i + 0.5) - half, h / rows * (j + 0.5) - half,
                      w / cols * (i + 0.5) + half, h / rows * (j + 0.5) + half)
                     for j in range(rows) for i in range(cols)])


def algorithm_params(alg: str, n: int, d_max: float) -> dict[str, Any]:
    """Each algorithm's parameters in the garage (all share dx_max, the iteration and no send jitter)."""
    common = {"dx_max_m": DX_MAX_M, "iteration_s": 1.0, "comm_window_s": 0.25, "send_jitter_s": 0.0,
              "log_every": 0}
    if alg == "rdpso":
        g = max(1, n // 5)
        return {**common, **SETS["S1"], "d_max_m": d_max, "subgroups_min": 0, "subgroups_init": g,
                "subgroups_max": 2 * g, "sc_max": 30, "r_w_m": R_W_M, "payload_max": 4096}
    if alg == "epso":
        return {**common, "range_m": d_max, "avoid_m": 1.0, "memory_iterations": MEMORY_ITERATIONS}
    if alg == "ppso":
        return {**common, "collide_m": 0.5, "back_m": 0.5, "memory_iterations": MEMORY_ITERATIONS}
    if alg == "gso":
        return {**common, "r_s_m": d_max, "step_m": DX_MAX_M, "beta": 0.5, "avoid_m": 1.0}
    if alg == "afs":
        return {**common, "c_m2": 12.0, "dt_s": 0.02, "rho": 150.0, "gamma": 50.0, "r_w_m": R_W_M,
                "grad_radius_m": 2 * R_W_M, "payload_max": 4096}
    raise ValueError(f"unknown algorithm {alg!r}; known: {', '.join(ALGORITHMS)}")


def mapping_trial(alg: str, n: int, d_max: float, iterations: int, seed: int) -> tuple[np.ndarray, int]:
    """One mission: robots dropped uniformly at random on the garage's free floor; eta_exp[0..iterations] and the
    collisions."""
    rng = np.random.default_rng(seed)
    obstacles = garage_obstacles()
    field = MappingField(GARAGE, obstacles, cell_m=CELL_M, r_w_m=R_W_M)
    start = numerical.chain_deployment(n, [list(range(n))], GARAGE, math.inf, obstacles, rng)
    params = {**algorithm_params(alg, n, d_max), "swarm_seed": int(rng.integers(1 << 31))} if alg == "rdpso" \
        else algorithm_params(alg, n, d_max)
    res = numerical.run(alg, params, n, iterations, field, GARAGE, obstacles, numerical.LinkModel(range_m=d_max),
                        seed=int(rng.integers(1 << 31)), start=start)
    return field.eta_curve(iterations), res.collisions


@register
class B13Benchmark(Experiment):
    name = "b13-benchmark"
    title = "B13: RDPSO vs EPSO, PPSO, GSO and AFS mapping a garage (entropy objective, numerical runner)"
    description = (
        "Thesis section 8.2.1 (digest E11, target B13). The ISR-UC garage as an 85 x 35 m floor (A = 2975 m^2) "
        "with 56 square pillars of 1.6 m (4 x 14, 4.8 % of the floor), an occupancy grid of 0.5 m cells, robots "
        "dropped uniformly at random on the free floor, N_T in {10, 20, 30}, d_max in {30, 100} m as the radio "
        "range (and RDPSO's connectivity target, EPSO's R_r, GSO's r_s), 500 iterations of 1 s, dx_max = 1 m "
        "(v = 1 m/s, Table 9.1). Each robot scans the cells within R_w = 3 m in line of sight and senses eq. 8.1: "
        "its best frontier cell's line-of-sight factor x normalised smoothed entropy gradient "
        "(bridge/numerical/entropy_map.py). "
        "eta_exp = explored free cells / free cells (eq. 8.3); AUC = mean of eta_exp[0..500] (eq. 8.4). RDPSO: "
        "S1 (alpha 0.632, rho 0.1/0.3/0.79/0.79), subgroups 0/(N_T/5)/(2 N_T/5), SC_max 30, R_w 3 m. EPSO and PPSO "
        f"forget personal (and PPSO's heard-of) bests older than {MEMORY_ITERATIONS} iterations; GSO step = dx_max, "
        "beta 0.5 m; AFS c = 12 m^2 (spacing 6 m), rho 150, gamma 50, dt 0.02. Parameters in docs/baselines.md.")
    trials = 30
    smoke_trials = 1
    curves = (("eta", "exploration ratio eta_exp"),)
    boxes = (("auc", "normalised AUC of eta_exp"), ("eta_final", "final eta_exp"))
    SIZES: ClassVar[tuple[int, ...]] = (10, 20, 30)
    DMAX: ClassVar[tuple[int, ...]] = (30, 100)
    THESIS_AUC: ClassVar[dict[str, float]] = {"rdpso": 0.80, "afs": 0.75, "gso": 0.75, "epso": 0.70, "ppso": 0.70}

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        if smoke:
            return [{"alg": a, "n": 10, "d_max": 30} for a in ("rdpso", "gso")]
        return [{"alg": a, "n": n, "d_max": d} for n in self.SIZES for d in self.DMAX for a in ALGORITHMS]

    def run(self, trial: Trial) -> TrialResult:
        c = trial.cell
        its = 60 if trial.smoke else 500
        eta, collisions = mapping_trial(c["alg"], int(c["n"]), float(c["d_max"]), its, trial.seed)
        metrics = {
            "auc": round(normalised_auc(eta), 5),
            "eta_final": round(float(eta[-1]), 5),
            "eta_50": round(float(eta[min(50, its)]), 5),
            "early_auc": round(normalised_auc(eta[:min(50, its) + 1]), 5),
            "collisions": collisions,
        }
        return TrialResult(metrics, {"eta": np.round(eta, 5).tolist()})

    def targets(self) -> list[Target]:
        return [
            Target("B13a", "median AUC at N_T = 30 (both d_max pooled)", "RDPSO ~0.80 > AFS ~ GSO ~0.75 > EPSO ~ "
                   "PPSO ~0.70", "RDPSO > AFS, GSO > EPSO, PPSO, and both gaps (RDPSO - mean(AFS, GSO), mean(AFS, "
                   "GSO) - mean(EPSO, PPSO)) within 5 +/- 3 pp", self._b13a),
            Target("B13b", "best median AUC per (N_T, d_max)", "RDPSO best in all six configurations",
                   "RDPSO's median AUC highest in every configuration run", self._b13b),
            Target("B13c", "AUC interquartile range, d_max 100 vs 30 m", "smaller at 100 m (most for EPSO, PPSO)",
                   "IQR(100) < IQR(30) in at least two thirds of the (algorithm, N_T) pairs", self._b13c),
            Target("B13d", "early exploration at (30, 30)", "GSO leads during the first iterations",
                   "GSO has the highest median AUC over iterations 0-50", self._b13d),
        ]

    def _medians(self, outcomes: list[Outcome], metric: str, **cell: Any) -> dict[str, float]:
        return {a: median(ok(outcomes, alg=a, **cell), metric) for a in ALGORITHMS if ok(outcomes, alg=a, **cell)}

    def _b13a(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        m = self._medians(outcomes, "auc", n=30)
        if len(m) < len(ALGORITHMS):
            return "missing algorithms at N_T = 30", None, ""
        mid, low = (m["afs"] + m["gso"]) / 2, (m["epso"] + m["ppso"]) / 2
        order = m["rdpso"] > max(m["afs"], m["gso"]) and min(m["afs"], m["gso"]) > max(m["epso"], m["ppso"])
        gaps = (m["rdpso"] - mid, mid - low)
        ours = ", ".join(f"{a.upper()} {m[a]:.3f}" for a in ALGORITHMS) + \
            f"; gaps {gaps[0] * 100:+.1f} / {gaps[1] * 100:+.1f} pp"
        good = order and all(abs(g - 0.05) <= 0.03 for g in gaps)
        return ours, good, "thesis: " + ", ".join(f"{a.upper()} {v:.2f}" for a, v in self.THESIS_AUC.items())

    def _b13b(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts, good, judged = [], True, False
        for n in self.SIZES:
            for d in self.DMAX:
                m = self._medians(outcomes, "auc", n=n, d_max=d)
                if "rdpso" not in m or len(m) < 2:
                    continue
                judged = True
                best = max(m, key=lambda a: m[a])
                good &= best == "rdpso"
                rival = max((a for a in m if a != "rdpso"), key=lambda a: m[a])
                parts.append(f"({n}, {d}): best {best.upper()}, RDPSO {m['rdpso']:.3f} vs {rival.upper()} "
                             f"{m[rival]:.3f}")
        return ("; ".join(parts) or "no configuration with RDPSO"), (good if judged else None), ""

    def _b13c(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        smaller = pairs = 0
        parts = []
        for a in ALGORITHMS:
            for n in self.SIZES:
                lo, hi = ok(outcomes, alg=a, n=n, d_max=30), ok(outcomes, alg=a, n=n, d_max=100)
                if len(lo) < 2 or len(hi) < 2:
                    continue
                pairs += 1
                q30, q100 = iqr(lo, "auc"), iqr(hi, "auc")
                smaller += q100 < q30
                parts.append(f"{a.upper()} {n}: {q30:.3f} -> {q100:.3f}")
        if not pairs:
            return "no pairs", None, ""
        return f"smaller at 100 m in {smaller}/{pairs} pairs", 3 * smaller >= 2 * pairs, "; ".join(parts)

    def _b13d(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        m = self._medians(outcomes, "early_auc", n=30, d_max=30)
        if "gso" not in m or len(m) < 2:
            return "no (30, 30) cells with GSO", None, ""
        best = max(m, key=lambda a: m[a])
        return ", ".join(f"{a.upper()} {v:.3f}" for a, v in m.items()), best == "gso", \
            "median AUC of eta_exp[0..50]"
