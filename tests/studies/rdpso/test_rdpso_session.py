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


@pytest.mark.long
def test_a_partition_and_a_board_reboot_the_swarm_rides_through(tmp_path: Path) -> None:
    """The RDPSO's fault tolerance (thesis ch. 5): a partition that cuts both subgroups is noticed as a crash is
    (each side drops the other within three missed hellos) and healed when it ends; a robot whose LLC reboots loses
    its odometry (the board's RAM) and iterates on with its subgroup."""
    cut_at, cut_s, reboot_at = 6.2, 8.0, 9.3
    faults = [{"kind": "partition", "at_s": cut_at, "groups": [[0, 1, 3], [2, 4, 5]], "duration_s": cut_s},
              {"kind": "firmware_reboot", "robot": 2, "at_s": reboot_at}]
    cfg = arena_variant(tmp_path / "arena.toml", 6, seed=4, duration=26.0, faults=faults)
    out = tmp_path / "run"
    code, s = run(cfg, out, "--robots-per-process", "6", timeout=600)
    assert code == 0 and not s["failures"], s.get("error")
    assert s["radio"]["impairments"]["partitioned"] > 0 and s["faults"]["count"] == {"firmware_reboot": 1}
    it = tomllib.loads(cfg.read_text())["robots"][0]["params"]["iteration_s"]
    for side in ([2, 4, 5], [0, 1, 3]):
        figures = crash_figures(out, side, it, cut_at)
        assert figures["mates_of_crashed"] > 0 and figures["notice_max_iterations"] <= 3, (side, figures)
    logs, *_ = read_rdpso_session(out)
    healed = int((cut_at + cut_s) // it) + 4  # three hellos after the partition's end
    sizes = {r: [rec["n_s"] for rec in recs if rec["k"] >= healed] for r, recs in logs.items()}
    assert all(n and min(n) == 3 for n in sizes.values()), sizes  # both subgroups whole again
    after = [rec for rec in logs[2] if reboot_at + 1.0 < rec["t"] < reboot_at + 1.0 + it]
    assert after and abs(after[0]["x"]) < 0.2 and abs(after[0]["y"]) < 0.2  # dead reckoning restarted at 0
    assert {recs[-1]["k"] for recs in logs.values()} == {logs[0][-1]["k"]}  # all iterate to the end
