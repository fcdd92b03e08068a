"""``swarm-sitl bench``: the demo behaviour at several robot counts and process packings.

Prints, per case: robots, processes, real-time factor, per-tick barrier latency (median and p99: from
sending a quantum's ticks to the last answer, physics overlapped), CPU per robot (all processes,
start-up included), resident memory per robot, and start-up time. Figures only, never pass/fail: the
machine is shared and noisy.
"""

from __future__ import annotations

import os
import pstats
import sys
from pathlib import Path

from bridge.launcher import run_session

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "hil_configs" / "demo.toml"

# (robots, robots per process)
FULL = [(1, 1), (10, 1), (10, 5), (25, 5), (50, 10), (50, 25), (100, 25)]
QUICK = [(10, 1)]
TARGETS = {(10, 1): 5.0, (50, 10): 1.0, (50, 25): 1.0}


def run_bench(quick: bool = False, duration: float | None = None, out_dir: str = "runs/bench",
              markdown: bool = False, profile: bool = False, config: str | None = None) -> int:
    cases = QUICK if quick else FULL
    dur = duration or (10.0 if quick else 30.0)
    cfg = config or str(DEMO)
    rows = []
    for n, k in cases:
        out = Path(out_dir) / f"n{n}_k{k}"
        env_before = os.environ.get("SWARM_SITL_PROFILE")
        if profile:
            (out / "profile").mkdir(parents=True, exist_ok=True)
            os.environ["SWARM_SITL_PROFILE"] = str((out / "profile").resolve())
        try:
            res = run_session(cfg, {"robots.count": n, "session.robots_per_process": k, "session.duration_s": dur,
                                    "session.speed": "max"}, str(out), progress=None, plot=False)
        finally:
            if env_before is None:
                os.environ.pop("SWARM_SITL_PROFILE", None)
        s = res.summary
        rows.append((n, k, s))
        print(f"  ran {n} robots, {k} per process: rtf {s['rtf']}x (exit {res.code})", file=sys.stderr)
        if profile:
            _print_profile(out / "profile" / "world.prof")
    _print_table(rows, dur, markdown)
    failed = [r for r in rows if r[2]["exit_code"] != 0]
    return 1 if failed else 0


def _fmt(v: float | None, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def _print_table(rows: list, dur: float, markdown: bool) -> None:
    head = ["robots", "robots/proc", "processes", "RTF", "target", "barrier median", "barrier p99",
            "CPU per robot", "RSS per robot", "start-up"]
    lines = []
    for n, k, s in rows:
        target = TARGETS.get((n, k))
        lines.append([
            str(n), str(k), str(s["processes"]), _fmt(s["rtf"], ".2f") + "x",
            f">= {target:g}x" if target else "",
            _fmt(s["barrier_us_median"], ".0f") + " us", _fmt(s["barrier_us_p99"], ".0f") + " us",
            _fmt(s["cpu_s_per_robot_per_sim_s"] and s["cpu_s_per_robot_per_sim_s"] * 1000, ".0f") + " ms/sim-s",
            _fmt(s["rss_mb_per_robot"], ".0f") + " MB", _fmt(s["startup_s"], ".1f") + " s",
        ])
    print(f"\nswarm-sitl bench: demo behaviour, {dur:g} s simulated per case, quantum 10 ms, {os.cpu_count()} cores")
    if markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "|".join("---" for _ in head) + "|")
        for line in lines:
            print("| " + " | ".join(line) + " |")
    else:
        widths = [max(len(h), *(len(r[i]) for r in lines)) for i, h in enumerate(head)]
        print("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
        for line in lines:
            print("  ".join(c.rjust(w) for c, w in zip(line, widths, strict=True)))


def _print_profile(path: Path, top: int = 12) -> None:
    if not path.exists():
        return
    print(f"\nworld process profile ({path}), by cumulative time:")
    st = pstats.Stats(str(path), stream=sys.stdout)
    st.sort_stats("cumulative").print_stats(top)
