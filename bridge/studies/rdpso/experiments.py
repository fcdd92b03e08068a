"""The RDPSO reproductions (Couceiro 2013): numerical studies (E1, E8, E9, E10) with the numerical runner, the
real-robot arena (E2) and the radio sanity figures (N1) in the full co-simulation.

Each experiment runs the same ``swarm_logic.families.rdpso.controller.Rdpso`` the co-simulation runs. Parameters are the
thesis' (digest table 4.1); what the thesis leaves open is chosen in ``docs/rdpso.md`` (assumptions A1-A31),
and the choices made here are named in each experiment's description.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.stats import iqr, mann_whitney, mean, median, ok, values
from bridge.numerical import runner as numerical
from bridge.numerical.objectives import LightField, make_field, random_obstacles
from bridge.studies.rdpso.parameter_sets import SETS
from bridge.studies.rdpso.sessions import CONFIGS, REPO, read_rdpso_session, run_checked, score_arena
from swarm_logic.families.rdpso.controller import Rdpso

# the thesis' numerical studies: no radio payload limit, no medium access (so no send jitter needed)
NUMERIC = {"payload_max": 4096, "log_every": 1, "send_jitter_s": 0.0}


def first_at_least(curve: np.ndarray, level: float) -> int | None:
    idx = np.flatnonzero(curve >= level)
    return int(idx[0]) if len(idx) else None


def numeric_trial(trial: Trial, field_name: str, size: float, n: int, iterations: int, params: dict[str, Any],
                  range_m: float, obstacles: bool = True, field_options: dict[str, float] | None = None,
                  ) -> TrialResult:
    """One numerical run: a fresh field and obstacle layout from the trial's seed, metrics and curves."""
    rng = np.random.default_rng(trial.seed)
    field = make_field(field_name, size, seed=int(rng.integers(1 << 31)), **(field_options or {}))
    obs = None
    if obstacles:
        obs = random_obstacles(size, rng=rng, keep_clear=[(*field.optimum(), 0.05 * size)])
    p = {**params, **NUMERIC, "swarm_seed": int(rng.integers(1 << 31))}
    res = numerical.run(Rdpso, p, n, iterations, field, (size, size), obs, numerical.LinkModel(range_m=range_m),
                        seed=int(rng.integers(1 << 31)))
    r99 = first_at_least(res.best, 0.99)
    r95 = first_at_least(res.best, 0.95)
    metrics = {
        "final": round(float(res.best[-1]), 6),
        "tracking": round(float(np.mean(res.current)), 6),
        "final_current": round(float(np.mean(res.current[-50:])), 6),
        "runtime99": iterations if r99 is None else r99 + 1,
        "runtime95": iterations if r95 is None else r95 + 1,
        "found99": r99 is not None,
        "collisions": res.collisions,
        "rupture_iterations": int(res.ruptures.sum()),
        "improvement_rate": round(res.improvements / max(1, res.robot_iterations), 4),
        "subgroups_end": int(res.subgroups[-1]),
        "excluded_end": int(res.excluded[-1]),
    }
    curves = {"best": np.round(res.best, 5).tolist(), "current": np.round(res.current, 5).tolist(),
              "excluded": res.excluded.tolist()}
    return TrialResult(metrics, curves)


# -- E9: static parameter sets on the benchmark functions (B3, B4, B5) ------------------------------------------

@register
class E9Static(Experiment):
    name = "e9-static"
    title = "E9: static parameter sets S1/S2 on peaks, Rastrigin and Rosenbrock (numerical runner)"
    description = (
        "Thesis section 7.4.1 (digest E9, targets B3-B5). 300 x 300 m arena with 20-30 random rectangular obstacles "
        "of 5-15 m (A14, kept 15 m clear of the optimum), N_T in {25, 50, 100} point robots deployed per subgroup "
        "as chains within d_max (A31), 500 iterations, d_max = 30 m (both the connectivity target and the radio "
        "range), dx_max = 0.5 m, subgroups min/init/max 0/5/8, SC_max = 30, R_w = 5 m (not given; assumed). "
        "Parameter sets S1 (alpha 0.632, rho 0.1/0.3/0.79/0.79) and S2 (0.632, 0.4/0.69/0.2/0.69) of Table 7.1. "
        "Functions mapped linearly onto the arena from peaks [-3,3]^2, Rastrigin [-5.12,5.12]^2 and Rosenbrock "
        "[-2.048,2.048]^2 and normalised by eq. 4.23 (1 = optimum). Runtime: first iteration with best >= 0.99 "
        "(500 if never).")
    trials = 100
    smoke_trials = 2
    curves = (("best", "best solution found"),)
    boxes = (("final", "final best solution"), ("runtime99", "iterations to 0.99"),
             ("collisions", "collisions"), ("rupture_iterations", "subgroup-iterations disconnected"))
    FUNCTIONS: ClassVar[tuple[str, ...]] = ("peaks", "rastrigin", "rosenbrock")
    SIZES: ClassVar[tuple[int, ...]] = (25, 50, 100)

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        if smoke:
            return [{"fn": "peaks", "n": 25, "set": "S1"}, {"fn": "rosenbrock", "n": 25, "set": "S2"}]
        return [{"fn": f, "n": n, "set": s} for f in self.FUNCTIONS for n in self.SIZES for s in ("S1", "S2")]

    @staticmethod
    def params(cell: dict[str, Any]) -> dict[str, Any]:
        return {**SETS[cell["set"]], "dx_max_m": 0.5, "d_max_m": 30.0, "subgroups_min": 0, "subgroups_init": 5,
                "subgroups_max": 8, "sc_max": 30, "r_w_m": 5.0}

    def run(self, trial: Trial, iterations: int | None = None) -> TrialResult:
        c = trial.cell
        its = iterations or (100 if trial.smoke else 500)
        return numeric_trial(trial, c["fn"], 300.0, c["n"], its, self.params(c), 30.0)

    def targets(self) -> list[Target]:
        return [
            Target("B3", "median final solution, S1, every function and N_T", "> 0.95", "median >= 0.95 in every cell",
                   self._b3),
            Target("B4", "runtime to 0.99 vs N_T (S1); final solution 50 vs 100", "runtime ~ 1/N_T; 100 not "
                   "significantly better than 50", "median runtime falls strictly 25 -> 50 -> 100 where it "
                   "discriminates; Mann-Whitney p > 0.05 for final 50 vs 100 for every function", self._b4),
            Target("B5", "S1 vs S2", "S1 >= S2 in most cells; S2 more collisions and ruptures; set effect ns for "
                   "peaks, significant for Rosenbrock", "S1 median >= S2 median in >= half the cells, and S2 more "
                   "collisions summed over cells", self._b5),
        ]

    def _b3(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts, good = [], True
        for f in self.FUNCTIONS:
            for n in self.SIZES:
                rs = ok(outcomes, fn=f, n=n, set="S1")
                if not rs:
                    continue
                m = median(rs, "final")
                good &= m >= 0.95
                parts.append(f"{f} {n}: {m:.3f}")
        if not parts:
            return "no S1 trials", None, ""
        return "; ".join(parts), good, ""

    def _b4(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts, notes, good, judged = [], [], True, False
        cap = max((o.result.metrics["runtime99"] for o in outcomes if o.result), default=500)
        for f in self.FUNCTIONS:
            runtimes = [median(ok(outcomes, fn=f, n=n, set="S1"), "runtime99") for n in self.SIZES]
            if any(math.isnan(r) for r in runtimes):
                continue
            p = mann_whitney(values(ok(outcomes, fn=f, n=50, set="S1"), "final"),
                             values(ok(outcomes, fn=f, n=100, set="S1"), "final"))
            parts.append(f"{f}: runtime {runtimes[0]:.0f}/{runtimes[1]:.0f}/{runtimes[2]:.0f}, final 50 vs 100 "
                         f"p = {p:.2f}")
            if all(r <= 2 for r in runtimes) or all(r >= cap for r in runtimes):
                notes.append(f"{f}: the runtime to 0.99 does not discriminate ("
                             + ("reached at once" if runtimes[0] <= 2 else "never reached") + ")")
                good &= p > 0.05
                continue
            judged = True
            good &= runtimes[0] > runtimes[1] > runtimes[2] and p > 0.05
        return ("; ".join(parts) or "not enough cells"), (good if judged else None), "; ".join(notes)

    def _b5(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        wins = cells = 0
        coll = {"S1": 0.0, "S2": 0.0}
        rupt = {"S1": 0.0, "S2": 0.0}
        pvals = []
        for f in self.FUNCTIONS:
            for n in self.SIZES:
                a, b = ok(outcomes, fn=f, n=n, set="S1"), ok(outcomes, fn=f, n=n, set="S2")
                if not a or not b:
                    continue
                cells += 1
                wins += median(a, "final") >= median(b, "final")
                for s, rs in (("S1", a), ("S2", b)):
                    coll[s] += float(np.sum(values(rs, "collisions")))
                    rupt[s] += float(np.sum(values(rs, "rupture_iterations")))
                pvals.append(f"{f} {n}: p = {mann_whitney(values(a, 'final'), values(b, 'final')):.2f}")
        if not cells:
            return "no paired cells", None, ""
        ours = (f"S1 >= S2 in {wins}/{cells} cells; collisions S1 {coll['S1']:.0f} vs S2 {coll['S2']:.0f}; "
                f"disconnected subgroup-iterations S1 {rupt['S1']:.0f} vs S2 {rupt['S2']:.0f}")
        return ours, wins * 2 >= cells and coll["S2"] > coll["S1"], "; ".join(pvals)


# -- E1: N_T x d_max (B1) ------------------------------------------------------------------------------------------

@register
class E1Dmax(Experiment):
    name = "e1-dmax"
    title = "E1: communication range d_max vs solution quality (numerical runner)"
    description = (
        "Thesis section 4.7.1 (digest E1, target B1). 300 x 300 m, random obstacles (A14), peaks (the 'Gaussian' "
        "cost) normalised by eq. 4.23, N_T in {9, 21, 33}, d_max in {inf, 100, 55, 10} m (infrastructure, WiFi, "
        "ZigBee, Bluetooth) as both connectivity target and radio range, 300 iterations, dx_max = 0.5 m, "
        "alpha 0.5, rho 0.2/0.4/0.8/0.8, subgroups 0/3/6, SC_max 30, R_w = 5 m (assumed).")
    trials = 50
    smoke_trials = 2
    curves = (("best", "best solution found"),)
    boxes = (("final", "final best solution"), ("runtime99", "iterations to 0.99"))
    DMAX: ClassVar[tuple[float, ...]] = (math.inf, 100.0, 55.0, 10.0)
    SIZES: ClassVar[tuple[int, ...]] = (9, 21, 33)

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        if smoke:
            return [{"d_max": "inf", "n": 9}, {"d_max": "10", "n": 9}]
        return [{"d_max": _dname(d), "n": n} for d in self.DMAX for n in self.SIZES]

    def run(self, trial: Trial) -> TrialResult:
        d = float(trial.cell["d_max"])
        params = {**SETS["ch4"], "dx_max_m": 0.5, "d_max_m": d, "subgroups_min": 0, "subgroups_init": 3,
                  "subgroups_max": 6, "sc_max": 30, "r_w_m": 5.0}
        return numeric_trial(trial, "peaks", 300.0, trial.cell["n"], 60 if trial.smoke else 300, params, d)

    def targets(self) -> list[Target]:
        return [Target("B1", "final solution by d_max (all N_T pooled)", "inf > 100 >~ 55 > 10; 10 m significantly "
                       "worst", "medians ordered inf >= 100 >= 55 >= 10 (ties allowed) and Mann-Whitney "
                       "p < 0.05 for inf vs 10", self._b1)]

    def _b1(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        names = [_dname(d) for d in self.DMAX]
        meds, finals = {}, {}
        for nm in names:
            rs = ok(outcomes, d_max=nm)
            if rs:
                finals[nm] = values(rs, "final")
                meds[nm] = float(np.median(finals[nm]))
        if len(meds) < len(names):
            return "missing cells", None, ""
        order = all(meds[a] >= meds[b] - 1e-9 for a, b in itertools.pairwise(names))
        p = mann_whitney(finals["inf"], finals["10"], "greater")
        ours = ", ".join(f"{k}: {v:.3f}" for k, v in meds.items()) + f"; inf vs 10 p = {p:.3g}"
        return ours, order and p < 0.05, "medians of the final solution, pooled over N_T"


def _dname(d: float) -> str:
    return "inf" if math.isinf(d) else f"{d:g}"


# -- E10: adaptive vs static in the dynamic FDO landscape (B6) ---------------------------------------------------

@register
class E10Dynamic(Experiment):
    name = "e10-dynamic"
    title = "E10: fuzzy-adaptive vs static RDPSO in a moving peaks landscape (numerical runner)"
    description = (
        "Thesis section 7.4.2 (digest E10, target B6). 600 x 600 m, peaks moved by a forced Duffing oscillator and "
        "smoothed (Algorithm 7.1, standard Duffing form, A19), 500 iterations, N_T in {25, 50, 100}, d_max = 15 m, "
        "dx_max = 0.75 m, subgroups 2/5/8, SC_max 30, R_w = 5 m, no obstacles (none are described for E10). Static: "
        "S1 (the thesis does not say which set; A-note). Adaptive: the chapter 7 fuzzy system (A17 output sets). "
        "Tracking value: the best objective value at the robots' positions, averaged over the run.")
    trials = 50
    smoke_trials = 2
    curves = (("current", "best value at the robots now"),)
    boxes = (("tracking", "mean tracking value"),)
    SIZES: ClassVar[tuple[int, ...]] = (25, 50, 100)

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        if smoke:
            return [{"n": 25, "mode": "static"}, {"n": 25, "mode": "adaptive"}]
        return [{"n": n, "mode": m} for n in self.SIZES for m in ("static", "adaptive")]

    def run(self, trial: Trial) -> TrialResult:
        params = {**SETS["S1"], "dx_max_m": 0.75, "d_max_m": 15.0, "subgroups_min": 2, "subgroups_init": 5,
                  "subgroups_max": 8, "sc_max": 30, "r_w_m": 5.0, "fuzzy": trial.cell["mode"] == "adaptive"}
        return numeric_trial(trial, "fdo_peaks", 600.0, trial.cell["n"], 100 if trial.smoke else 500, params, 15.0,
                             obstacles=False)

    def targets(self) -> list[Target]:
        return [Target("B6", "adaptive vs static tracking value per N_T", "adaptive: higher median, smaller IQR; "
                       "the IQR gap grows with N_T", "adaptive median >= static and adaptive IQR <= static for "
                       "every N_T", self._b6)]

    def _b6(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts, good, judged = [], True, False
        for n in self.SIZES:
            a, s = ok(outcomes, n=n, mode="adaptive"), ok(outcomes, n=n, mode="static")
            if not a or not s:
                continue
            judged = True
            ma, ms = median(a, "tracking"), median(s, "tracking")
            ia, i_s = iqr(a, "tracking"), iqr(s, "tracking")
            good &= ma >= ms and ia <= i_s
            parts.append(f"N {n}: median {ma:.3f} vs {ms:.3f}, IQR {ia:.3f} vs {i_s:.3f}")
        return ("; ".join(parts) or "no paired cells"), (good if judged else None), "adaptive vs static"


# -- E8: two-robot studies (B7) ----------------------------------------------------------------------------------

@register
class E8TwoRobots(Experiment):
    name = "e8-two-robots"
    title = "E8: two-robot phase-space studies, alpha and the cognitive/social balance (numerical runner)"
    description = (
        "Thesis section 7.2 (digest E8, target B7), in a 2.55 x 2.45 m arena with a light field, two point robots "
        "with eSwarBot step sizes (dx_max 0.1 m), one subgroup, no punishment (SC_max 10^4), 120 iterations. "
        "alpha study: one spot at the arena centre, robots start 0.5 m apart about 0.7 m from it, rho_i = 0.5 each "
        "(rho4 with d_max = 0.25 m), alpha in {0.01, 0.632, 0.99}. Shape of the approach: 'reversals' counts the "
        "iterations where the distance to the optimum grows again (0 for a monotone approach); 'turning' is the "
        "total heading change of the path. Cognition/socialisation study: a brighter and a dimmer spot 1.6 m apart, "
        "one robot at each, alpha 0.632, rho3 = rho4 = 0.1 (d_max 0.3 m), rho1 + rho2 = 1 in (0.1, 0.9) and (0.9, "
        "0.1); final distance between the robots. Connectivity study: one spot at the centre, robots 0.5 m apart "
        "next to it, d_max = 1 m, alpha 0.632, rho1 0.2, rho2 0.5, rho3 0.1, rho4 in {0.4, 0.8, 1.2}: final "
        "separation and its spread over the last 30 iterations. Obstacle study: the leader sits on the light (it "
        "starts there), the follower 1 m away with a 0.3 x 0.3 m obstacle between them whose near face is 0.5 m "
        "from the follower, R_w = 0.5 m, alpha 0.632, rho1 0.2, rho2 0.5, rho4 0.1 (d_max 1 m), rho3 in {0.4, 0.8, "
        "1.2} (the thesis prints rho2, A24): collisions (moves that would cross the obstacle), whether the follower "
        "reaches within 0.3 m of the light, and its largest retreat from the start away from the light.")
    trials = 20
    smoke_trials = 2
    curves = (("dist_opt", "distance to optimum [m]"),)
    boxes = (("reversals", "distance reversals"), ("final_sep", "final separation [m]"), ("collisions", "collisions"))

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        alphas = [{"study": "alpha", "alpha": a, "rho12": "0.5/0.5", "rho": 0.5} for a in (0.01, 0.632, 0.99)]
        social = [{"study": "social", "alpha": 0.632, "rho12": r, "rho": 0.1} for r in ("0.1/0.9", "0.9/0.1")]
        connect = [{"study": "connect", "alpha": 0.632, "rho12": "0.2/0.5", "rho": r} for r in (0.4, 0.8, 1.2)]
        obstacle = [{"study": "obstacle", "alpha": 0.632, "rho12": "0.2/0.5", "rho": r} for r in (0.4, 0.8, 1.2)]
        if smoke:
            return alphas[1:2] + social[:1] + connect[:1] + obstacle[:1]
        return alphas + social + connect + obstacle

    def run(self, trial: Trial) -> TrialResult:
        c = trial.cell
        rng = np.random.default_rng(trial.seed)
        size = (2.55, 2.45)
        obstacles = np.zeros((0, 4))
        r1, r2 = (float(v) for v in c["rho12"].split("/"))
        if c["study"] == "alpha":
            field = LightField([(1.275, 1.225, 1.0, 0.6)], size)
            a = rng.uniform(-math.pi, math.pi)
            mid = np.array([1.275, 1.225]) + 0.7 * np.array([math.cos(a), math.sin(a)])
            off = 0.25 * np.array([-math.sin(a), math.cos(a)])
            start = np.array([mid - off, mid + off])
            params = {"alpha": c["alpha"], "rho1": 0.5, "rho2": 0.5, "rho3": 0.5, "rho4": 0.5, "d_max_m": 0.25}
        elif c["study"] == "social":
            field = LightField([(0.475, 1.225, 1.0, 0.35), (2.075, 1.225, 0.8, 0.35)], size)
            start = np.array([[0.475, 1.225], [2.075, 1.225]]) + rng.normal(0, 0.02, (2, 2))
            params = {"alpha": c["alpha"], "rho1": r1, "rho2": r2, "rho3": 0.1, "rho4": 0.1, "d_max_m": 0.3}
        elif c["study"] == "connect":
            field = LightField([(1.275, 1.225, 1.0, 0.6)], size)
            a = rng.uniform(-math.pi, math.pi)
            off = 0.25 * np.array([math.cos(a), math.sin(a)])
            centre = np.array([1.275, 1.225])
            start = np.array([centre - off, centre + off])
            params = {"alpha": c["alpha"], "rho1": r1, "rho2": r2, "rho3": 0.1, "rho4": c["rho"], "d_max_m": 1.0}
        else:
            field = LightField([(1.8, 1.225, 1.0, 0.5)], size)
            start = np.array([[1.8, 1.225], [0.8, 1.225 + rng.normal(0, 0.02)]])
            obstacles = np.array([[1.3, 1.075, 1.6, 1.375]])
            params = {"alpha": c["alpha"], "rho1": r1, "rho2": r2, "rho3": c["rho"], "rho4": 0.1, "d_max_m": 1.0}
        params |= {"dx_max_m": 0.1, "r_w_m": 0.5, "subgroups_init": 1, "subgroups_max": 1, "sc_max": 10000,
                   "n_min": 1, "swarm_seed": int(rng.integers(1 << 31)), **NUMERIC}
        iters = 40 if trial.smoke else 120
        obs = obstacles if c["study"] == "obstacle" else None
        res = numerical.run(Rdpso, params, 2, iters, field, size, obs, numerical.LinkModel(), seed=trial.seed,
                            start=start, keep_logs=True)
        track = {0: [], 1: []}
        for rec in res.logs:
            if rec["topic"] == "rdpso":
                track[rec["robot"]].append((rec["x"], rec["y"]))
        opt = np.array(field.optimum())
        p0 = np.array(track[0])
        d = np.hypot(*(p0 - opt).T)
        steps = np.diff(p0, axis=0)
        heading = np.unwrap(np.arctan2(steps[:, 1], steps[:, 0])) if len(steps) > 1 else np.zeros(1)
        moving = np.hypot(*steps.T) > 1e-3 if len(steps) else np.zeros(0, bool)
        turning = float(np.sum(np.abs(np.diff(heading))[moving[1:]])) if len(steps) > 1 else 0.0
        sep = float(np.hypot(*(res.final_positions[0] - res.final_positions[1])))
        p1 = np.array(track[1])
        seps = np.hypot(*(p0[: len(p1)] - p1[: len(p0)]).T)
        d1 = np.hypot(*(p1 - opt).T)
        metrics = {
            "reversals": int(np.sum(np.diff(d) > 0.005)),
            "turning_rad": round(turning, 3),
            "final_dist_opt": round(float(d[-1]), 4),
            "final_sep": round(sep, 4),
            "sep_spread": round(float(np.std(seps[-30:])), 4),
            "late_spread": round(float(np.std(d[-40:])), 4),
            "collisions": res.collisions,
            "follower_reached": bool(d1.min() < 0.3),
            "follower_retreat": round(float(max(0.0, np.max(d1) - d1[0])), 4),
        }
        return TrialResult(metrics, {"dist_opt": np.round(d, 4).tolist()})

    def targets(self) -> list[Target]:
        return [
            Target("B7a", "alpha 0.01 / 0.632 / 0.99: shape of the approach", "0.01 monotone quasi-linear; 0.632 "
                   "spiral; 0.99 sustained oscillation or non-convergence", "reversals (steps away from the light) "
                   "rise with alpha, and the distance to the light varies more over the last 40 iterations at 0.99 "
                   "than at 0.632", self._alpha),
            Target("B7b", "final separation, rho1/rho2 = 0.1/0.9 vs 0.9/0.1", "a few cm vs about 1 m",
                   "0.1/0.9 median < 0.2 m and 0.9/0.1 median > 0.6 m", self._social),
            Target("B7c", "connectivity: separation vs rho4 = 0.4 / 0.8 / 1.2 with d_max = 1 m", "0.4 settles "
                   "loosely (large spiral) around d_max; larger rho4 holds d_max tighter; 1.2 hardly moves",
                   "|median separation - 1 m| and the spread shrink from 0.4 to 1.2", self._connect),
            Target("B7d", "obstacle: rho3 = 0.4 / 0.8 / 1.2, obstacle 0.5 m ahead", "0.4 stuck or collides; 0.8 "
                   "clean detour; 1.2 detour after a retreat of about 1.5 m", "collisions fall from 0.4 to 0.8 "
                   "and the follower reaches the light in most 0.8 trials", self._obstacle),
        ]

    def _connect(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        rows = {}
        for r in (0.4, 0.8, 1.2):
            rs = ok(outcomes, study="connect", rho=r)
            if rs:
                rows[r] = (median(rs, "final_sep"), median(rs, "sep_spread"))
        if len(rows) < 3:
            return "no trials", None, ""
        ours = "; ".join(f"rho4 {r}: separation {v[0]:.2f} m, spread {v[1]:.3f} m" for r, v in rows.items())
        err = [abs(rows[r][0] - 1.0) for r in (0.4, 0.8, 1.2)]
        spread = [rows[r][1] for r in (0.4, 0.8, 1.2)]
        return ours, err[0] >= err[2] and spread[0] >= spread[2], "medians over trials"

    def _obstacle(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        rows = {}
        for r in (0.4, 0.8, 1.2):
            rs = ok(outcomes, study="obstacle", rho=r)
            if rs:
                rows[r] = (mean(rs, "collisions"), mean(rs, "follower_reached"),
                           median(rs, "follower_retreat"))
        if len(rows) < 3:
            return "no trials", None, ""
        ours = "; ".join(f"rho3 {r}: collisions {v[0]:.1f}, reached {v[1]:.0%}, retreat {v[2]:.2f} m"
                         for r, v in rows.items())
        return ours, rows[0.4][0] >= rows[0.8][0] and rows[0.8][1] >= 0.5, "means (collisions, reached), median " \
            "(retreat) over trials"

    def _alpha(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        rows = {}
        for a in (0.01, 0.632, 0.99):
            rs = ok(outcomes, study="alpha", alpha=a)
            if rs:
                rows[a] = (median(rs, "reversals"), median(rs, "final_dist_opt"), median(rs, "late_spread"))
        if len(rows) < 3:
            return "; ".join(f"alpha {a}: reversals {v[0]:.0f}" for a, v in rows.items()) or "no trials", None, ""
        ours = "; ".join(f"alpha {a}: reversals {v[0]:.0f}, final distance {v[1]:.2f} m, late spread {v[2]:.3f} m"
                         for a, v in rows.items())
        good = rows[0.01][0] <= rows[0.632][0] <= rows[0.99][0] and rows[0.99][2] > rows[0.632][2]
        return ours, good, "medians over trials"

    def _social(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        a = ok(outcomes, study="social", rho12="0.1/0.9")
        b = ok(outcomes, study="social", rho12="0.9/0.1")
        if not a or not b:
            return "no trials", None, ""
        ma, mb = median(a, "final_sep"), median(b, "final_sep")
        return f"{ma:.2f} m vs {mb:.2f} m", ma < 0.2 and mb > 0.6, "median final separation"


# -- co-simulation: E2 arena (R1, R2) ----------------------------------------------------------------------------

@register
class E2Arena(Experiment):
    name = "e2-arena"
    title = "E2: RDPSO on 4, 8 and 12 emulated eSwarBots in the 2.55 x 2.45 m light arena (co-simulation)"
    description = (
        "Thesis section 4.7.2 (digest E2, targets R1 and R2), run in the full co-simulation: every robot's Arduino "
        "LLC emulated over CAN (rotate-then-go moves from quantised encoders), an XBee Series 2 module per robot on "
        "its serial port, the pybullet world, and poses from odometry. hil_configs/rdpso/rdpso_arena.toml: two light "
        "spots (the brighter reads about 830 counts on the 10-bit LDR, the dimmer about 715), no fixed obstacles, "
        "robots placed in two spirals (one per initial subgroup, Table 4.6: 0/2/3) centred on the two spots' "
        "perpendicular bisector, 1.31 m from each, dx_max 0.1 m, d_max 0.5 or 1.5 m (Table 4.6) "
        "enforced logically from shared positions (the thesis emulated the MANET range this way in the small "
        "arena), alpha 0.5, rho 0.2/0.4/0.8/0.8, SC_max 30, N_min max(1, N_I // 2), 1.5 s iterations (a move of up "
        "to 0.1 m fits after the hellos), 180 s trials; R1 pools both d_max per N_T, as the thesis' means do. "
        "Converged (A30): the "
        "swarm's best reading within 5 % of the brighter spot's peak; also reported: the first time a robot is "
        "within 0.25 m of it. Improvement rate (R2): iterations in which a robot improved its personal best, over "
        "all robot-iterations.")
    trials = 20
    smoke_trials = 1
    x_label = "time [s]"
    curves = (("best_light", "swarm best LDR reading [counts]"),)
    boxes = (("t_converge", "time to converge [s]"), ("improvement_rate", "personal-best improvements"))
    SIZES: ClassVar[tuple[int, ...]] = (4, 8, 12)
    THESIS_T: ClassVar[dict[int, float]] = {4: 77.0, 8: 106.0, 12: 112.0}
    D_MAX: ClassVar[tuple[float, ...]] = (0.5, 1.5)  # Table 4.6

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        if smoke:
            return [{"n": 4, "d_max": 0.5, "crashes": 0}]
        return ([{"n": n, "d_max": d, "crashes": 0} for d in self.D_MAX for n in self.SIZES]
                + [{"n": 12, "d_max": 0.5, "crashes": 2}])

    def run(self, trial: Trial) -> TrialResult:
        n = trial.cell["n"]
        duration = 40.0 if trial.smoke else 180.0
        rng = np.random.default_rng(trial.seed)
        crashed = sorted(int(r) for r in rng.choice(n, size=trial.cell["crashes"], replace=False))
        cfg = arena_variant(Path(trial.workdir) / "arena.toml", n, trial.seed, duration,
                            faults=[{"robot": r, "at_s": CRASH_AT_S} for r in crashed], d_max_m=trial.cell["d_max"])
        out = Path(trial.workdir) / "session"
        run_checked(cfg, out)
        res = score_arena(out, cfg, n, duration)
        res.metrics |= crash_figures(out, crashed, float(tomllib.loads(cfg.read_text())["robots"][0]["params"][
            "iteration_s"])) if crashed else {}
        return res

    def targets(self) -> list[Target]:
        return [
            Target("R1a", "success rate per N_T", "about 90 % for 4, 8 and 12", ">= 80 % for every N_T",
                   self._success),
            Target("R1b", "mean time to converge per N_T", "77 / 106 / 112 s", "within +/-30 % and increasing with "
                   "N_T", self._times),
            Target("R2", "personal-best improvements per robot-iteration", "about 15 % with 12 robots, slightly "
                   "lower with 4 and 8", "10-20 % with 12 robots", self._improve),
            Target("F1", f"two of 12 robots' firmware crashes at {CRASH_AT_S:g} s (battery deaths in the thesis)",
                   "the subgroup notices by missing hellos (3-hello link break) and carries on", "every mate "
                   "notices within 3 iterations; the trials are scored (success rate reported)", self._crashes),
        ]

    def _crashes(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        rs = ok(outcomes, n=12, crashes=2)
        if not rs:
            return "no trials", None, ""
        worst = values(rs, "notice_max_iterations")
        rate = mean(rs, "converged")
        ours = (f"slowest mate noticed after {worst.max():.0f} iterations (median {np.median(worst):.0f}); "
                f"converged in {rate:.0%} of {len(rs)} trials")
        return ours, bool(worst.max() <= 3), "counted from the first hello the crashed robots missed"

    def _success(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts, good = [], True
        for n in self.SIZES:
            rs = ok(outcomes, n=n, crashes=0)
            if rs:
                rate = mean(rs, "converged")
                good &= rate >= 0.8
                each = ", ".join(f"{d:g} m {mean(q, 'converged'):.0%}" for d in self.D_MAX
                                 if (q := ok(outcomes, n=n, d_max=d, crashes=0)))
                parts.append(f"{n}: {rate:.0%} of {len(rs)} ({each})")
        return ("; ".join(parts) or "no trials"), (good if parts else None), "both d_max pooled"

    def _times(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts, good, means = [], True, []
        for n in self.SIZES:
            rs = [r for r in ok(outcomes, n=n, crashes=0) if r.metrics.get("converged")]
            if rs:
                m = mean(rs, "t_converge")
                means.append(m)
                good &= abs(m - self.THESIS_T[n]) <= 0.3 * self.THESIS_T[n]
                each = ", ".join(f"{d:g} m {mean(q, 't_converge'):.0f} s" for d in self.D_MAX
                                 if (q := [r for r in ok(outcomes, n=n, d_max=d, crashes=0)
                                           if r.metrics.get("converged")]))
                parts.append(f"{n}: {m:.0f} s ({each})")
        if len(means) == len(self.SIZES):
            good &= means[0] <= means[1] <= means[2]
        return ("; ".join(parts) or "no converged trial"), (good if len(means) == len(self.SIZES) else None), \
            "mean over converged trials, both d_max pooled"

    def _improve(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        parts = {n: median(ok(outcomes, n=n, crashes=0), "improvement_rate") for n in self.SIZES
                 if ok(outcomes, n=n, crashes=0)}
        if not parts:
            return "no trials", None, ""
        ours = "; ".join(f"{n}: {v:.1%}" for n, v in parts.items())
        return ours, (0.10 <= parts[12] <= 0.20) if 12 in parts else None, "median over trials"


CRASH_AT_S = 60.2  # injected firmware crashes: mid-iteration, a minute into the run


def arena_variant(path: Path, n: int, seed: int, duration: float, faults: list[dict[str, Any]] | None = None,
                  **params: Any) -> Path:
    """hil_configs/rdpso/rdpso_arena.toml with ``n`` robots (N_T in their parameters too), a seed, a duration, and
    injected faults."""
    from bridge.core.config import to_toml

    raw = tomllib.loads((CONFIGS / "rdpso_arena.toml").read_text())
    raw["session"] |= {"seed": seed, "duration_s": duration}
    if faults:
        raw["faults"] = faults
    group = raw["robots"][0]
    group["count"] = n
    group["params"] |= {"n_total": n, "swarm_seed": seed % (1 << 31), **params}
    path.write_text(to_toml(raw))
    return path


def crash_figures(out: Path, crashed: list[int], iteration_s: float, crash_s: float = CRASH_AT_S) -> dict[str, Any]:
    """How many iterations each surviving mate of a crashed robot took to drop it (3-hello link break), counted from
    the first hello the crashed robots missed; a mate that never drops it counts as the rest of the run plus one.
    ``crashed`` may be robots that are only cut off (the other side of a partition starting at ``crash_s``): their
    subgroups are the ones they had before it."""
    logs, *_ = read_rdpso_session(out)
    k_missed = int(crash_s // iteration_s) + 1  # the first iteration whose hello the crashed robots miss
    by_k: dict[int, dict[int, dict[str, Any]]] = {}
    for robot, recs in logs.items():
        for rec in recs:
            by_k.setdefault(rec["k"], {})[robot] = rec
    before = by_k.get(k_missed - 1, {})
    dead_sids = {(before.get(d) or logs[d][-1])["sid"] for d in crashed if d in logs} - {0}
    delays = []
    for r, rec in before.items():
        if r in crashed or rec["sid"] not in dead_sids:
            continue
        alive = sum(1 for q, x in before.items() if q not in crashed and x["sid"] == rec["sid"])
        later = sorted(kk for kk in by_k if kk >= k_missed)
        for k in later:
            now = by_k[k].get(r)
            if now is not None and (now["sid"] != rec["sid"] or now["n_s"] <= alive):
                delays.append(k - k_missed + 1)
                break
        else:
            delays.append(later[-1] - k_missed + 2 if later else 1)
    return {"crashed": " ".join(map(str, crashed)), "mates_of_crashed": len(delays),
            "notice_max_iterations": max(delays) if delays else None}


# -- N1: the XBee radio's figures in the pavilion (co-simulation) -----------------------------------------------

@register
class N1Radio(Experiment):
    name = "n1-radio"
    title = "N1: XBee Series 2 RSSI and delivery vs distance in the 10 x 20 m pavilion (co-simulation)"
    description = (
        "Thesis section 3.2.3 (digest target N1): two robots wander among the pavilion's obstacles "
        "(hil_configs/demo.toml's arena) and one sends a message every 2 s through its emulated XBee Series 2 "
        "module over the radio medium (log-distance path loss, walls by ray casts, correlated shadowing, Rician "
        "fading, 802.15.4 PER, CSMA-CA); the receiver's RSSI is read from the module. One trial is one survey "
        "session (`swarm-sitl radio-survey`) with its own seed; 3600 s simulated (300 s in the smoke run).")
    trials = 5
    smoke_trials = 1
    x_label = "trial"
    boxes = (("median_rssi_2_4m_dbm", "median RSSI 2-4 m [dBm]"), ("pdr_beyond_10m", "delivery beyond 10 m"))

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        return [{"arena": "pavilion"}]

    def run(self, trial: Trial) -> TrialResult:
        from bridge.tools.radio_survey import run_survey

        cal = run_survey(str(REPO / "hil_configs" / "demo.toml"), str(Path(trial.workdir) / "survey"),
                         duration_s=300.0 if trial.smoke else 3600.0, seed=trial.seed % (1 << 31))
        return TrialResult({
            "messages": cal["messages"], "delivered": cal["delivered"],
            "median_rssi_2_4m_dbm": cal["median_rssi_2_4m_dbm"]["ours"],
            "crossing_m": cal["median_crosses_q_min_at_m"]["ours"],
            "pdr_beyond_10m": cal["delivery_beyond_10m"]["ours"],
            "weakest_dbm": cal["weakest_received_dbm"]["ours"],
            "furthest_m": cal["furthest_delivery_m"]["ours"],
        })

    def targets(self) -> list[Target]:
        return [
            Target("N1a", "median RSSI -75 dBm crossing distance", "about 3 m (2-4 m)", "median over trials in "
                   "[2, 4] m", lambda o: _median_in(o, "crossing_m", 2.0, 4.0, "{:.2f} m")),
            Target("N1b", "delivery ratio beyond 10 m", "about 2/3", "median over trials in [0.55, 0.8]",
                   lambda o: _median_in(o, "pdr_beyond_10m", 0.55, 0.8, "{:.3f}")),
            Target("N1c", "weakest packet received", "no reception below -94 dBm", ">= -94 dBm in every trial",
                   self._floor),
        ]

    def _floor(self, outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
        v = values(ok(outcomes), "weakest_dbm")
        if not len(v):
            return "no trials", None, ""
        return f"{v.min():.0f} dBm", bool(v.min() >= -94.0), "minimum over trials"


def _median_in(outcomes: list[Outcome], metric: str, lo: float, hi: float, fmt: str) -> tuple[str, bool | None, str]:
    rs = ok(outcomes)
    m = median(rs, metric)
    if math.isnan(m):
        return "no trials", None, ""
    return fmt.format(m) + f" (IQR {iqr(rs, metric):.3g}, {len(rs)} trials)", lo <= m <= hi, ""
