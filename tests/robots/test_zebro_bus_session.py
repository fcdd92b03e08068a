"""Two DeciZebros in a session: their programs walk through the locomotion layer on the simulated I2C bus to their
six leg modules; one program freezes at 3 s, and its legs stop within 2 s of the last sync write (Z-H3)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.core.recorder import iter_messages
from firmware_sim.robots.decizebro import zebrobus as zb
from tests.conftest import ROOT

pytestmark = pytest.mark.session

CONFIG = """
[session]
name = "zebro-bus"
duration_s = 8
seed = 4

[arena]
width_m = 8
length_m = 8

[[robots]]
count = 1
profile = "decizebro"
behaviour = "tests.support.zebro_walkers:Walker"
placement = { kind = "explicit", poses = [[1.5, 2.0, 0.0]] }

[[robots]]
count = 1
profile = "decizebro"
behaviour = "tests.support.zebro_walkers:FreezesAtThree"
placement = { kind = "explicit", poses = [[1.5, 5.0, 0.0]] }
"""

Q = 10_000_000


def legs(robot: dict) -> dict:
    """The leg modules' counters among the robot's own firmware entities (its radio has its own)."""
    return {role: c for role, c in robot["firmware"].items() if role.startswith("leg")}


def run(cfg: Path, out: Path, *extra: str) -> dict:
    cmd = [sys.executable, "-m", "bridge.tools.cli", "run", str(cfg), "--out", str(out), "--quiet", *extra]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    return json.loads((out / "summary.json").read_text())


def test_zebros_walk_on_their_leg_bus_and_stop_when_the_sync_stops(tmp_path: Path) -> None:
    cfg = tmp_path / "zebro.toml"
    cfg.write_text(CONFIG)
    out = tmp_path / "run"
    s = run(cfg, out)
    # the same session with both robots' firmware and logic in one process each records the same, byte for byte
    assert run(cfg, tmp_path / "packed", "--robots-per-process", "2")["digest"] == s["digest"]
    walker, frozen = s["per_robot"]
    assert not s["failures"]
    for rob in (walker, frozen):
        assert rob["i2c"]["slaves"] == {f"0x{0x10 + i:02X}": f"leg{i}" for i in range(6)}
        assert rob["i2c"]["nacks"] == rob["i2c"]["timeouts"] == 0
    # the walker walked forward at about the walking speed (0.31 m/s) once its legs had found their gait
    assert 0.25 * 7 < walker["distance_m"] < 0.4 * 8
    assert walker["final_pose"][0] > 1.5 + 1.7 and abs(walker["final_pose"][1] - 2.0) < 0.8
    assert all(legs(walker)[f"leg{i}"]["estops"] == 0 and legs(walker)[f"leg{i}"]["errors"] == 0 for i in range(6))
    assert s["message_counts"]["i2c_transactions"] == walker["i2c"]["transactions"] + frozen["i2c"]["transactions"]

    syncs: dict[int, list[int]] = {0: [], 1: []}
    duty: dict[int, list[tuple[int, float]]] = {i: [] for i in range(6)}
    poses: list[tuple[int, float, float]] = []
    for topic, t, data in iter_messages(out / "session.mcap"):
        if topic in ("/r000/i2c", "/r001/i2c"):
            m = json.loads(data)
            first = m["msgs"][0]
            if m["status"] == "ok" and first["addr"] == 0 and first["data"][:2] == f"{zb.SYNC_COUNTER:02x}":
                syncs[int(topic[2:5])].append(m["end_ns"])
        elif topic.startswith("/r001/leg") and topic.endswith("/pins"):
            duty[int(topic[9])].append((t, json.loads(data)["duty"]))
        elif topic == "/world/poses":
            p = json.loads(data)
            poses.append((t, p["x"][1], p["y"][1]))
    # once a second, at the first poll of the robot's devices (every 0.1 s) when it is due
    assert len(syncs[0]) == 8 and all(1e9 <= b - a <= 1.1e9 for a, b in zip(syncs[0], syncs[0][1:], strict=False))
    last = syncs[1][-1]
    assert 2.9e9 < last < 3.1e9 and len(syncs[1]) == 4  # written once a second (0, 1, 2, 3) until it froze
    for leg, loops in duty.items():
        off = next(t for t, d in loops if t > last and d == 0.0)
        assert off - last <= 2e9 + Q, (leg, off - last)  # the motor off 2 s after the last sync write
        assert all(d == 0.0 for t, d in loops if t >= off)  # and it stays off
    moved = [(t, x, y) for t, x, y in poses if t >= last + 2e9 + 600_000_000]
    assert math.dist(moved[0][1:], moved[-1][1:]) < 0.01  # the legs have run down: the body stands still
    assert all(leg["estops"] == 1 for leg in legs(frozen).values())
