"""The SonPI's Wi-Fi packets (one codec for the services and the robot) and its sonpi_wifi device over a real UDP
link on loopback: poses served as sonpi_pose and sonpi_localisation, odometry and status sent, malformed packets
counted and dropped."""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import pytest

from swarm_logic.drivers.wifi import UdpLink
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.interfaces import LOCALISATION, POSE
from swarm_logic.robots.sonpi.wifi import MISSION, NoPose, open_sonpi_wifi


def test_every_packet_round_trips() -> None:
    poses = [pp.PoseEntry(0, True, 1.5, 2.25, -0.5, 0.125, -0.25), pp.PoseEntry(7, False)]
    head, got = pp.decode(pp.encode_poses(41, 12.5, poses))
    assert (head.type, head.seq, head.t_s) == (pp.POSES, 41, 12.5)
    assert got == poses
    odo = pp.Odometry(3, 0.5, -0.25, 1.0, 0.25, -0.5, 1234, -56)
    assert pp.decode(pp.encode_odometry(2, 1.0, odo))[1] == odo
    m = pp.Mission(True, 3.0, 2.5)
    assert pp.decode(pp.encode_mission(0, 0.0, m))[1] == m
    s = pp.Status(5, "running", True, 1.0, 2.0, 0.5)
    assert pp.decode(pp.encode_status(9, 3.0, s))[1] == s
    assert len(pp.encode_poses(0, 0.0, poses)) == 16 + 2 + 2 * 23  # the documented sizes


@pytest.mark.parametrize(
    "data, why",
    [
        (b"", "shorter than a header"),
        (b"XX" + bytes(14), "magic"),
        (struct.pack("<2sBBIQ", b"SP", 2, 1, 0, 0) + b"\x00\x00", "version"),
        (struct.pack("<2sBBIQ", b"SP", 1, 9, 0, 0), "unknown type"),
        (struct.pack("<2sBBIQ", b"SP", 1, 1, 0, 0) + b"\x02\x00" + bytes(23), "bytes of body for 2 robots"),
        (
            struct.pack("<2sBBIQ", b"SP", 1, 1, 0, 0) + b"\x01\x00" + struct.pack("<HB5f", 0, 1, math.nan, 0, 0, 0, 0),
            "not finite",
        ),
        (struct.pack("<2sBBIQ", b"SP", 1, 1, 0, 0) + b"\x01\x00" + struct.pack("<HB5f", 0, 4, 0, 0, 0, 0, 0), "flags"),
        (pp.encode_mission(0, 0.0, pp.Mission(True, 1.0, 1.0)) + b"\x00", "expected"),
        (struct.pack("<2sBBIQ", b"SP", 1, 4, 0, 0) + struct.pack("<HBB3f", 0, 9, 0, 0, 0, 0), "unknown state"),
    ],
)
def test_malformed_packets_are_refused_naming_why(data: bytes, why: str) -> None:
    with pytest.raises(pp.PacketError, match=why):
        pp.decode(data)


class Clock:
    """The robot's clock for a device test on the real link: wall time is the link's own, but the device asks only
    ``now`` (for its periods), which advances here by hand."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t


def test_the_device_serves_poses_sends_odometry_and_status_and_drops_malformed() -> None:
    service = UdpLink("udp://127.0.0.1:0")
    sent: list[tuple[str, dict]] = []
    reading = SimpleNamespace(
        t_s=0.5, x_m=0.1, y_m=0.2, yaw_rad=0.3, v_mps=0.4, w_rps=0.5, left_counts=10, right_counts=12
    )
    odometry = SimpleNamespace(read=lambda: reading)
    robot = SimpleNamespace(
        id=1,
        clock=Clock(),
        faces={"sonpi_odometry": odometry},
        devices={},
        log=lambda topic, **v: sent.append((topic, v)),
    )
    addr = f"127.0.0.1:{service.address[1]}"
    dev = open_sonpi_wifi(
        {
            "url": "udp://127.0.0.1:0",
            "localisation": addr,
            "controller": addr,
            "first_pose_timeout_s": 5.0,
            "log_period_s": 1.0,
        },
        robot,
    )
    try:
        me = f"127.0.0.1:{dev.link.address[1]}"
        faces = dev.faces()
        assert faces[LOCALISATION].poses() == [] and faces[MISSION].read() is None
        service.send(b"garbage", me)
        service.send(
            pp.encode_poses(
                3,
                1.0,
                [
                    pp.PoseEntry(0, True, 1.0, 1.0, 0.0, 0.0, 0.0),
                    pp.PoseEntry(1, True, 2.0, 3.0, 0.5, 0.1, 0.2),
                    pp.PoseEntry(2, False),
                ],
            ),
            me,
        )
        own = faces[POSE].read()  # waits for the first pose, taking the garbage on the way
        assert (own.id, own.x_m, own.y_m, own.yaw_rad) == (1, 2.0, 3.0, 0.5) and faces[POSE].fresh
        assert dev.counters["malformed"] == 1
        assert [p.id for p in faces[LOCALISATION].poses()] == [0]  # robot 2 unseen: no pose for it
        service.send(pp.encode_mission(0, 1.0, pp.Mission(True, 3.0, 3.0)), me)
        service.send(
            pp.encode_poses(4, 1.1, [pp.PoseEntry(0, True, 1.1, 1.0, 0.0, 0.0, 0.0), pp.PoseEntry(1, False)]), me
        )
        for _ in range(200):  # the packets cross the loopback in wall time
            dev.poll()
            if dev.counters["pose_packets"] == 2 and dev.mission is not None:
                break
            robot.clock.t += 0.01
        assert faces[MISSION].read().run and not faces[POSE].fresh and faces[POSE].read().x_m == 2.0
        # the camera lost it: its own odometry carries the last pose on (0.1 m ahead and 0.2 rad left in its frame)
        reading.x_m += 0.1 * math.cos(0.3)
        reading.y_m += 0.1 * math.sin(0.3)
        reading.yaw_rad += 0.2
        p = faces[POSE].read()
        assert (p.x_m, p.y_m) == pytest.approx((2.0 + 0.1 * math.cos(0.5), 3.0 + 0.1 * math.sin(0.5)))
        assert p.yaw_rad == pytest.approx(0.7) and p.vx_mps == pytest.approx(0.4 * math.cos(0.7))
        got = {pp.decode(service.recv(5.0)[0])[0].type for _ in range(2)}
        assert got == {pp.ODOMETRY, pp.STATUS}
        assert dev.counters["odometry_sent"] >= 1 and dev.counters["status_sent"] >= 1
        assert sent and sent[0][0] == "wifi_pose"
    finally:
        dev.close()
        service.close()


def test_no_pose_within_the_timeout_is_an_error_naming_the_setting() -> None:
    class Ticking(Clock):
        def now(self) -> float:
            self.t += 0.3
            return self.t

    robot = SimpleNamespace(id=0, clock=Ticking(), faces={}, devices={}, log=lambda *a, **k: None)
    dev = open_sonpi_wifi({"url": "udp://127.0.0.1:0", "first_pose_timeout_s": 0.5}, robot)
    try:
        with pytest.raises(NoPose, match="first_pose_timeout_s"):
            dev.faces()[POSE].read()
        t = robot.clock.t
        with pytest.raises(NoPose, match="still no pose"):  # the wait is the first read's only: no stall
            dev.faces()[POSE].read()
        assert robot.clock.t == t
    finally:
        dev.close()
    with pytest.raises(ValueError, match="unknown settings"):
        open_sonpi_wifi({"url": "udp://127.0.0.1:0", "port": 3}, robot)
