"""The slcan (LAWICEL) USB-CAN adapter's line parser, as a host's serial bytes reach it on its pseudo-terminal,
between frames from the bus and changes of the bus's error state (which set the flags ``F`` reports)."""

from __future__ import annotations

from firmware_sim.modules.slcan import BUS_STATES, SlcanAdapter
from fuzz.harness import Cursor, Target, chunks

MS = 1_000_000


def _run(data: bytes) -> None:
    """Chunks: header bits 0-1 say what it is (0, 1: the host's bytes; 2: a frame from the bus, id and data from the
    chunk; 3: the bus's state and error counters), the rest of the header is time passing."""
    c = Cursor(data)
    a = SlcanAdapter(tx_queue=4, rx_buffer=8)
    t = 0
    while c.more():
        head = c.u8()
        t += (head >> 2) * MS
        body = c.chunk()
        kind = head & 3
        if kind < 2:
            a.feed(body)
        elif kind == 2:
            ext = bool(body[:1]) and body[0] & 1 == 1
            arb = int.from_bytes(body[1:5].ljust(4, b"\0"), "little") & (0x1FFFFFFF if ext else 0x7FF)
            a.on_bus_frame(t, arb, body[5:13], ext)
        else:
            b = body.ljust(3, b"\0")
            a.set_bus_state(BUS_STATES[b[0] % 3], b[1] * 2, b[2] * 2)
        a.take_output()
        a.take_tx()


def _seeds() -> list[bytes]:
    lines = [b"C\r", b"S6\r", b"\r", b"O\r", b"O\r", b"V\r", b"N\r", b"F\r", b"t1232AABB\r",
             b"T1FFFFFFF81122334455667788\r", b"r1230\r", b"R123456780\r", b"t7FF0\r\n"]
    setup = [b"S5\r", b"s031C\r", b"Z1\r", b"M24600000\r", b"m001FFFFF\r", b"L\r", b"F\r", b"C\r", b"Z0\r", b"O\r"]
    frame = bytes((0,)) + (0x123).to_bytes(4, "little") + b"\x01\x02\x03"
    return [
        chunks(*((0x04, line) for line in lines)),
        chunks(*((0x00, line) for line in setup), (0x06, frame), (0x07, bytes((1, 60, 0))), (0x00, b"F\r"),
               (0x07, bytes((2, 200, 0))), (0x00, b"t1230\r"), (0x07, bytes((0, 0, 0)))),
        chunks((0x00, b"S6\rO\r"), (0x00, b"7" * 100 + b"\r"), (0x00, b"t12" + b"\r"), (0x06, frame)),
    ]


TARGETS = [Target("slcan", "slcan (LAWICEL) USB-CAN adapter: a host's serial lines, bus frames, bus states", _run,
                  _seeds)]
