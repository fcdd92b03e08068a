"""Acceptance: MAVProxy-style use of a session. A pymavlink client on the swarm's one UDP endpoint sees every
robot's heartbeat (each its own system id), arms one, changes one of its parameters (and is refused a value out of
its range) and sends it to a position, which it reaches; the others, never armed, do not move."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from pathlib import Path

import pytest

from bridge.core.recorder import iter_messages
from tests.conftest import ROOT
from tests.core.test_session import cli, wait_started

pytestmark = pytest.mark.session

from pymavlink import mavutil  # noqa: E402  (MAVLINK20 is set by conftest first)

CFG = """
[session]
name = "mavlink"
duration_s = 3600
seed = 4
speed = 2
[arena]
width_m = 6
length_m = 6
[mavlink]
endpoint = "udpout:127.0.0.1:{port}"
boot = "disarmed"
[[robots]]
count = 4
behaviour = "random_walk"
[robots.placement]
kind = "explicit"
poses = [[1.5, 1.5, 0.0], [4.5, 1.5, 90.0], [1.5, 3.5, 0.0], [4.5, 4.5, 180.0]]
"""
ROBOT, SYSID = 2, 3  # robot 2 is system 3 (system_id_base 1)
GOAL_N, GOAL_E = 4.5, 2.5  # NED of the arena point x = 2.5, y = 4.5


def wait_for(conn: mavutil.mavfile, kind: str, cond, timeout: float = 120.0):  # only bounds a hang
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = conn.recv_match(type=kind, blocking=True, timeout=0.5)
        if m is not None and cond(m):
            return m
    raise AssertionError(f"no {kind} matching within {timeout} s")


def test_ground_station_arms_tunes_and_sends_a_robot(tmp_path: Path) -> None:
    gcs = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190,
                                     dialect="common")
    port = gcs.port.getsockname()[1]
    cfg = tmp_path / "mavlink.toml"
    cfg.write_text(CFG.format(port=port))
    out = tmp_path / "run"
    session = subprocess.Popen(cli("run", str(cfg), "--out", str(out)), cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    try:
        wait_started(session)
        seen: dict[int, object] = {}
        deadline = time.monotonic() + 120
        while len(seen) < 4 and time.monotonic() < deadline:
            m = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if m is not None:
                seen[m.get_srcSystem()] = m
        assert sorted(seen) == [1, 2, 3, 4]
        for hb in seen.values():
            assert hb.type == mavutil.mavlink.MAV_TYPE_GROUND_ROVER
            assert not hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED  # boot = "disarmed"

        gcs.mav.command_long_send(SYSID, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = wait_for(gcs, "COMMAND_ACK", lambda m: m.get_srcSystem() == SYSID and m.command == 400)
        assert ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
        wait_for(gcs, "HEARTBEAT", lambda m: m.get_srcSystem() == SYSID
                 and m.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

        gcs.mav.param_set_send(SYSID, 1, b"SPEED_MPS", 0.25, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)  # as MAVProxy
        pv = wait_for(gcs, "PARAM_VALUE", lambda m: m.get_srcSystem() == SYSID and m.param_id == "SPEED_MPS")
        assert pv.param_value == pytest.approx(0.25)
        gcs.mav.param_request_read_send(SYSID, 1, b"speed_mps", -1)  # any case
        pv = wait_for(gcs, "PARAM_VALUE", lambda m: m.get_srcSystem() == SYSID and m.param_id == "SPEED_MPS")
        assert pv.param_value == pytest.approx(0.25)
        gcs.mav.param_set_send(SYSID, 1, b"SPEED_MPS", 50, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)  # out of range
        pv = wait_for(gcs, "PARAM_VALUE", lambda m: m.get_srcSystem() == SYSID and m.param_id == "SPEED_MPS")
        assert pv.param_value == pytest.approx(0.25)  # refused: the value it keeps

        gcs.mav.command_long_send(SYSID, 1, mavutil.mavlink.MAV_CMD_DO_SET_MODE, 0,
                                  mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15, 0, 0, 0, 0, 0)
        ack = wait_for(gcs, "COMMAND_ACK", lambda m: m.get_srcSystem() == SYSID and m.command == 176)
        assert ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
        wait_for(gcs, "HEARTBEAT", lambda m: m.get_srcSystem() == SYSID and m.custom_mode == 15)
        gcs.mav.set_position_target_local_ned_send(0, SYSID, 1, mavutil.mavlink.MAV_FRAME_LOCAL_NED, 0x0FF8,
                                                   GOAL_N, GOAL_E, 0, 0, 0, 0, 0, 0, 0, 0, 0)
        there = wait_for(gcs, "LOCAL_POSITION_NED", lambda m: m.get_srcSystem() == SYSID
                         and math.hypot(m.x - GOAL_N, m.y - GOAL_E) < 0.08, timeout=240)
        assert abs(there.vx) < 0.3
    finally:
        if session.poll() is None:
            session.send_signal(signal.SIGINT)
        session.wait(timeout=240)
        gcs.close()
    s = json.loads((out / "summary.json").read_text())
    assert not s["failures"]
    m = s["mavlink"]
    assert m["from_gcs_packets"] == 6 and m.get("bad_packets", 0) == 0 and m["to_gcs_datagrams"] > 100
    per = {r["id"]: r for r in s["per_robot"]}
    for r in (0, 1, 3):
        assert per[r]["distance_m"] < 0.01  # never armed: never moved
    x, y = per[ROBOT]["final_pose"][:2]
    assert math.hypot(x - GOAL_E, y - GOAL_N) < 0.15  # the ground truth agrees with its odometry, within drift
    msgs = list(iter_messages(out / "session.mcap"))
    cmds = [json.loads(p)["type"] for topic, _t, p in msgs if topic == "/mavlink/from_gcs"]
    assert {"COMMAND_LONG", "PARAM_SET", "SET_POSITION_TARGET_LOCAL_NED"} <= set(cmds)
    refused = [json.loads(p) for topic, _t, p in msgs if topic == f"/r{ROBOT:03d}/log/mavlink_param_refused"]
    assert [(r["param"], r["value"]) for r in refused] == [("speed_mps", 50.0)]
