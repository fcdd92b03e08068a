"""The SonPI's Wi-Fi packets (docs/localisation.md, "Wire format"): the localisation service's pose broadcasts, a
robot's odometry to it, the global controller's mission and a robot's status (version 1); a robot's sonar window to
the global controller and the region controller's plan to the robots (version 2). One codec for both ends.

Every packet is one UDP datagram, little-endian, starting with a 16-byte header:

    magic "SP" (2 bytes) | version u8 | type u8 | seq u32 | t_us u64 (the sender's time of the content, us)

A packet carries the version that defined its type (``SINCE``): version 1's packets are byte for byte what they were,
and a receiver that speaks only version 1 refuses the newer types by their version, not as garbage.

then by type:

- ``POSES`` (1): count u16, then per robot id u16, flags u8 (bit 0: valid), x, y, yaw, vx, vy (f32: m, rad, m/s,
  world frame). A robot the service cannot see this frame is sent with valid = 0 and zeros: no pose rather than a
  wrong one.
- ``ODOMETRY`` (2): id u16, x, y, yaw, v, w (f32: the robot's dead-reckoned pose in its odometry frame, its speed and
  turn rate), left, right (i32: encoder counts).
- ``MISSION`` (3): flags u8 (bit 0: run), target x, y (f32, m).
- ``STATUS`` (4): id u16, state u8 (``STATES``), flags u8 (bit 0: it has a pose), x, y, yaw (f32: its own estimate).
- ``SONAR`` (5, version 2): id u16, count m u8, then m ranges u16 (mm; ``NO_ECHO`` 0xFFFF: the beam heard nothing,
  ``NO_READING`` 0xFFFE: the sensor gave nothing usable); ``t_us`` is the window's end.
- ``PLAN`` (6, version 2): flags u8 (bit 0: done, bit 1: a heading to face follows), law u8 (its index in
  ``LAWS``), unit_m f32 (the length unit of the goals and parameters, m), count n u8, [face f64: the world heading
  (rad) the robots should face, only with flag bit 1], then per agent id u16, group u8 (``NO_GROUP`` 255: none),
  flags u8 (bit 0: leader), goal x, y f32; then the law's parameters: count u8, each a name (u8 length, ASCII) and a
  typed value (``P_*``: null, f64 number, bool, string, f64 list, a dict of the same, or an N x N matrix over the
  plan's agents as its non-zero entries: symmetric u8, count u16, then i u8, j u8, value f32, i < j when symmetric).

A datagram that is not one of these (another magic or version, an unknown type, a length that does not match, a
non-finite number) raises ``PacketError``: the receiver counts it and drops it. An encoder given what does not fit
one datagram (``MAX_DATAGRAM``) raises ``PacketTooLarge`` naming the size.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any

MAGIC = b"SP"
VERSION = 2  # the newest this codec speaks
POSES, ODOMETRY, MISSION, STATUS, SONAR, PLAN = 1, 2, 3, 4, 5, 6
SINCE = {POSES: 1, ODOMETRY: 1, MISSION: 1, STATUS: 1, SONAR: 2, PLAN: 2}  # the version each type is sent with
STATES = ("idle", "running", "arrived", "stopped")
# the local laws a plan names (swarm_logic.families.roy.regions.planner.LAWS), by their code on the wire
LAWS = ("formation", "scalable", "packing", "split_merge")
MAX_DATAGRAM = 1472  # one 802.11 frame without IP fragmentation (the session's Wi-Fi network's default)
NO_ECHO, NO_READING = 0xFFFF, 0xFFFE
MAX_RANGE_MM = 0xFFFD
NO_GROUP = 255

_HEADER = struct.Struct("<2sBBIQ")
_COUNT = struct.Struct("<H")
_POSE = struct.Struct("<HB5f")
_ODOM = struct.Struct("<H5f2i")
_MISSION = struct.Struct("<B2f")
_STATUS = struct.Struct("<HBB3f")
_SONAR = struct.Struct("<HB")
_PLAN = struct.Struct("<BBfB")
_AGENT = struct.Struct("<HBB2f")
_EDGE = struct.Struct("<BBf")
_MATRIX = struct.Struct("<BH")
_F64 = struct.Struct("<d")
P_NULL, P_NUMBER, P_BOOL, P_STRING, P_LIST, P_DICT, P_MATRIX = range(7)
MAX_ROBOTS = (65507 - _HEADER.size - _COUNT.size) // _POSE.size


class PacketError(ValueError):
    """A datagram that is not a valid SonPI packet."""


class PacketTooLarge(ValueError):
    """What an encoder was given does not fit one datagram (``MAX_DATAGRAM``)."""


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


@dataclass(frozen=True, slots=True)
class SonarWindow:
    """A robot's sonar window (its end is the packet's time): ``ranges_m`` per beam in the robot's order, m;
    ``math.inf`` the beam heard nothing, None the sensor gave nothing usable."""

    id: int
    ranges_m: tuple[float | None, ...]


@dataclass(frozen=True, slots=True)
class PlanAgent:
    """One agent's row of a plan: its sub-swarm (None: none), whether it leads it, its goal (plan units)."""

    id: int
    group: int | None
    leader: bool
    goal_x: float
    goal_y: float


@dataclass(frozen=True, slots=True)
class PlanPacket:
    """The region controller's plan as the robots get it: the agents' rows, the law by name and its keyword
    parameters (an N x N matrix over the agents, ``desired``, as nested lists), the unit of lengths (m), done, and the
    heading to face, if any."""

    agents: tuple[PlanAgent, ...]
    law: str
    params: dict[str, Any]
    unit_m: float
    done: bool = False
    face_rad: float | None = None  # the world heading the robots should face (none: as the law turns them)


Content = list[PoseEntry] | Odometry | Mission | Status | SonarWindow | PlanPacket


def _header(kind: int, seq: int, t_s: float) -> bytes:
    return _HEADER.pack(MAGIC, SINCE[kind], kind, seq & 0xFFFFFFFF, max(0, round(t_s * 1e6)))


def _fits(data: bytes, what: str, limit: int) -> bytes:
    if len(data) > limit:
        raise PacketTooLarge(f"{what}: {len(data)} bytes, more than one datagram ({limit} bytes)")
    return data


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


def _range_code(r: float | None) -> int:
    if r is None or math.isnan(r):
        return NO_READING
    if r == math.inf:
        return NO_ECHO
    mm = round(r * 1000)
    if not 0 <= mm <= MAX_RANGE_MM:
        raise ValueError(f"a sonar range of {r} m is outside 0..{MAX_RANGE_MM / 1000} m")
    return mm


def encode_sonar(seq: int, t_s: float, w: SonarWindow, limit: int = MAX_DATAGRAM) -> bytes:
    """A robot's sonar window ending at ``t_s``; ValueError for a negative or too long range or over 255 beams."""
    if len(w.ranges_m) > 255:
        raise ValueError(f"at most 255 beams fit a sonar window, got {len(w.ranges_m)}")
    codes = [_range_code(r) for r in w.ranges_m]
    body = _SONAR.pack(w.id, len(codes)) + struct.pack(f"<{len(codes)}H", *codes)
    return _fits(_header(SONAR, seq, t_s) + body, f"a sonar window of {len(codes)} beams", limit)


def _name(name: str) -> bytes:
    raw = name.encode("ascii", "replace")
    if not (name.isidentifier() and name.isascii() and len(raw) <= 64):
        raise ValueError(f"parameter name {name!r}: an ASCII identifier of at most 64 characters")
    return bytes([len(raw)]) + raw


def _is_matrix(v: Any, n: int) -> bool:
    return (
        n > 0
        and isinstance(v, (list, tuple))
        and len(v) == n
        and all(isinstance(row, (list, tuple)) and len(row) == n for row in v)
    )


def _entries(v: Any, n: int) -> tuple[bool, list[tuple[int, int, float]]]:
    """An N x N matrix's non-zero entries as the wire sends them (those with i < j when it is symmetric)."""
    m = [[float(x) for x in row] for row in v]
    sym = all(m[i][j] == m[j][i] for i in range(n) for j in range(i))
    return sym, [(i, j, m[i][j]) for i in range(n) for j in range(n) if m[i][j] != 0 and (not sym or i < j)]


def _value(v: Any, n: int, where: str) -> bytes:
    if v is None:
        return bytes([P_NULL])
    if isinstance(v, bool):
        return bytes([P_BOOL, int(v)])
    if isinstance(v, (int, float)):
        if not math.isfinite(v):
            raise ValueError(f"{where}: {v} is not finite")
        return bytes([P_NUMBER]) + _F64.pack(float(v))
    if isinstance(v, str):
        raw = v.encode()
        if len(raw) > 255:
            raise ValueError(f"{where}: a string of at most 255 bytes")
        return bytes([P_STRING, len(raw)]) + raw
    if isinstance(v, dict):
        if len(v) > 255:
            raise ValueError(f"{where}: at most 255 entries")
        return bytes([P_DICT, len(v)]) + b"".join(_name(k) + _value(x, n, f"{where}.{k}") for k, x in v.items())
    if _is_matrix(v, n):
        sym, entries = _entries(v, n)
        if not all(math.isfinite(e[2]) for e in entries):
            raise ValueError(f"{where}: a matrix entry is not finite")
        if len(entries) > 0xFFFF:
            raise ValueError(f"{where}: too many entries")
        return bytes([P_MATRIX]) + _MATRIX.pack(int(sym), len(entries)) + b"".join(_EDGE.pack(*e) for e in entries)
    if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        if len(v) > 255 or not all(math.isfinite(x) for x in v):
            raise ValueError(f"{where}: a list of at most 255 finite numbers")
        return bytes([P_LIST, len(v)]) + struct.pack(f"<{len(v)}d", *v)
    raise ValueError(
        f"{where}: {type(v).__name__} has no wire encoding (numbers, bools, strings, number lists, "
        f"dicts, an N x N matrix over the {n} agents)"
    )


def encode_plan(seq: int, t_s: float, plan: PlanPacket, limit: int = MAX_DATAGRAM) -> bytes:
    """The region controller's plan; ValueError naming what has no encoding, ``PacketTooLarge`` past ``limit``."""
    n = len(plan.agents)
    if n > 255:
        raise PacketTooLarge(f"a plan of {n} agents: at most 255 fit its count")
    if plan.law not in LAWS:
        raise ValueError(f"law: expected one of {', '.join(LAWS)}, got {plan.law!r}")
    if not (math.isfinite(plan.unit_m) and plan.unit_m > 0):
        raise ValueError(f"unit_m: must be finite and > 0, got {plan.unit_m}")
    if plan.face_rad is not None and not math.isfinite(plan.face_rad):
        raise ValueError(f"face_rad: a heading must be finite, got {plan.face_rad}")
    rows = []
    for a in plan.agents:
        g = NO_GROUP if a.group is None else a.group
        if a.group is not None and not 0 <= a.group < NO_GROUP:
            raise ValueError(f"agent {a.id}: group {a.group} is outside 0..{NO_GROUP - 1}")
        if not (math.isfinite(a.goal_x) and math.isfinite(a.goal_y)):
            raise ValueError(f"agent {a.id}: its goal is not finite")
        rows.append(_AGENT.pack(a.id, g, int(a.leader), a.goal_x, a.goal_y))
    if len(plan.params) > 255:
        raise ValueError("params: at most 255 entries")
    params = b"".join(_name(k) + _value(v, n, f"params.{k}") for k, v in plan.params.items())
    flags = int(plan.done) | (2 if plan.face_rad is not None else 0)
    body = _PLAN.pack(flags, LAWS.index(plan.law), plan.unit_m, n)
    body += b"" if plan.face_rad is None else _F64.pack(plan.face_rad)
    body += b"".join(rows)
    body += bytes([len(plan.params)]) + params
    edges = sum(len(_entries(v, n)[1]) for v in plan.params.values() if _is_matrix(v, n))
    return _fits(_header(PLAN, seq, t_s) + body, f"a plan of {n} agents ({edges} matrix entries)", limit)


def accept(data: bytes, kind: type | tuple[type, ...], sender: int | None) -> tuple[str, Header | None, Content | None]:
    """A receiver's verdict on a datagram from robot ``sender`` (None: not a robot) that should carry ``kind``
    (``Odometry``, ``Status``, or a tuple of them): ``"ok"`` with its header and content; ``"ignored"``, another
    SonPI packet (a broadcast meant for others); ``"malformed"``, not a packet, or one naming another robot
    than its sender."""
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
    if not 1 <= version <= VERSION:
        raise PacketError(f"version {version}, this codec speaks 1 to {VERSION}")
    if kind in SINCE and version != SINCE[kind]:
        raise PacketError(f"type {kind} is a version {SINCE[kind]} packet, got version {version}")
    head = Header(kind, seq, t_us / 1e6)
    body = memoryview(data)[_HEADER.size :]
    if kind == SONAR:
        return head, _decode_sonar(body)
    if kind == PLAN:
        return head, _decode_plan(body)
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


def _decode_sonar(body: memoryview) -> SonarWindow:
    if len(body) < _SONAR.size:
        raise PacketError("a sonar window without its id and count")
    rid, m = _SONAR.unpack_from(body)
    if len(body) != _SONAR.size + 2 * m:
        raise PacketError(f"{len(body)} bytes of body for {m} sonar ranges")
    codes = struct.unpack_from(f"<{m}H", body, _SONAR.size)
    return SonarWindow(rid, tuple(None if c == NO_READING else math.inf if c == NO_ECHO else c / 1000 for c in codes))


class _Reader:
    """Reads a body front to back; running out is a ``PacketError``."""

    def __init__(self, body: memoryview) -> None:
        self.body, self.at = body, 0

    def take(self, fmt: struct.Struct) -> tuple[Any, ...]:
        if self.at + fmt.size > len(self.body):
            raise PacketError(f"a plan cut short at byte {self.at}")
        vals = fmt.unpack_from(self.body, self.at)
        self.at += fmt.size
        return vals

    def u8(self) -> int:
        if self.at >= len(self.body):
            raise PacketError(f"a plan cut short at byte {self.at}")
        self.at += 1
        return int(self.body[self.at - 1])

    def raw(self, k: int) -> bytes:
        if self.at + k > len(self.body):
            raise PacketError(f"a plan cut short at byte {self.at}")
        self.at += k
        return bytes(self.body[self.at - k : self.at])

    def name(self) -> str:
        try:
            name = self.raw(self.u8()).decode("ascii")
        except UnicodeDecodeError:
            raise PacketError("a parameter name is not ASCII") from None
        if not name.isidentifier():
            raise PacketError(f"parameter name {name!r} is not an identifier")
        return name

    def value(self, n: int, depth: int = 0) -> Any:
        kind = self.u8()
        if kind == P_NULL:
            return None
        if kind == P_BOOL:
            b = self.u8()
            if b > 1:
                raise PacketError(f"a bool of {b}")
            return bool(b)
        if kind == P_NUMBER:
            (v,) = self.take(_F64)
            _finite((v,))
            return v
        if kind == P_STRING:
            try:
                return self.raw(self.u8()).decode()
            except UnicodeDecodeError:
                raise PacketError("a string is not UTF-8") from None
        if kind == P_LIST:
            k = self.u8()
            vals = self.take(struct.Struct(f"<{k}d"))
            _finite(vals)
            return list(vals)
        if kind == P_DICT:
            if depth >= 4:
                raise PacketError("parameters nested deeper than 4")
            return self.entries(n, depth + 1)
        if kind == P_MATRIX:
            sym, count = self.take(_MATRIX)
            if sym > 1:
                raise PacketError(f"a matrix's symmetric flag of {sym}")
            m = [[0.0] * n for _ in range(n)]
            for _ in range(count):
                i, j, v = self.take(_EDGE)
                _finite((v,))
                if i >= n or j >= n or i == j or (sym and i > j):
                    raise PacketError(f"a matrix entry ({i}, {j}) outside the plan's {n} agents")
                m[i][j] = v
                if sym:
                    m[j][i] = v
            return m
        raise PacketError(f"unknown parameter type {kind}")

    def entries(self, n: int, depth: int) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for _ in range(self.u8()):
            name = self.name()
            out[name] = self.value(n, depth)
        return out


def _decode_plan(body: memoryview) -> PlanPacket:
    r = _Reader(body)
    flags, law, unit_m, n = r.take(_PLAN)
    if flags & ~3:
        raise PacketError(f"unknown flags 0x{flags:02x}")
    if law >= len(LAWS):
        raise PacketError(f"unknown law {law}")
    if not (math.isfinite(unit_m) and unit_m > 0):
        raise PacketError(f"unit_m {unit_m} is not a length")
    face = None
    if flags & 2:
        (face,) = r.take(_F64)
        _finite((face,))
    agents = []
    for _ in range(n):
        rid, group, aflags, gx, gy = r.take(_AGENT)
        _finite((gx, gy))
        if aflags & ~1:
            raise PacketError(f"unknown agent flags 0x{aflags:02x}")
        agents.append(PlanAgent(rid, None if group == NO_GROUP else group, bool(aflags & 1), gx, gy))
    params = r.entries(n, 0)
    if r.at != len(body):
        raise PacketError(f"{len(body) - r.at} bytes after the plan's parameters")
    return PlanPacket(tuple(agents), LAWS[law], params, unit_m, bool(flags & 1), face)
