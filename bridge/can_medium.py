"""A CAN bus as a shared medium: frames contend by arbitration ID and take their bit time on the wire.

Frames offered during quantum k start contending at the end of k (they are delivered at k+1 at the
earliest, like every message in a session). The lowest ID wins arbitration; each frame occupies the bus
for its worst-case stuffed length at the bus bit rate; a frame is delivered at the first quantum
boundary at or after the end of its transmission. The order of delivery is the order on the wire, so it
does not depend on which process sent first.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field


def frame_bits(dlc: int, extended: bool = False) -> int:
    """Worst-case bits on the wire for a classic data frame with bit stuffing, plus 3 bits interframe."""
    if extended:
        return 67 + 8 * dlc + (54 + 8 * dlc - 1) // 4 + 3
    return 47 + 8 * dlc + (34 + 8 * dlc - 1) // 4 + 3


@dataclass(order=True)
class _Pending:
    arbitration_id: int
    src: str
    seq: int
    data: bytes = field(compare=False)
    extended: bool = field(compare=False, default=False)


@dataclass(frozen=True, slots=True)
class Delivery:
    t_ns: int  # quantum boundary at which it is delivered
    wire_end_ns: int  # when its last bit left the wire
    arbitration_id: int
    data: bytes
    src: str
    extended: bool


class CanMedium:
    """One CAN bus segment (one robot's bus)."""

    def __init__(self, name: str, bitrate: int = 500_000) -> None:
        self.name = name
        self.bitrate = bitrate
        self.pending: list[_Pending] = []
        self.busy_until_ns = 0
        self.frames = 0
        self.bits = 0

    def offer(self, src: str, seq: int, arbitration_id: int, data: bytes, extended: bool = False) -> None:
        heapq.heappush(self.pending, _Pending(arbitration_id, src, seq, bytes(data), extended))

    def transmit(self, t_start_ns: int, q_ns: int) -> list[Delivery]:
        """Put pending frames on the wire from ``t_start_ns`` for one quantum; return what completes.

        Frames still contending at the end of the quantum stay pending for the next call.
        """
        out: list[Delivery] = []
        t = max(self.busy_until_ns, t_start_ns)
        horizon = t_start_ns + q_ns
        while self.pending and t < horizon:
            f = heapq.heappop(self.pending)
            bits = frame_bits(len(f.data), f.extended)
            end = t + (bits * 1_000_000_000 + self.bitrate - 1) // self.bitrate
            deliver = -(-end // q_ns) * q_ns
            out.append(Delivery(max(deliver, t_start_ns), end, f.arbitration_id, f.data, f.src, f.extended))
            self.frames += 1
            self.bits += bits
            t = end
        self.busy_until_ns = max(self.busy_until_ns, t)
        return out
