"""The SonPI's Wi-Fi packets (docs/localisation.md, "Wire format"): the localisation service's pose broadcasts, a
robot's odometry to it, the global controller's mission and a robot's status. One codec for both ends.

Every packet is one UDP datagram, little-endian, starting with a 16-byte header:

    magic "SP" (2 bytes) | version u8 (1) | type u8 | seq u32 | t_us u64 (the sender's time of the content, us)

then by type:

- ``POSES`` (1): count u16, then per robot id u16, flags u8 (bit 0: valid), x, y, yaw, vx, vy (f32: m, rad, m/s,
  world frame). A robot the service cannot see this frame is sent with valid = 0 and zeros: no pose rather than a
  wrong one.
- ``ODOMETRY`` (2): id u16, x, y, yaw, v, w (f32: the robot's dead-reckoned pose in its odometry frame, its speed and
  turn rate), left, right (i32: encoder counts).
- ``MISSION`` (3): flags u8 (bit 0: run), target x, y (f32, m).
- ``STATUS`` (4): id u16, state u8 (``STATES``), flags u8 (bit 0: it has a pose), x, y, yaw (f32: its own estimate).

A datagram that is not one of these (another magic or version, an unknown type, a length that does not match, a
non-finite number) raises ``PacketError``: the receiver counts it and drops it.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

MAGIC = b"SP"
VERSION = 1
POSES, ODOMETRY, MISSION, STATUS = 1, 2, 3, 4
STATES = ("idle", "running", "arrived", "stopped")

_HEADER = struct.Struct("<2sBBIQ")
_COUNT = struct.Struct("<H")
_POSE = struct.Struct("<HB5f")
_ODOM = struct.Struct("<H5f2i")
_MISSION = struct.Struct("<B2f")
_STATUS = struct.Struct("<HBB3f")
MAX_ROBOTS = (65507 - _HEADER.size - _COUNT.size) // _POSE.size


class PacketError(ValueError):
    """A datagram that is not a valid SonPI packet."""


@dataclass(frozen=True, slots=True)
class Header:
    type: int
    seq: int
    t_s: float


@dataclass(frozen=True, slots=True)
class PoseEntry:
    id: int
    valid: bool
    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    vx_mps: float = 0.0
    vy_mps: float = 0.0


@dataclass(frozen=True, slots=True)
class Odometry:
    id: int
    x_m: float
    y_m: float
    yaw_rad: float
    v_mps: float
    w_radps: float
    left: int
    right: int


@dataclass(frozen=True, slots=True)
class Mission:
    run: bool
    target_x_m: float
    target_y_m: float


@dataclass(frozen=True, slots=True)
class Status:
    id: int
    state: str
    has_pose: bool
    x_m: float
    y_m: float
    yaw_rad: float


Content = list[PoseEntry] | Odometry | Mission | Status


def _header(kind: int, seq: int, t_s: float) -> bytes:
    return _HEADER.pack(MAGIC, VERSION, kind, seq & 0xFFFFFFFF, max(0, round(t_s * 1e6)))


def encode_poses(seq: int, t_s: float, poses: list[PoseEntry]) -> bytes:
    """A pose broadcast: every robot's entry (an invalid one carries zeros)."""
    if len(poses) > MAX_ROBOTS:
        raise ValueError(f"at most {MAX_ROBOTS} robots fit one datagram, got {len(poses)}")
    body = b"".join(
        _POSE.pack(p.id, 1, p.x_m, p.y_m, p.yaw_rad, p.vx_mps, p.vy_mps)
        if p.valid
        else _POSE.pack(p.id, 0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for p in poses
    )
    return _header(POSES, seq, t_s) + _COUNT.pack(len(poses)) + body


def encode_odometry(seq: int, t_s: float, o: Odometry) -> bytes:
    return _header(ODOMETRY, seq, t_s) + _ODOM.pack(o.id, o.x_m, o.y_m, o.yaw_rad, o.v_mps, o.w_radps, o.left, o.right)


def encode_mission(seq: int, t_s: float, m: Mission) -> bytes:
    return _header(MISSION, seq, t_s) + _MISSION.pack(int(m.run), m.target_x_m, m.target_y_m)


def encode_status(seq: int, t_s: float, s: Status) -> bytes:
    return _header(STATUS, seq, t_s) + _STATUS.pack(
        s.id, STATES.index(s.state), int(s.has_pose), s.x_m, s.y_m, s.yaw_rad
    )


def accept(data: bytes, kind: type, sender: int | None) -> tuple[str, Header | None, Content | None]:
    """A receiver's verdict on a datagram from robot ``sender`` (None: not a robot) that should carry ``kind``
    (``Odometry``, ``Status``): ``"ok"`` with its header and content; ``"ignored"``, another SonPI packet (a broadcast
    meant for others); ``"malformed"``, not a packet, or one naming another robot than its sender."""
    try:
        head, content = decode(data)
    except PacketError:
        return "malformed", None, None
    if not isinstance(content, kind):
        return "ignored", None, None
    if getattr(content, "id", sender) != sender:
        return "malformed", None, None
    return "ok", head, content


def _finite(values: tuple[float, ...]) -> None:
    if not all(math.isfinite(v) for v in values):
        raise PacketError("a number is not finite")


def decode(data: bytes) -> tuple[Header, Content]:
    """The header and content of a packet; ``PacketError`` if it is not one."""
    if len(data) < _HEADER.size:
        raise PacketError(f"{len(data)} bytes: shorter than a header")
    magic, version, kind, seq, t_us = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise PacketError(f"magic {magic!r} is not {MAGIC!r}")
    if version != VERSION:
        raise PacketError(f"version {version}, this codec speaks {VERSION}")
    head = Header(kind, seq, t_us / 1e6)
    body = memoryview(data)[_HEADER.size :]
    if kind == POSES:
        if len(body) < _COUNT.size:
            raise PacketError("a pose packet without its count")
        (n,) = _COUNT.unpack_from(body)
        if len(body) != _COUNT.size + n * _POSE.size:
            raise PacketError(f"{len(body)} bytes of body for {n} robots")
        out = []
        for i in range(n):
            rid, flags, *vals = _POSE.unpack_from(body, _COUNT.size + i * _POSE.size)
            _finite(tuple(vals))
            if flags & ~1:
                raise PacketError(f"unknown flags 0x{flags:02x}")
            out.append(PoseEntry(rid, bool(flags & 1), *vals))
        return head, out
    sizes = {ODOMETRY: _ODOM, MISSION: _MISSION, STATUS: _STATUS}
    fmt = sizes.get(kind)
    if fmt is None:
        raise PacketError(f"unknown type {kind}")
    if len(body) != fmt.size:
        raise PacketError(f"{len(body)} bytes of body for type {kind}, expected {fmt.size}")
    vals = fmt.unpack(body)
    if kind == ODOMETRY:
        _finite(vals[1:6])
        return head, Odometry(*vals)
    if kind == MISSION:
        _finite(vals[1:])
        if vals[0] & ~1:
            raise PacketError(f"unknown flags 0x{vals[0]:02x}")
        return head, Mission(bool(vals[0] & 1), vals[1], vals[2])
    rid, state, flags, x, y, yaw = vals
    _finite((x, y, yaw))
    if state >= len(STATES) or flags & ~1:
        raise PacketError(f"unknown state {state} or flags 0x{flags:02x}")
    return head, Status(rid, STATES[state], bool(flags & 1), x, y, yaw)
