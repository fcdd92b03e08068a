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
    """Worst-case bits on the wire for a classic data frame: 47 (standard) or 67 (extended) bits of
    framing including the 3-bit interframe space, 8 per data byte, and the worst-case stuff bits over
    the 34 + 8n (54 + 8n) bits from start of frame to the end of the CRC."""
    if extended:
        return 67 + 8 * dlc + (54 + 8 * dlc - 1) // 4
    return 47 + 8 * dlc + (34 + 8 * dlc - 1) // 4


def frame_fault(arbitration_id: int, data: bytes, extended: bool) -> str | None:
    """Why a classic CAN data frame cannot exist on the wire, or None if it can."""
    if len(data) > 8:
        return f"classic CAN frame holds at most 8 bytes, got {len(data)}"
    if not 0 <= arbitration_id <= (0x1FFFFFFF if extended else 0x7FF):
        kind = "an extended" if extended else "a standard"
        return f"arbitration id 0x{arbitration_id:X} out of range for {kind} frame"
    return None


def arbitration_key(arbitration_id: int, extended: bool) -> tuple[int, int, int]:
    """Who wins arbitration: the 11-bit base ID first; at equal base IDs a standard frame beats an
    extended one (its RTR/IDE bits are dominant where the extended frame sends recessive SRR/IDE)."""
    if extended:
        return (arbitration_id >> 18, 1, arbitration_id & 0x3FFFF)
    return (arbitration_id, 0, 0)


@dataclass(order=True)
class _Pending:
    key: tuple[int, int, int]
    src: str
    seq: int
    arbitration_id: int = field(compare=False)
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
        if (fault := frame_fault(arbitration_id, data, extended)) is not None:
            raise ValueError(fault)
        heapq.heappush(self.pending, _Pending(arbitration_key(arbitration_id, extended), src, seq,
                                              arbitration_id, bytes(data), extended))

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
            out.append(Delivery(deliver, end, f.arbitration_id, f.data, f.src, f.extended))
            self.frames += 1
            self.bits += bits
            t = end
        self.busy_until_ns = max(self.busy_until_ns, t)
        return out
