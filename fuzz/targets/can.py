"""CAN frames against the robots' DBCs: the CAN medium (arbitration, bit stuffing, fault confinement) as nodes offer
frames, the eSwarBot's LLC and the foot-bot's base and range-and-bearing boards as the bus delivers frames from any
node (a host on the slcan adapter included), and the robots' drivers (``LlcClient``, ``FootbotBoards``) as their
boards' frames reach them.

A frame is read from the input as a selector byte (below 0x80: the n-th message of the DBC, its data cut or padded
to the message's length, so decoding is reached; otherwise a raw 11-bit id from two more bytes, bit 6 extended, with
data of any length up to 8) then a data chunk.
"""

from __future__ import annotations

from typing import Any

import can

from bridge.media.can import CanMedium, _valid_can
from firmware_sim.board.arduino import Board
from firmware_sim.board.can_controller import Frame
from firmware_sim.robots.eswarbot.llc import LlcParams, LowLevelController
from firmware_sim.robots.footbot.base_board import FootbotBase
from firmware_sim.robots.footbot.rab_board import RabBoard
from fuzz.harness import Cursor, FakeClock, Target, lp
from swarm_logic.drivers.llc_client import LlcClient
from swarm_logic.robots.eswarbot import eswarbot_llc_db
from swarm_logic.robots.footbot import footbot_db
from swarm_logic.robots.footbot.can_boards import FootbotBoards

MS = 1_000_000
ESWARBOT = eswarbot_llc_db()
FOOTBOT = footbot_db()


def _frame(c: Cursor, db: Any) -> tuple[int, bytes, bool]:
    """(id, data, extended) as the module docstring reads it."""
    sel = c.u8()
    data = c.chunk()
    if sel < 0x80:
        m = db.messages[sel % len(db.messages)]
        return m.frame_id, data[:m.length].ljust(m.length, b"\0"), False
    ext = bool(sel & 0x40)
    arb = c.u16() | (c.u16() << 16 if ext else 0)
    return arb & (0x1FFFFFFF if ext else 0x7FF), data[:8], ext


def _seed(db: Any, frames: list[tuple[str, dict[str, float]]], raw: list[tuple[int, bytes]] = ()) -> bytes:
    """Seed helper: DBC messages by name and signals (missing ones 0, values out of range allowed: a seed may be a bad
    command), each after a time byte of 1, then raw frames."""
    names = [m.name for m in db.messages]
    out = b""
    for name, sig in frames:
        m = db.get_message_by_name(name)
        full = {s.name: sig.get(s.name, 0) for s in m.signals}
        out += b"\x01" + bytes((names.index(name),)) + lp(m.encode(full, strict=False))
    for arb, data in raw:
        out += b"\x01\x80" + lp(data) + arb.to_bytes(2, "little")
    return out


# -- the CAN medium ----------------------------------------------------------------------------------------------------
def _medium(data: bytes) -> None:
    """Items as the participants send them, validated as the medium validates them (``[bus, id, data, extended]``,
    a fifth ``True`` asks for the echo): per item a node byte (bits 0-1 which of three nodes, bit 2 the echo, bit 3
    not "can0", bits 4-7 the quanta before it), a raw id (4 bytes: beyond the range is refused), an extended flag and
    data (beyond 8 bytes refused). Every fourth node byte with bit 3 also starts noise on the wire."""
    c = Cursor(data)
    bus = CanMedium("r000/can0", 500_000, seed=1)
    nodes = ["r000/llc", "r000/logic", "r000/slcan"]
    for n in nodes:
        bus.add_node(n)
    t, q, seq = 0, 10 * MS, 0
    while c.more():
        head = c.u8()
        t += (head >> 4) * q
        arb = int.from_bytes(c.take(4).ljust(4, b"\0"), "little") >> (c.u8() % 20)
        ext = bool(c.u8() & 1)
        payload = c.chunk()[:9]
        item: list[Any] = ["can1" if head & 8 else "can0", arb, payload, ext] + ([True] if head & 4 else [])
        if head & 8 and head & 3 == 3:
            bus.inject("*", "noise", t, t + 5 * q, 0.5)
        if _valid_can(item):
            seq += 1
            bus.offer(nodes[head % 3], seq, arb, payload, ext)
        if bus.busy(t, q):
            bus.transmit(t, q)
            bus.drain_events()
    for k in range(1, 200):
        if not bus.busy(t + k * q, q):
            break
        bus.transmit(t + k * q, q)
        bus.drain_events()


def _medium_seeds() -> list[bytes]:
    def item(head: int, arb: int, ext: bool, payload: bytes) -> bytes:
        return bytes((head,)) + arb.to_bytes(4, "little") + bytes((0, int(ext))) + lp(payload)

    return [
        item(0x10, 0x100, False, b"\x01\x02") + item(0x00, 0x0FF, False, bytes(8)) + item(0x01, 0x1FFFFFFF, True, b"")
        + item(0x12, 0x7FF, False, b"\xff" * 8) + item(0x04, 0x123, False, b"echo"),
        item(0x0B, 0x100, False, b"x") + item(0x10, 0x800, False, b"") + item(0x01, 0x100, False, bytes(9))
        + item(0x02, 0x20000000, True, b"") + item(0x20, 0x001, False, b"\x00" * 8),
    ]


# -- the eSwarBot's LLC ------------------------------------------------------------------------------------------------
def _llc(data: bytes) -> None:
    """Frames from the bus, each after its time byte (2 ms units; the LLC's loop runs every 20 ms meanwhile); the first
    byte fits a conveyor (a TraxBot's LLC) or not."""
    c = Cursor(data)
    b = Board()
    llc = LowLevelController(b, LlcParams(conveyor_slots=4) if c.u8() & 1 else LlcParams())
    llc.setup()
    while c.more():
        dt_us = c.u8() * 2_000
        arb, payload, ext = _frame(c, ESWARBOT)
        b.can.on_bus_frame(Frame(arb, payload, b.time_us, ext))
        end = b.time_us + dt_us
        while b.time_us < end:
            b.time_us += llc.loop_period_us
            b.encoder_counts = [b.encoder_counts[0] + 3, b.encoder_counts[1] + 4]
            llc.loop()
        b.can.take_tx()


def _llc_seeds() -> list[bytes]:
    cmds = [("DRIVE_CMD", {"v_mm_s": 200, "w_mrad_s": -300, "seq": 1}),
            ("LED_CMD", {"red": 255, "green": 1, "blue": 2}),
            ("ODOM_SET", {"x_mm": 100, "y_mm": -200, "theta_mrad": 1500}),
            ("MOVE_CMD", {"rot_mrad": 1571, "dist_mm": 300, "speed_mm_s": 100, "seq": 2}),
            ("MOVE_CMD", {"rot_mrad": 0, "dist_mm": -1, "speed_mm_s": 0, "seq": 3}),
            ("CONVEYOR_CMD", {"slots": 2, "seq": 4}), ("ODOMETRY", {"x_mm": 0, "y_mm": 0, "theta_mrad": 0})]
    return [b"\x01" + _seed(ESWARBOT, cmds, [(0x7FF, b"\x00"), (0x100, b"\x01\x02")]),
            b"\x00" + _seed(ESWARBOT, cmds[3:4]) + b"\x64" * 4]


# -- the eSwarBot's LLC client -----------------------------------------------------------------------------------------
class _Bus:
    """A python-can bus whose ``recv`` hands out the frames the harness queued."""

    def __init__(self) -> None:
        self.rx: list[can.Message] = []
        self.sent: list[can.Message] = []

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.rx.pop(0) if self.rx else None

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)

    def shutdown(self) -> None:
        pass


def _message(c: Cursor, db: Any, t: float) -> can.Message:
    flags = c.u8()
    arb, payload, ext = _frame(c, db)
    return can.Message(timestamp=t, arbitration_id=arb, data=payload, is_extended_id=ext,
                       is_error_frame=flags & 0x81 == 0x81, is_remote_frame=flags & 0x82 == 0x82)


def _llc_client(data: bytes) -> None:
    """The LLC's frames as the driver polls them: per frame a flags byte (error, remote frames), then the frame."""
    c = Cursor(data)
    bus = _Bus()
    client = LlcClient(bus)  # type: ignore[arg-type]
    t = 0.0
    while c.more():
        t += 0.01
        bus.rx.append(_message(c, ESWARBOT, t))
        if c.u8() & 1:
            client.poll()
    client.poll()


def _llc_client_seeds() -> list[bytes]:
    frames = [("ODOMETRY", {"x_mm": 100, "y_mm": -50, "theta_mrad": 300, "v_mm_s": 120}),
              ("ENCODERS", {"left": 1000, "right": -1000}), ("SONAR", {"range_mm": 500, "valid": 1}),
              ("LIGHT", {"ldr_raw": 512}), ("BATTERY", {"voltage_mv": 8100, "soc_pct": 90}),
              ("MOVE_STATUS", {"seq": 1, "state": 7, "rot_pulses": 10, "fwd_pulses": -3}),
              ("SONAR_SIDES", {"left_mm": 300, "left_valid": 1, "right_mm": 0, "right_valid": 0}),
              ("CONVEYOR_STATUS", {"seq": 2, "moving": 1, "position_slots": 3, "pending_slots": 1})]
    names = [m.name for m in ESWARBOT.messages]
    out = b""
    for name, sig in frames:
        m = ESWARBOT.get_message_by_name(name)
        full = {s.name: sig.get(s.name, 0) for s in m.signals}
        out += b"\x00" + bytes((names.index(name),)) + lp(m.encode(full, strict=False)) + b"\x01"
    status = ESWARBOT.get_message_by_name("STATUS")
    out += b"\x00" + bytes((names.index("STATUS"),)) + lp(bytes(status.length)) + b"\x01"
    return [out, b"\x81\x00" + lp(bytes(5)) + b"\x01" + b"\x00\x80" + lp(b"\x01") + b"\x85\x01\x01"]


# -- the foot-bot's boards ---------------------------------------------------------------------------------------------
def _footbot_base(data: bytes) -> None:
    """Frames from the bus to the base board, each after its time byte (2 ms units; its loop runs every 20 ms)."""
    c = Cursor(data)
    b = Board(can_rx_depth=16)
    fw = FootbotBase(b)
    fw.setup()
    while c.more():
        dt_us = c.u8() * 2_000
        arb, payload, ext = _frame(c, FOOTBOT)
        b.can.on_bus_frame(Frame(arb, payload, b.time_us, ext))
        end = b.time_us + dt_us
        while b.time_us < end:
            b.time_us += fw.loop_period_us
            fw.loop()
        b.can.take_tx()


def _rab(data: bytes) -> None:
    """Frames from the bus to the range-and-bearing board (per frame: the time before it in 10 ms, the frame), with a
    neighbour's emission heard now and then (its payload from the input too)."""
    c = Cursor(data)
    board = RabBoard(period_ms=100)
    t = 0
    while c.more():
        t += c.u8() * 10 * MS
        arb, payload, _ = _frame(c, FOOTBOT)
        heard = []
        if payload[:1] == b"\xee":
            heard.append({"src": 1 + c.u8() % 5, "range_m": c.u8() / 50.0, "bearing_rad": (c.u8() - 128) / 40.0,
                          "data": c.chunk()[:10]})
        board.step(t, [(arb, payload)], heard)


def _footbot_seeds() -> list[bytes]:
    cmds = [("WHEELS_CMD", {"left_mm_s": 100, "right_mm_s": -100, "seq": 0}),
            ("LEDS_CMD", {"red": 1, "green": 2, "blue": 3}),
            ("RAB_DATA_0", {f"d{i}": i for i in range(7)} | {"length": 9}),
            ("RAB_DATA_1", {"d7": 7, "d8": 8, "d9": 9})]
    out = []
    for name, sig in cmds:
        m = FOOTBOT.get_message_by_name(name)
        full = {s.name: sig.get(s.name, 0) for s in m.signals}
        out.append((name, full))
    return [_seed(FOOTBOT, out, [(0x140, b"\x0b" + bytes(7)), (0x141, b"ab"), (0x100, b"\x00")]),
            _seed(FOOTBOT, out[2:]) + b"\x0a\x7f" + lp(b"\xee\x05") + b"\x02\x32\x80" + lp(b"hello")]


def _footbot_driver(data: bytes) -> None:
    """The boards' frames as the foot-bot's driver polls them (flags byte, frame), its faces read now and then."""
    c = Cursor(data)
    bus = _Bus()
    clock = FakeClock()
    drv = FootbotBoards(bus, clock)  # type: ignore[arg-type]
    faces = list(drv.faces().values())
    while c.more():
        clock.sleep(0.01)
        bus.rx.append(_message(c, FOOTBOT, clock.now()))
        k = c.u8()
        if k & 1:
            drv.poll()
            face = faces[(k >> 1) % len(faces)]
            reader = getattr(face, "readings", None)
            if reader is not None:
                reader()
    drv.poll()


def _footbot_driver_seeds() -> list[bytes]:
    rab0 = FOOTBOT.get_message_by_name("RAB_RX_0")
    names = [m.name for m in FOOTBOT.messages]

    def frame(name: str, payload: bytes, poll: int = 1) -> bytes:
        return b"\x00" + bytes((names.index(name),)) + lp(payload) + bytes((poll,))

    r0 = rab0.encode({s.name: 0 for s in rab0.signals} | {"index": 0, "range_cm": 50, "bearing": 90, "length": 6})
    return [frame("PROXIMITY_0", bytes(range(8))) + frame("GROUND", bytes([51, 102, 153, 204, 0x85, 1]))
            + frame("ENCODERS", bytes(8)) + frame("BASE_STATUS", bytes(6)) + frame("RAB_RX_0", r0, 0)
            + frame("RAB_RX_1", b"\x00abcdef", 0) + frame("RAB_SCAN", b"\x01\x01\x00\x00", 3)
            + frame("LIGHT_2", bytes(8), 5) + frame("RAB_SCAN", b"\x03\x02\x00\x00", 7)]


TARGETS = [
    Target("can_medium", "the CAN medium: frames offered by nodes (validation, arbitration, stuffing, errors)",
           _medium, _medium_seeds),
    Target("eswarbot_llc", "eSwarBot LLC firmware: CAN frames from the bus decoded against eswarbot_llc.dbc", _llc,
           _llc_seeds),
    Target("llc_client", "the eSwarBot's LLC driver: the LLC's CAN frames decoded against the DBC", _llc_client,
           _llc_client_seeds),
    Target("footbot_base", "foot-bot base board firmware: CAN frames from the bus against footbot.dbc", _footbot_base,
           _footbot_seeds),
    Target("footbot_rab", "foot-bot range-and-bearing board firmware: CAN frames from the bus, emissions heard", _rab,
           _footbot_seeds),
    Target("footbot_driver", "the foot-bot's CAN driver (FootbotBoards): its boards' frames against footbot.dbc",
           _footbot_driver, _footbot_driver_seeds),
]
