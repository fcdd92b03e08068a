"""Acceptance: the same host code talks to a simulated XBee through a ``sitl://`` port (inside the session) and
through a pseudo-terminal (from outside, in wall time), reading identity, sending unicast and broadcast, and
receiving the other robots' answers with RSSI."""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import pytest
import serial

from bridge.core.entities import xbee_serial64
from bridge.core.recorder import iter_messages
from swarm_logic.clock import WallClock
from swarm_logic.drivers.xbee import XBee
from tests.conftest import ROOT
from tests.core.test_session import cli, wait_started
from tests.support.xbee_probe import probe

pytestmark = pytest.mark.session

CFG = """
[session]
name = "xbee-probe"
duration_s = {duration}
seed = 11
speed = {speed}
[arena]
width_m = 8
length_m = 8
[[obstacles]]
type = "box"
x = 4
y = 6
size = [3.0, 0.2, 0.8]
[[robots]]
count = 1
behaviour = "{probe}"
xbee = {{ series = 2, api_mode = {api}, baud = 115200{pty} }}
[robots.placement]
kind = "explicit"
poses = [[4.0, 4.0, 0.0]]
[[robots]]
count = 2
behaviour = "tests.support.xbee_probe:Echo"
xbee = {{ series = 2, api_mode = 1, baud = 115200 }}
[robots.params]
speed_mps = 0.0
[robots.placement]
kind = "explicit"
poses = [[6.5, 4.0, 0.0], [4.0, 7.5, 90.0]]
"""


def check(res: dict) -> None:
    assert int(res["sh"] + res["sl"], 16) == xbee_serial64(0)
    assert res["ni"] == "r000" and res["series"] == 2
    assert res["unicast_status"] == 0 and res["broadcast_status"] == 0
    by = {}
    for e in res["echoes"]:
        by.setdefault(e["data"], e)
    # the unicast is answered by robot 1; the broadcast by robots 1 and 2 (robot 2 is behind a wall)
    assert set(by) == {"echo:ping-unicast from 1", "echo:ping-broadcast from 1", "echo:ping-broadcast from 2"}
    for e in res["echoes"]:
        assert e["src64"] in (xbee_serial64(1), xbee_serial64(2)) and not e["broadcast"]
        assert -94 <= e["rssi_dbm"] <= -30
    near = by["echo:ping-unicast from 1"]["rssi_dbm"]
    behind_wall = by["echo:ping-broadcast from 2"]["rssi_dbm"]
    assert near > behind_wall - 10  # 2.5 m in the open vs 3.5 m through a wall: not stronger by much
    assert 30 <= res["db"] <= 94


@pytest.mark.parametrize("api", [1, 2])
def test_xbee_through_a_sitl_port(tmp_path: Path, api: int) -> None:
    cfg = tmp_path / "probe.toml"
    cfg.write_text(CFG.format(duration=12, speed='"max"', probe="tests.support.xbee_probe:Probe", api=api, pty=""))
    out = tmp_path / "run"
    r = subprocess.run(cli("run", str(cfg), "--out", str(out), "--quiet"), cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    logged = [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/r000/log/probe"]
    assert len(logged) == 1, "the probe did not finish in the session"
    check(logged[0])


def test_xbee_through_a_pseudo_terminal(tmp_path: Path) -> None:
    cfg = tmp_path / "probe.toml"
    # a session far longer than the probe, stopped after it
    cfg.write_text(CFG.format(duration=3600, speed=1, probe="tests.support.xbee_probe:Idle", api=1,
                              pty=', pty = "xbee0"'))
    out = tmp_path / "run"
    p = subprocess.Popen(cli("run", str(cfg), "--out", str(out)), cwd=ROOT, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True)
    try:
        wait_started(p)
        link = out / "xbee0"
        assert link.is_symlink()
        with serial.Serial(str(link), 115200, timeout=0) as port:
            res = probe(XBee(port, WallClock(), api_mode=1, rssi_from_db=True), WallClock(),
                        [xbee_serial64(1), xbee_serial64(2)], patience_s=60)  # each wait ends on its answer
        check(res)
    finally:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(timeout=240)
        except subprocess.TimeoutExpired:
            p.kill()
    assert not (out / "xbee0").exists()  # the link goes with the session
