"""The firmware of a USB-CAN adapter speaking the LAWICEL / slcan serial protocol, as a node on a simulated bus.

A robot's simulated CAN bus is exposed on a pseudo-terminal through this adapter, so outside tools reach it the
way they reach a CANUSB or CANable: ``can.Bus(interface="slcan", channel=..., bitrate=500000)``. It is sans-IO:
the session feeds it the bytes the host wrote (``feed``) and the frames the bus delivered (``on_bus_frame``),
reports the bus's error state (``set_bus_state``), and takes back the bytes for the host (``take_output``) and
the frames for the bus (``take_tx``). Time only enters through the ``t_ns`` of a received frame.

Sources: the LAWICEL CANUSB manual's ASCII command set (as remembered, not re-checked against the PDF), the
SJA1000 data sheet (BTR0/BTR1, single acceptance filter, interrupt flags behind ``F``), the CANtact/CANable
firmware's ``slcan.c`` (``O`` and ``C`` always answer CR, S7 is 750 kbit/s), and python-can 4.6.1's
``can/interfaces/slcan.py`` (what a host sends and parses).

Protocol as modelled:

- A line ends at CR or LF; empty lines (so the LF of CR LF) are ignored without a reply. A line longer than
  ``MAX_LINE`` characters is discarded: one BEL when it overflows, the rest up to the next terminator dropped.
- Every other line gets exactly one reply: BEL for an error, otherwise something ending in CR (``\\r`` alone,
  ``z\\r``/``Z\\r`` after a standard/extended transmit as LAWICEL does, ``Vhhss\\r``, ``Nxxxx\\r``, ``Fxx\\r``).
  Syntax is checked before state: a malformed line is malformed whatever the state.
- ``Sn`` uses python-can's table (``BITRATES``: S7 is 750 kbit/s as on CANable, not LAWICEL's 800; S9 is
  83.3 kbit/s, kept as python-can's 83300). ``sxxyy`` takes SJA1000 BTR0/BTR1 for an 8 MHz CAN clock
  (python-can's ``f_clock``): bit rate = 8 MHz / (BRP x (1 + TSEG1 + TSEG2)); any register value is taken, as the
  SJA1000 takes it, and only the resulting bit rate is modelled (not the sample point or SJW).
- ``S``, ``s``, ``Z``, ``M``, ``m`` only while closed; ``O``/``L`` open only after a bit rate was set (LAWICEL:
  "initiated"). Where LAWICEL answers BEL and CANable CR, this adapter follows CANable, because python-can relies
  on it (it writes ``C``, ``S6``, an empty line, ``O`` and ``O`` again when it opens): ``C`` while closed answers
  CR, and so does ``O``/``L`` while already open in that same mode; switching between ``O`` and ``L`` needs a
  ``C`` first.
- ``t``/``T`` queue a data frame for the bus (exact length, id within 0x7FF / 0x1FFFFFFF, DLC 0..8, hex digits of
  either case) only while open, not listen-only and not bus-off; a full transmit queue refuses with BEL.
  ``r``/``R`` are checked and refused with BEL: the simulated bus carries classic data frames only.
- Received frames reach the host as ``tiiildd..\\r`` / ``Tiiiiiiiildd..\\r`` only while open and passed by the
  acceptance filter; ``Z1`` appends 4 hex digits of the frame's time in ms modulo 60000 (the adapter's timer runs
  on session time). The filter is the SJA1000's single filter (``Mxxxxxxxx`` = ACR0..ACR3, ``mxxxxxxxx`` =
  AMR0..AMR3, a mask bit of 1 is "don't care"; default accept all): standard frames compare ID.28-18, RTR and the
  first two data bytes, extended frames ID.28-0 and RTR. Data bytes a frame does not have are not compared
  (assumption).
- At most ``rx_buffer`` received frames wait in the output between two ``take_output``; more are dropped.
- ``F`` (only while open) answers the LAWICEL flags: bit 0 receive buffer full, 1 transmit queue full, 2 error
  warning (TEC or REC >= 96, or passive, or bus-off), 3 data overrun, 5 error passive (passive or bus-off: LAWICEL
  has no bus-off bit), 7 bus error. A bit reads 1 if its condition holds now or arose (for 2 and 5: changed)
  since the last ``F``; reading clears what was latched. Bit 6 (arbitration lost) is never set: the bus does not
  report lost arbitration.

A node at the wrong bit rate only sees errors: opened at a bit rate more than ``BITRATE_TOLERANCE`` away from
the bus's, the adapter receives nothing (each frame counted in ``rx_bitrate_mismatch``) and its transmissions,
acknowledged with ``z``/``Z`` as the controller took them, never reach the bus (``tx_bitrate_mismatch``); both
latch the bus-error flag. The error frames such a node would inflict on the others, and the climb of its own
error counters, are not modelled: the bus state comes from ``set_bus_state`` only. While bus-off the adapter
neither sends nor receives, and transmit commands are refused; recovery is the session's call.

Malformed or refused input never raises: it is answered and counted in ``counters``.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import NamedTuple

MS = 1_000_000  # ns
MAX_LINE = 64  # characters before the terminator; the longest valid line (T, 8 data bytes) has 26
OK, ERROR = b"\r", b"\a"
SJA1000_CAN_CLOCK = 8_000_000  # Hz: a 16 MHz crystal halved, the clock BTR0/BTR1 count in
BITRATES = {  # Sn, as python-can's slcanBus._BITRATES
    "0": 10_000, "1": 20_000, "2": 50_000, "3": 100_000, "4": 125_000,
    "5": 250_000, "6": 500_000, "7": 750_000, "8": 1_000_000, "9": 83_300,
}
BITRATE_TOLERANCE = 0.005  # relative bit-rate difference a node still synchronises across (assumption)
VERSION = "1013"  # V: hardware 10, software 13, decimal as python-can's get_version parses it
TIMESTAMP_MODULO_MS = 60_000
ERROR_WARNING_LIMIT = 96  # SJA1000 default EWLR
BUS_STATES = ("active", "passive", "bus_off")

# F status bits
F_RX_FULL, F_TX_FULL, F_ERROR_WARNING, F_DATA_OVERRUN = 0x01, 0x02, 0x04, 0x08
F_ERROR_PASSIVE, F_BUS_ERROR = 0x20, 0x80  # bit 4 is unused, bit 6 (arbitration lost) never set

COUNTER_KEYS = (
    # serial input: every non-empty line of at most MAX_LINE characters counts in ``lines`` and ends in exactly
    # one of the next seven; overlong and empty lines are counted apart
    "lines", "commands_ok", "malformed_lines", "unknown_commands", "refused", "tx_refused", "tx_queue_full",
    "remote_refused",
    "overlong_lines", "empty_lines",
    # parts of commands_ok
    "tx_frames", "tx_bitrate_mismatch",
    # every on_bus_frame ends in exactly one of these
    "rx_frames", "rx_invalid", "rx_dropped_closed", "rx_dropped_bus_off", "rx_bitrate_mismatch", "rx_filtered",
    "rx_overrun",
)

_H = "[0-9A-Fa-f]"
_SYNTAX = {
    "S": re.compile(r"S([0-9])"),
    "s": re.compile(rf"s({_H}{{4}})"),
    "Z": re.compile(r"Z([01])"),
    "M": re.compile(rf"M({_H}{{8}})"),
    "m": re.compile(rf"m({_H}{{8}})"),
    "t": re.compile(rf"t({_H}{{3}})([0-8])((?:{_H}{_H})*)"),
    "T": re.compile(rf"T({_H}{{8}})([0-8])((?:{_H}{_H})*)"),
    "r": re.compile(rf"r({_H}{{3}})([0-8])"),
    "R": re.compile(rf"R({_H}{{8}})([0-8])"),
}
_Outcome = tuple[str, bytes]  # (counter, reply)
_MALFORMED: _Outcome = ("malformed_lines", ERROR)
_REFUSED: _Outcome = ("refused", ERROR)
_DONE: _Outcome = ("commands_ok", OK)


class TxFrame(NamedTuple):
    """A frame the host asked to transmit, for the session to put on the bus."""

    arbitration_id: int
    data: bytes
    extended: bool


def btr_bitrate(btr0: int, btr1: int) -> float:
    """The bit rate SJA1000 bus timing registers give at an 8 MHz CAN clock."""
    brp = (btr0 & 0x3F) + 1
    tseg1 = (btr1 & 0x0F) + 1
    tseg2 = ((btr1 >> 4) & 0x07) + 1
    return SJA1000_CAN_CLOCK / (brp * (1 + tseg1 + tseg2))


class SlcanAdapter:
    """A LAWICEL/slcan USB-CAN adapter: serial line on one side, a node of the simulated CAN bus on the other."""

    def __init__(self, bus_bitrate: int = 500_000, *, serial_number: str = "A001", tx_queue: int = 64,
                 rx_buffer: int = 512) -> None:
        if not re.fullmatch(r"[0-9A-Za-z]{4}", serial_number):
            raise ValueError(f"serial number must be 4 alphanumeric characters, got {serial_number!r}")
        self.bus_bitrate = bus_bitrate
        self.serial_number = serial_number
        self.tx_queue = tx_queue
        self.rx_buffer = rx_buffer
        self.counters = dict.fromkeys(COUNTER_KEYS, 0)
        self.acceptance_code = 0x00000000
        self.acceptance_mask = 0xFFFFFFFF
        self._bitrate: float | None = None
        self._open = False
        self._listen_only = False
        self._timestamps = False
        self._bus_state = "active"
        self._tec = 0
        self._rec = 0
        self._latched = 0
        self._line = bytearray()
        self._discarding = False
        self._out = bytearray()
        self._rx_pending = 0
        self._tx: list[TxFrame] = []
        self._handlers: dict[str, Callable[[str], _Outcome]] = {
            "S": self._setup, "s": self._setup_btr, "O": self._open_cmd, "L": self._open_cmd, "C": self._close,
            "t": self._transmit, "T": self._transmit, "r": self._remote, "R": self._remote,
            "Z": self._set_timestamps, "M": self._set_filter, "m": self._set_filter,
            "V": self._version, "N": self._serial, "F": self._flags,
        }

    # -- state --------------------------------------------------------------------------------------------------
    @property
    def bitrate(self) -> int | None:
        """The bit rate set by ``S`` or ``s`` (rounded to bit/s), None before either."""
        return None if self._bitrate is None else round(self._bitrate)

    @property
    def is_open(self) -> bool:
        return self._open

    @property
    def listen_only(self) -> bool:
        return self._open and self._listen_only

    @property
    def timestamps(self) -> bool:
        return self._timestamps

    @property
    def bus_state(self) -> str:
        return self._bus_state

    @property
    def bitrate_matches(self) -> bool:
        """Whether the adapter's bit rate is close enough to the bus's to take part in it."""
        return self._bitrate is not None and abs(self._bitrate - self.bus_bitrate) <= (
            BITRATE_TOLERANCE * self.bus_bitrate)

    # -- session side -------------------------------------------------------------------------------------------
    def feed(self, data: bytes) -> None:
        """Bytes the host wrote to the serial port, in any chunking."""
        for byte in data:
            if byte in b"\r\n":
                if self._discarding:
                    self._discarding = False
                elif self._line:
                    self._handle(self._line.decode("latin-1"))
                    self._line.clear()
                else:
                    self.counters["empty_lines"] += 1
            elif self._discarding:
                continue
            elif len(self._line) >= MAX_LINE:
                self.counters["overlong_lines"] += 1
                self._out += ERROR
                self._line.clear()
                self._discarding = True
            else:
                self._line.append(byte)

    def on_bus_frame(self, t_ns: int, arbitration_id: int, data: bytes, extended: bool = False) -> None:
        """A data frame the bus delivered to this node at ``t_ns``."""
        data = bytes(data)
        if len(data) > 8 or not 0 <= arbitration_id <= (0x1FFFFFFF if extended else 0x7FF):
            key = "rx_invalid"
        elif not self._open:
            key = "rx_dropped_closed"
        elif self._bus_state == "bus_off":
            key = "rx_dropped_bus_off"
        elif not self.bitrate_matches:
            key = "rx_bitrate_mismatch"
            self._latched |= F_BUS_ERROR
        elif not self._accepts(arbitration_id, data, extended):
            key = "rx_filtered"
        elif self._rx_pending >= self.rx_buffer:
            key = "rx_overrun"
            self._latched |= F_RX_FULL | F_DATA_OVERRUN
        else:
            key = "rx_frames"
            head = f"T{arbitration_id:08X}" if extended else f"t{arbitration_id:03X}"
            stamp = f"{t_ns // MS % TIMESTAMP_MODULO_MS:04X}" if self._timestamps else ""
            self._out += f"{head}{len(data)}{data.hex().upper()}{stamp}\r".encode()
            self._rx_pending += 1
        self.counters[key] += 1

    def set_bus_state(self, state: str, tec: int = 0, rec: int = 0) -> None:
        """The controller's error state as the bus reports it: "active", "passive" or "bus_off"."""
        if state not in BUS_STATES:
            raise ValueError(f"bus state must be one of {BUS_STATES}, got {state!r}")
        before = self._error_flags()
        self._bus_state, self._tec, self._rec = state, tec, rec
        self._latched |= before ^ self._error_flags()

    def take_output(self) -> bytes:
        """Bytes for the host, in order; the receive buffer is free again."""
        out, self._out = bytes(self._out), bytearray()
        self._rx_pending = 0
        return out

    def take_tx(self) -> list[TxFrame]:
        """Frames for the bus, in the order the host sent them."""
        out, self._tx = self._tx, []
        return out

    # -- line protocol ------------------------------------------------------------------------------------------
    def _handle(self, line: str) -> None:
        self.counters["lines"] += 1
        handler = self._handlers.get(line[0])
        key, reply = handler(line) if handler is not None else ("unknown_commands", ERROR)
        self.counters[key] += 1
        self._out += reply

    def _setup(self, line: str) -> _Outcome:
        if (m := _SYNTAX["S"].fullmatch(line)) is None:
            return _MALFORMED
        if self._open:
            return _REFUSED
        self._bitrate = BITRATES[m[1]]
        return _DONE

    def _setup_btr(self, line: str) -> _Outcome:
        if (m := _SYNTAX["s"].fullmatch(line)) is None:
            return _MALFORMED
        if self._open:
            return _REFUSED
        self._bitrate = btr_bitrate(int(m[1][:2], 16), int(m[1][2:], 16))
        return _DONE

    def _open_cmd(self, line: str) -> _Outcome:
        if len(line) != 1:
            return _MALFORMED
        listen_only = line == "L"
        if self._open:
            return _DONE if listen_only == self._listen_only else _REFUSED
        if self._bitrate is None:
            return _REFUSED
        self._open, self._listen_only = True, listen_only
        return _DONE

    def _close(self, line: str) -> _Outcome:
        if len(line) != 1:
            return _MALFORMED
        self._open = False
        return _DONE

    def _transmit(self, line: str) -> _Outcome:
        m = _SYNTAX[line[0]].fullmatch(line)
        extended = line[0] == "T"
        if m is None or len(m[3]) != 2 * int(m[2]):
            return _MALFORMED
        arbitration_id = int(m[1], 16)
        if arbitration_id > (0x1FFFFFFF if extended else 0x7FF):
            return _MALFORMED
        if not self._open or self._listen_only or self._bus_state == "bus_off":
            return ("tx_refused", ERROR)
        if len(self._tx) >= self.tx_queue:
            self._latched |= F_TX_FULL
            return ("tx_queue_full", ERROR)
        ack = b"Z\r" if extended else b"z\r"
        if not self.bitrate_matches:
            self._latched |= F_BUS_ERROR
            self.counters["tx_bitrate_mismatch"] += 1
            return ("commands_ok", ack)
        self._tx.append(TxFrame(arbitration_id, bytes.fromhex(m[3]), extended))
        self.counters["tx_frames"] += 1
        return ("commands_ok", ack)

    def _remote(self, line: str) -> _Outcome:
        m = _SYNTAX[line[0]].fullmatch(line)
        if m is None or int(m[1], 16) > (0x1FFFFFFF if line[0] == "R" else 0x7FF):
            return _MALFORMED
        return ("remote_refused", ERROR)

    def _set_timestamps(self, line: str) -> _Outcome:
        if (m := _SYNTAX["Z"].fullmatch(line)) is None:
            return _MALFORMED
        if self._open:
            return _REFUSED
        self._timestamps = m[1] == "1"
        return _DONE

    def _set_filter(self, line: str) -> _Outcome:
        if (m := _SYNTAX[line[0]].fullmatch(line)) is None:
            return _MALFORMED
        if self._open:
            return _REFUSED
        if line[0] == "M":
            self.acceptance_code = int(m[1], 16)
        else:
            self.acceptance_mask = int(m[1], 16)
        return _DONE

    def _version(self, line: str) -> _Outcome:
        return _MALFORMED if len(line) != 1 else ("commands_ok", f"V{VERSION}\r".encode())

    def _serial(self, line: str) -> _Outcome:
        return _MALFORMED if len(line) != 1 else ("commands_ok", f"N{self.serial_number}\r".encode())

    def _flags(self, line: str) -> _Outcome:
        if len(line) != 1:
            return _MALFORMED
        if not self._open:
            return _REFUSED
        flags = self._latched | self._error_flags()
        if self._rx_pending >= self.rx_buffer:
            flags |= F_RX_FULL
        if len(self._tx) >= self.tx_queue:
            flags |= F_TX_FULL
        self._latched = 0
        return ("commands_ok", f"F{flags:02X}\r".encode())

    # -- controller -----------------------------------------------------------------------------------------------
    def _error_flags(self) -> int:
        """Error warning and error passive as they stand now."""
        if self._bus_state != "active":
            return F_ERROR_WARNING | F_ERROR_PASSIVE
        return F_ERROR_WARNING if max(self._tec, self._rec) >= ERROR_WARNING_LIMIT else 0

    def _accepts(self, arbitration_id: int, data: bytes, extended: bool) -> bool:
        """SJA1000 single acceptance filter on a data frame (RTR bit 0)."""
        if extended:
            bits, compared = arbitration_id << 3, 0xFFFFFFFC
        else:
            compared = 0xFFF00000 | (0xFF00 if len(data) >= 1 else 0) | (0xFF if len(data) >= 2 else 0)
            bits = arbitration_id << 21 | int.from_bytes(data[:2].ljust(2, b"\0"), "big")
        return (bits ^ self.acceptance_code) & ~self.acceptance_mask & compared == 0
