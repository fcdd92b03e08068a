"""RDPSO in the full co-simulation: emulated LLCs over CAN, XBee Series 2 modules, odometry, pybullet."""

from __future__ import annotations

import json
import tomllib
from collections import defaultdict
from pathlib import Path

import pytest

from bridge.config import to_toml
from bridge.rdpso_experiments import arena_variant, read_rdpso_session, score_arena
from tests.test_session import run

pytestmark = pytest.mark.session


def test_two_firmware_crashes_are_noticed_within_three_hellos_and_the_swarm_goes_on(tmp_path: Path) -> None:
    cfg = arena_variant(tmp_path / "arena.toml", 8, seed=21, duration=36.0)
    raw = tomllib.loads(cfg.read_text())
    crash_s = 15.2  # mid-iteration: the crashed robots' next hellos (at 16.5 s) never go out
    raw["faults"] = [{"robot": 1, "at_s": crash_s}, {"robot": 6, "at_s": crash_s}]
    cfg.write_text(to_toml(raw))
    out = tmp_path / "run"
    code, s = run(cfg, out, timeout=400)
    assert code == 0, s.get("error")
    assert sorted((f["robot"], f["kind"]) for f in s["failures"]) == [(1, "raised"), (6, "raised")]
    assert all("injected fault" in f["detail"] for f in s["failures"])
    assert [r["alive"] for r in s["per_robot"]] == [r not in (1, 6) for r in range(8)]

    logs, *_ = read_rdpso_session(out)
    it = raw["robots"][0]["params"]["iteration_s"]
    k_first_missed = int(crash_s // it) + 1
    by_k: dict[int, dict[int, dict]] = defaultdict(dict)
    for robot, recs in logs.items():
        for rec in recs:
            by_k[rec["k"]][robot] = rec
    before = by_k[k_first_missed - 1]
    dead = {1, 6}
    dead_sids = {logs[d][-1]["sid"] for d in dead}  # their subgroups when they crashed
    # who shared a subgroup with a crashed robot just before the crash
    mates = {r: rec["sid"] for r, rec in before.items() if r not in dead and rec["sid"] in dead_sids - {0}}
    assert mates, "no survivor shared a subgroup with the crashed robots"
    for r, sid in mates.items():
        alive_mates = sum(1 for q, rec in before.items() if q not in dead and rec["sid"] == sid)
        noticed = next(k for k in sorted(by_k) if k >= k_first_missed and r in by_k[k] and (
            by_k[k][r]["sid"] != sid or by_k[k][r]["n_s"] <= alive_mates))
        assert noticed - k_first_missed + 1 <= 3, (r, noticed, k_first_missed)
    last = max(by_k)
    assert set(by_k[last]) == set(range(8)) - dead  # the others carry on to the end of the run
    assert all(rec["t"] > 34.0 for rec in by_k[last].values())


def test_the_arena_swarm_climbs_the_light(tmp_path: Path) -> None:
    cfg = arena_variant(tmp_path / "arena.toml", 6, seed=4, duration=40.0)
    out = tmp_path / "run"
    code, s = run(cfg, out, timeout=400)
    assert code == 0, s.get("error")
    res = score_arena(out, cfg, 6, 40.0)
    curve = res.curves["best_light"]
    assert curve[-1] > curve[3] + 50  # the swarm best reading rose (LDR counts)
    assert 0.05 < res.metrics["improvement_rate"] < 0.8
    assert json.loads((out / "summary.json").read_text())["radio"]["totals"]["tx"]["frames"] > 6 * 20  # hellos
