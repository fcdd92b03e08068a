"""The Zebro study's speed figures (``swarm-sitl bench --study zebro``): sessions of 20 DeciZebros with their legs on
ZebroBus, UWB radios and the mature algorithm (setup E6, realistic sensing; the election repeating its frames, so that
no lost frame halts the swarm for the whole run: the robots walk) at several packings, per body model
(target: at least 2x real time on two cores), and the wall time of the numerical 360-run table (target: under 2
minutes). Figures only, never pass/fail: the machine is shared and noisy."""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from bridge.core.config import to_toml
from bridge.core.launcher import run_session
from bridge.studies.zebro.cosim import scenario_config

FULL = [(5, "gait"), (10, "gait"), (20, "gait"), (10, "contact")]  # (robots per process, body model)
QUICK = [(10, "gait")]
TARGET_RTF = 2.0
TARGET_TABLE_S = 120.0


def body_models() -> tuple[str, ...]:
    """The DeciZebro's body models its options offer (``body``), the gait-level one alone if it has no choice."""
    from bridge.robots.decizebro.radio import RadioOptions

    field = RadioOptions.model_fields.get("body")
    return tuple(field.annotation.__args__) if field is not None else ("gait",)  # type: ignore[union-attr]


def bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench") -> int:
    dur = duration or (10.0 if quick else 30.0)
    models = body_models()
    cases = [(k, b) for k, b in (QUICK if quick else FULL) if b in models]
    rows = []
    code = 0
    for k, body in cases:
        raw = scenario_config("E6", "mature_resend", "realistic", 1, name="zebro-bench", robots_per_process=k)
        raw["session"]["duration_s"] = dur
        raw["decision"].pop("end_after_meal_s")  # run the whole duration, meal or not
        if body != "gait":
            raw["robots"][0]["body"] = body
        out = Path(out_dir) / f"zebro_k{k}_{body}"
        out.mkdir(parents=True, exist_ok=True)
        cfg = out.parent / f"zebro_k{k}_{body}.toml"
        cfg.write_text(to_toml(raw))
        res = run_session(str(cfg), None, str(out), progress=None, plot=False)
        s = res.summary
        code = code or res.code
        rows.append((k, body, s))
        print(f"  ran 20 Zebros, {k} per process, {body} body: rtf {s['rtf']}x (exit {res.code})", file=sys.stderr)
    from bridge.experiments.runner import execute_experiment

    with tempfile.TemporaryDirectory(prefix="swarm-sitl-bench-") as d:
        run = execute_experiment("zebro-decisions", out=d, smoke=quick, progress=False)
    print(f"\nswarm-sitl bench --study zebro ({os.cpu_count()} cores)")
    for k, body, s in rows:
        walked = sum(r.get("distance_m") or 0.0 for r in s["per_robot"]) / max(1, len(s["per_robot"]))
        print(f"  co-simulation, 20 DeciZebros (E6, mature with repeats, realistic), {k} per process, {body} body, "
              f"{dur:g} s: rtf {s['rtf']}x (target >= {TARGET_RTF:g}x), {s['processes']} processes, start-up "
              f"{s['startup_s']} s, CPU {s['cpu_s_per_robot_per_sim_s'] * 1000:.0f} ms per robot per simulated s, "
              f"{walked:.1f} m walked per robot")
    print(f"  numerical zebro-decisions, {run.total} runs{' (smoke)' if quick else ''}: {run.wall_s:.1f} s wall with "
          f"{os.cpu_count()} jobs (target for the 360-run table: < {TARGET_TABLE_S:g} s)")
    return code or (1 if run.failed else 0)
