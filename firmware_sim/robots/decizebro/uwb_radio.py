"""The Zebro's DWM1001 UWB radio with data (nRF52832 + DW1000, AN-TDMA firmware), sans-IO and deterministic.

What it does, and where the behaviour comes from (docs/zebro-radio.md has the figures and the UART bytes):

- **AN-TDMA turns within the swarm's frame budget.** The air carries ``frames_per_s`` = 512 frames a second for the
  whole collision domain (Agrawal 2019, App. B.2: 16 robots x 32/s or 32 x 16/s). Each slot holds one frame
  (1.953 ms); module ``slot`` of ``n_slots`` owns slots ``k * n_slots + slot`` (``firmware_sim.modules.uwb.TdmaSlots``,
  slot clocks assumed synchronised as AN-TDMA does), so a module sends at most ``frames_per_s / n_slots`` frames a
  second, and exactly that when it always has something to send. A turn with nothing to send stays silent.
- **Ranging beacons.** Once per update period (1 Hz) a turn carries a beacon: the module's id, the heading its host
  last set, and the timestamps of swarm ranging (a broadcast frame that carries its transmit time and the receive
  times of the neighbours' latest frames gives every receiver a two-way range: Shan et al., *Ultra-wideband swarm
  ranging*, IEEE INFOCOM 2021). Each neighbour that hears it gets a range (the medium's DW1000 error model) and,
  from its two antennas, the phase difference of arrival.
- **Bearing from phase difference (PDoA).** Two antennas half a wavelength apart across the robot measure the
  carrier's phase difference, which gives the sine of the angle of arrival: ``aoa = asin(pd / pi)`` (Dotlic et al.,
  *Angle of arrival estimation using Decawave DW1000 integrated circuits*, WPNC 2017). A frame from behind reads as
  its mirror image in front (the two antennas cannot tell front from back), and the estimate spreads as
  ``1 / cos(aoa)`` towards broadside; the module flags a bearing within ``fov_deg`` (60 degrees) of the antenna axis
  as valid and reports the others folded and unflagged. In the ideal (faithful) mode the medium gives the true
  bearing, front or back.
- **Data.** ``SEND`` queues a broadcast payload (at most ``MAX_PAYLOAD`` = 112 bytes, ``queue_frames`` deep); the
  turns that carry no beacon carry the queue's head, oldest first; a full queue refuses (``QUEUE_FULL``). Frames
  the medium delivers go to the host as ``RX_DATA`` as they arrive (one longer than ``MAX_PAYLOAD``, which no DW1000
  frame carries, is dropped and counted, ``rx_data_oversize``); the neighbour table goes to the host once per update
  period, with each own beacon (``NEIGHBOURS``).
- **UART** at 115200 baud, 8N1, paced (``PacedTx``); frames as ``swarm_logic.robots.decizebro.uwb_protocol`` defines
  them. A malformed frame (bad CRC, truncated, unknown type, wrong length, bad value) is counted, dropped and
  answered with a NACK; nothing the host sends raises. Bytes the host cannot take fast enough (a module hearing
  more than the line carries) are dropped beyond ``uart_buffer`` bytes, counted.

Left out: the first round of swarm ranging (a real module reports a neighbour's range one beacon after first hearing
it; here the first beacon gives one), clock drift between slots, the module's processing time, spatial reuse of
slots by robots out of each other's range (one collision domain), BLE, GPIO, sleep.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from firmware_sim.modules.uwb import PacedTx, TdmaSlots
from swarm_logic.robots.decizebro import uwb_protocol as P

FW_VERSION = (1, 0)


@dataclass
class RadioOutput:
    uart_tx: bytes = b""
    air: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class _Neighbour:
    range_m: float
    bearing_rad: float
    flags: int
    heading_cdeg: int
    t_ns: int


class UwbRadio:
    """One robot's UWB radio: TDMA scheduler, transmit queue, neighbour table and the host UART.

    ``step(t_ns, uart_rx, events)``: ``uart_rx`` are the host's bytes since the last step; ``events`` what the medium
    delivered: ``{"ev": "beacon", "src", "t_ns", "range_m", "rx_dbm", "fp_dbm", "heading_cdeg", and "aoa_sin" (the
    measured sine of the angle of arrival) or "bearing_rad" (ideal)}`` and ``{"ev": "data", "src", "t_ns", "seq",
    "data"}``. It returns ``RadioOutput(uart_tx, air)`` with ``{"op": "tx", "t_ns": slot start, "kind": "beacon",
    "heading_cdeg"}`` or ``{..., "kind": "data", "seq", "data"}`` for every turn up to ``t_ns`` that carries a frame.
    """

    def __init__(self, *, robot: int, slot: int, n_slots: int, frames_per_s: int = 512, update_rate_hz: float = 1.0,
                 uart_baud: int = 115200, fov_deg: float = 60.0, ideal: bool = False, queue_frames: int = 16,
                 nlos_fp_gap_db: float = 10.0, neighbour_timeout_s: float = 3.0, uart_buffer: int = 4096) -> None:
        self.robot = robot
        self.tdma = TdmaSlots(int(frames_per_s), 1, slot, n_slots)
        self.tx = PacedTx(uart_baud)
        self.parser = P.Parser()
        self.period_ns = max(1, round(1e9 / update_rate_hz))
        self.fov = math.radians(fov_deg)
        self.ideal = ideal
        self.queue_frames = queue_frames
        self.nlos_fp_gap_db = nlos_fp_gap_db
        self.timeout_ns = round(neighbour_timeout_s * 1e9)
        self.uart_buffer = uart_buffer
        self.heading_cdeg = P.HEADING_UNKNOWN
        self.queue: deque[tuple[int, int, bytes]] = deque()  # (time queued, host seq, payload)
        self.neighbours: dict[int, _Neighbour] = {}
        self.last_seq = 0
        self._status_due = False
        self._k: int | None = None  # the next turn not yet decided
        self._last_beacon: int | None = None
        self.counters: dict[str, int] = dict.fromkeys((*P.STATUS_FIELDS, "uart_rx_bytes", "uart_tx_bytes",
                                                        "uart_tx_dropped", "neighbour_reports", "events_unknown",
                                                        "rx_data_oversize"), 0)

    # -- host UART ----------------------------------------------------------------------------------------
    def _send(self, t: int, typ: int, body: bytes = b"") -> None:
        data = P.frame(typ, body)
        if self.tx.pending + len(data) > self.uart_buffer:
            self.counters["uart_tx_dropped"] += 1
            return
        self.counters["uart_tx_bytes"] += len(data)
        self.tx.send(t, data)

    def _nack(self, t: int, typ: int | None, status: int, counter: str) -> None:
        self.counters[counter] += 1
        self._send(t, P.ACK, bytes((0 if typ is None else typ, status)))

    def _uart(self, t: int, data: bytes) -> None:
        self.counters["uart_rx_bytes"] += len(data)
        junk = self.parser.junk
        bad_counter = {P.BAD_CRC: "uart_bad_crc", P.TRUNCATED: "uart_truncated", P.BAD_LENGTH: "uart_bad_length"}
        for item in self.parser.feed(t, data):
            if isinstance(item, P.Bad):
                self._nack(t, item.typ, item.status, bad_counter[item.status])
                continue
            self.counters["uart_frames"] += 1
            self._request(t, *item)
        self.counters["uart_junk_bytes"] += self.parser.junk - junk

    def _request(self, t: int, typ: int, body: bytes) -> None:
        sizes = {P.INFO_GET: (0, 0), P.SET_HEADING: (2, 2), P.SEND: (2, 1 + P.MAX_PAYLOAD), P.NEIGHBOURS_GET: (0, 0),
                 P.STATUS_GET: (0, 0)}
        if typ not in sizes:
            self._nack(t, typ, P.UNKNOWN_TYPE, "uart_unknown_type")
            return
        lo, hi = sizes[typ]
        if not lo <= len(body) <= hi:
            self._nack(t, typ, P.BAD_LENGTH, "uart_bad_length")
            return
        if typ == P.SET_HEADING:
            (h,) = struct.unpack("<H", body)
            if h >= 36000:
                self._nack(t, typ, P.BAD_PARAM, "uart_bad_param")
                return
            self.heading_cdeg = h
            self._send(t, P.ACK, bytes((typ, P.OK)))
        elif typ == P.SEND:
            self.last_seq = body[0]
            self._status_due = True
            if len(self.queue) >= self.queue_frames:
                self._nack(t, typ, P.QUEUE_FULL, "queue_full")
                return
            self.queue.append((t, body[0], bytes(body[1:])))
        elif typ == P.INFO_GET:
            self._send(t, P.INFO, P.INFO_BODY.pack(self.robot & 0xFFFF, self.tdma.slot, self.tdma.n_slots,
                                                   self.tdma.fps, P.MAX_PAYLOAD, self.queue_frames,
                                                   min(0xFFFF, self.period_ns // 1_000_000), int(self.ideal)))
        elif typ == P.NEIGHBOURS_GET:
            self._report(t)
        else:
            self._send(t, P.STATUS, b"".join(struct.pack("<I", self.counters[k] & 0xFFFFFFFF)
                                             for k in P.STATUS_FIELDS))

    def _report(self, t: int) -> None:
        """The neighbour table, heard within the timeout, by id, in as many frames as it takes."""
        for p in [p for p, nb in self.neighbours.items() if t - nb.t_ns > self.timeout_ns]:
            del self.neighbours[p]
        rows = []
        for p in sorted(self.neighbours):
            nb = self.neighbours[p]
            mm = max(0, min(0xFFFF, round(nb.range_m * 1000.0))) if math.isfinite(nb.range_m) else 0
            age = max(0, min(0xFFFF, (t - nb.t_ns) // 1_000_000))
            rows.append(P.NEIGHBOUR.pack(p & 0xFFFF, mm, P.cdeg(nb.bearing_rad), nb.heading_cdeg, nb.flags, age))
        per = P.NEIGHBOURS_PER_FRAME
        parts = max(1, -(-len(rows) // per))
        for i in range(parts):
            chunk = rows[i * per:(i + 1) * per]
            self._send(t, P.NEIGHBOURS, bytes((i, parts, len(chunk))) + b"".join(chunk))
        self.counters["neighbour_reports"] += 1

    # -- air ------------------------------------------------------------------------------------------------
    def _on_event(self, t: int, ev: dict[str, Any]) -> None:
        kind, src = ev.get("ev"), ev.get("src")
        if type(src) is not int or src == self.robot:
            self.counters["events_unknown"] += 1
            return
        t_ev = int(ev.get("t_ns", t))
        if kind == "data":
            data = bytes(ev["data"])
            if len(data) > P.MAX_PAYLOAD:  # no DW1000 frame carries it (an item no module sent): counted, dropped
                self.counters["rx_data_oversize"] += 1
                return
            self.counters["rx_data"] += 1
            self._send(t, P.RX_DATA, struct.pack("<HB", src & 0xFFFF, int(ev["seq"]) & 0xFF) + data)
        elif kind == "beacon":
            self.counters["rx_beacons"] += 1
            flags = 0
            if "bearing_rad" in ev:  # ideal: the true bearing, all round
                bearing = float(ev["bearing_rad"])
                flags |= P.F_BEARING
            else:
                bearing = math.asin(max(-1.0, min(1.0, float(ev["aoa_sin"]))))
                if abs(bearing) <= self.fov:
                    flags |= P.F_BEARING
            h = int(ev.get("heading_cdeg", P.HEADING_UNKNOWN))
            if h != P.HEADING_UNKNOWN:
                flags |= P.F_HEADING
            if float(ev.get("rx_dbm", 0.0)) - float(ev.get("fp_dbm", 0.0)) > self.nlos_fp_gap_db:
                flags |= P.F_NLOS
            self.neighbours[src] = _Neighbour(float(ev["range_m"]), bearing, flags, h, t_ev)
        else:
            self.counters["events_unknown"] += 1

    def _beacon_due(self) -> int:
        return -(2**62) if self._last_beacon is None else self._last_beacon + self.period_ns

    def _run_turns(self, t: int, out: RadioOutput) -> None:
        tdma = self.tdma
        while self._k is not None:
            tk = tdma.turn_time(self._k)
            if tk > t:
                return
            if tk >= self._beacon_due():
                self._last_beacon = tk
                self.counters["tx_beacons"] += 1
                out.air.append({"op": "tx", "t_ns": tk, "kind": "beacon", "heading_cdeg": self.heading_cdeg})
                self._report(t)
                self._k += 1
            elif self.queue and self.queue[0][0] <= tk:
                _, seq, data = self.queue.popleft()
                self.counters["tx_data"] += 1
                self._status_due = True
                out.air.append({"op": "tx", "t_ns": tk, "kind": "data", "seq": seq, "data": data})
                self._k += 1
            else:  # nothing to send in this turn: skip to the next one that may have something
                nxt = min(self._beacon_due(), self.queue[0][0] if self.queue else t + 1, t + 1)
                self._k = max(self._k + 1, tdma.first_turn_at_or_after(nxt))

    # -- host interface ------------------------------------------------------------------------------------
    def step(self, t_ns: int, uart_rx: bytes, events: list[dict[str, Any]]) -> RadioOutput:
        """Advance to ``t_ns``: take the medium's frames and the host's bytes, run due turns, clock out the UART."""
        t = int(t_ns)
        out = RadioOutput()
        if self._k is None:
            self._k = self.tdma.first_turn_at_or_after(t)
        for ev in events:
            self._on_event(t, ev)
        for bad in self.parser.expire(t):
            self._nack(t, None, bad.status, "uart_truncated")
        if uart_rx:
            self._uart(t, bytes(uart_rx))
        self._run_turns(t, out)
        if self._status_due:
            self._status_due = False
            self._send(t, P.TX_STATUS, bytes((self.last_seq, self.queue_frames - len(self.queue))))
        out.uart_tx = self.tx.clock_out(t)
        return out

    def next_wake(self) -> int | None:
        """Earliest time the module has something to do: a byte to clock out, a truncated frame to drop, a turn
        with a beacon or a queued frame."""
        cands = [w for w in (self.tx.next_wake(), self.parser.deadline()) if w is not None]
        if self._k is not None:
            due = self._beacon_due()
            if self.queue:
                due = min(due, self.queue[0][0])
            cands.append(self.tdma.turn_time(max(self._k, self.tdma.first_turn_at_or_after(max(0, due)))))
        return min(cands) if cands else None
