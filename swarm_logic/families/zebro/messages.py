"""The Zebro algorithms' frames (thesis Tables 3.2, 3.3, 3.6, 3.8; digest section 2.6) as UWB payload bytes.

One type byte, then the logical fields, one byte each: robot ids are unsigned bytes (ids below 256), utilities
signed bytes (int8, A-14: the thesis' "within +/-256" normalised so one fits in a byte). The immature frames:

- m0 ``00 src``: STOP; m1 ``01 src [u]``: the neighbour beacon (``u`` only in the prose reading of A-10);
- m2 ``02 src u``: the sensed utility; m3 ``03 src max_u leader``: exactly 3 bytes of logical payload (own id,
  max-utility, my-leader; section 3.5.2).

The mature frames: STOP ``10 src seq``, n1 ``11 src``, n2 ``12 src X [origin parent]``, n3 ``13 src X [origin
parent]``, n4 ``14 src dst X [origin]``, EOE ``15 src seq leader X``, ERASE ``16 src seq`` and the link list M
``17 src n (i j neg)*n``. The bracketed ids are A-5's repair (a wave's tag is (X, origin); a receiver tells a
child from a sibling by the parent field); the literal election sends the short forms.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

# immature (Table 3.2)
M0_STOP, M1, M2, M3 = 0x00, 0x01, 0x02, 0x03
# mature (Tables 3.3, 3.6, 3.8)
STOP, N1, N2, N3, N4, EOE, ERASE, LINKS = 0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17

NAMES = {M0_STOP: "m0", M1: "m1", M2: "m2", M3: "m3", STOP: "stop", N1: "n1", N2: "n2", N3: "n3", N4: "n4",
         EOE: "eoe", ERASE: "erase", LINKS: "links"}
NO_ID = 0xFF  # "none" in an id field (an origin's parent)


def utility_byte(u: int) -> int:
    """``u`` as the unsigned byte of an int8; ValueError outside -128..127 (A-14)."""
    if not -128 <= u <= 127 or int(u) != u:
        raise ValueError(f"utility {u!r} does not fit a signed byte (-128..127)")
    return int(u) & 0xFF


def _id(i: int) -> int:
    if not 0 <= i < NO_ID:
        raise ValueError(f"robot id {i!r} must lie in 0..254 (one byte; 255 means none)")
    return i


def _int8(b: int) -> int:
    return b - 256 if b > 127 else b


@dataclass(frozen=True, slots=True)
class Frame:
    """A decoded frame: its type, sender and the fields its type has (absent ones 0 / None)."""

    kind: int
    src: int
    value: int = 0  # utility, max-utility or X
    origin: int | None = None  # n2/n3/n4 (A-5 repaired); m3's my-leader; EOE's leader
    parent: int | None = None  # n2/n3: the sender's parent (A-5 repaired); n4: the addressee
    seq: int = 0  # STOP, EOE, ERASE: the election's sequence number
    links: tuple[tuple[int, int, bool], ...] = ()  # M: (i, j, negated)

    @property
    def name(self) -> str:
        return NAMES.get(self.kind, f"0x{self.kind:02x}")


def m0(src: int) -> bytes:
    return bytes((M0_STOP, _id(src)))


def m1(src: int, utility: int | None = None) -> bytes:
    return bytes((M1, _id(src))) if utility is None else bytes((M1, _id(src), utility_byte(utility)))


def m2(src: int, utility: int) -> bytes:
    return bytes((M2, _id(src), utility_byte(utility)))


def m3(src: int, max_utility: int, leader: int) -> bytes:
    return bytes((M3, _id(src), utility_byte(max_utility), _id(leader)))


def stop(src: int, seq: int) -> bytes:
    return bytes((STOP, _id(src), seq & 0xFF))


def n1(src: int) -> bytes:
    return bytes((N1, _id(src)))


def n2(src: int, x: int, origin: int | None = None, parent: int | None = None, kind: int = N2) -> bytes:
    """n2 (or n3 with ``kind``): the short literal form without ``origin``, else with origin and parent."""
    if origin is None:
        return bytes((kind, _id(src), utility_byte(x)))
    return bytes((kind, _id(src), utility_byte(x), _id(origin), NO_ID if parent is None else _id(parent)))


def n3(src: int, x: int, origin: int | None = None, parent: int | None = None) -> bytes:
    return n2(src, x, origin, parent, kind=N3)


def n4(src: int, dst: int, x: int, origin: int | None = None) -> bytes:
    base = bytes((N4, _id(src), _id(dst), utility_byte(x)))
    return base if origin is None else base + bytes((_id(origin),))


def eoe(src: int, seq: int, leader: int, x: int) -> bytes:
    return bytes((EOE, _id(src), seq & 0xFF, _id(leader), utility_byte(x)))


def erase(src: int, seq: int) -> bytes:
    return bytes((ERASE, _id(src), seq & 0xFF))


def links(src: int, entries: list[tuple[int, int, bool]] | tuple[tuple[int, int, bool], ...]) -> bytes:
    """M: the sender's link list, each (i, j, negated); at most 255 entries."""
    if len(entries) > 255:
        raise ValueError(f"a link list holds at most 255 links, got {len(entries)}")
    out = bytearray((LINKS, _id(src), len(entries)))
    for i, j, neg in entries:
        out += bytes((_id(i), _id(j), 1 if neg else 0))
    return bytes(out)


@lru_cache(maxsize=4096)
def decode(data: bytes) -> Frame | None:
    """The frame in ``data``; None for a frame that is not one of these (unknown type, wrong length).

    Cached: a broadcast reaches many robots with the same bytes. The result is immutable."""
    n = len(data)
    if n < 2:
        return None
    k, src = data[0], data[1]
    if k in (M0_STOP, N1) and n == 2:
        return Frame(k, src)
    if k == M1 and n in (2, 3):
        return Frame(k, src, _int8(data[2]) if n == 3 else 0)
    if k == M2 and n == 3:
        return Frame(k, src, _int8(data[2]))
    if k == M3 and n == 4:
        return Frame(k, src, _int8(data[2]), origin=data[3])
    if k in (STOP, ERASE) and n == 3:
        return Frame(k, src, seq=data[2])
    if k in (N2, N3) and n in (3, 5):
        if n == 3:
            return Frame(k, src, _int8(data[2]))
        return Frame(k, src, _int8(data[2]), origin=data[3], parent=None if data[4] == NO_ID else data[4])
    if k == N4 and n in (4, 5):
        return Frame(k, src, _int8(data[3]), origin=data[4] if n == 5 else None, parent=data[2])
    if k == EOE and n == 5:
        return Frame(k, src, _int8(data[4]), origin=data[3], seq=data[2])
    if k == LINKS and n >= 3 and n == 3 + 3 * data[2]:
        entries = tuple((data[3 + 3 * e], data[4 + 3 * e], bool(data[5 + 3 * e])) for e in range(data[2]))
        return Frame(k, src, links=entries)
    return None
