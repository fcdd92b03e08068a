"""The RDPSO hello: the one frame each robot broadcasts every iteration (one hop), as XBee payload bytes.

The thesis' messages (section 3.4 of the digest: position broadcast, improvement message, send_choice, CALL,
SPAWN, the excluded robots' position broadcast) all ride on this one record, so a robot sends one frame per
iteration whatever happens:

- who and where: robot id, subgroup id (0 = socially excluded), iteration number, position, personal best;
- the subgroup's ledger as the sender holds it (best value and where it was sensed, stagnancy counter SC_s,
  punish counter N_kill), so subgroup state spreads one hop per iteration;
- the neighbours the sender chose for its connectivity term last iteration (Algorithm 5.2's send_choice);
- flags: improved (the thesis' header bit 1), CALL, SPAWN, founder of a new subgroup, candidate for a call;
- the members the sender knows of its subgroup (or excluded cluster): id, the iteration of that member's
  newest hello it has heard of, over how many relays, and that member's personal best, so membership,
  3-missed-hello link breaks and the worst member (the one punished) are known across hops without routing.

Layout (little-endian): ``<BBHHffffffBBBHB`` header (36 bytes), ``k`` chosen ids (1 byte each), then per member
``<BBBe`` (id, iteration mod 256, relays, personal best as a half float). A ZigBee broadcast carries at most 92
bytes: 36 + k + 5 m, so 11 members with k = 1; when more are known, those over the fewest relays are sent (``encode``'s
``limit``; the numerical runner, with no radio payload limit, raises it). Robot ids must be below 256.

The wide hello (``id_width`` 2, magic ``W``) is the same record with 16-bit robot ids and 32-bit subgroup ids:
``<BHIHffffffBBBIB`` header (42 bytes), ``k`` chosen ids (2 bytes each), per member ``<HBBe`` (6 bytes). It is for
swarms beyond 255 robots (the numerical runner's large cells); a ZigBee broadcast carries fewer members with it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from functools import lru_cache

MAGIC = 0x52  # "R", RDPSO hello, version 1
HEADER = struct.Struct("<BBHHffffffBBBHB")
MEMBER = struct.Struct("<BBBe")
MAGIC_WIDE = 0x57  # "W", the wide hello: 16-bit robot ids, 32-bit subgroup ids
HEADER_WIDE = struct.Struct("<BHIHffffffBBBIB")
MEMBER_WIDE = struct.Struct("<HBBe")
MAX_ID = {1: 0xFF, 2: 0xFFFF}  # the largest robot id each id width carries
ZIGBEE_BROADCAST_MAX = 92

F_IMPROVED, F_CALL, F_SPAWN, F_FOUNDER, F_CANDIDATE = 1, 2, 4, 8, 16


@dataclass(slots=True)
class Hello:
    robot: int
    sid: int
    k: int  # iteration number, mod 65536
    x: float
    y: float
    hbest: float  # personal best value
    ledger_h: float  # the subgroup's best value (ledger)
    ledger_x: float  # where it was sensed (chi_2)
    ledger_y: float
    sc: int
    n_kill: int
    flags: int
    target: int  # SPAWN: the new subgroup's id; CANDIDATE: the subgroup applied for
    chosen: tuple[int, ...] = ()
    members: tuple[tuple[int, int, int, float], ...] = field(default=())  # (id, iteration mod 256, relays, best)


def encode(h: Hello, limit: int = ZIGBEE_BROADCAST_MAX, id_width: int = 1) -> bytes:
    """Bytes of ``h``; when the member list does not fit in ``limit`` bytes, the nearest members are kept.
    ``id_width`` 1: the ZigBee hello (ids below 256); 2: the wide hello."""
    wide = id_width == 2
    header, member = (HEADER_WIDE, MEMBER_WIDE) if wide else (HEADER, MEMBER)
    members = h.members
    room = (limit - header.size - id_width * len(h.chosen)) // member.size
    if len(members) > room:
        members = tuple(sorted(members, key=lambda m: (m[2], m[0]))[:max(0, room)])
    head = header.pack(MAGIC_WIDE if wide else MAGIC, h.robot, h.sid, h.k & 0xFFFF, h.x, h.y, h.hbest, h.ledger_h,
                       h.ledger_x, h.ledger_y, min(h.sc, 255), min(h.n_kill, 255), h.flags, h.target, len(h.chosen))
    flat = []
    for i, kk, hops, best in members:
        flat += (i, kk & 0xFF, hops if hops < 255 else 255, best if -65504.0 <= best <= 65504.0 else _half(best))
    chosen = struct.pack(f"<{len(h.chosen)}H", *h.chosen) if wide else bytes(h.chosen)
    return head + chosen + _members_struct(len(members), wide).pack(*flat)


@lru_cache(maxsize=512)
def _members_struct(m: int, wide: bool = False) -> struct.Struct:
    return struct.Struct("<" + ("HBBe" if wide else "BBBe") * m)


def _half(v: float) -> float:
    return max(-65504.0, min(65504.0, v))  # the half-float range


@lru_cache(maxsize=1024)
def decode(data: bytes) -> Hello | None:
    """The hello in ``data``, or None when it is not one (another application's frame, or truncated).

    Cached: a broadcast reaches many robots with the same bytes (in one process, the numerical runner), so each
    is unpacked once. The result is shared: treat it as read-only."""
    n = len(data)
    if n and data[0] == MAGIC_WIDE:
        header, member, width = HEADER_WIDE, MEMBER_WIDE, 2
    else:
        header, member, width = HEADER, MEMBER, 1
    if n < header.size or data[0] not in (MAGIC, MAGIC_WIDE):
        return None
    _, robot, sid, k, x, y, hbest, lh, lx, ly, sc, n_kill, flags, target, n_chosen = header.unpack_from(data)
    end = header.size + width * n_chosen
    if end > n or (n - end) % member.size:
        return None
    chosen = tuple(data[header.size:end]) if width == 1 else struct.unpack_from(f"<{n_chosen}H", data, header.size)
    members = tuple(member.iter_unpack(data[end:])) if end < n else ()
    return Hello(robot, sid, k, x, y, hbest, lh, lx, ly, sc, n_kill, flags, target, chosen, members)
