"""The virtual-regions part of ``swarm-sitl bench --study roy``: chapter 6's numerical cases with 1000 point agents
(``ch6-case2``, the target: at least 10x real time; ``ch6-case1`` and ``ch6-case3`` for comparison), and a session of
six SonPIs with the global controller hosting chapter 6's region planner and the overhead camera tracking them
(``hil_configs/sonpi/regions_ch6.toml``, shortened; target at least 2x real time). Figures only, never pass/fail."""

from __future__ import annotations

import time
import tomllib
from pathlib import Path
from typing import Any

from bridge.studies.roy.regions_scenarios import load_scenario, make_planner
from bridge.studies.roy.regions_world import run_mission

CH6_CASES = ("ch6-case2", "ch6-case1", "ch6-case3")  # the first is the target's
CH6_AGENTS = 1000
CH6_SEED = 1
TARGET_CH6_RTF = 10.0
QUICK_CH6_S = 10.0  # simulated seconds of the quick run (one case)
REGIONS_SESSION = Path(__file__).resolve().parents[3] / "hil_configs" / "sonpi" / "regions_ch6.toml"
TARGET_SESSION_RTF = 2.0


def ch6_figures(quick: bool = False, duration: float | None = None) -> list[str]:
    """Chapter 6's cases at ``CH6_AGENTS`` agents, seed ``CH6_SEED``, each a mission to its end (``duration``: that many
    simulated seconds; quick: ``ch6-case2`` alone, ``QUICK_CH6_S`` s); a line each: simulated and wall seconds, the
    real-time factor (simulated per wall second), CPU seconds and simulated seconds per CPU second (what a quiet core
    would give), and where the wall time went (planner, sonar cast, the law and the moves)."""
    max_s = duration if duration is not None else (QUICK_CH6_S if quick else None)
    lines = []
    for k, name in enumerate(CH6_CASES[:1] if quick else CH6_CASES):
        sc = load_scenario(name).with_agents(CH6_AGENTS)
        planner = make_planner(sc)
        cpu0 = time.process_time()
        res = run_mission(sc, planner, CH6_SEED, max_time_s=max_s)
        cpu = time.process_time() - cpu0
        p = res.perf
        wall = max(p["wall_s"], 1e-9)
        goal = f"target >= {TARGET_CH6_RTF:g}x" if k == 0 else "for comparison"
        end = "arrived" if res.summary["arrived"] else "not arrived"
        lines.append(
            f"  chapter 6 numerical model, {name} with {CH6_AGENTS} agents (seed {CH6_SEED}, {end}): "
            f"{p['sim_s']:.2f} simulated s in {p['wall_s']:.2f} s wall, rtf {p['sim_s'] / wall:.1f}x ({goal}); "
            f"{cpu:.2f} CPU-s ({p['sim_s'] / max(cpu, 1e-9):.1f} simulated s per CPU-s); wall s in the planner "
            f"{p['plan_s']:.2f}, the sonar cast {p['cast_s']:.2f}, the law and the moves {p['world_s']:.2f}"
        )
    return lines


def region_session(duration: float) -> dict[str, Any]:
    """``regions_ch6.toml`` for ``duration`` simulated seconds (the split comes at about 46 s, the merge at 88 s)."""
    raw = tomllib.loads(REGIONS_SESSION.read_text())
    raw["session"].update(duration_s=duration, name="roy-bench-regions6")
    return raw
