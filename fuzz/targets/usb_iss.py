"""The Devantech USB-ISS (USB-to-I2C adapter), both ends: the adapter's firmware as a host's serial bytes reach it (its
I2C transactions answered by a bus of scripted slaves), and the host's smbus2 driver as a real adapter's answers reach
it."""

from __future__ import annotations

import errno
import types
from typing import Any

import serial
from smbus2 import i2c_msg

from firmware_sim.modules.usb_iss import EREMOTEIO, UsbIss
from fuzz.harness import Cursor, FakeClock, ScriptedPort, Target, chunks, lp
from swarm_logic.drivers import usb_iss as driver

MS = 1_000_000


def _adapter(data: bytes) -> None:
    """Chunks of the host's bytes (header: the time before it in ms; an incomplete command is dropped after a 50 ms
    gap); every transaction the adapter puts on the bus ends as the next input byte says: bit 0 NACKed (the
    address nobody answers), else done, reads filled with that byte."""
    c = Cursor(data)
    iss = UsbIss()
    t = 0
    while c.more():
        t += c.u8() * MS
        iss.feed(t, c.chunk())
        for _ in range(64):
            txn = iss.poll(t)
            if txn is None:
                break
            b = c.u8()
            reads = [bytes([b]) * int(n) for _, rd, n in txn if rd]
            iss.on_result(EREMOTEIO if b & 1 else 0, [] if b & 1 else reads)
        iss.take_output()
    iss.poll(t + 100 * MS)


def _adapter_seeds() -> list[bytes]:
    cmds = [(b"\x5a\x01", 0), (b"\x5a\x03", 0), (b"\x5a\x02\x60\x0a", 0), (b"\x5a\x02\x31\x00\x9b", 0),
            (b"\x5a\x02\x07\x00", 0), (b"\x53\x21", 1), (b"\x54\x20\x03abc", 1), (b"\x55\x21\x10\x04", 1),
            (b"\x56\x20\x00\x10\x02xy", 1), (b"\x58\x20", 1), (b"\x58\x21", 1),
            (b"\x57\x01\x30\x20\x31\x12\x34\x02\x30\x21\x23\x03", 1),
            (b"\x57\x01\x30\x21\x2f\x03\x01\x30\x22\x20\x03", 2), (b"\x57\x01\x03", 0), (b"\x57\x30\x20", 0),
            (b"\x5a\x02\x00\x00", 0), (b"\x53\x20\x01", 0), (b"\x5a\x02\x40\x00", 0), (b"\x90", 0)]
    ok = b""
    for i, (cmd, txns) in enumerate(cmds):
        ok += bytes((1,)) + lp(cmd) + bytes((2 * i,)) * txns
    nack = b"".join(bytes((1,)) + lp(cmd) + b"\x01" * min(txns, 1) for cmd, txns in cmds[5:13])
    return [ok, nack, chunks((1, b"\x55\x21"), (60, b"\x10"), (1, b"\x57\x01\x35\x20"), (60, b""))]


# -- the host's driver -------------------------------------------------------------------------------------------------
def _driver(data: bytes) -> None:
    """The adapter answers the driver's identification and mode with the first two chunks (opening the bus), then one
    chunk per call the header byte picks (register reads and writes, a combined transaction, a quick write)."""
    c = Cursor(data)
    clock = FakeClock()
    port = ScriptedPort(clock, [c.chunk(), c.chunk()])
    bus = driver.UsbIssSMBus()
    real = driver.serial
    driver.serial = types.SimpleNamespace(Serial=lambda *a, **k: port,  # type: ignore[assignment]
                                          SerialTimeoutException=serial.SerialTimeoutException)
    try:
        bus.open("usb-iss://fuzz")
    except OSError:  # not a USB-ISS, no or a refusing answer: the driver's documented errors
        return
    finally:
        driver.serial = real
    calls: list[Any] = [
        lambda: bus.read_i2c_block_data(0x12, 0x10, 8),
        lambda: bus.write_i2c_block_data(0x12, 0x20, [1, 2, 3]),
        lambda: bus.read_byte_data(0x12, 0x11),
        lambda: bus.read_word_data(0x12, 0x41),
        lambda: bus.i2c_rdwr(i2c_msg.write(0x12, [0x40]), i2c_msg.read(0x12, 10), i2c_msg.read(0x13, 3)),
        lambda: bus.write_quick(0x12),
        lambda: bus.read_byte(0x12),
        lambda: bus.process_call(0x12, 0x05, 0x1234),
    ]
    while c.more():
        op = c.u8()
        port.answers.append(c.chunk())
        try:
            calls[op % len(calls)]()
        except OSError as e:  # smbus2's errors, as the driver documents them
            if e.errno not in (errno.EREMOTEIO, errno.ETIMEDOUT, errno.EIO, errno.EOPNOTSUPP):
                raise
        port.answers.clear()
    bus.close()


def _driver_seeds() -> list[bytes]:
    ident, mode = b"\x07\x07\x40", b"\xff\x00"
    return [
        lp(ident) + lp(mode) + bytes((0,)) + lp(b"\xff\x08" + bytes(range(8))) + bytes((1,)) + lp(b"\xff\x00")
        + bytes((2,)) + lp(b"\xff\x01\x7f") + bytes((3,)) + lp(b"\xff\x02\x01\x02") + bytes((4,))
        + lp(b"\xff\x0d" + bytes(13)) + bytes((5,)) + lp(b"\x00\x01") + bytes((6,)) + lp(b"\x00\x04")
        + bytes((0,)) + lp(b"\xff\x03abc") + bytes((7,)) + lp(b"\xff"),
        lp(b"\x06\x07\x40") + lp(mode),
        lp(ident) + lp(b"\x00\x05"),
    ]


TARGETS = [
    Target("usb_iss", "Devantech USB-ISS firmware (I2C mode): a host's commands, I2C_DIRECT frames included",
           _adapter, _adapter_seeds),
    Target("usb_iss_driver", "the host's USB-ISS smbus2 driver: a real adapter's answers", _driver, _driver_seeds),
]
