"""MAVLink from a ground station: the world's gateway (``bridge.hil.mavlink_gateway``) routing a datagram to the robots
by ``target_system``, and a robot's MAVLink face (``swarm_logic.mavlink.face``) handling what reaches it (commands,
modes, parameters, position targets) while its supervisor runs the robot.

An input is a stream of records, each a selector byte: below 0x40, raw bytes (a chunk) as they come off the wire;
otherwise a packet the harness frames as MAVLink 2 with a correct CRC, so mutations reach past the checksum: the
selector picks the message (one a face handles, or any of the dialect's), then a chunk of payload, the sender's system
and component bytes, and a flags byte (bit 0 marks it signed, with a 13-byte signature from the chunk's tail).
"""

from __future__ import annotations

import math
import os
import struct
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
import numpy as np
from pymavlink.dialects.v20 import common as mavlink
from pymavlink.generator.mavcrc import x25crc

from bridge.hil.mavlink_gateway import MavlinkGateway
from fuzz.harness import Cursor, FakeClock, Target, lp
from swarm_logic.drivers.llc_client import LlcState
from swarm_logic.families.rdpso.controller import Rdpso
from swarm_logic.mavlink.face import RATES, MavlinkFace
from swarm_logic.mavlink.supervisor import Supervisor
from swarm_logic.robot import Robot

HANDLED = [mavlink.MAVLINK_MSG_ID_COMMAND_LONG, mavlink.MAVLINK_MSG_ID_COMMAND_INT, mavlink.MAVLINK_MSG_ID_SET_MODE,
           mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST, mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
           mavlink.MAVLINK_MSG_ID_PARAM_SET, mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED,
           mavlink.MAVLINK_MSG_ID_HEARTBEAT]
ALL_IDS = sorted(mavlink.mavlink_map)


def packet(msg_id: int, payload: bytes, sysid: int, compid: int, seq: int = 0, signed: bool = False) -> bytes:
    """A MAVLink 2 frame of ``payload`` (trailing zeros trimmed, as senders do) with the dialect's CRC."""
    cls = mavlink.mavlink_map.get(msg_id)
    extra = cls.crc_extra if cls is not None else 0
    body = payload.rstrip(b"\0") or payload[:1]
    signature = b""
    if signed:
        body, signature = body[:-13] if len(body) > 13 else body, (payload[-13:] if len(payload) >= 13 else bytes(13))
    head = struct.pack("<BBBBBBBHB", 0xFD, len(body), 1 if signed else 0, 0, seq & 0xFF, sysid, compid,
                       msg_id & 0xFFFF, msg_id >> 16)
    crc = x25crc(head[1:] + body)
    crc.accumulate(bytes((extra,)))
    return head + body + struct.pack("<H", crc.crc) + signature


def datagrams(c: Cursor) -> list[bytes]:
    """The records of the module docstring, each as the bytes that go on the wire."""
    out = []
    seq = 0
    while c.more():
        sel = c.u8()
        if sel < 0x40:
            out.append(c.chunk())
            continue
        msg_id = HANDLED[sel % len(HANDLED)] if sel < 0xC0 else ALL_IDS[c.u8() % len(ALL_IDS)]
        payload = c.chunk()
        sysid, compid, flags = c.u8(), c.u8(), c.u8()
        seq += 1
        out.append(packet(msg_id, payload, sysid, compid, seq, bool(flags & 1)))
    return out


def record(msg: Any, sysid: int = 255, compid: int = 190) -> bytes:
    """Seed helper: a pymavlink message as a framed record (selector, payload, system, component, flags)."""
    mav = mavlink.MAVLink(None, sysid, compid)
    raw = msg.pack(mav)
    n = raw[1]
    msg_id = raw[7] | raw[8] << 8 | raw[9] << 16
    sel = 0x40 + HANDLED.index(msg_id) if msg_id in HANDLED else 0xC0
    pick = b"" if msg_id in HANDLED else bytes((ALL_IDS.index(msg_id),))
    return bytes((sel,)) + pick + lp(raw[10:10 + n]) + bytes((sysid, compid, 0))


def seed_messages() -> list[Any]:
    m = mavlink
    cmd = m.MAVLink_command_long_message
    return [
        m.MAVLink_heartbeat_message(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3),
        cmd(1, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0),
        cmd(1, 1, m.MAV_CMD_DO_SET_MODE, 0, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15, 0, 0, 0, 0, 0),
        cmd(0, 0, m.MAV_CMD_DO_CHANGE_SPEED, 0, 1, 0.3, -1, 0, 0, 0, 0),
        cmd(1, 1, m.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m.MAVLINK_MSG_ID_ATTITUDE, 50000, 0, 0, 0, 0, 0),
        cmd(1, 1, m.MAV_CMD_REQUEST_MESSAGE, 0, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0),
        cmd(1, 1, m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 0, 1, 0, 0, 0, 0, 0, 0),
        cmd(1, 1, m.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0, 1, 0, 0, 0, 0, 0, 0),
        cmd(1, 1, 31000, 0, math.nan, math.inf, 0, 0, 0, 0, 0),
        m.MAVLink_command_int_message(1, 1, m.MAV_FRAME_LOCAL_NED, m.MAV_CMD_DO_SET_MODE, 0, 0, 1, 10, 0, 0, 0, 0, 0),
        m.MAVLink_set_mode_message(1, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15),
        m.MAVLink_param_request_list_message(1, 1),
        m.MAVLink_param_request_read_message(1, 1, b"ALPHA", -1),
        m.MAVLink_param_request_read_message(1, 1, b"", 3),
        m.MAVLink_param_set_message(1, 1, b"ALPHA", 0.7, m.MAV_PARAM_TYPE_REAL32),
        m.MAVLink_param_set_message(1, 1, b"FUZZY", 2.0, m.MAV_PARAM_TYPE_INT32),
        m.MAVLink_param_set_message(1, 1, b"nope", 1.0, m.MAV_PARAM_TYPE_REAL32),
        m.MAVLink_set_position_target_local_ned_message(0, 1, 1, m.MAV_FRAME_LOCAL_NED, 0b1101_1111_1100, 1.0, 2.0, 0,
                                                        0, 0, 0, 0, 0, 0, 0, 0),
        m.MAVLink_set_position_target_local_ned_message(0, 1, 1, m.MAV_FRAME_BODY_NED, 0b0101_1110_0111, 0, 0, 0,
                                                        0.2, 0.0, 0, 0, 0, 0, 0, 0.3),
        m.MAVLink_set_position_target_local_ned_message(0, 1, 1, m.MAV_FRAME_LOCAL_OFFSET_NED, 0b1001_1111_1111, 0, 0,
                                                        0, 0, 0, 0, 0, 0, 0, 1.0, 0),
        m.MAVLink_statustext_message(m.MAV_SEVERITY_INFO, b"hello", 0, 0),
    ]


def _seeds() -> list[bytes]:
    msgs = seed_messages()
    framed = b"".join(record(msg) for msg in msgs)
    raw = b"".join(bytes((0x00,)) + lp(msg.pack(mavlink.MAVLink(None, 255, 190))) for msg in msgs[:6])
    garbage = bytes((0x01,)) + lp(b"\xfd\x09\x00\x00\x00\xff\xbe\x00\x00\x00garbage\xfe\x05") + record(msgs[1], 1, 1)
    return [framed, raw, garbage, b"".join(record(msg) for msg in msgs[9:])]


# -- the gateway -------------------------------------------------------------------------------------------------------
_GATEWAY: MavlinkGateway | None = None


def _gateway(data: bytes) -> None:
    """The records as one ground station's datagrams, routed to a swarm of robots (system ids 1-4), each datagram
    parsed by a fresh ground-station parser, as the gateway parses a new ground station's bytes."""
    global _GATEWAY
    if _GATEWAY is None:  # one UDP socket (on the loopback, any port) for the life of the fuzzing process
        _GATEWAY = MavlinkGateway("udpin:127.0.0.1:0", {0: 1, 1: 2, 2: 3, 3: 4})
    parser = _GATEWAY.parser()
    for datagram in datagrams(Cursor(data)):
        _GATEWAY.route(parser, datagram)
        _GATEWAY.route(_GATEWAY.parser(), datagram, robot=2)


# -- a robot's face ----------------------------------------------------------------------------------------------------
class _Link:
    """The face's byte link: what the ground station sent waits in ``inbox``; what the face writes is dropped."""

    def __init__(self) -> None:
        self.inbox = bytearray()

    def write(self, data: bytes) -> None:
        pass

    def read(self) -> bytes:
        data = bytes(self.inbox)
        self.inbox.clear()
        return data

    def close(self) -> None:
        pass


class _Llc:
    """A low level that obeys without moving: what the supervisor and the face need of an LLC."""

    def __init__(self) -> None:
        self.state = LlcState(x=1.0, y=1.0, theta=0.3, battery_v=8.1, battery_soc=90, heartbeat=1, sonar_m=0.8,
                              sonar_valid=True, odom_t=0.0)

    def poll(self) -> int:
        return 0

    def drive(self, v: float, w: float) -> None:
        pass

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        return 0

    def stop(self) -> None:
        pass

    def set_led(self, r: int, g: int, b: int) -> None:
        pass

    def set_odometry(self, x: float, y: float, theta: float) -> None:
        self.state.x, self.state.y, self.state.theta = x, y, theta


class _Radio:
    """A radio nobody hears (rdpso needs one)."""

    last_rssi_dbm = -60

    def send_nowait(self, dest64: int | None, data: bytes, *, options: int = 0, radius: int = 0) -> int:
        return 0

    def recv(self, timeout: float | None = 0.0) -> None:
        return None

    def poll(self) -> None:
        pass


QUIET = {name: 0.0 for name in RATES if name != "HEARTBEAT"}  # telemetry is not parsing: only what a command asks


def _face(data: bytes) -> None:
    """The records reach robot 1's face one by one; the supervisor ticks after each (0.05 s of the robot's clock
    pass), so commands take effect (arming, modes, a reboot, targets followed) before the next arrives."""
    clock = FakeClock()
    link = _Link()
    face = MavlinkFace(link, clock, 1, boot="disarmed", rates=QUIET)
    robot = Robot(0, clock, _Llc(), np.random.default_rng(1), {"n_total": 4}, xbee=_Radio(),  # type: ignore[arg-type]
                  mavlink=face, start_pose=(1.0, 1.0, 0.0))
    sup = Supervisor(Rdpso(), robot)
    sup.start()
    for wire in datagrams(Cursor(data)):
        link.inbox += wire
        sup.tick()
        clock.sleep(0.05)
    sup.tick()


TARGETS = [
    Target("mavlink_gateway", "the MAVLink gateway: a ground station's datagrams parsed (pymavlink) and routed",
           _gateway, _seeds),
    Target("mavlink_face", "a robot's MAVLink face: a ground station's packets (commands, modes, params, targets)",
           _face, _seeds),
]
