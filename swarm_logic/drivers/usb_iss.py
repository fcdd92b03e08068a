"""An I2C bus behind a Devantech USB-ISS (a USB-to-I2C adapter, a USB CDC serial port) as an ``smbus2.SMBus``.

``open_smbus("usb-iss:///dev/ttyACM0", scl_hz=100_000)`` (entry point group ``swarm_sitl.i2c``, scheme ``usb-iss``)
gives the calls the robot code makes (``write_i2c_block_data``, ``read_i2c_block_data``, ``i2c_rdwr`` with
``smbus2.i2c_msg``, and the other SMBus calls a plain I2C adapter can emulate), each one I2C transaction sent as one
``I2C_DIRECT`` command (START, the messages after repeated STARTs, STOP), so an address nobody ACKs is reported for
reads as for writes. A program on a PC with a USB-ISS wired to a real Zebro's I2C bus drives its leg modules with
it; a session exposes a simulated robot's bus as the same adapter on a pseudo-terminal (the robot group's
``i2c_pty``: ``usb-iss://PATH``, a relative path as it is).

Errors are smbus2's on Linux: ``OSError(EREMOTEIO)`` when a device does not ACK (the adapter's ``00 01``),
``OSError(ETIMEDOUT)`` when the adapter does not answer within ``timeout_s`` (its pages ask hosts to wait 500 ms),
``OSError(EOPNOTSUPP)`` for a transaction the adapter cannot carry in one command (a frame of 60 bytes or more, more
than 64 bytes read: what Linux returns for a transfer outside an adapter's quirks), SMBus block reads and PEC
(the adapter cannot read a count byte first), ``OSError(EINVAL)`` for a 10-bit address, ``OSError(EIO)`` for an
answer it cannot parse, ``OSError(EBADF)`` on a closed bus. The adapter's protocol: ``firmware_sim.modules.usb_iss``
emulates it and cites its source; ``docs/zebrobus.md``.

Why not a package: ``usb-iss`` (PyPI, 2.0.1, January 2022) is GPL-3.0 and targets Python up to 3.7, and this
project is MIT; ``pyusbiss`` drives only SPI. This client needs only pyserial.
"""

from __future__ import annotations

import errno as errno_
import os
from typing import Any

import serial
from smbus2 import I2cFunc, i2c_msg

from swarm_logic.drivers.i2c import Message, PlainI2cSMBus

SCHEME = "usb-iss://"
ISS_CMD, ISS_VERSION, ISS_MODE = 0x5A, 0x01, 0x02
I2C_DIRECT = 0x57
D_START, D_RESTART, D_STOP, D_READ, D_WRITE = 0x01, 0x02, 0x03, 0x20, 0x30
ACK = 0xFF
MODULE_ID = 7
IO_INPUTS = 0x0A  # I/O1 and I/O2 as digital inputs: nothing else is driven
MODES = {20_000: 0x20, 50_000: 0x30, 100_000: 0x60, 400_000: 0x70, 1_000_000: 0x80}  # hardware I2C where it can
MAX_FRAME = 59  # "limit the frame to < 60 bytes"
MAX_READ = 64  # the module's buffer
FUNCS = I2cFunc.I2C | (I2cFunc.SMBUS_EMUL & ~I2cFunc.SMBUS_PEC & ~I2cFunc.SMBUS_READ_BLOCK_DATA
                       & ~I2cFunc.SMBUS_BLOCK_PROC_CALL)


def _error(code: int, what: str = "") -> OSError:
    return OSError(code, os.strerror(code) + (f": {what}" if what else ""))


def direct_frame(msgs: list[Message]) -> bytes:
    """One I2C transaction as an I2C_DIRECT command: START, each message (its address byte, then its data in WRITEs
    of at most 16 bytes, or READs of at most 16), a repeated START between messages, STOP. ``EOPNOTSUPP`` if it does
    not fit the adapter's frame."""
    out = bytearray([I2C_DIRECT])
    reads = 0
    for i, (addr, read, data) in enumerate(msgs):
        out.append(D_RESTART if i else D_START)
        if read:
            out += bytes([D_WRITE, (addr << 1) | 1])
            n = int(data)  # type: ignore[arg-type]
            reads += n
            while n > 0:
                k = min(n, 16)
                out.append(D_READ + k - 1)
                n -= k
        else:
            payload = bytes([addr << 1]) + bytes(data)  # type: ignore[arg-type]
            for j in range(0, len(payload), 16):
                chunk = payload[j:j + 16]
                out += bytes([D_WRITE + len(chunk) - 1]) + chunk
    out.append(D_STOP)
    if len(out) > MAX_FRAME or reads > MAX_READ:
        raise _error(errno_.EOPNOTSUPP, f"a USB-ISS carries frames under 60 bytes and reads of at most {MAX_READ} "
                                        f"bytes in one command ({len(out)} bytes, {reads} read)")
    return bytes(out)


class UsbIssSMBus(PlainI2cSMBus):
    """``UsbIssSMBus("usb-iss:///dev/ttyACM0", scl_hz=100_000)``: the bus behind a USB-ISS, at that SCL rate (20,
    50, 100, 400 kHz or 1 MHz; the module's hardware I2C where it offers the rate)."""

    def __init__(self, bus: Any = None, force: bool = False, *, scl_hz: int = 100_000,
                 timeout_s: float = 0.5) -> None:
        if int(scl_hz) not in MODES:
            raise ValueError(f"a USB-ISS runs I2C at {', '.join(f'{f // 1000} kHz' for f in MODES)}, not {scl_hz} Hz")
        self.scl_hz = int(scl_hz)
        self.timeout_s = float(timeout_s)
        self.port: serial.Serial | None = None
        super().__init__(bus, force)

    # -- opening and closing ----------------------------------------------------------------------------------
    def open(self, bus: Any) -> None:
        if not isinstance(bus, str) or not bus.startswith(SCHEME) or len(bus) == len(SCHEME):
            raise ValueError(f"a USB-ISS bus is {SCHEME}PATH (its serial port), got {bus!r}")
        if self.port is not None:
            self.close()
        path = bus[len(SCHEME):]
        # a CDC port: the rate is not used; a write that cannot go out (the adapter gone, its buffer full) fails
        # like a read that gets no answer, so closing the bus (which stops the motors) never blocks for good
        self.port = serial.Serial(path, 115200, timeout=self.timeout_s, write_timeout=self.timeout_s)
        try:
            ident = self._command(bytes([ISS_CMD, ISS_VERSION]), 3)
            if ident[0] != MODULE_ID:
                raise _error(errno_.EIO, f"{path}: not a USB-ISS (module id {ident[0]}, expected {MODULE_ID})")
            self.firmware = ident[1]
            status = self._command(bytes([ISS_CMD, ISS_MODE, MODES[self.scl_hz], IO_INPUTS]), 2)
            if status[0] != ACK:
                raise _error(errno_.EIO, f"{path}: the USB-ISS refused I2C mode 0x{MODES[self.scl_hz]:02X} "
                                         f"(error 0x{status[1]:02X})")
        except OSError:
            self.close()
            raise
        self.fd = -1  # open (smbus2 looks at fd)
        self.funcs = FUNCS

    def close(self) -> None:
        if self.port is not None:
            self.port.close()
        self.port = None
        self.fd = None
        self.address = None
        self._force_last = None

    # -- one command --------------------------------------------------------------------------------------------
    def _command(self, frame: bytes, n: int) -> bytes:
        """Send a command, wait for its ``n``-byte answer."""
        port = self.port
        if port is None:
            raise _error(errno_.EBADF)
        port.reset_input_buffer()  # what a command the adapter ignored left behind
        try:
            port.write(frame)
        except serial.SerialTimeoutException:
            raise _error(errno_.ETIMEDOUT, f"the USB-ISS took none of a {len(frame)}-byte command") from None
        return self._read(n)

    def _read(self, n: int) -> bytes:
        assert self.port is not None
        got = self.port.read(n)
        if len(got) != n:
            raise _error(errno_.ETIMEDOUT, f"the USB-ISS answered {len(got)} of {n} bytes")
        return got

    def _transfer(self, msgs: list[Message]) -> list[bytes]:
        """One transaction; the bytes each read message got."""
        frame = direct_frame(msgs)
        status = self._command(frame, 2)
        if status[0] != ACK:
            if status[1] == 0x01:
                raise _error(errno_.EREMOTEIO)
            raise _error(errno_.EIO, f"the USB-ISS refused the frame (error 0x{status[1]:02X})")
        want = sum(int(d) for _, r, d in msgs if r)  # type: ignore[arg-type]
        if status[1] != want:
            raise _error(errno_.EIO, f"the USB-ISS read {status[1]} bytes, {want} were asked")
        data = self._read(want) if want else b""
        out, pos = [], 0
        for _, read, n in msgs:
            if read:
                out.append(data[pos:pos + int(n)])  # type: ignore[arg-type]
                pos += int(n)  # type: ignore[arg-type]
        return out


__all__ = ["UsbIssSMBus", "direct_frame", "i2c_msg"]
