"""A session's CAN buses as python-can and CAN tools see them: bus-off injected on one robot stops its motors
through the LLC watchdog and is reported; the traffic logged with python-can's loggers decodes with cantools and
the robot's DBC."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can
import numpy as np
import pytest

from bridge.core.recorder import iter_messages
from bridge.tools.canlog import decode, export
from swarm_logic.robots.eswarbot import eswarbot_llc_db
from tests.conftest import ROOT
from tests.core.test_session import cli

pytestmark = pytest.mark.session

BUS_OFF = ROOT / "hil_configs" / "demos" / "can_bus_off.toml"
DBC = ROOT / "swarm_logic" / "robots" / "eswarbot" / "eswarbot_llc.dbc"
FAULT_S, FAULT_END_S = 4.0, 9.0


@pytest.fixture(scope="module")
def bus_off_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, str]:
    out = tmp_path_factory.mktemp("bus_off") / "run"
    r = subprocess.run(cli("run", str(BUS_OFF), "--out", str(out)), cwd=ROOT, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return out, json.loads((out / "summary.json").read_text()), r.stderr


def test_bus_off_stops_the_motors_through_the_llc_watchdog(bus_off_run: tuple[Path, dict, str]) -> None:
    out, s, stderr = bus_off_run
    assert not s["failures"]  # a bus-off is not a robot failure: the robot lives on
    offs = [e for e in s["can_events"] if e["event"] == "bus_off"]
    assert offs and {(e["robot"], e["node"]) for e in offs} == {(0, "logic")}
    first = offs[0]["t_s"]
    assert FAULT_S <= first < FAULT_S + 0.02  # 32 destroyed frames at 500 kbit/s take milliseconds
    assert all(FAULT_S <= e["t_s"] < FAULT_END_S for e in offs)
    assert "robot 0: CAN node logic bus-off at sim t=4.0" in stderr  # the launcher said so
    nodes = s["per_robot"][0]["can"]["nodes"]
    assert nodes["logic"]["bus_off_count"] == len(offs) and nodes["logic"]["tx_errors"] >= 32 * len(offs)
    assert s["per_robot"][1]["can"]["error_frames"] == 0

    pwm: dict[int, list[tuple[float, list[int]]]] = {0: [], 1: []}
    status: list[tuple[float, dict]] = []
    poses = []
    db = eswarbot_llc_db()
    for topic, t, payload in iter_messages(out / "session.mcap"):
        if topic in ("/r000/llc/pins", "/r001/llc/pins"):
            m = json.loads(payload)
            if "pwm" in m:
                pwm[int(topic[2:5])].append((t / 1e9, m["pwm"]))
        elif topic == "/r000/can0":
            m = json.loads(payload)
            if m["name"] == "STATUS" and not m.get("error"):
                status.append((t / 1e9, db.decode_message(m["id"], bytes.fromhex(m["data"]))))
        elif topic == "/world/poses":
            m = json.loads(payload)
            poses.append((t / 1e9, m["x"][0], m["y"][0], m["x"][1], m["y"][1]))
    # the last DRIVE_CMD got through just before the fault; the watchdog stops the motors 0.5 s later (+ a loop)
    stop = next(t for t, p in pwm[0] if t > FAULT_S and p == [0, 0])
    assert FAULT_S + 0.4 <= stop <= FAULT_S + 0.52, stop
    assert all(p == [0, 0] for t, p in pwm[0] if stop <= t < FAULT_END_S)
    assert any(p != [0, 0] for t, p in pwm[0] if FAULT_END_S < t < FAULT_END_S + 0.2)  # it drives on after
    assert any(st["fault_watchdog"] for t, st in status if stop < t < FAULT_END_S)
    a = np.array(poses)
    still = (a[:, 0] > stop + 0.3) & (a[:, 0] < FAULT_END_S)
    assert np.ptp(a[still, 1]) < 0.005 and np.ptp(a[still, 2]) < 0.005  # robot 0 stands still...
    assert np.hypot(np.ptp(a[still, 3]), np.ptp(a[still, 4])) > 0.3  # ...while robot 1 drives on


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_session_can_log_decodes_with_cantools(bus_off_run: tuple[Path, dict, str], tmp_path: Path,
                                               suffix: str) -> None:
    out, s, _ = bus_off_run
    path = tmp_path / f"bus{suffix}"
    n = export(out / "session.mcap", path, {0, 1})
    frames = [m for m in can.LogReader(str(path)) if isinstance(m, can.Message) and not m.is_error_frame]
    assert n >= len(frames) and len(frames) == sum(r["can_frames"] for r in s["per_robot"])
    names = {name for msg, name, _sig in decode(path) if not msg.is_error_frame}
    assert {"DRIVE_CMD", "LED_CMD", "ENCODERS", "ODOMETRY", "SONAR", "LIGHT", "BATTERY", "STATUS"} <= names
    assert "" not in names  # every data frame is one the DBC knows
    stamps = [m.timestamp for m in frames]
    assert stamps == sorted(stamps) and stamps[-1] <= s["sim_time_s"]


def test_candump_log_through_cantools_cli(bus_off_run: tuple[Path, dict, str], tmp_path: Path) -> None:
    out, _, _ = bus_off_run
    log = tmp_path / "r0.log"
    r = subprocess.run(cli("canlog", str(out), str(log), "--robot", "0"), cwd=ROOT, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0 and "frames to" in r.stdout, r.stderr
    with open(log) as f:
        dec = subprocess.run([sys.executable, "-m", "cantools", "decode", str(DBC)], stdin=f, capture_output=True,
                             text=True, timeout=60)
    assert dec.returncode == 0
    assert "DRIVE_CMD(" in dec.stdout and "STATUS(" in dec.stdout and "fault_watchdog: 1" in dec.stdout
    assert "Unknown frame id" not in dec.stdout
