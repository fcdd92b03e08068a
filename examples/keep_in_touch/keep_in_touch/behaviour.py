"""KeepInTouch: a random walk that keeps the XBee network together, and says who its neighbours are.

It is the library's RSSI keeper (``swarm_logic.families.demo.rssi_keeper``: hellos every ``hello_s``, turn back
when fewer than ``k`` links are good) with this project's own neighbour bookkeeping: neighbours are known by their
robot id (from their hellos), a neighbour not heard for ``forget_hellos`` hello periods is dropped, and every
change is logged (``neighbour_found``, ``neighbour_lost``), so the tests can see when a robot is dropped.
"""

from __future__ import annotations

import struct
from typing import ClassVar

from swarm_logic.families.demo.rssi_keeper import HELLO, RssiKeeper

HELLO_BODY = struct.Struct("<HH")  # robot id, sequence number


class KeepInTouch(RssiKeeper):
    defaults: ClassVar[dict[str, float]] = {**RssiKeeper.defaults, "forget_hellos": 2.5}
    ranges: ClassVar[dict[str, str]] = {**RssiKeeper.ranges, "forget_hellos": "(1, inf)"}

    def init(self, robot) -> None:
        self.heard_at: dict[int, float] = {}  # robot id -> when its last hello came (s)
        super().init(robot)

    def _radio(self, now: float) -> None:
        r = self.robot
        a = self.p["rssi_smoothing"]
        while (pkt := r.xbee.recv(timeout=0)) is not None:
            if not pkt.data.startswith(HELLO) or len(pkt.data) != 1 + HELLO_BODY.size:
                continue
            rid, _ = HELLO_BODY.unpack(pkt.data[1:])
            if rid not in self.heard_at:
                r.log("neighbour_found", id=rid)
            self.heard_at[rid] = now
            old = self.table.get(rid)
            rssi = pkt.rssi_dbm if pkt.rssi_dbm is not None else (old[0] if old else None)
            if rssi is not None:
                self.table[rid] = (rssi if old is None else a * rssi + (1 - a) * old[0], now)
        horizon = self.p["forget_hellos"] * self.p["hello_s"]
        for rid in sorted(rid for rid, t in self.heard_at.items() if now - t > horizon):
            last = self.heard_at.pop(rid)
            self.table.pop(rid, None)
            r.log("neighbour_lost", id=rid, last_heard_s=round(last, 3))
        if now >= self.next_hello:
            self.next_hello += self.p["hello_s"]
            self.hello_seq = (self.hello_seq + 1) & 0xFFFF
            r.xbee.send_nowait(None, HELLO + HELLO_BODY.pack(r.id & 0xFFFF, self.hello_seq), radius=1)

    def neighbours(self) -> list[int]:
        return sorted(self.heard_at)
