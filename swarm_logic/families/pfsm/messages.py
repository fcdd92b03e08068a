"""The range-and-bearing payloads (K-11): a kind byte, the sender's state, then the kind's fields; 4 of the board's
10 bytes, so that the range-and-bearing board reports each reading in one CAN frame (it carries 4 payload bytes beside
the range and bearing).

- searcher: ``SEARCHER, state | found << 7, target id (2 bytes, little-endian)``; ``found`` = 1 while it gives the
  target named energy.
- target: ``TARGET, state, own id (2 bytes)``: ARGoS's board carries no sender id, so a target names itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

SEARCHER = 1
TARGET = 2

# states, as carried in byte 1
SEARCH, RETURN, TIMEOUT = 0, 1, 2  # a searcher's
WAITING, HOMING, HOME = 0, 1, 2  # a target's
STATE_NAMES = {SEARCHER: ("search", "return", "timeout"), TARGET: ("waiting", "homing", "home")}


@dataclass(frozen=True, slots=True)
class Payload:
    kind: int
    state: int
    found: bool = False
    target_id: int = 0  # a searcher: the target it gives energy to; a target: its own id


def encode(p: Payload) -> bytes:
    if not 0 <= p.target_id < 1 << 16:
        raise ValueError(f"target id {p.target_id} does not fit in 2 bytes")
    if p.kind == SEARCHER:
        return bytes((SEARCHER, p.state | int(p.found) << 7)) + p.target_id.to_bytes(2, "little")
    return bytes((TARGET, p.state)) + p.target_id.to_bytes(2, "little")


@lru_cache(maxsize=1024)
def decode(data: bytes) -> Payload | None:
    """The payload ``data`` carries; None for anything else (an empty or foreign message). Cached: a swarm sends
    few distinct payloads, and every neighbour decodes each."""
    if len(data) >= 4 and data[0] == SEARCHER:
        return Payload(SEARCHER, data[1] & 0x7F, bool(data[1] & 0x80), int.from_bytes(data[2:4], "little"))
    if len(data) >= 4 and data[0] == TARGET:
        return Payload(TARGET, data[1], False, int.from_bytes(data[2:4], "little"))
    return None
