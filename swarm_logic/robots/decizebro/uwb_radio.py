"""The Raspberry Pi's driver of the Zebro's DWM1001 UWB radio (``ZebroRadio``), over any pyserial port:
``sitl://uwb_radio`` in a session, ``/dev/serial0`` (the Pi's UART) on the robot. Frames as ``uwb_protocol`` defines
them; docs/zebro-radio.md.

Single threaded and non-blocking after ``open``: every call first takes what the module sent (``poll``): its
neighbour reports, the broadcasts it received, its transmit-queue status. ``broadcast`` is refused (False) when the
module's queue has no room by the driver's count: the queue's free places the module last reported, less the frames
sent since the one it had seen then (``SEND`` carries a sequence number; ``TX_STATUS`` the last one seen). Once a
second the driver sends the robot's heading to the module (``SET_HEADING``), which carries it in its ranging beacons:
the IMU's (``robot.devices["imu"]``, when the robot has one) or what ``set_heading`` was last given.
"""

from __future__ import annotations

import math
import struct
from typing import Any

from swarm_logic.clock import Clock
from swarm_logic.devices import open_port
from swarm_logic.robots.decizebro import uwb_protocol as P
from swarm_logic.robots.decizebro.interfaces import IMU, Message, Neighbour

HEADING_PERIOD_S = 1.0  # the update rate: one beacon a second carries it


class UwbRadioError(Exception):
    """The module did not answer, or answered what cannot be understood."""


class ZebroUwbRadio:
    """The module on ``port``; ``robot`` (optional) gives it the robot's IMU."""

    max_payload = P.MAX_PAYLOAD

    def __init__(self, port: Any, clock: Clock, robot: Any = None, *, timeout: float = 0.5) -> None:
        self.port = port
        self.clock = clock
        self.robot = robot
        self.parser = P.Parser(timeout_ns=10**18)  # a reader has no deadline: bytes come when they come
        self._t_parse = 0
        self.info: dict[str, int] = {}
        self.table: list[Neighbour] = []
        self._parts: dict[int, list[Neighbour]] = {}
        self.inbox: list[Message] = []
        self.seq = 0
        self.seen_seq = 0
        self.queue_free = 0
        self.heading: float | None = None
        self._heading_sent_at: float | None = None
        self.counters: dict[str, int] = dict.fromkeys(
            ("frames", "bad_frames", "junk_bytes", "nacks", "refused", "sent", "received", "reports",
             "unknown_frames"), 0)
        self.nacks: dict[str, int] = {}
        self.report_t: float | None = None  # clock time of the latest complete neighbour report
        self._identify(timeout)

    # -- transport ---------------------------------------------------------------------------------------------
    def _take(self) -> list[tuple[int, bytes]]:
        n = self.port.in_waiting
        data = self.port.read(n) if n else b""
        self._t_parse += 1
        out = []
        junk = self.parser.junk
        for item in self.parser.feed(self._t_parse, data):
            if isinstance(item, P.Bad):
                self.counters["bad_frames"] += 1
            else:
                out.append(item)
        self.counters["junk_bytes"] += self.parser.junk - junk
        return out

    def _handle(self, typ: int, body: bytes) -> None:
        self.counters["frames"] += 1
        try:
            if typ == P.RX_DATA:
                src, _seq = struct.unpack_from("<HB", body)
                self.inbox.append(Message(src, bytes(body[3:])))
                self.counters["received"] += 1
            elif typ == P.NEIGHBOURS:
                self._neighbours(body)
            elif typ == P.TX_STATUS:
                self.seen_seq, self.queue_free = body[0], body[1]
            elif typ == P.ACK:
                if body[1] != P.OK:
                    self.counters["nacks"] += 1
                    why = P.STATUS_NAMES.get(body[1], str(body[1]))
                    self.nacks[why] = self.nacks.get(why, 0) + 1
            elif typ == P.INFO:
                keys = ("id", "slot", "n_slots", "frames_per_s", "max_payload", "queue", "period_ms", "ideal")
                self.info = dict(zip(keys, P.INFO_BODY.unpack(body), strict=True))
            else:
                self.counters["unknown_frames"] += 1
        except (struct.error, IndexError, ValueError):
            self.counters["bad_frames"] += 1

    def _neighbours(self, body: bytes) -> None:
        part, parts, count = body[0], body[1], body[2]
        if len(body) != 3 + count * P.NEIGHBOUR.size:
            raise ValueError
        rows = []
        for k in range(count):
            nid, mm, b_cdeg, h_cdeg, flags, _age = P.NEIGHBOUR.unpack_from(body, 3 + k * P.NEIGHBOUR.size)
            heading = math.radians(h_cdeg / 100.0) if flags & P.F_HEADING else None
            rows.append(Neighbour(nid, mm / 1000.0, math.radians(b_cdeg / 100.0), heading))
        if part == 0:
            self._parts = {}
        self._parts[part] = rows
        if len(self._parts) == parts:
            self.table = [nb for p in sorted(self._parts) for nb in self._parts[p]]
            self.counters["reports"] += 1
            self.report_t = self.clock.now()

    def poll(self) -> None:
        """Take what the module sent; send it the heading when a second has passed."""
        for typ, body in self._take():
            self._handle(typ, body)
        self._send_heading()

    def _send_heading(self) -> None:
        now = self.clock.now()
        if self._heading_sent_at is not None and now - self._heading_sent_at < HEADING_PERIOD_S:
            return
        imu = self.robot.devices.get(IMU) if self.robot is not None else None
        if imu is not None:
            self.heading = float(imu.heading())
        if self.heading is None:
            return
        self._heading_sent_at = now
        self.port.write(P.frame(P.SET_HEADING, struct.pack("<H", P.heading_cdeg(self.heading))))

    def _identify(self, timeout: float) -> None:
        """Ask the module who it is and how deep its queue is (blocking, in clock time)."""
        self.port.write(P.frame(P.INFO_GET))
        self._read_until(lambda: bool(self.info), timeout, "no answer from the UWB radio (INFO)")
        self.queue_free = self.info["queue"]

    def wait_neighbourhood(self, timeout: float | None = None) -> None:
        """Block (in clock time) until the module has reported a neighbourhood it ranged for one whole update period
        since now: every neighbour in range has beaconed once. A program calls it before it acts on its neighbours
        (the Zebro controllers do at start)."""
        period = self.info["period_ms"] / 1000.0
        since = self.clock.now() + period
        self._read_until(lambda: self.report_t is not None and self.report_t >= since,
                         2 * period + 0.5 if timeout is None else timeout, "no neighbour report from the UWB radio")

    def _read_until(self, done: Any, timeout: float, what: str) -> None:
        deadline = self.clock.now() + timeout
        while not done():
            left = deadline - self.clock.now()
            self.port.timeout = max(left, 0)  # past the deadline: one look at what already arrived
            first = self.port.read(1)
            self.port.timeout = 0
            if left <= 0 and not first:
                raise UwbRadioError(what)
            if first:
                self.parser.buf += first
            for typ, body in self._take():
                self._handle(typ, body)
            if self.info:
                self._send_heading()

    # -- ZebroRadio ----------------------------------------------------------------------------------------
    def neighbours(self) -> list[Neighbour]:
        """The neighbour table of the module's latest report (ranged within the last 3 s), by id."""
        self.poll()
        return list(self.table)

    def broadcast(self, data: bytes) -> bool:
        """Queue ``data`` (1..112 bytes) for the module's next turns; False when its queue has no room."""
        if not 1 <= len(data) <= P.MAX_PAYLOAD:
            raise ValueError(f"a UWB broadcast carries 1..{P.MAX_PAYLOAD} bytes, got {len(data)}")
        self.poll()
        in_flight = (self.seq - self.seen_seq) & 0xFF
        if self.queue_free - in_flight <= 0:
            self.counters["refused"] += 1
            return False
        self.seq = (self.seq + 1) & 0xFF
        self.port.write(P.frame(P.SEND, bytes((self.seq,)) + bytes(data)))
        self.counters["sent"] += 1
        return True

    def receive(self) -> list[Message]:
        """The broadcasts received since the last call, oldest first."""
        self.poll()
        out, self.inbox = self.inbox, []
        return out

    # -- extras ----------------------------------------------------------------------------------------------
    def set_heading(self, heading_rad: float) -> None:
        """The heading the module carries in its beacons, for a robot without an IMU device (sent within a second)."""
        self.heading = float(heading_rad)

    def close(self) -> None:
        self.port.close()


def open_uwb_radio(cfg: dict[str, Any], robot: Any) -> ZebroUwbRadio:
    """The HAL ``uwb_radio`` table: ``port`` (``sitl://uwb_radio``, ``/dev/serial0``), ``baudrate`` (115200)."""
    port = open_port(dict(cfg), "uwb_radio", 115200)
    try:
        return ZebroUwbRadio(port, robot.clock, robot)
    except BaseException:
        port.close()
        raise
