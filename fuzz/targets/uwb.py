"""The DWM1001 UWB module's TLV API, both ends: the module's firmware as a host's UART bytes reach it, and the
robot's driver (``swarm_logic.drivers.uwb``) as a real module's answers reach it."""

from __future__ import annotations

import struct

from bridge.media.uwb import UwbCfg
from firmware_sim.modules.uwb import (
    CMD_LOC_GET,
    CMD_RESET,
    CMD_STATUS_GET,
    CMD_SWARM_INFO_GET,
    CMD_UR_GET,
    CMD_UR_SET,
    CMD_VER_GET,
    UwbModule,
    tlv,
)
from fuzz.harness import Cursor, FakeClock, ScriptedPort, Target, chunks, lp
from swarm_logic.drivers.uwb import Uwb, UwbError

US = 1_000
PEERS = [(1, 0x1001), (2, 0x1002), (3, 0x1003)]


def _module(data: bytes) -> None:
    """Chunks: header bit 0 frames the chunk as one TLV (its first byte the type), bit 1 adds a range to a peer
    before it (so ``dwm_loc_get`` has something to report), the rest is the quiet time before it in 100 us: under
    the module's 763 us gap the chunk joins the request before."""
    c = Cursor(data)
    m = UwbModule(addr16=0x1000, robot=0, peers=PEERS, slot=0, n_slots=4, rng=None, cfg=UwbCfg())
    t = 0
    m.step(t, b"", [])
    while c.more():
        head = c.u8()
        t += (head >> 2) * 100 * US
        body = c.chunk()
        events = []
        if head & 2:
            peer = 1 + c.u8() % 3
            mm, rx, fp = c.u16(), c.u8(), c.u8()
            events.append({"ev": "range", "peer": peer, "ok": bool(mm), "range_m": mm / 1000.0,
                           "rx_dbm": -rx / 2.0, "fp_dbm": -fp / 2.0, "t_ns": t, "responder": bool(mm & 1)})
        data_ = tlv(body[0], body[1:254]) if head & 1 and body else body  # a TLV's value holds at most 253 bytes
        m.step(t, data_, events)
    for _ in range(16):
        w = m.next_wake()
        if w is None or w > t + 10_000 * US:
            break
        t = max(t, w)
        m.step(t, b"", [])


def _module_seeds() -> list[bytes]:
    reqs = [tlv(CMD_VER_GET), tlv(CMD_SWARM_INFO_GET), tlv(CMD_UR_SET, struct.pack("<HH", 5, 10)), tlv(CMD_UR_GET),
            tlv(CMD_STATUS_GET), tlv(CMD_LOC_GET), tlv(CMD_RESET), tlv(0x7F), tlv(CMD_UR_SET, b"\x00\x00\x00\x00"),
            b"\x0c\x05\x00"]

    def ranged(head: int, body: bytes, peer: int, mm: int, rx: int, fp: int) -> bytes:
        return bytes((head | 2,)) + lp(body) + bytes((peer,)) + mm.to_bytes(2, "little") + bytes((rx, fp))

    return [
        chunks(*((0x40, r) for r in reqs)),
        ranged(0x40, b"", 0, 10001, 160, 170) + ranged(0x40, b"", 1, 2500, 160, 200) + ranged(0x40, b"", 2, 0, 0, 0)
        + chunks((0x41, bytes((CMD_LOC_GET,))), (0x41, bytes((CMD_STATUS_GET,)))),
        chunks((0x40, b"\x0c"), (0x00, b"\x00"), (0x40, bytes(255))),
    ]


# -- the robot's driver ------------------------------------------------------------------------------------------------
def _driver(data: bytes) -> None:
    """The driver asks (the header picks identify, loc_get, update_rate, status, set_update_rate, reset) and the
    module answers with the chunk (bit 3 of the header: the chunk is TLVs to put after an ``ok`` status)."""
    c = Cursor(data)
    clock = FakeClock()
    port = ScriptedPort(clock)
    uwb = Uwb(port, clock, timeout=0.2, vendor=None if c.u8() & 1 else True)
    while c.more():
        head = c.u8()
        body = c.chunk()
        if head & 8:
            body = tlv(0x40, b"\x00") + body
        port.answers.append(body)
        port.answers.append(c.chunk())  # identify asks twice; the second answer waits for the next write otherwise
        op = head & 7
        try:
            if op == 0:
                uwb.identify()
            elif op == 1:
                uwb.loc_get()
            elif op == 2:
                uwb.update_rate()
            elif op == 3:
                uwb.status()
            elif op == 4:
                uwb.set_update_rate(1.0, 2.0)
            else:
                uwb.reset()
        except UwbError:  # an error status, a timeout, an answer that cannot be understood: the driver's errors
            pass
        port.answers.clear()


def _driver_seeds() -> list[bytes]:
    def op(head: int, first: bytes, second: bytes = b"") -> bytes:
        return bytes((head,)) + lp(first) + lp(second)

    ver = (tlv(0x50, bytes((1, 0, 0, 1))) + tlv(0x51, struct.pack("<I", 0x10000))
           + tlv(0x52, struct.pack("<I", 0xDECA002A)))
    swarm = tlv(0x40, b"\x00") + tlv(0xC1, struct.pack("<HHHH", 0x1000, 0, 4, 3))
    loc = (tlv(0x41, bytes(13)) + tlv(0x48, bytes((1,)) + struct.pack("<QIB", 0x1001, 1234, 100))
           + tlv(0xC0, bytes((1,)) + struct.pack("<HhhBH", 0x1001, -8000, -8600, 0, 12)))
    return [
        bytes((0,)) + op(0x08, ver, swarm) + op(0x09, loc) + op(0x0A, tlv(0x45, b"\x0a\x00\x14\x00"))
        + op(0x0B, tlv(0x5A, b"\x03\x00")) + op(0x0C, b"") + op(0x0D, b""),
        bytes((1,)) + op(0x08, ver, tlv(0x40, b"\x01")) + op(0x01, tlv(0x40, b"\x02"))
        + op(0x09, tlv(0x48, b"\x02" + bytes(13))) + op(0x02, b"\x40\x01"),
    ]


TARGETS = [
    Target("uwb_tlv", "DWM1001 UWB module firmware: a host's TLV requests on its UART, with ranging results", _module,
           _module_seeds),
    Target("uwb_driver", "the robot's DWM1001 driver: a real module's TLV answers (identify, loc_get, status, ...)",
           _driver, _driver_seeds),
]
