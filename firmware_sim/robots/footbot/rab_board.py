"""The foot-bot's infrared range-and-bearing board as its firmware behaves, sans-IO and deterministic: a node of the
robot's CAN bus on one side, its infrared emitters and receivers on the other.

- **Emission.** Once the host has given it a payload (RAB_DATA_0, and RAB_DATA_1 for bytes 7-9 of a longer one), it
  emits that payload once every update period (``period_ms``, at its own phase ``phase_ms`` within the period) until
  given another: ``["rab", {"op": "tx", "data": bytes}]`` on the air. Before the first payload it is silent.
- **Reception.** What the air delivers (``{"src", "range_m", "bearing_rad", "data"}``: a neighbour's emission as
  this board's receivers measured it) is kept, the latest per sender, until the end of the period.
- **Report.** At every period boundary it sends the period's readings on the bus: per robot heard RAB_RX_0 (index,
  range in cm, bearing in 1/1024 of a turn, payload length and bytes 0-3) and, for a payload longer than 4 bytes,
  RAB_RX_1 (bytes 4-9), then RAB_SCAN
  (how many, the scan's number and the malformed frames so far), even when it heard no one.
- **Bad input.** A payload longer than ``max_payload`` bytes, a frame of the wrong length or a RAB_DATA_1 with no
  RAB_DATA_0 before it: counted (``bad_frames``), dropped; the payload it emits stays the last good one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from swarm_logic.robots.footbot import footbot_db

MAX_READINGS = 255  # the index and the count are 8 bits


@dataclass
class RabOutput:
    can: list[tuple[int, bytes]] = field(default_factory=list)
    air: list[dict[str, Any]] = field(default_factory=list)


class RabBoard:
    def __init__(self, *, period_ms: int = 100, phase_ms: int = 0, max_payload: int = 10) -> None:
        db = footbot_db()
        self.period_ns = period_ms * 1_000_000
        self.phase_ns = (phase_ms % period_ms) * 1_000_000
        self.max_payload = max_payload
        self.m = {name: db.get_message_by_name(name) for name in
                  ("RAB_DATA_0", "RAB_DATA_1", "RAB_RX_0", "RAB_RX_1", "RAB_SCAN")}
        self.id_data0, self.id_data1 = self.m["RAB_DATA_0"].frame_id, self.m["RAB_DATA_1"].frame_id
        self.payload: bytes | None = None
        self.pending: bytes | None = None  # a long payload's first 7 bytes and its length, until RAB_DATA_1
        self.pending_len = 0
        self.heard: dict[int, dict[str, Any]] = {}
        self.next_ns = self.phase_ns
        self.scan = 0
        self.counters = {"bad_frames": 0, "emitted": 0, "heard": 0, "scans": 0, "readings_over_max": 0}

    def next_wake(self) -> int:
        return self.next_ns

    def step(self, t_ns: int, can_rx: list[tuple[int, bytes]], air_rx: list[dict[str, Any]]) -> RabOutput:
        out = RabOutput()
        for arb_id, data in can_rx:
            if arb_id == self.id_data0:
                self._data0(data)
            elif arb_id == self.id_data1:
                self._data1(data)
        for ev in air_rx:
            self.counters["heard"] += 1
            self.heard[int(ev["src"])] = ev
        while t_ns >= self.next_ns:
            self._report(out)
            if self.payload is not None:
                out.air.append({"op": "tx", "data": self.payload})
                self.counters["emitted"] += 1
            self.next_ns += self.period_ns
        return out

    def _data0(self, data: bytes) -> None:
        n = data[0] if len(data) == 8 else -1
        if not 0 <= n <= self.max_payload:
            self.counters["bad_frames"] += 1
            self.pending = None
            return
        if n <= 7:
            self.payload, self.pending = bytes(data[1:1 + n]), None
        else:
            self.pending, self.pending_len = bytes(data[1:8]), n

    def _data1(self, data: bytes) -> None:
        if self.pending is None or len(data) != 3:
            self.counters["bad_frames"] += 1
            self.pending = None
            return
        self.payload = (self.pending + bytes(data))[:self.pending_len]
        self.pending = None

    def _report(self, out: RabOutput) -> None:
        readings = [self.heard[src] for src in sorted(self.heard)]
        self.heard = {}
        if len(readings) > MAX_READINGS:
            self.counters["readings_over_max"] += len(readings) - MAX_READINGS
            readings = readings[:MAX_READINGS]
        rx0, rx1 = self.m["RAB_RX_0"], self.m["RAB_RX_1"]
        for k, ev in enumerate(readings):
            d = bytes(ev["data"]) + bytes(10)
            rng = min(1023, max(0, round(ev["range_m"] * 100)))
            b = math.remainder(float(ev["bearing_rad"]), math.tau)
            bearing = min(511, max(-512, round(b / math.tau * 1024)))
            out.can.append((rx0.frame_id, bytes([k, rng & 0xFF, ((rng >> 8) & 0x03) | ((bearing & 0x3F) << 2),
                                                 ((bearing >> 6) & 0x0F) | (min(len(ev["data"]), 10) << 4),
                                                 *d[0:4]])))
            if len(ev["data"]) > 4:  # the rest of a longer payload
                out.can.append((rx1.frame_id, bytes([k, *d[4:10]])))
        self.scan = (self.scan + 1) & 0xFF
        self.counters["scans"] += 1
        out.can.append((self.m["RAB_SCAN"].frame_id, self.m["RAB_SCAN"].encode(
            {"count": len(readings), "scan": self.scan, "bad_frames": min(self.counters["bad_frames"], 65535)})))
