"""The foot-bot's boards as its computer reaches them: one python-can bus (a session's simulated one, socketcan on
the robot, any interface python-can has) and the robot's CAN database (``footbot.dbc``), serving the device faces
the PFSM controllers use (``interfaces``: ``range_and_bearing``, ``footbot_proximity``, ``footbot_light``,
``footbot_motor_ground``, ``footbot_base_ground``, ``differential_steering``, ``leds``).

``poll()`` (the robot calls it before each control step) drains the bus: the base board's sensor frames update the
rings and the ground sensors, the range-and-bearing board's RAB_RX frames fill a scan that its RAB_SCAN frame
completes (``readings()`` is the last complete scan; a reading missing a half, or with a length over 10, is counted
and left out). Frames are decoded with the DBC's signal layouts (compiled
once: ``FastDecoder``); a frame whose length is not its message's is counted (``counters["bad_frames"]``) and
dropped. Commands go out when they change; the wheels' command is repeated every ``keepalive_s`` so the base's
watchdog (0.5 s) holds while the controller keeps the same speeds.
"""

from __future__ import annotations

import math
from typing import Any

import can
from cantools.database.can import Database

from swarm_logic.robots.footbot import footbot_db
from swarm_logic.robots.footbot.interfaces import (
    BASE_GROUND,
    BASE_GROUND_OFFSETS_M,
    LEDS,
    LIGHT,
    LIGHT_COUNT,
    MOTOR_GROUND,
    MOTOR_GROUND_OFFSETS_M,
    PROXIMITY,
    PROXIMITY_COUNT,
    RAB_PAYLOAD_BYTES,
    RAB_RANGE_M,
    RANGE_AND_BEARING,
    WHEELS,
    GroundReading,
    RabPacket,
    RingReading,
    check_payload,
    ring_angles,
)


class FastDecoder:
    """A CAN database's little-endian signals compiled to shifts and masks: ``decode(frame_id, data)`` gives the
    message's name and its signals (scaled) in a few microseconds, as cantools would give them."""

    def __init__(self, db: Database) -> None:
        self.messages: dict[int, tuple[str, int, list[tuple[str, int, int, bool, float, float]]]] = {}
        for m in db.messages:
            sigs = []
            for s in m.signals:
                if s.byte_order != "little_endian":
                    raise ValueError(f"{m.name}.{s.name}: only little-endian signals are compiled")
                sigs.append((s.name, s.start, (1 << s.length) - 1, s.is_signed, float(s.scale), float(s.offset)))
            self.messages[m.frame_id] = (m.name, m.length, sigs)

    def decode(self, frame_id: int, data: bytes) -> tuple[str, dict[str, float]] | None:
        """(name, signals), or None for a frame not in the database or of the wrong length."""
        m = self.messages.get(frame_id)
        if m is None or len(data) != m[1]:
            return None
        raw = int.from_bytes(data, "little")
        out: dict[str, float] = {}
        for name, start, mask, signed, scale, offset in m[2]:
            v = (raw >> start) & mask
            if signed and v > (mask >> 1):
                v -= mask + 1
            out[name] = v * scale + offset if scale != 1.0 or offset != 0.0 else v
        return m[0], out


class FootbotBoards:
    """The HAL table ``footbot_can``: python-can's Bus arguments (``interface``, ``channel``, ...), and optionally
    ``keepalive_s`` (0.2) and ``rab_range_m`` (what the board is rated for, 3 m)."""

    def __init__(self, bus: can.BusABC, clock: Any, keepalive_s: float = 0.2, rab_range_m: float = RAB_RANGE_M,
                 db: Database | None = None) -> None:
        self.bus, self.clock = bus, clock
        self.db = db or footbot_db()
        self.dec = FastDecoder(self.db)
        self.ids = {m.name: m.frame_id for m in self.db.messages}
        self.keepalive_s = keepalive_s
        self.proximity = [0.0] * PROXIMITY_COUNT
        self.light = [0.0] * LIGHT_COUNT
        self.ground = [1.0] * len(MOTOR_GROUND_OFFSETS_M)
        self.base_ground = [1.0] * len(BASE_GROUND_OFFSETS_M)
        self.encoders = (0, 0)
        self.status: dict[str, float] = {}
        self.rab_scan: list[RabPacket] = []
        self._rx0: dict[int, dict[str, float]] = {}
        self._rx1: dict[int, bytes] = {}
        self._wheels: tuple[int, int] | None = None
        self._wheels_t = -math.inf
        self._leds: tuple[int, int, int] | None = None
        self._payload: bytes | None = None
        self.counters = {"frames": 0, "bad_frames": 0, "scans": 0, "send_errors": 0}
        self._faces = {RANGE_AND_BEARING: RabFace(self, rab_range_m),
                       PROXIMITY: RingFace(self, "proximity", PROXIMITY_COUNT),
                       LIGHT: RingFace(self, "light", LIGHT_COUNT), MOTOR_GROUND: GroundFace(self),
                       BASE_GROUND: GroundFace(self, "base_ground", BASE_GROUND_OFFSETS_M), WHEELS: WheelsFace(self),
                       LEDS: LedsFace(self)}

    def faces(self) -> dict[str, Any]:
        return self._faces

    # -- receive ------------------------------------------------------------------------------------------------
    def poll(self) -> int:
        """Drain the bus; the frames taken."""
        n = 0
        while (msg := self.bus.recv(0.0)) is not None:
            n += 1
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            self._frame(msg.arbitration_id, bytes(msg.data))
        self.counters["frames"] += n
        return n

    def _frame(self, arb_id: int, data: bytes) -> None:
        d = self.dec.decode(arb_id, data)
        if d is None:
            if arb_id in self.dec.messages:
                self.counters["bad_frames"] += 1
            return
        name, s = d
        if name.startswith("PROXIMITY_"):
            k = 8 * int(name[-1])
            self.proximity[k:k + 8] = [b / 255 for b in data]
        elif name.startswith("LIGHT_"):
            k = 8 * int(name[-1])
            self.light[k:k + 8] = [b / 255 for b in data]
        elif name == "GROUND":
            self.ground = [b / 255 for b in data[:len(self.ground)]]
            self.base_ground = [float(data[4] >> i & 1) for i in range(len(self.base_ground))]
        elif name == "RAB_RX_0":
            self._rx0[int(s["index"])] = s
        elif name == "RAB_RX_1":
            self._rx1[int(s["index"])] = data[1:7]
        elif name == "RAB_SCAN":
            self._scan(int(s["count"]))
        elif name == "ENCODERS":
            self.encoders = (int(s["left"]), int(s["right"]))
        elif name == "BASE_STATUS":
            self.status = s

    def _scan(self, count: int) -> None:
        """RAB_SCAN: the readings 0 .. count-1 are the robots heard (a payload longer than 4 bytes in two frames);
        one that lost a frame, or whose length is more than a message carries, is left out (counted)."""
        out = []
        for k in range(count):
            a = self._rx0.get(k)
            b = self._rx1.get(k) if a is not None and a["length"] > 4 else b""
            if a is None or b is None or int(a["length"]) > RAB_PAYLOAD_BYTES:
                self.counters["bad_frames"] += 1
                continue
            n = int(a["length"])
            data = bytes([int(a["d0"]), int(a["d1"]), int(a["d2"]), int(a["d3"])]) + b
            out.append(RabPacket(a["range_cm"] / 100.0, math.radians(a["bearing"]), data[:n]))
        self.rab_scan = out
        self._rx0, self._rx1 = {}, {}
        self.counters["scans"] += 1

    # -- send ---------------------------------------------------------------------------------------------------
    def send(self, name: str, data: bytes) -> None:
        try:
            self.bus.send(can.Message(arbitration_id=self.ids[name], data=data, is_extended_id=False))
        except can.CanError:  # a full transmit queue, a bus-off controller: the command is lost, counted
            self.counters["send_errors"] += 1

    def wheels(self, left_mps: float, right_mps: float) -> None:
        mm = (round(left_mps * 1000), round(right_mps * 1000))
        now = self.clock.now()
        if mm == self._wheels and now - self._wheels_t < self.keepalive_s:
            return
        self._wheels, self._wheels_t = mm, now
        m = self.db.get_message_by_name("WHEELS_CMD")
        self.send("WHEELS_CMD", m.encode({"left_mm_s": mm[0], "right_mm_s": mm[1], "seq": 0}))

    def leds(self, rgb: tuple[int, int, int]) -> None:
        if rgb != self._leds:
            self._leds = rgb
            self.send("LEDS_CMD", bytes(rgb))

    def payload(self, data: bytes) -> None:
        if data == self._payload:
            return
        self._payload = data
        self.send("RAB_DATA_0", bytes([len(data)]) + data[:7] + bytes(max(0, 7 - len(data))))
        if len(data) > 7:
            self.send("RAB_DATA_1", data[7:10] + bytes(10 - len(data)))

    def close(self) -> None:
        if self._wheels is not None and self._wheels != (0, 0):
            self.wheels(0.0, 0.0)
        self.bus.shutdown()


class RabFace:
    """``RangeAndBearing`` over the range-and-bearing board."""

    max_payload = RAB_PAYLOAD_BYTES

    def __init__(self, boards: FootbotBoards, range_m: float) -> None:
        self.boards, self.range_m = boards, range_m

    def readings(self) -> list[RabPacket]:
        return self.boards.rab_scan

    def send(self, data: bytes) -> None:
        self.boards.payload(check_payload(data, self.max_payload))


class RingFace:
    """``Proximity`` or ``Light``: a ring of sensors on the base board (24 each)."""

    def __init__(self, boards: FootbotBoards, ring: str, count: int) -> None:
        self.boards, self.ring = boards, ring
        self.angles = ring_angles(count)

    def readings(self) -> list[RingReading]:
        return [RingReading(v, a) for v, a in zip(getattr(self.boards, self.ring), self.angles, strict=True)]


class GroundFace:
    """``MotorGround`` (the 4 grey-level sensors) or ``BaseGround`` (the 8 black-or-white ones) on the base board."""

    def __init__(self, boards: FootbotBoards, sensors: str = "ground",
                 offsets: tuple[tuple[float, float], ...] = MOTOR_GROUND_OFFSETS_M) -> None:
        self.boards, self.sensors, self.offsets = boards, sensors, offsets

    def readings(self) -> list[GroundReading]:
        return [GroundReading(v, o) for v, o in zip(getattr(self.boards, self.sensors), self.offsets, strict=True)]


class WheelsFace:
    """``DifferentialSteering``: WHEELS_CMD to the base board."""

    max_speed_mps = 0.3  # the base clips its commands to 30 cm/s

    def __init__(self, boards: FootbotBoards) -> None:
        self.boards = boards

    def set_speeds(self, left_mps: float, right_mps: float) -> None:
        v = self.max_speed_mps
        self.boards.wheels(max(-v, min(v, left_mps)), max(-v, min(v, right_mps)))


class LedsFace:
    """``Leds``: LEDS_CMD to the base board."""

    def __init__(self, boards: FootbotBoards) -> None:
        self.boards = boards

    def set_all_colors(self, rgb: tuple[int, int, int]) -> None:
        self.boards.leds(tuple(max(0, min(255, int(c))) for c in rgb))  # type: ignore[arg-type]


def open_footbot_can(cfg: dict[str, Any], robot: Any) -> FootbotBoards:
    """The HAL ``footbot_can`` table's device: the robot's CAN bus with its two boards."""
    args = {k: v for k, v in cfg.items() if k not in ("keepalive_s", "rab_range_m")}
    if "interface" not in args:
        raise ValueError("HAL config footbot_can.interface: a python-can interface name is needed (socketcan, "
                         "slcan, sitl, ...)")
    bus = can.Bus(**args)
    return FootbotBoards(bus, robot.clock, float(cfg.get("keepalive_s", 0.2)),
                         float(cfg.get("rab_range_m", RAB_RANGE_M)))
