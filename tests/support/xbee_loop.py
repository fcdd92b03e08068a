"""Test helper: XBee modules on serial lines to host drivers, in simulated time with a manual clock.

``World`` holds module endpoints (``firmware_sim.modules.xbee.XBeeModule``
or the ``ScriptedModule`` stand-in below, both
``step(t_ns, uart_rx, air_events) -> output`` with ``uart_tx``/``air_tx`` and ``next_wake()``), an ideal radio
medium between them and one pyserial-like ``LoopPort`` per module. A driver blocked in ``LoopPort.read`` is what
makes time pass, as a SITL port does: the world steps every endpoint up to the next event (a byte on a line, an
air event, a module timer, or ``tick_ns`` at the latest) until the read is satisfied or its timeout runs out.
Host-to-module bytes are paced by the line (10 bits a byte at the port's baud); module-to-host bytes are
paced by the module itself.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.models.mode import OperatingMode
from digi.xbee.models.status import ModemStatus, TransmitStatus
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommQueuePacket,
    ATCommResponsePacket,
    ModemStatusPacket,
    ReceivePacket,
    TransmitPacket,
    TransmitStatusPacket,
)
from digi.xbee.packets.factory import build_frame
from digi.xbee.packets.raw import RX64Packet, TX64Packet, TXStatusPacket

NS = 1_000_000_000


def byte_ns(baud: int) -> int:
    """Time one byte takes on an 8N1 line (10 bits)."""
    return 10 * NS // baud


class ManualClock:
    """The ``swarm_logic.clock.Clock`` of a driver in a ``World``: reads and advances the world's time."""

    def __init__(self, world: World) -> None:
        self.world = world

    def now(self) -> float:
        return self.world.t_ns / NS

    def sleep(self, dt: float) -> None:
        self.world.run_until(self.world.t_ns + max(0, round(dt * NS)))

    def sleep_until(self, t: float) -> None:
        self.world.run_until(max(self.world.t_ns, round(t * NS)))


class LoopPort:
    """The host end of one serial line: the parts of pyserial's ``Serial`` the driver uses."""

    def __init__(self, world: World, index: int, baudrate: int) -> None:
        self.world = world
        self.index = index
        self.baudrate = baudrate
        self.timeout: float | None = None
        self.is_open = True
        self.rx = bytearray()  # module -> host, arrived
        self.tx: deque[tuple[int, int]] = deque()  # host -> module: (arrival time ns, byte)
        self._line_free_ns = 0

    @property
    def in_waiting(self) -> int:
        return len(self.rx)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, waiting up to ``timeout`` simulated seconds (forever if None)."""
        w = self.world
        deadline = None if self.timeout is None else w.t_ns + max(0, round(self.timeout * NS))
        while len(self.rx) < size and (deadline is None or w.t_ns < deadline):
            w.advance(deadline)
        out = bytes(self.rx[:size])
        del self.rx[:size]
        return out

    def write(self, data: bytes) -> int:
        t = max(self.world.t_ns, self._line_free_ns)
        step = byte_ns(self.baudrate)
        for b in bytes(data):
            t += step
            self.tx.append((t, b))
        self._line_free_ns = t
        return len(data)

    def flush(self) -> None:
        pass

    def reset_input_buffer(self) -> None:
        self.rx.clear()

    def close(self) -> None:
        self.is_open = False

    def inject(self, data: bytes) -> None:
        """Bytes that appear on the host's receive line now (noise, a foreign frame)."""
        self.rx += data


@dataclass
class Air:
    """What the ideal medium has in flight: (due time, endpoint, event)."""

    events: list[tuple[int, int, dict]] = field(default_factory=list)


class World:
    """Endpoints, their lines and an ideal medium; ``run_until``/``advance`` move simulated time."""

    def __init__(self, endpoints: list[Any], *, baud: int = 9600, tick_ns: int = 1_000_000,
                 link: Callable[[int, int], int | None] | None = None, limit_s: float = 3600.0) -> None:
        """``link(i, j)``: RSSI (dBm) at j of what i sends, None when j cannot hear i (default: -60 for all)."""
        self.endpoints = endpoints
        self.ports = [LoopPort(self, i, baud) for i in range(len(endpoints))]
        self.clock = ManualClock(self)
        self.t_ns = 0
        self.tick_ns = tick_ns
        self.link = link or (lambda i, j: -60)
        self.limit_ns = round(limit_s * NS)
        self.nodes: list[dict | None] = [None] * len(endpoints)
        self.air = Air()
        self.air_log: list[tuple[int, int, dict]] = []  # (t_ns, sender, frame)
        self.rssi_pwm: list[list[tuple[int, float]]] = [[] for _ in endpoints]
        self._step_all(0)

    def run_until(self, t_ns: int) -> None:
        while self.t_ns < t_ns:
            self.advance(t_ns)

    def advance(self, horizon_ns: int | None) -> None:
        """Step every endpoint at the next event time, at most ``tick_ns`` ahead and not beyond the horizon."""
        t = self.t_ns + self.tick_ns
        for ep in self.endpoints:
            w = ep.next_wake()
            if w is not None and w > self.t_ns:
                t = min(t, w)
        for p in self.ports:
            if p.tx:
                t = min(t, max(p.tx[0][0], self.t_ns + 1))
        for due, _, _ in self.air.events:
            t = min(t, max(due, self.t_ns + 1))
        if horizon_ns is not None:
            t = min(t, horizon_ns)
        t = max(t, self.t_ns + 1)
        if t > self.limit_ns:
            raise RuntimeError("simulated time limit reached (a read without timeout that nothing answers?)")
        self._step_all(t)

    def _step_all(self, t: int) -> None:
        self.t_ns = t
        due = [e for e in self.air.events if e[0] <= t]
        self.air.events = [e for e in self.air.events if e[0] > t]
        for i, ep in enumerate(self.endpoints):
            p = self.ports[i]
            rx = bytearray()
            while p.tx and p.tx[0][0] <= t:
                rx.append(p.tx.popleft()[1])
            evs = sorted((e[2] for e in due if e[1] == i), key=lambda e: e["t_ns"])
            out = ep.step(t, bytes(rx), evs)
            p.rx += out.uart_tx
            if getattr(out, "node", None) is not None:
                self.nodes[i] = out.node
            if getattr(out, "rssi_pwm", None) is not None:
                self.rssi_pwm[i].append((t, out.rssi_pwm))
            for frame in out.air_tx:
                self._submit(i, t, frame)

    def _submit(self, i: int, t: int, frame: dict) -> None:
        """Ideal medium: no collisions, no CSMA; air time (6 + psdu_len) x 32 us; unicast acked if heard."""
        self.air_log.append((t, i, frame))
        t_end = t + (6 + frame.get("psdu_len", len(frame["payload"]) + 20)) * 32_000
        acked = False
        for j, node in enumerate(self.nodes):
            if j == i or node is None or node.get("channel") != frame.get("channel"):
                continue
            rssi = self.link(i, j)
            if rssi is None:
                continue
            self.air.events.append((t_end, j, {"ev": "rx", "t_ns": t_end, "frame": frame, "rssi_dbm": rssi}))
            key = {"64": "addr64", "16": "addr16"}.get(frame["dst"])
            acked = acked or (key is not None and node.get(key) == frame["dst_addr"])
        if frame["dst"] == "bcast" or not frame.get("ack", True) or acked:
            status, attempts = "ok", 1
        else:
            status, attempts = "no_ack", 1 + frame.get("mac_retries", 3)
        t_done = t_end + (attempts - 1) * 2_000_000 + (1_056_000 if status == "ok" and frame["dst"] != "bcast" else 0)
        self.air.events.append((t_done, i, {"ev": "done", "t_ns": t_done, "handle": frame["handle"],
                                            "status": status, "attempts": attempts}))


# -- a scripted stand-in for the module, built from digi-xbee's packet classes ------------------------------------


@dataclass
class ScriptedOutput:
    uart_tx: bytes = b""
    air_tx: list = field(default_factory=list)
    node: dict | None = None
    rssi_pwm: float | None = None


class ScriptedModule:
    """Answers AT commands from a table and TX requests with a chosen status, after ``latency_ns``, paced at
    ``baud``. No radio: ``air_tx`` stays empty; ``deliver`` queues an RX frame for the host. Only for testing the
    driver's request/response logic where the real module emulation would be in the way."""

    def __init__(self, *, series: int = 1, api_mode: int = 1, baud: int = 9600, latency_ns: int = 2_000_000,
                 at: dict[str, bytes] | None = None, tx_status: int = 0, silent: bool = False) -> None:
        self.series = series
        self.escaped = api_mode == 2
        self.byte_ns = byte_ns(baud)
        self.latency_ns = latency_ns
        s1 = series == 1
        self.at_values: dict[str, bytes] = {
            "SH": bytes.fromhex("0013A200"), "SL": bytes.fromhex("40A1B2C3"),
            "MY": bytes.fromhex("0007" if s1 else "1A2B"),
            "NI": b"SCRIPTED", "HV": bytes.fromhex("1744" if s1 else "1941"),
            "VR": bytes.fromhex("10EC" if s1 else "21A7"), "DB": b"\x37",
        }
        self.at_values.update(at or {})
        self.tx_status = tx_status
        self.silent = silent
        self.received: list[Any] = []  # digi-xbee packets the host sent
        self._in = bytearray()
        self._esc = False
        self._out: deque[tuple[int, bytes]] = deque()  # (earliest start ns, bytes)
        self._line_free = 0
        self._t = 0

    def emit(self, data: bytes, t_ns: int | None = None) -> None:
        """Queue raw bytes for the host, from ``t_ns`` (default: now + latency)."""
        self._out.append((self._t + self.latency_ns if t_ns is None else t_ns, bytes(data)))

    def emit_packet(self, pkt: Any, t_ns: int | None = None) -> None:
        self.emit(bytes(pkt.output(escaped=self.escaped)), t_ns)

    def deliver(self, src64: int, data: bytes, *, rssi_dbm: int = -60, broadcast: bool = False) -> None:
        """An RF packet arrives: the host gets an RX64 (Series 1) or a receive packet (Series 2)."""
        a64 = XBee64BitAddress(src64.to_bytes(8, "big"))
        if self.series == 1:
            self.emit_packet(RX64Packet(a64, -rssi_dbm, 0x02 if broadcast else 0, bytearray(data)))
        else:
            self.at_values["DB"] = bytes([-rssi_dbm])
            self.emit_packet(ReceivePacket(a64, XBee16BitAddress(b"\x12\x34"), 0x02 if broadcast else 0x01,
                                           bytearray(data)))

    def power_up(self) -> None:
        self.emit_packet(ModemStatusPacket(ModemStatus.HARDWARE_RESET if self.series == 1
                                           else ModemStatus.JOINED_NETWORK))

    def next_wake(self) -> int | None:
        if not self._out:
            return None
        return max(self._out[0][0], self._line_free)

    def step(self, t_ns: int, uart_rx: bytes, air_events: list[dict]) -> ScriptedOutput:
        self._t = t_ns
        for b in uart_rx:
            if self.escaped and b == 0x7D:
                self._esc = True
                continue
            if self._esc:
                b ^= 0x20
                self._esc = False
            self._in.append(b)
        self._parse()
        return ScriptedOutput(uart_tx=self._clock_out(t_ns))

    def _clock_out(self, t_ns: int) -> bytes:
        """Bytes whose last bit has left by ``t_ns``; the rest waits (``next_wake``)."""
        out = bytearray()
        while self._out:
            start, data = self._out[0]
            t = max(start, self._line_free)
            k = 0
            while k < len(data) and t + self.byte_ns <= t_ns:
                t += self.byte_ns
                k += 1
            out += data[:k]
            if k < len(data):
                self._out[0] = (t, data[k:])
                self._line_free = t
                break
            self._out.popleft()
            self._line_free = t
        return bytes(out)

    def _parse(self) -> None:
        buf = self._in
        while True:
            start = buf.find(0x7E)
            if start < 0:
                buf.clear()
                return
            del buf[:start]
            if len(buf) < 3:
                return
            n = int.from_bytes(buf[1:3], "big")
            if len(buf) < n + 4:
                return
            frame = bytearray(buf[: n + 4])
            del buf[: n + 4]
            if frame[3] == 0x00:  # build_frame does not know the Series 1 TX requests (host -> module only)
                self._handle(TX64Packet.create_packet(frame, OperatingMode.API_MODE))
            else:
                self._handle(build_frame(frame, OperatingMode.API_MODE))

    def _handle(self, pkt: Any) -> None:
        self.received.append(pkt)
        if self.silent:
            return
        if isinstance(pkt, ATCommPacket | ATCommQueuePacket):
            cmd = pkt.command
            if pkt.parameter:
                self.at_values[cmd] = bytes(pkt.parameter)
                resp = ATCommResponsePacket(pkt.frame_id, cmd, 0)
            elif cmd in self.at_values:
                resp = ATCommResponsePacket(pkt.frame_id, cmd, 0, bytearray(self.at_values[cmd]))
            else:
                resp = ATCommResponsePacket(pkt.frame_id, cmd, 2)
            self.emit_packet(resp)
        elif isinstance(pkt, TX64Packet):
            self.emit_packet(TXStatusPacket(pkt.frame_id, _tx_status(self.tx_status)))
        elif isinstance(pkt, TransmitPacket):
            self.emit_packet(TransmitStatusPacket(pkt.frame_id, XBee16BitAddress(b"\xff\xfe"), 1,
                                                  _tx_status(self.tx_status)))


def _tx_status(code: int) -> TransmitStatus:
    return TransmitStatus.get(code)
