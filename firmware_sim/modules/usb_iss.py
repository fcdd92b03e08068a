"""The firmware of a Devantech USB-ISS in I2C mode, as the master of a simulated I2C bus.

A robot's simulated I2C bus is exposed on a pseudo-terminal through this adapter, so a program outside the session
drives it as it would drive a USB-ISS plugged into a PC and wired to the robot's SDA and SCL
(``swarm_logic.drivers.usb_iss`` is such a program's smbus2-compatible driver). It is sans-IO: the session feeds it
the bytes the host wrote (``feed``), asks it for the next I2C transaction to put on the bus (``poll``: one at a
time, as the module has one bus), reports each transaction's end (``on_result``: the errno the I2C medium gives,
``EREMOTEIO`` for an address nobody ACKed, and the bytes read) and takes back the bytes for the host
(``take_output``). Time only enters through ``t_ns`` (the command synchronisation gap).

Source: Devantech's technical pages, "USB-ISS Multifunction USB Communications Module, Technical Specification"
(``usb_iss_tech.htm``: the ISS_CMD 0x5A sub-commands, the operating modes, the mode response bytes) and "I2C Mode -
Technical Specification" (``usb_iss_i2c_tech.htm``: I2C_SGL 0x53, I2C_AD0 0x54, I2C_AD1 0x55, I2C_AD2 0x56,
I2C_DIRECT 0x57 with its sub-commands and error codes, I2C_TEST 0x58), both robot-electronics.co.uk, as archived in
June 2023.

Protocol as modelled:

- Addresses are given as on the wire, the 7-bit address shifted left with the R/W bit (0x21 reads from 0x10).
- ``5A 01`` answers the module id 7, the firmware version (``FIRMWARE``: V5 or later, which has I2C_TEST) and the
  current mode; ``5A 03`` the 8-digit ASCII serial number; ``5A 02 MODE ...`` sets the mode (I2C 20/50/100/400 kHz
  bit-bashed 0x20-0x50, 100/400/1000 kHz hardware 0x60-0x80, each + 0x01 with the serial port; I/O, I/O change,
  SPI) and answers ``FF 00``, or ``00 05`` for an unknown mode. The module powers up in 0x40 (I2C, 100 kHz); the
  mode's SCL rate times the transactions on the bus.
- I2C_SGL, I2C_AD0, I2C_AD1 and I2C_AD2 writes answer one byte, ``00`` if the device did not ACK, non-zero (``FF``)
  if it did; their reads answer the bytes read. The register of I2C_AD1 and I2C_AD2 reads is written first, then the
  bytes are read after a repeated START. What a read answers when its device does not ACK is not documented: here
  as many ``00`` bytes as were asked for. Writes carry at most 60 data bytes (59 for I2C_AD2), reads at most 60 (64
  for I2C_AD2): the module's 64-byte buffer.
- I2C_DIRECT: the sub-commands START ``01``, RESTART ``02``, STOP ``03``, NACK ``04`` (NACK after the next read:
  accepted, it changes nothing on this bus), READ ``20``-``2F`` (1-16 bytes) and WRITE ``30``-``3F`` (1-16 bytes,
  which follow). The first byte written after a START or RESTART is the address. The answer is ``FF n`` then the n
  bytes read, or ``00 e``: 01 a device did not ACK (the transaction stops there, with a STOP), 02 a frame of 60
  bytes or more, the 0x57 included (or over 64 bytes read), 03 fewer write bytes than the WRITE promised, 04 an
  unknown sub-command. One frame may hold several transactions, each from START to STOP.
- I2C_TEST ``58 addr`` puts the address alone on the bus (a write of no bytes) and answers non-zero if it was ACKed.

Choices where the pages say nothing, each documented in ``docs/zebrobus.md``: the module takes a command from the
bytes that arrive without a gap (the pages: "a gap will result in the USB-ISS re-starting its internal command
synchronization loop and ignoring the message"); a command not complete ``GAP_NS`` after its last byte is dropped
unanswered (``truncated``). An I2C_DIRECT frame is checked whole before anything goes on the bus: a sequence the bus
cannot carry (a READ or WRITE outside START..STOP, a READ after a write address or data after a read address, a
read of no bytes, a sequence not closed by a STOP) answers ``00 04`` and touches nothing, where the real module may
have started the sequence. A byte that starts no known command (the SPI, serial and I/O commands included: nothing
is wired to those pins) is dropped (``unknown_command``). I2C commands outside an I2C mode touch nothing and answer
as a failure. Nothing a host sends makes it raise: every refusal is counted in ``counters``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

ISS_CMD = 0x5A
ISS_VERSION, ISS_MODE, GET_SER_NUM = 0x01, 0x02, 0x03
I2C_SGL, I2C_AD0, I2C_AD1, I2C_AD2, I2C_DIRECT, I2C_TEST = 0x53, 0x54, 0x55, 0x56, 0x57, 0x58
D_START, D_RESTART, D_STOP, D_NACK = 0x01, 0x02, 0x03, 0x04
D_READ, D_WRITE = 0x20, 0x30  # + n - 1, n = 1..16

MODULE_ID = 7
FIRMWARE = 7  # V5 or later: I2C_TEST
ACK, NACK = 0xFF, 0x00
MODE_UNKNOWN = 0x05
DEVICE_ERROR, BUFFER_OVERFLOW, BUFFER_UNDERFLOW, UNKNOWN_SUBCOMMAND = 0x01, 0x02, 0x03, 0x04

I2C_MODES = {0x20: 20_000, 0x30: 50_000, 0x40: 100_000, 0x50: 400_000,  # bit-bashed
             0x60: 100_000, 0x70: 400_000, 0x80: 1_000_000}  # the PIC's I2C hardware
POWER_UP_MODE = 0x40
IO_MODE, IO_CHANGE, SERIAL = 0x00, 0x10, 0x01
SPI_MODES = range(0x90, 0x94)

MAX_WRITE = {I2C_AD0: 60, I2C_AD1: 60, I2C_AD2: 59}
MAX_READ = {I2C_SGL: 1, I2C_AD0: 60, I2C_AD1: 60, I2C_AD2: 64}
DIRECT_FRAME = 60  # "limit the frame to < 60 bytes"
READ_BUFFER = 64
EREMOTEIO = 121  # the I2C medium's errno for an address nobody ACKed (Linux's)
GAP_NS = 50_000_000  # a command not complete this long after its last byte is dropped (our figure)

Msg = list  # [addr, read, data bytes | read length], as the I2C medium takes a message
Result = tuple[int, list[bytes]]  # (errno, the bytes each read message got)


class _Need(Exception):
    """The command is not complete yet."""

    def __init__(self, underflow: bool = False) -> None:
        self.underflow = underflow  # inside an I2C_DIRECT WRITE's data


class _Refused(Exception):
    """An I2C_DIRECT frame the module refuses before touching the bus."""

    def __init__(self, code: int, end: int) -> None:
        self.code, self.end = code, end


@dataclass
class _Job:
    """A command's transactions, put on the bus one after the other (the next only if the one before was ACKed),
    and how its answer is made of their results."""

    txns: list[list[Msg]]
    answer: Callable[[list[Result]], bytes]
    results: list[Result] = field(default_factory=list)


def mode_length(mode: int) -> int | None:
    """The length of ``5A 02 MODE ...`` for an operating mode, None for an unknown one."""
    if mode in I2C_MODES or mode in (IO_MODE, IO_CHANGE) or mode in SPI_MODES:
        return 4  # + IO_TYPE or the SPI divisor
    if mode & 0x0F == SERIAL and (mode - SERIAL in I2C_MODES):
        return 5  # + the baud rate divisor
    if mode == IO_MODE + SERIAL:
        return 6  # + the baud rate divisor and IO_TYPE
    return None


class UsbIss:
    """One USB-ISS: the host's bytes in, transactions for the bus out, their results in, answers out."""

    def __init__(self, serial: str = "00000001", gap_ns: int = GAP_NS) -> None:
        if len(serial) != 8 or not serial.isdigit():
            raise ValueError(f"a USB-ISS serial number is 8 ASCII digits, got {serial!r}")
        self.serial = serial.encode()
        self.gap_ns = gap_ns
        self.mode = POWER_UP_MODE
        self.buf = bytearray()
        self.last_rx = 0
        self.out = bytearray()
        self.job: _Job | None = None
        self.in_flight = False
        self.counters = {"commands": 0, "transactions": 0, "nacks": 0, "bus_errors": 0, "truncated": 0,
                         "unknown_command": 0, "bad_mode": 0, "bad_length": 0, "overflow": 0, "underflow": 0,
                         "bad_sequence": 0, "not_i2c_mode": 0}

    @property
    def scl_hz(self) -> int:
        """The SCL rate of the current I2C mode."""
        return I2C_MODES.get(self.mode & 0xF0, 100_000)

    @property
    def i2c_mode(self) -> bool:
        return (self.mode & 0xF0) in I2C_MODES

    # -- the host's side ------------------------------------------------------------------------------------------
    def feed(self, t_ns: int, data: bytes) -> None:
        """Bytes the host wrote, arrived at ``t_ns``."""
        if data:
            self.buf += data
            self.last_rx = t_ns

    def take_output(self) -> bytes:
        out, self.out = bytes(self.out), bytearray()
        return out

    # -- the bus side ---------------------------------------------------------------------------------------------
    def poll(self, t_ns: int) -> list[Msg] | None:
        """The next transaction to put on the bus (None: nothing now); answers what can be answered."""
        while True:
            if self.job is not None:
                if self.in_flight:
                    return None
                job = self.job
                failed = any(errno for errno, _ in job.results)
                if not failed and len(job.results) < len(job.txns):
                    self.in_flight = True
                    self.counters["transactions"] += 1
                    return job.txns[len(job.results)]
                self.out += job.answer(job.results)
                self.job = None
            if not self.buf:
                return None
            try:
                self._parse()
            except _Need as need:
                if t_ns - self.last_rx < self.gap_ns:
                    return None
                self._gap(need)

    def on_result(self, errno: int, reads: list[bytes]) -> None:
        """The transaction ``poll`` gave has ended: ``errno`` 0 (done), or the I2C medium's error."""
        if self.job is None or not self.in_flight:
            return  # nothing was asked of the bus: a stray result
        self.in_flight = False
        if errno:
            self.counters["nacks" if errno == EREMOTEIO else "bus_errors"] += 1
        self.job.results.append((int(errno), [bytes(b) for b in reads]))

    # -- parsing ----------------------------------------------------------------------------------------------------
    def _need(self, n: int) -> None:
        if len(self.buf) < n:
            raise _Need

    def _consume(self, n: int) -> bytes:
        got = bytes(self.buf[:n])
        del self.buf[:n]
        return got

    def _gap(self, need: _Need) -> None:
        """A command stopped short and nothing more came: an I2C_DIRECT frame is answered, anything else dropped."""
        if self.buf[0] == I2C_DIRECT:
            self.counters["underflow" if need.underflow else "bad_sequence"] += 1
            self.out += bytes([NACK, BUFFER_UNDERFLOW if need.underflow else UNKNOWN_SUBCOMMAND])
        else:
            self.counters["truncated"] += 1
        self.buf.clear()

    def _parse(self) -> None:
        """Take one command from the front of the buffer: answer it now, or make it the job (raises ``_Need`` when
        it is not complete, consuming nothing)."""
        c = self.buf[0]
        if c == ISS_CMD:
            self._setup()
        elif c in (I2C_SGL, I2C_AD0, I2C_AD1, I2C_AD2):
            self._addressed(c)
        elif c == I2C_DIRECT:
            self._direct()
        elif c == I2C_TEST:
            self._need(2)
            addr = self._consume(2)[1] >> 1
            self._start([[[addr, False, b""]]], lambda res: bytes([NACK if res[-1][0] else ACK]), b"\x00")
        else:
            self._consume(1)
            self.counters["unknown_command"] += 1

    def _setup(self) -> None:
        self._need(2)
        sub = self.buf[1]
        if sub == ISS_VERSION:
            self._consume(2)
            self.out += bytes([MODULE_ID, FIRMWARE, self.mode])
        elif sub == GET_SER_NUM:
            self._consume(2)
            self.out += self.serial
        elif sub == ISS_MODE:
            self._need(3)
            n = mode_length(self.buf[2])
            if n is None:
                self._consume(3)
                self.counters["bad_mode"] += 1
                self.out += bytes([NACK, MODE_UNKNOWN])
                return
            self._need(n)
            self.mode = self._consume(n)[2]
            self.out += bytes([ACK, 0x00])
        else:
            self._consume(2)
            self.counters["bad_mode"] += 1
            self.out += bytes([NACK, MODE_UNKNOWN])
        self.counters["commands"] += 1

    def _addressed(self, c: int) -> None:
        """I2C_SGL, I2C_AD0, I2C_AD1, I2C_AD2: ``c addr [register] [count] [data]``."""
        reg_len = {I2C_SGL: 0, I2C_AD0: 0, I2C_AD1: 1, I2C_AD2: 2}[c]
        self._need(2)
        a = self.buf[1]
        addr, read = a >> 1, bool(a & 1)
        head = 2 + reg_len + (0 if c == I2C_SGL else 1)  # the command, address, register and count bytes
        self._need(head)
        n = 1 if c == I2C_SGL else self.buf[head - 1]
        if not read:
            self._need(head + n)
        raw = self._consume(head if read else head + n)
        reg = raw[2:2 + reg_len]
        data = raw[head:]
        if read:
            if n == 0:
                self.counters["bad_length"] += 1
                return
            zeros = bytes(n)
            if n > MAX_READ[c]:
                self.counters["overflow"] += 1
                self.out += zeros
                return
            txn = ([[addr, False, reg]] if reg else []) + [[addr, True, n]]
            self._start([txn], lambda res: zeros if res[-1][0] else res[-1][1][-1], zeros)
        else:
            if c != I2C_SGL and n > MAX_WRITE[c]:
                self.counters["overflow"] += 1
                self.out += bytes([NACK])
                return
            self._start([[[addr, False, reg + data]]], lambda res: bytes([NACK if res[-1][0] else ACK]), b"\x00")

    def _start(self, txns: list[list[Msg]], answer: Callable[[list[Result]], bytes], refused: bytes) -> None:
        """A command for the bus, or its failure answer outside an I2C mode."""
        self.counters["commands"] += 1
        if not self.i2c_mode:
            self.counters["not_i2c_mode"] += 1
            self.out += refused
            return
        self.job = _Job(txns, answer)

    def _direct(self) -> None:
        try:
            txns, end = self._direct_frame()
        except _Refused as e:
            self._consume(e.end)
            self.counters["overflow" if e.code == BUFFER_OVERFLOW else "bad_sequence"] += 1
            self.counters["commands"] += 1
            self.out += bytes([NACK, e.code])
            return
        self._consume(end)

        def answer(res: list[Result]) -> bytes:
            if any(errno for errno, _ in res):
                return bytes([NACK, DEVICE_ERROR])
            got = b"".join(b for _, reads in res for b in reads)
            return bytes([ACK, len(got)]) + got

        self._start(txns, answer, bytes([NACK, UNKNOWN_SUBCOMMAND]))

    def _direct_frame(self) -> tuple[list[list[Msg]], int]:
        """The transactions of the I2C_DIRECT frame at the front of the buffer, and its length. A frame ends after a
        STOP not followed by a START in the bytes at hand."""
        buf = self.buf
        txns: list[list[Msg]] = []
        cur: list[Msg] | None = None
        expect_addr = False
        bad = 0  # the first refusal found: the frame is still read to its end
        reads = 0
        i = 1
        while True:
            if i >= len(buf):
                if cur is None and txns:
                    break
                if cur is None and bad:  # a broken frame: the bytes at hand are all of it
                    break
                raise _Need
            s = buf[i]
            if cur is None and txns and s != D_START:
                break  # the next command
            i += 1
            if s == D_START:
                if cur is not None:
                    bad = bad or UNKNOWN_SUBCOMMAND
                cur, expect_addr = [], True
            elif s in (D_RESTART, D_STOP, D_NACK):
                if cur is None or (s != D_NACK and expect_addr):
                    bad = bad or UNKNOWN_SUBCOMMAND
                    if cur is None:
                        continue
                if s == D_RESTART:
                    expect_addr = True
                elif s == D_STOP:
                    if cur and cur[-1][1] and cur[-1][2] == 0:
                        bad = bad or UNKNOWN_SUBCOMMAND  # a read of no bytes
                    txns.append(cur)
                    cur = None
            elif D_READ <= s < D_READ + 16:
                n = s - D_READ + 1
                if cur is None or expect_addr or not cur or not cur[-1][1]:
                    bad = bad or UNKNOWN_SUBCOMMAND
                    continue
                cur[-1][2] += n
                reads += n
            elif D_WRITE <= s < D_WRITE + 16:
                n = s - D_WRITE + 1
                if i + n > len(buf):
                    raise _Need(underflow=True)
                data = bytes(buf[i:i + n])
                i += n
                if cur is None:
                    bad = bad or UNKNOWN_SUBCOMMAND
                    continue
                if expect_addr:
                    if cur and cur[-1][1] and cur[-1][2] == 0:
                        bad = bad or UNKNOWN_SUBCOMMAND  # a read of no bytes before a repeated START
                    a = data[0]
                    cur.append([a >> 1, True, 0] if a & 1 else [a >> 1, False, b""])
                    expect_addr = False
                    data = data[1:]
                if data:
                    if cur[-1][1]:
                        bad = bad or UNKNOWN_SUBCOMMAND  # the master cannot write while it reads
                    else:
                        cur[-1][2] += data
            else:
                bad = bad or UNKNOWN_SUBCOMMAND
        if i >= DIRECT_FRAME or reads > READ_BUFFER:
            bad = BUFFER_OVERFLOW
        if bad:
            raise _Refused(bad, i)
        return txns, i
