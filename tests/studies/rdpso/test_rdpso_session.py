"""RDPSO in the full co-simulation: emulated LLCs over CAN, XBee Series 2 modules, odometry, pybullet."""

from __future__ import annotations

import json
import tomllib
from collections import defaultdict
from pathlib import Path

import pytest

from bridge.core.config import to_toml
from bridge.studies.rdpso.experiments import arena_variant, crash_figures
from bridge.studies.rdpso.sessions import read_rdpso_session, score_arena
from tests.core.test_session import run

pytestmark = pytest.mark.session

# several robots a process: the same recording as one robot a process (packing never changes a session's digest), in
# fewer processes; a crashed robot shares its firmware process with robots that must go on
PACKED = ("--robots-per-process", "4")


def test_two_firmware_crashes_are_noticed_within_three_hellos_and_the_swarm_goes_on(tmp_path: Path) -> None:
    cfg = arena_variant(tmp_path / "arena.toml", 8, seed=21, duration=36.0)
    raw = tomllib.loads(cfg.read_text())
    crash_s = 15.2  # mid-iteration: the crashed robots' next hellos (at 16.5 s) never go out
    raw["faults"] = [{"robot": 1, "at_s": crash_s}, {"robot": 6, "at_s": crash_s}]
    cfg.write_text(to_toml(raw))
    out = tmp_path / "run"
    code, s = run(cfg, out, *PACKED, timeout=600)
    assert code == 0, s.get("error")
    assert sorted((f["robot"], f["kind"]) for f in s["failures"]) == [(1, "raised"), (6, "raised")]
    assert all("injected fault" in f["detail"] for f in s["failures"])
    assert [r["alive"] for r in s["per_robot"]] == [r not in (1, 6) for r in range(8)]

    it = raw["robots"][0]["params"]["iteration_s"]
    figures = crash_figures(out, [1, 6], it, crash_s)
    assert figures["mates_of_crashed"] > 0, "no survivor shared a subgroup with the crashed robots"
    assert figures["notice_max_iterations"] <= 3  # every mate dropped them within three missed hellos

    logs, *_ = read_rdpso_session(out)
    dead = {1, 6}
    by_k: dict[int, dict[int, dict]] = defaultdict(dict)
    for robot, recs in logs.items():
        for rec in recs:
            by_k[rec["k"]][robot] = rec
    last = max(by_k)
    assert set(by_k[last]) == set(range(8)) - dead  # the others carry on to the end of the run
    assert all(rec["t"] > 34.0 for rec in by_k[last].values())


def test_the_arena_swarm_climbs_the_light(tmp_path: Path) -> None:
    cfg = arena_variant(tmp_path / "arena.toml", 6, seed=4, duration=40.0)
    out = tmp_path / "run"
    code, s = run(cfg, out, "--robots-per-process", "3", timeout=600)
    assert code == 0, s.get("error")
    res = score_arena(out, cfg, 6, 40.0)
    curve = res.curves["best_light"]
    assert curve[-1] > curve[3] + 50  # the swarm best reading rose (LDR counts)
    assert 0.05 < res.metrics["improvement_rate"] < 0.8
    assert json.loads((out / "summary.json").read_text())["radio"]["totals"]["tx"]["frames"] > 6 * 20  # hellos
