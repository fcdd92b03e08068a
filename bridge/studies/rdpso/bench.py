"""The RDPSO study's speed figures (``swarm-sitl bench --study rdpso``): one E9 cell in the numerical runner (100
robots, 500 iterations, one core; target < 10 s), the same cell at scale (1000 robots, 500 iterations, one core;
goal < 60 s) and the co-simulation's real-time factor with the 12-robot arena. Figures only, never pass/fail: the
machine is shared and noisy."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from bridge.core.launcher import run_session
from bridge.studies.rdpso.sessions import CONFIGS


def numerical_cell(iterations: int = 500, n: int = 100, seed: int = 1) -> tuple[float, float, float]:
    """One E9 cell (peaks, S1, 300 x 300 m with obstacles) in the numerical runner, in this process: wall and CPU
    seconds, and the final best solution."""
    from bridge.experiments.runner import Trial
    from bridge.studies.rdpso.experiments import E9Static

    exp = E9Static()
    trial = Trial(exp.name, {"fn": "peaks", "n": n, "set": "S1"}, 0, seed, smoke=False, workdir=".")
    w0, c0 = time.perf_counter(), time.process_time()
    res = exp.run(trial, iterations)
    return time.perf_counter() - w0, time.process_time() - c0, float(res.metrics["final"])


SCALE_ROBOTS = 1000  # the scale goal: 1000 robots x 500 iterations in under 60 s on one core
SCALE_GOAL_S = 60.0


def bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench") -> int:
    """Numerical E9 cell wall time (< 10 s target), the 1000-robot cell's (< 60 s goal; with ``quick`` a few
    iterations only) and the arena's real-time factor."""
    iterations = 100 if quick else 500
    walls = []
    for seed in (1,) if quick else (1, 2, 3):
        wall, cpu, final = numerical_cell(iterations, seed=seed)
        walls.append(wall)
        print(f"numerical runner, E9 cell (peaks, S1, 100 robots, {iterations} iterations), seed {seed}: "
              f"{wall:.2f} s wall, {cpu:.2f} s CPU, final best {final:.4f}", file=sys.stderr)
    scale_its = 5 if quick else 500
    scale_wall, scale_cpu, scale_final = numerical_cell(scale_its, n=SCALE_ROBOTS, seed=1)
    print(f"numerical runner, E9 cell (peaks, S1, {SCALE_ROBOTS} robots, {scale_its} iterations), seed 1: "
          f"{scale_wall:.2f} s wall, {scale_cpu:.2f} s CPU, final best {scale_final:.4f}", file=sys.stderr)
    dur = duration or (20.0 if quick else 60.0)
    res = run_session(str(CONFIGS / "rdpso_arena.toml"), {"session.duration_s": dur},
                      str(Path(out_dir) / "rdpso_arena"), progress=None, plot=False)
    s = res.summary
    print(f"\nswarm-sitl bench --study rdpso ({os.cpu_count()} cores)")
    print(f"  numerical E9 cell, {iterations} iterations: median {sorted(walls)[len(walls) // 2]:.2f} s wall "
          f"(target for 500 iterations: < 10 s)")
    print(f"  numerical E9 cell, {SCALE_ROBOTS} robots, {scale_its} iterations: {scale_wall:.2f} s wall, "
          f"{scale_cpu:.2f} s CPU (goal for 500 iterations: < {SCALE_GOAL_S:g} s)")
    print(f"  co-simulation, rdpso_arena.toml, 12 robots, {dur:g} s: rtf {s['rtf']}x, {s['processes']} processes, "
          f"start-up {s['startup_s']} s (exit {res.code})")
    return res.code


