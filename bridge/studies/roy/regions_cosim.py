"""The co-simulated cells of ``roy-regions`` (kind "cosim"): SonPI sessions with the overhead camera and the global
controller hosting a region planner, the analogs of the thesis' hardware runs (chapter 7, digest 001 §4.5.2-4.5.3,
targets D1, D3, D4, D5 of §6).

A cell's scenario is a name of ``COSIM``: a session file of ``hil_configs/sonpi/`` (its comment header says which
thesis run it is the analog of), the number of robots (the file's first N poses), and a sensing profile of
``NOISE_FILE`` (``noiseless``: the thesis' simulation's sensing, exact poses and noiseless sonars; ``d1``: the noise
calibrated so that the region's area scatters as the thesis' hardware did, ``calibrate_d1``). A trial runs one session
(``bridge.experiments.sessions.run_config``) from the trial's seed (the sensors' noise, and the start poses jittered
by up to ``JITTER_M``, as a hand placing robots does), a smoke trial cut at ``SMOKE_S``, and reads its figures from
summary.json and the recording: the region's area over time (``/svc/controller/log/plan``) and its COV, the goal
time (the planner's ``done``, or the study's arrival test from the true poses for a planner without one), the
split and merge times and areas, the "all in circles" releases and region updates (chapter 5), the formations the
planner chose (chapter 4) and the formation error (``[formation]``).

Our robots are faster than the thesis' (0.15 m/s): a judge compares times after the speed calibration of
``docs/roy-ch4.md`` (one mission fixes the time scale, thesis / ours, and the others must fall within +-20 % of the
thesis' once scaled), or compares ratios; each says what it compared.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from bridge.core.recorder import iter_messages
from bridge.core.rng import stream
from bridge.experiments.runner import Outcome, Trial, TrialResult
from bridge.experiments.sessions import run_config
from bridge.experiments.stats import mean, values
from bridge.services.global_controller.regions import RegionController
from bridge.studies.roy import regions_judging as judging
from bridge.studies.roy.regions_judging import Verdict, every, fmt, no_runs
from swarm_logic.families.roy.regions.planner import PLANNERS

SONPI_DIR = Path(__file__).resolve().parents[3] / "hil_configs" / "sonpi"
NOISE_FILE = SONPI_DIR / "noise_profiles.toml"
SMOKE_S = 20.0  # smoke trials: this much simulated time per session
JITTER_M = 0.03  # start poses jittered by up to this (m), and their headings by up to JITTER_DEG, from the seed
JITTER_DEG = 10.0
UNIT_M = 0.1  # the thesis' length unit (digest §5.4)
UNIT_CM2 = 100.0  # one thesis unit^2 (0.1 m squared) in cm^2
TIME_TOL = 0.2  # D3-D5: +-20 % on times after the speed calibration
AREA_TOL = 0.2  # D4: +-20 % on areas
COV_TOL = 0.5  # D1: the area's COV within 50 % of the thesis' (as C4-COV)
NO_SCATTER = 1e-9  # D1: a COV below this is an area kept exactly (rounding leaves 1e-16)
LINES = ("line", "column", "row")  # the line formations (Algorithm 1's shapes)

# the thesis' figures (digest §6 D1, D3-D5; §4.5.2)
THESIS_COV = {3: 0.097, 6: 0.02}  # D1: hardware
THESIS_COV_NOISELESS = {3: 0.022, 6: 0.001}  # ... its simulation
THESIS_D3_GOAL = {3: 251.08, 6: 615.0}
THESIS_D4 = {"pre_split_cm2": 3120.0, "overlap_s": 220.0, "goal_s": 385.0, "final_cm2": 2400.0}
THESIS_D4_EXEC = {4: (309.7, 0.0733), 5: (349.56, 0.0461), 6: (386.77, 0.0381)}  # mean (s), COV
THESIS_D5 = {"circles_1": 42.0, "circles_2": 100.0, "boundary": 112.0, "goal": 367.0}


@dataclass(frozen=True)
class CosimScenario:
    """A co-simulated cell's session: ``config`` a file of ``hil_configs/sonpi/``, ``n`` its robots (the file's first
    ``n`` poses; None: all), ``noise`` a profile of ``NOISE_FILE`` (None: the file's own sensing), ``target`` the
    D target it serves, ``jitter`` whether the trial's seed jitters the start poses (else only the sensors' noise
    differs between trials)."""

    config: str
    target: str
    n: int | None = None
    noise: str | None = None
    jitter: bool = True


# the two-lane cells keep the file's start poses (a start 3 cm and 10 degrees off kept the ch6 detector from seeing
# both lanes): their trials differ by the seed's sensor noise alone, which can keep it from splitting too
# (docs/roy-regions.md, "What the co-simulated runs show")
COSIM: dict[str, CosimScenario] = {
    "d3-ch4-3": CosimScenario("regions_ch4_d3.toml", "D1, D3", noise="d1"),
    "d3-ch4-6": CosimScenario("regions_ch4_d3_6.toml", "D1, D3", noise="d1"),
    "d1-ch4-3-noiseless": CosimScenario("regions_ch4_d3.toml", "D1", noise="noiseless"),
    "d1-ch4-6-noiseless": CosimScenario("regions_ch4_d3_6.toml", "D1", noise="noiseless"),
    "d4-ch6-4": CosimScenario("regions_ch6.toml", "D4", n=4, jitter=False),
    "d4-ch6-5": CosimScenario("regions_ch6.toml", "D4", n=5, jitter=False),
    "d4-ch6-6": CosimScenario("regions_ch6.toml", "D4", n=6, jitter=False),
    "d5-ch5-3": CosimScenario("regions_ch5.toml", "D5"),
}


def noise_profiles() -> dict[str, dict[str, Any]]:
    """The sensing profiles of ``NOISE_FILE``, by name."""
    return tomllib.loads(NOISE_FILE.read_text())


def apply_noise(cfg: dict[str, Any], profile: dict[str, Any], workdir: Path) -> None:
    """Give every SonPI group the profile's sonar options and the camera service its options (in noise mode, its
    error model written to ``workdir``)."""
    for g in cfg["robots"]:
        g.update(profile.get("sonar", {}))
    cam = profile.get("camera")
    if cam is None:
        return
    opts = {k: v for k, v in cam.items() if k != "model"}
    if "model" in cam:
        path = workdir / "camera_noise.json"
        path.write_text(json.dumps({"model": cam["model"], "provenance": {"source": profile.get("source", "")}}))
        opts["noise_model"] = str(path)
    for s in cfg["services"]:
        if s["kind"] == "overhead_camera":
            s["options"] = opts


def session_config(
    name: str,
    seed: int,
    workdir: Path,
    max_s: float | None = None,
    profile: dict[str, Any] | None = None,
    planner: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The session of ``COSIM[name]`` from ``seed`` (the session's seed, the start poses' jitter), cut at ``max_s``;
    ``profile`` replaces the scenario's sensing profile and ``planner`` overrides parameters of its region planner
    (``calibrate_d1``'s sweep; a ValueError names an unknown parameter or a bad value)."""
    if name not in COSIM:
        raise ValueError(f"scenario: no co-simulated scenario {name!r}; known: {', '.join(COSIM)}")
    sc = COSIM[name]
    cfg = tomllib.loads((SONPI_DIR / sc.config).read_text())
    (group,) = cfg["robots"]
    poses = group["placement"]["poses"]
    n = sc.n or len(poses)
    if n > len(poses):
        raise ValueError(f"n: {sc.config} places {len(poses)} robots, not {n}")
    rng = stream(seed, "roy-regions", "cosim", name)
    jit = rng.uniform(-1.0, 1.0, (n, 3)) * [JITTER_M, JITTER_M, JITTER_DEG] * sc.jitter
    group["count"] = n
    group["placement"]["poses"] = [
        [round(p + d, 4) for p, d in zip(pose, j, strict=True)] for pose, j in zip(poses[:n], jit.tolist(), strict=True)
    ]
    cfg["session"].update(seed=seed, robots_per_process=n, name=f"{cfg['session']['name']}-{name}")
    if max_s is not None:
        cfg["session"]["duration_s"] = min(float(cfg["session"]["duration_s"]), max_s)
    if "formation" not in cfg:  # the study's loop functions: the formation scored, the session ended after "done"
        (ctl,) = [v["options"] for v in cfg["services"] if v["kind"] == "global_controller"]
        target, r_s = ctl["target"], ctl["params"]["planner_params"]["r_s"] * UNIT_M
        cfg["formation"] = {"target": target, "r_s_m": r_s, "end_on_event": "controller/done", "end_after_event_s": 1.0}
    if planner:
        override_planner(cfg, planner, sc.config)
    if profile is None and sc.noise is not None:
        profile = noise_profiles()[sc.noise]
    if profile is not None:
        apply_noise(cfg, profile, workdir)
    return cfg


def override_planner(cfg: dict[str, Any], params: dict[str, Any], source: str) -> None:
    """Set ``params`` in the planner parameters of the session's region controller (``source`` names the file in
    errors); a ValueError names a parameter the planner does not have or a value it refuses."""
    ctls = [s for s in cfg["services"] if s["kind"] == "global_controller" and s["options"]["controller"] == "region"]
    if len(ctls) != 1:
        raise ValueError(f"planner: {source} has {len(ctls)} region controllers, not one")
    opts = ctls[0]["options"]["params"]
    cls = PLANNERS.get(opts["planner"])
    names = {f.name for f in fields(cls.Params)} if hasattr(cls, "Params") else set()
    unknown = sorted(set(params) - names)
    if unknown:
        raise ValueError(f"planner: {unknown[0]!r} is not a parameter of planner {opts['planner']!r} ({source})")
    own = opts.get("planner_params", {})
    # each override alone (the error names it), then all together (a combination the planner refuses)
    for what, over in [*((f"{k} = {v!r}", {k: v}) for k, v in params.items()), (f"overrides {params}", params)]:
        try:
            RegionController.check_params({**opts, "planner_params": {**own, **over}})
        except ValueError as e:
            raise ValueError(f"planner: {source}: {what}: {e}") from None
    opts["planner_params"] = {**own, **params}


def _messages(mcap: Path, suffix: str) -> list[dict[str, Any]]:
    return [json.loads(d) for topic, _, d in iter_messages(mcap) if topic.endswith(suffix)]


def region_series(plans: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """Per plan with a region: its time, the regions' total area (units^2), their count, and the first region's
    semi-axes (NaN for a polygon)."""
    rows = [p for p in plans if p["regions"]]
    first = [p["regions"][0] for p in rows]
    return {
        "t": np.array([p["t"] for p in rows], float),
        "area": np.array([sum(r["area"] for r in p["regions"]) for p in rows], float),
        "regions": np.array([len(p["regions"]) for p in rows], float),
        "a": np.array([r.get("a", math.nan) for r in first], float),
        "b": np.array([r.get("b", math.nan) for r in first], float),
    }


def _cov(v: np.ndarray) -> float | None:
    return float(np.std(v, ddof=1) / np.mean(v)) if len(v) > 1 and np.mean(v) > 0 else None


def formation_figures(events: list[dict[str, Any]], ser: dict[str, np.ndarray]) -> dict[str, Any]:
    """Chapter 4: the planner's formations (``formation`` events: the first one's ``from`` at t = 0, then each
    ``to``), and the one in force where the region was narrowest (its b smallest: the corridor)."""
    forms = [e for e in events if e["kind"] == "formation" and "t" in e]
    if not forms:
        return {}
    changes = [(0.0, str(forms[0]["from"]))] if forms[0].get("from") else []  # the formation it started with
    changes += [(float(e["t"]), str(e["to"])) for e in forms]
    at_narrowest = None
    b = ser["b"]
    if np.isfinite(b).any():
        tn = float(ser["t"][int(np.nanargmin(b))])
        at_narrowest = next((s for t, s in reversed(changes) if t <= tn + 1e-9), changes[0][1])
    return {
        "formation_first": changes[0][1],
        "formation_sequence": " > ".join(f"{s}@{t:g}" for t, s in changes),
        "formation_changes": len(changes) - 1,
        "formation_at_narrowest": at_narrowest,
        "line_seen": any(s in LINES for _, s in changes),
    }


def split_merge_figures(events: list[dict[str, Any]], ser: dict[str, np.ndarray]) -> dict[str, Any]:
    """Chapter 6: the first split (time, sizes, the parent's area and the sub-areas' sum) and the first merge (time,
    its area and the sum of the merged areas), areas in cm^2."""
    splits = [e for e in events if e["kind"] == "split"]
    merges = [e for e in events if e["kind"] == "merge"]
    out: dict[str, Any] = {"splits": len(splits), "merges": len(merges)}
    if splits:
        s = splits[0]
        out |= {
            "split_s": s["t"],
            "split_sizes": "+".join(str(k) for k in s["sizes"]),
            "pre_split_cm2": s["parent_area"] * UNIT_CM2,
            "split_sum_cm2": sum(s["areas"]) * UNIT_CM2,
        }
        before = ser["t"] < s["t"]
        if before.any():
            out["pre_split_a_cm"] = float(ser["a"][before][-1]) * 10
            out["pre_split_b_cm"] = float(ser["b"][before][-1]) * 10
    if merges:
        m = merges[0]
        out |= {"merge_s": m["t"], "merge_cm2": m["area"] * UNIT_CM2, "merge_sum_cm2": sum(m["areas"]) * UNIT_CM2}
    return out


def circle_figures(events: list[dict[str, Any]]) -> dict[str, Any]:
    """Chapter 5: the "all in circles" releases of the iteration barrier and the region updates (new boundaries):
    how many, the first two releases' times and the first region made after the second."""
    rel = [float(e["t"]) for e in events if e["kind"] == "barrier" and e.get("reason") == "all in circles"]
    upd = [float(e["t"]) for e in events if e["kind"] == "region" and "t" in e]
    if not rel and not upd:
        return {}
    after = [t for t in upd if len(rel) > 1 and t >= rel[1]]
    return {
        "circle_releases": len(rel),
        "region_updates": len(upd),
        "circles_1_s": rel[0] if rel else None,
        "circles_2_s": rel[1] if len(rel) > 1 else None,
        "boundary_s": after[0] if after else None,
    }


def session_metrics(s: dict[str, Any], out: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """A trials.csv row from a session's summary and recording, and the region's series."""
    ctl = s["services"]["controller"]
    f = s.get("formation") or {}
    mcap = out / "session.mcap"
    events = _messages(mcap, "/svc/controller/log/event")
    ser = region_series(_messages(mcap, "/svc/controller/log/plan"))
    goal = ctl.get("done_s") if ctl.get("done_s") is not None else f.get("mission_s")
    area = ser["area"]
    metrics: dict[str, Any] = {
        "n": s["robots"],
        "arrived": goal is not None,
        "arrival_s": goal,
        "goal_by": "planner" if ctl.get("done_s") is not None else "arrival test" if goal is not None else None,
        "sim_s": s["sim_time_s"],
        "final_area": float(area[-1]) if len(area) else None,
        "final_cm2": float(area[-1]) * UNIT_CM2 if len(area) else None,
        "area_mean": float(np.mean(area)) if len(area) else None,
        "area_sd": float(np.std(area, ddof=1)) if len(area) > 1 else None,
        "area_cov": _cov(area),
        "fe_mean": f.get("fe_mean"),
        "nn_min_m": f.get("nn_min_m"),
        "planner_errors": ctl["planner_errors"],
        "malformed": ctl["malformed"],
        "went_silent": ctl["went_silent"],
        **formation_figures(events, ser),
        **split_merge_figures(events, ser),
        **circle_figures(events),
    }
    return metrics, ser


def cosim_trial(cell: dict[str, Any], trial: Trial) -> TrialResult:
    """One session of the cell's co-simulated scenario from the trial's seed (``SMOKE_S`` of it in a smoke run): its
    figures, and the region's area and axes per planner period."""
    wd = Path(trial.workdir)
    wd.mkdir(parents=True, exist_ok=True)
    cfg = session_config(cell["scenario"], trial.seed % (1 << 31), wd, SMOKE_S if trial.smoke else None)
    s, out = run_config(cfg, wd, "regions")
    metrics, ser = session_metrics(s, out)
    t = ser["t"].tolist()
    curves = {k: ser[k].tolist() for k in ("area", "a", "b")}
    timings = {"session_wall_s": float(s["wall_time_s"]), "cpu_s": float(s.get("cpu_s_total") or 0.0)}
    return TrialResult(metrics, curves, {k: t for k in curves}, timings)


# -- judging ---------------------------------------------------------------------------------------------------------


def _f(x: Any, nd: int = 1) -> str:
    return fmt(x, nd)


def whole(outcomes: list[Outcome], scenario: str) -> list[TrialResult]:
    """The results of a co-simulated scenario's whole sessions (a smoke run's stop early)."""
    return judging.whole(outcomes, scenario, kind="cosim")


def _none(outcomes: list[Outcome], cells: str) -> Verdict:
    return no_runs(outcomes, f"needs {cells}", f"smoke run: the sessions stop at {SMOKE_S:g} s")


def _within(x: float, ref: float, tol: float) -> bool:
    return math.isfinite(x) and abs(x - ref) <= tol * ref


def _goal(res: list[TrialResult]) -> float:
    """The mean goal time over runs that all arrived (NaN if one did not)."""
    t = values(res, "arrival_s")
    return float(np.mean(t)) if len(t) == len(res) and len(t) else math.nan


def judge_d1(outcomes: list[Outcome]) -> Verdict:
    """The region area's COV with the calibrated noise (the D3 cells) against the thesis' hardware figures, above the
    noiseless sessions' at each N, falling with N."""
    cov = {
        (n, p): mean(whole(outcomes, c), "area_cov")
        for n in (3, 6)
        for p, c in (("d1", f"d3-ch4-{n}"), ("noiseless", f"d1-ch4-{n}-noiseless"))
    }
    if all(math.isnan(v) for v in cov.values()):
        return _none(outcomes, "d3-ch4-3/6 and d1-ch4-3/6-noiseless")
    ours = "; ".join(
        f"N={n}: noisy {_f(cov[n, 'd1'], 4)} (thesis {THESIS_COV[n]}), noiseless {_f(cov[n, 'noiseless'], 4)} "
        f"(thesis {THESIS_COV_NOISELESS[n]})"
        for n in (3, 6)
    )
    if any(math.isnan(v) for v in cov.values()):
        return ours, None, "needs all four cells"
    near = all(_within(cov[n, "d1"], THESIS_COV[n], COV_TOL) for n in (3, 6))
    above = all(cov[n, "d1"] > cov[n, "noiseless"] for n in (3, 6))
    falls = cov[6, "d1"] < cov[3, "d1"]
    good = near and above and falls
    if max(cov.values()) < NO_SCATTER:
        return ours, False, "no scatter at all: chapter 4's repaired region keeps pi a b = pi r_c^2 exactly (A4)"
    why = (
        f"noisy COV within {100 * COV_TOL:g} % of the thesis' {'yes' if near else 'no'}, above noiseless "
        f"{'yes' if above else 'no'}, falling with N {'yes' if falls else 'no'} (COV of pi a b over each session's "
        "planner periods, mean over the runs)"
    )
    return ours, good, why


def judge_d3(outcomes: list[Outcome]) -> Verdict:
    """Speed calibrated on the 3-robot run (thesis 251.08 s): the 6-robot run's scaled goal time within +-20 % of
    615 s; a line formation (line, column, row) in force where the region was narrowest, in every run."""
    r3, r6 = whole(outcomes, "d3-ch4-3"), whole(outcomes, "d3-ch4-6")
    if not r3 or not r6:
        return _none(outcomes, "d3-ch4-3 and d3-ch4-6")
    g3, g6 = _goal(r3), _goal(r6)
    k = THESIS_D3_GOAL[3] / g3
    scaled = k * g6
    lines = sum(r.metrics.get("formation_at_narrowest") in LINES for r in r3 + r6)
    ours = (
        f"goal {_f(g3)} s (3), {_f(g6)} s (6); x {_f(k, 2)} (calibrated on 3): 6 robots {_f(scaled)} s; a line at "
        f"the narrowest region {lines}/{len(r3) + len(r6)}"
    )
    good = _within(scaled, THESIS_D3_GOAL[6], TIME_TOL) and lines == len(r3) + len(r6)
    why = "ratio 6/3 robots " + _f(g6 / g3, 2) + f" against the thesis' {THESIS_D3_GOAL[6] / THESIS_D3_GOAL[3]:.2f}"
    if math.isnan(g3) or math.isnan(g6):
        why = "a run did not arrive"
    return ours, good, why


def judge_d4(outcomes: list[Outcome]) -> Verdict:
    """Speed calibrated on N = 6's goal (thesis 386.77 s, the mean of its runs): the 6-robot session's pre-split
    area, split 3 + 3, the scaled overlap (merge) time and the final area against the thesis' (+-20 %); the scaled
    mean goal times of N = 4, 5 within +-20 % of 309.7 / 349.56 s, rising with N."""
    res = {n: whole(outcomes, f"d4-ch6-{n}") for n in (4, 5, 6)}
    if not res[6]:
        return _none(outcomes, "d4-ch6-6 (and -4, -5)")
    r6 = res[6]
    g = {n: _goal(r) for n, r in res.items() if r}
    k = THESIS_D4_EXEC[6][0] / g[6]
    pre, fin, merge = mean(r6, "pre_split_cm2"), mean(r6, "final_cm2"), k * mean(r6, "merge_s")
    split33 = sum(r.metrics.get("split_sizes") == "3+3" for r in r6)
    covs = {n: _cov(values(r, "arrival_s")) for n, r in res.items() if r}
    ours = (
        f"pre-split {_f(pre, 0)} cm^2, split 3+3 {split33}/{len(r6)}, merge {_f(mean(r6, 'merge_s'))} s "
        f"(x {_f(k, 2)}: {_f(merge)} s), final {_f(fin, 0)} cm^2; goal "
        + ", ".join(f"N={n} {_f(v)} s ({_f(k * v)} scaled, COV {_f(covs.get(n), 4)})" for n, v in g.items())
    )
    checks = {
        "pre-split area": _within(pre, THESIS_D4["pre_split_cm2"], AREA_TOL),
        "split 3+3": split33 == len(r6),
        "overlap time": _within(merge, THESIS_D4["overlap_s"], TIME_TOL),
        "final area": _within(fin, THESIS_D4["final_cm2"], AREA_TOL),
    }
    if all(n in g for n in (4, 5)):
        checks["N=4, 5 times"] = all(_within(k * g[n], THESIS_D4_EXEC[n][0], TIME_TOL) for n in (4, 5))
        checks["rising with N"] = g[4] < g[5] < g[6]
    failed = [c for c, v in checks.items() if not v]
    why = "failed: " + ", ".join(failed) if failed else "all of: " + ", ".join(checks)
    why += f" (thesis pre-split {THESIS_D4['pre_split_cm2']:g}, final {THESIS_D4['final_cm2']:g} cm^2)"
    return ours, not failed, why


def judge_d5(outcomes: list[Outcome]) -> Verdict:
    """Speed calibrated on the goal (thesis 367 s): the first two "all in circles" releases and the first new
    boundary after the second, scaled, within +-20 % of 42, 100 and 112 s, in that order, in every run."""
    res = whole(outcomes, "d5-ch5-3")
    if not res:
        return _none(outcomes, "d5-ch5-3")
    goal = _goal(res)
    k = THESIS_D5["goal"] / goal
    got = {key: k * mean(res, f"{key}_s") for key in ("circles_1", "circles_2", "boundary")}
    keys = ("circles_1_s", "circles_2_s", "boundary_s", "arrival_s")
    ordered = every(
        res,
        lambda m: (
            all(m.get(key) is not None for key in keys)  # a run that never arrived (or never released) is out of order
            and m["circles_1_s"] < m["circles_2_s"] <= m["boundary_s"] < m["arrival_s"]
        ),
    )
    near = {key: _within(v, THESIS_D5[key], TIME_TOL) for key, v in got.items()}
    ours = (
        f"goal {_f(goal)} s (x {_f(k, 2)}); scaled: "
        + ", ".join(f"{key} {_f(v)} s" for key, v in got.items())
        + f"; releases {_f(mean(res, 'circle_releases'), 1)}, regions {_f(mean(res, 'region_updates'), 1)} per run"
    )
    arrived = sum(r.metrics.get("arrival_s") is not None for r in res)
    failed = [key for key, v in near.items() if not v] + ([] if ordered else ["order"])
    failed += [] if arrived == len(res) else [f"arrived {arrived}/{len(res)}"]
    why = "failed: " + ", ".join(failed) if failed else "times and order"
    return ours, not failed and not math.isnan(goal), why + " (thesis 42, 100, 112, 367 s)"
