"""``pfsm-cosim``: the 25 m^2 arena's 9 scenarios (10, 20, 30 searchers x 10, 20, 30 targets) on emulated foot-bots,
beside the numerical model's runs of the same deployments.

Each trial is one session (``scenario_config``): the numerical study's deployment (``numerical.deploy``: searchers
uniform in the base strip, targets uniform in the rest, same seed same places), the base a grey floor patch under a
light, every robot a foot-bot with its base board and range-and-bearing board on its CAN bus, the controllers
unchanged with the grid's readings (``experiments.GRID_PARAMS``). Scored by the study's loop functions (``search``
in summary.json); the numerical model runs the same seed and scenario in the same trial, so each row carries both.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from bridge.experiments.runner import Experiment, Outcome, Target, Trial, TrialResult, register
from bridge.experiments.sessions import run_config
from bridge.experiments.stats import mean, ok
from bridge.studies.pfsm.experiments import GRID_PARAMS, SEARCHERS, TARGETS, search_trial
from bridge.studies.pfsm.numerical import Arena, deploy

SIDE = 5.0
COSIM_MAX_S = 240.0  # a session's limit (s): the numerical model's 25 m^2 runs find every target within ~230 s


def scenario_config(ns: int, nt: int, seed: int, max_s: float = COSIM_MAX_S, name: str | None = None,
                    robots_per_process: int = 30) -> dict[str, Any]:
    """A session of Khan's scenario (side 5 m, ``ns`` searchers, ``nt`` targets) deployed from ``seed`` as the
    numerical model deploys it."""
    arena = Arena(SIDE)
    dep = deploy(arena, ns, nt, seed)
    lx, ly = arena.light
    searchers = [[round(float(x), 4), round(float(y), 4), round(math.degrees(float(h)), 3)]
                 for (x, y), h in zip(dep.searchers, dep.headings, strict=True)]
    targets = [[round(float(x), 4), round(float(y), 4), 0.0] for x, y in dep.targets]
    return {
        "session": {"name": name or f"pfsm-{ns}x{nt}-{seed}", "duration_s": max_s, "seed": seed,
                    "robots_per_process": robots_per_process},
        "arena": {"width_m": SIDE, "length_m": SIDE,
                  "floor": [{"x_min": 0.0, "y_min": 0.0, "x_max": arena.base_depth_m, "y_max": SIDE, "grey": 0.5}]},
        "light": {"ambient_lux": 0.0, "sources": [{"x": lx, "y": ly, "peak_lux": 1000.0, "sigma_m": 2 * SIDE}]},
        "can": {"bitrate": 1_000_000},  # the marXbot's bus (ASEBA's CAN translator)
        "search": {"end_after_found_s": 0.0},
        "robots": [
            {"count": ns, "profile": "footbot", "behaviour": "pfsm_searcher", "params": dict(GRID_PARAMS),
             "placement": {"kind": "explicit", "poses": searchers}},
            {"count": nt, "profile": "footbot", "behaviour": "pfsm_target",
             "placement": {"kind": "explicit", "poses": targets}},
        ],
    }


def run_session(cfg: dict[str, Any], workdir: Path) -> dict[str, Any]:
    """Write ``cfg``, run it in ``workdir``, return its summary (a failed session raises)."""
    return run_config(cfg, workdir, "pfsm")[0]


def cosim_trial(ns: int, nt: int, seed: int, workdir: Path, max_s: float = COSIM_MAX_S) -> TrialResult:
    """One session and the numerical run of the same scenario and seed, side by side."""
    summary = run_session(scenario_config(ns, nt, seed, max_s), workdir)
    s = summary["search"]
    rab = (summary.get("radio") or {}).get("rab") or {}
    num = search_trial(SIDE, ns, nt, seed, GRID_PARAMS, max_s).metrics
    m: dict[str, Any] = {
        "found": s["found"], "missed": s["targets"] - s["found"], "all_found": s["all_found"],
        "t_total_s": s["t_total_s"], "e_total": s["e_total"],
        "p_sta": s["p_sta"], "home": s["home"],
        "rab_emissions_per_robot_s": round(rab.get("emitted", 0) / (ns + nt) / max(summary["sim_time_s"], 1e-9), 2),
        "rab_occluded_share": round(rab.get("occluded", 0) / max(1, rab.get("occluded", 0) + rab.get("heard_by", 0)),
                                    4),
        "num_found": num["found"], "num_t_total_s": num["t_total_s"], "num_e_total": num["e_total"],
        "num_p_sta": num["p_sta"],
    }
    return TrialResult(m)


@register
class PfsmCosim(Experiment):
    name = "pfsm-cosim"
    title = "PFSM-LJ search on emulated foot-bots: the 25 m^2 arena's 9 scenarios, co-simulated and numerical"
    description = (
        "Khan's 25 m^2 scenarios (digest 4.1): a closed 5 m square, the base the 1 m strip along the west wall (a grey "
        "floor patch, 0.5) under a light, 10, 20 or 30 searchers deployed in it and 10, 20 or 30 targets in the rest "
        "exactly as the numerical model deploys them for the same seed. Every robot a foot-bot of the pybullet world: "
        "its base board (wheel servo at 50 Hz, proximity and light rings and motor-ground sensors at 10 Hz) and its "
        "range-and-bearing board (3 m, 10 bytes, every 100 ms at its own phase, occluded by walls and bodies, ARGoS's "
        "zero noise and loss) on its 1 Mbit/s CAN bus, its computer running pfsm_searcher or pfsm_target through "
        "python-can and footbot.dbc, with the grid's readings (search_vector = diffusion, MaxTime_SEARCH 150 s). A "
        "session ends when every target has been found or at 240 s; the numerical model runs the same scenario and "
        "seed to the same limit (num_* columns). P_STA is eq. 2 from the study's loop functions.")
    trials = 5
    smoke_trials = 1
    boxes = (("p_sta", "P_STA (eq. 2), co-simulated"), ("t_total_s", "T_total (s), co-simulated"))
    means = (("searchers", ("p_sta", "num_p_sta"), "P_STA (eq. 2): co-simulated, numerical", {}),
             ("targets", ("p_sta", "num_p_sta"), "P_STA (eq. 2): co-simulated, numerical", {}),
             ("targets", ("t_total_s", "num_t_total_s"), "T_total (s): co-simulated, numerical", {}))

    def cells(self, smoke: bool) -> list[dict[str, Any]]:
        if smoke:
            return [{"searchers": 10, "targets": 10}]
        return [{"searchers": n, "targets": t} for n in SEARCHERS for t in TARGETS]

    def run(self, trial: Trial) -> TrialResult:
        c = trial.cell
        return cosim_trial(c["searchers"], c["targets"], trial.seed % (1 << 31), Path(trial.workdir))

    def targets(self) -> list[Target]:
        return [
            Target("P1", "every target found in co-simulation", "the numerical model finds them all in the 25 m^2 "
                   "arena", "every session finds every target within 240 s", _p1),
            Target("P2", "co-simulation agrees with the numerical model", "the same controllers on the same "
                   "deployments", "mean T_total within a factor of 2 of the numerical model's in every cell", _p2),
            Target("P3", "K-S3 in co-simulation: P_STA per swarm size", "best at 10, dip at 20, plateau at 30",
                   "P(10) highest, P(20) lowest, P(30) >= P(20)", _p3),
            Target("P4", "K-S4 in co-simulation: P_STA per target count", "clear positive slope",
                   "P(10) < P(20) < P(30)", _p4),
        ]


def _p1(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    rs = ok(outcomes)
    if not rs:
        return "no runs", None, ""
    missed = [r for r in rs if not r.metrics["all_found"]]
    num = sum(1 for r in rs if r.metrics["num_found"] == r.metrics["found"] + r.metrics["missed"])
    return f"{len(rs) - len(missed)} of {len(rs)} sessions found every target", not missed, \
        f"numerical, same scenarios: {num} of {len(rs)}"


def _p2(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    ratios = []
    for n in SEARCHERS:
        for t in TARGETS:
            rs = ok(outcomes, searchers=n, targets=t)
            if rs:
                ratios.append(mean(rs, "t_total_s") / max(1e-9, mean(rs, "num_t_total_s")))
    if not ratios:
        return "no runs", None, ""
    return (f"T_total co-sim / numerical: {min(ratios):.2f} .. {max(ratios):.2f} over {len(ratios)} cells",
            all(0.5 <= r <= 2.0 for r in ratios), "")


def _levels(outcomes: list[Outcome], key: str, levels: tuple[int, ...], metric: str) -> list[float]:
    return [mean(ok(outcomes, **{key: v}), metric) for v in levels]


def _trend(outcomes: list[Outcome], key: str, levels: tuple[int, ...], judge: Any) -> tuple[str, bool | None, str]:
    p = _levels(outcomes, key, levels, "p_sta")
    q = _levels(outcomes, key, levels, "num_p_sta")
    txt = "/".join("-" if math.isnan(v) else f"{v:.3g}" for v in p)
    if any(math.isnan(v) for v in p):
        return f"P_STA {txt}", None, "needs every level"
    return f"P_STA {txt}", bool(judge(*p)), "numerical, same seeds: " + "/".join(f"{v:.3g}" for v in q)


def _p3(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    return _trend(outcomes, "searchers", SEARCHERS, lambda a, b, c: a > b and a > c and c >= b)


def _p4(outcomes: list[Outcome]) -> tuple[str, bool | None, str]:
    return _trend(outcomes, "targets", TARGETS, lambda a, b, c: a < b < c)
