"""The Roy study's speed figures (``swarm-sitl bench --study roy``): 100 runs of the numerical chapter 3 scenario
(roy-ch3-v2, BAT re-tuning every agent's gains at every step, 25 bats x 50 iterations) stepped in batches over the
machine's cores (target: under 5 minutes), and one run through the controllers for comparison; then sessions of
SonPIs running chapter 3's law (fixed gains: the optimisers' cost is the numerical figure's) under the overhead
camera: six in tracking mode (``hil_configs/sonpi/camera_formation.toml``, target at least 2x real time) and thirty
in noise mode (target at least 1x), each with its real-time factor and every process's CPU seconds per simulated
second; then chapters 4-6's virtual regions (``regions_bench``): chapter 6's numerical cases with 1000 agents (target
at least 10x real time) and six SonPIs with the global controller hosting chapter 6's region planner under the
tracking camera (target at least 2x). Figures only, never pass/fail: the machine is shared and noisy."""

from __future__ import annotations

import os
import sys
import time
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from bridge.experiments.sessions import run_config
from bridge.studies.roy.numerical import SCENARIOS, ch3_batch, ch3_trial
from bridge.studies.roy.regions_bench import TARGET_SESSION_RTF, ch6_figures, region_session

RUNS = 100
QUICK_RUNS = 10
TARGET_S = 300.0
CAMERA_FORMATION = Path(__file__).resolve().parents[3] / "hil_configs" / "sonpi" / "camera_formation.toml"
SWARM_N = 30
TARGET_RTF = {"tracking": 2.0, "noise": 1.0}


def camera_sessions(duration: float) -> list[tuple[str, dict[str, Any]]]:
    """The two camera sessions: ``camera_formation.toml`` (six SonPIs, tracking), and the same with ``SWARM_N``
    SonPIs on a 6 x 5 grid in a 6 x 6 m arena, the camera in noise mode (too many to colour apart)."""
    six = tomllib.loads(CAMERA_FORMATION.read_text())
    six["session"].update(duration_s=duration, name="roy-bench-camera6")
    many = tomllib.loads(CAMERA_FORMATION.read_text())
    many["session"].update(duration_s=duration, name=f"roy-bench-camera{SWARM_N}", robots_per_process=15)
    many["arena"].update(width_m=6.0, length_m=6.0)
    many["obstacles"] = [{"type": "cylinder", "x": 3.0, "y": 3.6, "radius": 0.2}]
    group = many["robots"][0]
    group["count"] = SWARM_N
    group["placement"] = {"kind": "grid", "origin": [0.6, 0.6], "spacing_m": 0.45, "columns": 6, "yaw_deg": 45}
    group["params"] = {**group["params"], "target_x": 50.0, "target_y": 50.0}
    many["services"][0]["options"] = {"mode": "noise", "fps": 10}
    many["services"][1]["options"] = {**many["services"][1]["options"], "target": [5.0, 5.0]}
    return [("tracking", six), ("noise", many)]


def _session(name: str, raw: dict[str, Any], out_dir: str) -> dict[str, Any]:
    work = Path(out_dir) / name
    work.mkdir(parents=True, exist_ok=True)
    return run_config(raw, work, name)[0]


def session_line(what: str, raw: dict[str, Any], target: float, out_dir: str) -> str:
    """Run a session; its line: ``what``, its duration, real-time factor against ``target``, and every process's CPU
    seconds per simulated second."""
    s = _session(raw["session"]["name"], raw, out_dir)
    sim = max(float(s["sim_time_s"]), 1e-9)
    cpu = ", ".join(f"{p} {v / sim:.2f}" for p, v in sorted((s.get("process_cpu_s") or {}).items()))
    print(f"  ran {what}: rtf {s['rtf']}x", file=sys.stderr)
    return (
        f"  {what}, {raw['session']['duration_s']:g} s: rtf {s['rtf']}x (target >= {target:g}x), "
        f"{s['processes']} processes; CPU-s per simulated s: {cpu}"
    )


def camera_figures(duration: float, out_dir: str) -> list[str]:
    """Run the camera sessions; a line each: robots, mode, real-time factor against its target, and every
    process's CPU seconds per simulated second."""
    return [
        session_line(f"{raw['robots'][0]['count']} SonPIs, camera in {mode} mode", raw, TARGET_RTF[mode], out_dir)
        for mode, raw in camera_sessions(duration)
    ]


def _batch(seeds: list[int], max_s: float | None) -> tuple[int, int, float]:
    """Arrivals, simulated ticks and CPU seconds of one batch."""
    t0 = time.process_time()
    runs = ch3_batch(seeds, {"optimiser": "bat"}, SCENARIOS["roy-ch3-v2"], max_s)
    return sum(r.success for r in runs), sum(r.ticks for r in runs), time.process_time() - t0


def bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench") -> int:
    """``RUNS`` (``QUICK_RUNS``) seeded runs to arrival or the 600 s timeout (``duration``: simulated seconds per
    run instead), in one batch per core; then the camera sessions (``duration`` or 10 s quick, 30 s full); then
    the regions figures: the chapter 6 session (``duration`` or 10 s quick, 60 s full: through the split) and the
    1000-agent numerical cases (each to its end, ``duration`` s, or quick one case for 10 s)."""
    camera = camera_figures(duration or (10.0 if quick else 30.0), out_dir)
    regions = [
        session_line(
            "6 SonPIs, global controller hosting the ch6 region planner, camera in tracking mode",
            region_session(duration or (10.0 if quick else 60.0)),
            TARGET_SESSION_RTF,
            out_dir,
        )
    ]
    regions += ch6_figures(quick, duration)
    n = QUICK_RUNS if quick else RUNS
    jobs = max(1, min(os.cpu_count() or 1, n))
    seeds = list(range(1, n + 1))
    parts = [seeds[k::jobs] for k in range(jobs)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(jobs) as pool:
        out = list(pool.map(_batch, parts, [duration] * jobs))
    wall = time.perf_counter() - t0
    arrived, ticks, cpu = (sum(o[k] for o in out) for k in range(3))
    sim_s = ticks * 0.05
    t1 = time.process_time()
    ch3_trial(1, {"optimiser": "bat"}, SCENARIOS["roy-ch3-v2"], max_s=5.0)
    alone = (time.process_time() - t1) / 5.0
    print(f"\nswarm-sitl bench --study roy ({os.cpu_count()} cores)")
    print(f"  numerical chapter 3 scenario (roy-ch3-v2, BAT 25 x 50 every step, 6 agents): {n} runs in {wall:.1f} s "
          f"wall with {jobs} processes, {n / wall:.2f} runs/s (target for 100 runs: < {TARGET_S:g} s); "
          f"{arrived}/{n} arrived; {sim_s:.0f} simulated s, {cpu / max(sim_s, 1e-9):.4f} CPU-s per simulated s "
          f"({cpu / max(sim_s, 1e-9) * 200:.1f} CPU-s per 200-s run)")
    print(f"  ran {n} runs in {wall:.1f} s", file=sys.stderr)
    print(f"  one run through the controllers (RoyApf per agent, no batch): {alone:.3f} CPU-s per simulated s")
    for line in camera:
        print(line)
    print("  virtual regions (chapters 4-6):")
    for line in regions:
        print(line)
    return 0
