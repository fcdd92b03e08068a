"""The UART protocol between the Zebro's Raspberry Pi and its DWM1001 UWB radio (ours: the Zebro's firmware is not
public). Both ends use this module: the module's firmware (``firmware_sim.robots.decizebro.uwb_radio``) and the Pi's
driver (``swarm_logic.robots.decizebro.uwb_radio``). docs/zebro-radio.md has the byte-by-byte description.

A frame is ``A5 LEN TYPE BODY CRC``: start byte 0xA5, LEN = 1 + len(BODY) (1..255), the message type, its body, and
a CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF, ``binascii.crc_hqx``) over LEN, TYPE and BODY, little
endian. All integers are little endian. Angles are centidegrees: bearings signed (-18000..18000, + = left of the
robot's heading), headings 0..35999 counter-clockwise from the arena's x axis (east), 0xFFFF when unknown.
"""

from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass

SOF = 0xA5
MAX_BODY = 254

# host -> module
INFO_GET = 0x01  # empty -> INFO
SET_HEADING = 0x02  # heading u16 cdeg -> ACK
SEND = 0x03  # seq u8, payload (1..MAX_PAYLOAD bytes) -> ACK (QUEUE_FULL when the queue is full)
NEIGHBOURS_GET = 0x04  # empty -> NEIGHBOURS frame(s)
STATUS_GET = 0x05  # empty -> STATUS
# module -> host
ACK = 0x80  # type u8 (the request's), status u8: an answer, or a NACK when status is not OK
INFO = 0x81  # id u16, slot u16, n_slots u16, frames_per_s u16, max_payload u8, queue u8, period_ms u16, ideal u8
RX_DATA = 0x82  # src u16, seq u8, payload: a neighbour's broadcast (unsolicited)
TX_STATUS = 0x83  # last host seq u8, queue_free u8 (unsolicited, after frames left the queue)
NEIGHBOURS = 0x84  # part u8, parts u8, count u8, count x NEIGHBOUR (unsolicited once per update period, or asked)
STATUS = 0x85  # the counters in STATUS_FIELDS order, u32 each

# ACK status codes
OK = 0
BAD_CRC = 1
TRUNCATED = 2  # the frame did not complete within FRAME_TIMEOUT_NS of its start byte
UNKNOWN_TYPE = 3
BAD_LENGTH = 4  # the body's length does not fit the type
QUEUE_FULL = 5
BAD_PARAM = 6
STATUS_NAMES = {OK: "ok", BAD_CRC: "bad CRC", TRUNCATED: "truncated frame", UNKNOWN_TYPE: "unknown type",
                BAD_LENGTH: "bad length", QUEUE_FULL: "transmit queue full", BAD_PARAM: "bad parameter"}

# A DW1000 frame holds 127 bytes: 802.15.4 data header with short addresses (frame control 2, sequence 1, PAN 2,
# destination 2, source 2), our AN-TDMA header (type 1, host seq 1, heading 2) and the FCS (2) leave 112
MAX_PAYLOAD = 112
FRAME_TIMEOUT_NS = 50_000_000
NEIGHBOUR = struct.Struct("<HHhHBH")  # id, range mm, bearing cdeg, heading cdeg, flags, age ms
NEIGHBOURS_PER_FRAME = (MAX_BODY - 3) // NEIGHBOUR.size
HEADING_UNKNOWN = 0xFFFF
# NEIGHBOUR flags
F_BEARING = 0x01  # the bearing is within the antennas' field of view (outside it: folded, unreliable)
F_HEADING = 0x02  # the neighbour's heading is known (it has been set on its module)
F_NLOS = 0x04  # the DW1000 diagnostics say likely NLOS (RX - first path > 10 dB, Decawave APS006)
INFO_BODY = struct.Struct("<HHHHBBHB")
STATUS_FIELDS = ("tx_beacons", "tx_data", "rx_beacons", "rx_data", "queue_full", "uart_frames", "uart_bad_crc",
                 "uart_truncated", "uart_unknown_type", "uart_bad_length", "uart_bad_param", "uart_junk_bytes")


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE."""
    return binascii.crc_hqx(data, 0xFFFF)


def frame(typ: int, body: bytes = b"") -> bytes:
    """One frame of ``typ`` carrying ``body``."""
    if len(body) > MAX_BODY:
        raise ValueError(f"a frame body holds at most {MAX_BODY} bytes, got {len(body)}")
    head = bytes((len(body) + 1, typ & 0xFF))
    return bytes((SOF,)) + head + body + struct.pack("<H", crc16(head + body))


@dataclass(frozen=True)
class Bad:
    """A malformed frame the parser dropped: why (an ACK status), and the type when it got that far."""

    status: int
    typ: int | None = None


class Parser:
    """Splits a byte stream into frames: ``feed(t_ns, data)`` returns ``(type, body)`` pairs and ``Bad`` entries in
    arrival order. Bytes before a start byte are junk (counted in ``junk``); a bad CRC drops the start byte only and
    hunts again from the next byte, so a good frame after a broken one is still found; a frame still incomplete
    ``timeout_ns`` after its start byte arrived is dropped as truncated (``expire``)."""

    def __init__(self, timeout_ns: int = FRAME_TIMEOUT_NS) -> None:
        self.buf = bytearray()
        self.start_ns: int | None = None  # when the pending frame's start byte arrived
        self.timeout_ns = timeout_ns
        self.junk = 0

    def expire(self, t_ns: int) -> list[Bad]:
        """Drop a pending frame that has waited too long for its rest."""
        if self.buf and self.start_ns is not None and t_ns - self.start_ns >= self.timeout_ns:
            self.buf.clear()
            self.start_ns = None
            return [Bad(TRUNCATED)]
        return []

    def deadline(self) -> int | None:
        """When a pending incomplete frame will be dropped (None: nothing pending)."""
        return None if not self.buf or self.start_ns is None else self.start_ns + self.timeout_ns

    def feed(self, t_ns: int, data: bytes) -> list[tuple[int, bytes] | Bad]:
        out: list[tuple[int, bytes] | Bad] = [*self.expire(t_ns)]
        self.buf += data
        buf = self.buf
        while buf:
            if buf[0] != SOF:
                i = buf.find(SOF)
                n = len(buf) if i < 0 else i
                self.junk += n
                del buf[:n]
                continue
            if self.start_ns is None:
                self.start_ns = t_ns
            if len(buf) < 2:
                break
            n = buf[1]
            if n == 0:  # no type byte: a start byte followed by a zero cannot begin a frame
                out.append(Bad(BAD_LENGTH))
                del buf[:1]
                self.start_ns = None
                continue
            if len(buf) < 4 + n:
                break
            head, crc = bytes(buf[1:2 + n]), struct.unpack_from("<H", buf, 2 + n)[0]
            if crc16(head) != crc:
                out.append(Bad(BAD_CRC))
                del buf[:1]
            else:
                out.append((head[1], head[2:]))
                del buf[:4 + n]
            self.start_ns = None
        return out


def cdeg(rad: float) -> int:
    """An angle in radians as signed centidegrees (-18000..18000)."""
    d = math.degrees(math.remainder(rad, math.tau))
    return max(-18000, min(18000, round(d * 100)))


def heading_cdeg(rad: float) -> int:
    """A heading in radians as 0..35999 centidegrees."""
    return round(math.degrees(rad % math.tau) * 100) % 36000
