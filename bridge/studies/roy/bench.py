"""The Roy study's speed figures (``swarm-sitl bench --study roy``): 100 runs of the numerical chapter 3 scenario
(roy-ch3-v2, BAT re-tuning every agent's gains at every step, 25 bats x 50 iterations) stepped in batches over the
machine's cores (target: under 5 minutes), and one run through the controllers for comparison. Figures only, never
pass/fail: the machine is shared and noisy."""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

from bridge.studies.roy.numerical import SCENARIOS, ch3_batch, ch3_trial

RUNS = 100
QUICK_RUNS = 10
TARGET_S = 300.0


def _batch(seeds: list[int], max_s: float | None) -> tuple[int, int, float]:
    """Arrivals, simulated ticks and CPU seconds of one batch."""
    t0 = time.process_time()
    runs = ch3_batch(seeds, {"optimiser": "bat"}, SCENARIOS["roy-ch3-v2"], max_s)
    return sum(r.success for r in runs), sum(r.ticks for r in runs), time.process_time() - t0


def bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench") -> int:
    """``RUNS`` (``QUICK_RUNS``) seeded runs to arrival or the 600 s timeout (``duration``: simulated seconds per
    run instead), in one batch per core."""
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
    return 0
