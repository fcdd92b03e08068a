"""The PFSM study's speed figures (``swarm-sitl bench --study pfsm``): a session of 30 searchers and 30 targets on
emulated foot-bots in the 25 m^2 arena (every robot's base board and range-and-bearing board on its CAN bus; target:
at least 1x real time on two cores, packing allowed) at several packings, and the wall time of the numerical 270-run
grid (target: under 5 minutes). Figures only, never pass/fail: the machine is shared and noisy."""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from bridge.core.config import to_toml
from bridge.core.launcher import run_session
from bridge.studies.pfsm.cosim_experiments import scenario_config

FULL = (15, 30)  # robots per process
QUICK = (30,)
TARGET_RTF = 1.0
TARGET_GRID_S = 300.0


def bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench") -> int:
    dur = duration or (10.0 if quick else 30.0)
    rows = []
    code = 0
    for k in QUICK if quick else FULL:
        raw = scenario_config(30, 30, 1, max_s=dur, name="pfsm-bench", robots_per_process=k)
        raw["search"]["end_after_found_s"] = dur  # run the whole duration, every target found or not
        out = Path(out_dir) / f"pfsm_k{k}"
        out.mkdir(parents=True, exist_ok=True)
        cfg = out.parent / f"pfsm_k{k}.toml"
        cfg.write_text(to_toml(raw))
        res = run_session(str(cfg), None, str(out), progress=None, plot=False)
        code = code or res.code
        rows.append((k, res.summary))
        print(f"  ran 30 + 30 foot-bots, {k} per process: rtf {res.summary['rtf']}x (exit {res.code})",
              file=sys.stderr)
    from bridge.experiments.runner import execute_experiment

    with tempfile.TemporaryDirectory(prefix="swarm-sitl-bench-") as d:
        run = execute_experiment("pfsm-search", out=d, smoke=quick, progress=False)
    print(f"\nswarm-sitl bench --study pfsm ({os.cpu_count()} cores)")
    for k, s in rows:
        frames = s.get("message_counts", {}).get("can_frames", 0)
        cpu = s.get("process_cpu_s") or {}
        print(f"  co-simulation, 30 searchers + 30 targets (25 m^2), {k} per process, {dur:g} s: rtf {s['rtf']}x "
              f"(target >= {TARGET_RTF:g}x), {s['processes']} processes, start-up {s['startup_s']} s, "
              f"{frames / max(s['sim_time_s'], 1e-9):.0f} CAN frames per simulated s, world process "
              f"{cpu.get('world', 0) / max(s['sim_time_s'], 1e-9):.2f} CPU-s per simulated s, targets found "
              f"{(s.get('search') or {}).get('found')}")
    print(f"  numerical pfsm-search, {run.total} runs{' (smoke)' if quick else ''}: {run.wall_s:.1f} s wall with "
          f"{os.cpu_count()} jobs (target for the 270-run grid: < {TARGET_GRID_S:g} s)")
    return code or (1 if run.failed else 0)
