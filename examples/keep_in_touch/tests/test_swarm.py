"""keep_in_touch's integration tests: the swarm in swarm-sitl, driven in simulated time by the swarm_session fixture
(swarm-sitl's pytest plugin). Each test is as deterministic as a session: the same seed, the same outcome."""

from __future__ import annotations

import math
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

SWARM = Path(__file__).resolve().parents[1] / "configs" / "swarm.toml"
HELLO_S = 1.0  # the behaviour's hello period (its default)
GUIDED = 15  # ArduPilot Rover's custom mode number for GUIDED
POSITION_ONLY = 0b1101_1111_1100  # SET_POSITION_TARGET_LOCAL_NED: use x and y only


def neighbours(s, robot: int) -> set[int]:
    """Robot ``robot``'s neighbours as its own logs tell them so far."""
    known: set[int] = set()
    for line in s.logs(robot=robot):
        if line.topic == "neighbour_found":
            known.add(line.values["id"])
        elif line.topic == "neighbour_lost":
            known.discard(line.values["id"])
    return known


def test_the_swarm_stays_connected_for_a_minute(swarm_session):
    s = swarm_session(SWARM)
    for _ in range(6):
        s.run_for(10.0)
        assert all(neighbours(s, r) for r in s.robots), f"a robot heard nobody at t={s.t:.0f} s"
    radio = s.radio()["connectivity"]
    assert s.t == 60.0 and radio["samples"] >= 50
    assert radio["connected_share"] == 1.0 and radio["partition_events"] == 0
    assert all(s.alive(r) for r in s.robots)


def test_a_robot_whose_firmware_is_killed_is_dropped_within_three_hellos(swarm_session):
    s = swarm_session(SWARM)
    s.run_for(10.0)
    heard_it = [r for r in s.robots if r != 2 and 2 in neighbours(s, r)]
    assert heard_it, "robot 2 had no neighbour to lose it"
    s.fault("firmware_crash", robot=2)
    killed = s.t + 0.01  # faults take effect at the next quantum
    s.run_until(lambda s: all(2 not in neighbours(s, r) for r in heard_it), timeout_s=3 * HELLO_S)
    assert not s.alive(2)
    for r in heard_it:
        lost = [ln for ln in s.logs(robot=r, topic="neighbour_lost") if ln.values["id"] == 2]
        assert lost[-1].t_s - killed <= 3 * HELLO_S


def test_a_guided_go_to_over_mavlink_arrives_within_0_2_m(swarm_session):
    s = swarm_session(SWARM, mavlink=True)
    gcs = s.mavlink
    s.run_for(2.0)
    gcs.mav.command_long_send(gcs.system_id(0), 1, mavlink.MAV_CMD_DO_SET_MODE, 0,
                              mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED, 0, 0, 0, 0, 0)
    s.run_until(lambda s: gcs.last("COMMAND_ACK", 0) is not None, timeout_s=1.0)
    assert gcs.last("COMMAND_ACK", 0).result == mavlink.MAV_RESULT_ACCEPTED
    x, y = 5.0, 8.5  # the arena frame: MAVLink's local NED has north along y and east along x
    gcs.mav.set_position_target_local_ned_send(0, gcs.system_id(0), 1, mavlink.MAV_FRAME_LOCAL_NED, POSITION_ONLY,
                                               y, x, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    s.run_until(lambda s: math.dist(s.pose(0)[:2], (x, y)) <= 0.2, timeout_s=60.0)
    s.run_for(2.0)  # and it stays there
    assert math.dist(s.pose(0)[:2], (x, y)) <= 0.2


def test_an_xbee_unplugged_mid_run_fails_only_its_robot(swarm_session):
    s = swarm_session(SWARM)
    s.run_for(5.0)
    s.fault("unplugged", robot=1, device="xbee")
    s.run_until(lambda s: not s.alive(1), timeout_s=1.0)
    failure = [e.values for e in s.events() if e.values.get("robot") == 1 and e.values["kind"] == "raised"]
    assert failure and "device disconnected" in failure[0]["detail"]
    s.run_for(10.0)
    assert [r for r in s.robots if not s.alive(r)] == [1]
    assert all(1 not in neighbours(s, r) for r in s.robots if r != 1)
