"""The field trials' faults and their bookkeeping: battery deaths, and partitions of the radio network."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from bridge.core.recorder import iter_messages
from bridge.media.radio import splits as _splits
from swarm_logic.families.rdpso.graph import components
from tests.conftest import ROOT
from tests.core.test_session import cli


def test_components_count_the_pieces_of_a_manet() -> None:
    a = np.zeros((6, 6))
    assert components(a) == 6 and components(np.zeros((0, 0))) == 0
    for i, j in ((0, 1), (1, 2), (3, 4)):
        a[i, j] = 1  # one way is enough: a link counts if it works either way
    assert components(a) == 3  # {0, 1, 2}, {3, 4}, {5}
    a[2, 5] = a[4, 5] = 1
    assert components(a) == 1


def test_partition_events_count_each_piece_that_breaks_off() -> None:
    assert _splits([1, 1, 2, 2, 1, 3]) == 3  # 1 -> 2, then 1 -> 3 (two pieces at once)
    assert _splits([0, 1, 1]) == 0  # robots arriving are not a split
    assert _splits([]) == 0


CFG = """[session]
duration_s = 8
seed = 2
[arena]
width_m = 6
length_m = 6
[[robots]]
count = 4
behaviour = "rssi_keeper"
xbee = { series = 2, baud = 115200 }
placement = { kind = "explicit", poses = [[1.0, 1.0, 90.0], [2.0, 1.0, 90.0], [3.0, 1.0, 90.0], [4.0, 1.0, 90.0]] }
[[faults]]
robot = 1
at_s = 3.0
kind = "battery_depleted"
"""


@pytest.mark.session
def test_a_battery_death_stops_the_robot_and_silences_its_radio(tmp_path: Path) -> None:
    cfg = tmp_path / "battery.toml"
    cfg.write_text(CFG)
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run")), cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    (failure,) = s["failures"]
    assert failure["robot"] == 1 and failure["kind"] == "battery_depleted" and failure["t_s"] == 3.0
    assert [x["alive"] for x in s["per_robot"]] == [True, False, True, True]
    assert s["per_robot"][1]["battery_v"] < 6.5  # two cells, empty
    poses, tx_after = [], 0
    for topic, t, payload in iter_messages(tmp_path / "run" / "session.mcap"):
        if topic == "/world/poses" and t >= 3.05e9:
            poses.append(json.loads(payload)["x"][1:2] + json.loads(payload)["y"][1:2])
        elif topic == "/radio/tx" and t >= 3.05e9 and json.loads(payload)["src"] == 1:
            tx_after += 1
    assert tx_after == 0
    assert np.ptp(np.array(poses), axis=0).max() < 1e-3  # it stopped where it was
    conn = s["radio"]["connectivity"]  # 1 m apart in a 6 m room: the three survivors still hear each other
    assert conn["pieces_max"] == 1 and conn["partition_events"] == 0 and conn["samples"] >= 7
