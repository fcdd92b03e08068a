"""The Zebro's utility sensor board, sans-IO: it streams what its sensor reads (the utility in its forward cone, the
direction of what it sees, the particles the robot has eaten) to the Raspberry Pi at 10 Hz, in the protocol of
``swarm_logic.robots.decizebro.utility_protocol``. What it reads comes from the world through its pins."""

from __future__ import annotations

import math
from typing import Any

from firmware_sim.modules.uwb import PacedTx
from swarm_logic.robots.decizebro import utility_protocol as P


class UtilityBoard:
    """``step(t_ns, sens)`` returns the bytes clocked out by ``t_ns``; ``sens`` is what the sensor reads now
    (``utility``, ``bearing_rad`` or None, ``eaten``, ``eaten_sum``)."""

    def __init__(self, baud: int = P.BAUD) -> None:
        self.tx = PacedTx(baud)
        self.next_report_ns = 0
        self.counters: dict[str, int] = {"reports": 0, "uart_tx_bytes": 0, "uart_rx_ignored_bytes": 0}

    def step(self, t_ns: int, sens: dict[str, Any] | None, uart_rx: bytes = b"") -> bytes:
        self.counters["uart_rx_ignored_bytes"] += len(uart_rx)  # the board takes no requests
        if sens is not None and t_ns >= self.next_report_ns:
            b = sens.get("bearing_rad")
            bearing = P.NO_BEARING if b is None else max(-18000, min(18000, round(math.degrees(b) * 100)))
            utility = max(-32768, min(32767, int(sens.get("utility", 0))))
            body = P.REPORT_BODY.pack(utility, bearing, int(sens.get("eaten", 0)) & 0xFFFF,
                                      max(-(1 << 31), min((1 << 31) - 1, int(sens.get("eaten_sum", 0)))))
            data = P.frame(P.REPORT, body)
            self.tx.send(t_ns, data)
            self.counters["reports"] += 1
            self.counters["uart_tx_bytes"] += len(data)
            while self.next_report_ns <= t_ns:
                self.next_report_ns += P.REPORT_PERIOD_NS
        return self.tx.clock_out(t_ns)

    def next_wake(self, t_ns: int) -> int:
        pending = self.tx.next_wake()
        return self.next_report_ns if pending is None else min(pending, self.next_report_ns)
