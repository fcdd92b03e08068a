"""The emulated Devantech USB-ISS (``firmware_sim.modules.usb_iss``) against a stand-in bus, its client
(``swarm_logic.drivers.usb_iss``), and both together on a pseudo-terminal in front of the I2C medium and six leg
modules (the lock-step bench, no processes)."""

from __future__ import annotations

import errno
import os
import random
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from smbus2 import i2c_msg

from bridge.hil.usb_iss import UsbIssEntity
from firmware_sim.modules import usb_iss as iss
from firmware_sim.robots.decizebro import zebrobus as zb
from swarm_logic.drivers.i2c import open_smbus
from swarm_logic.drivers.usb_iss import UsbIssSMBus, direct_frame
from tests.support.i2c_bench import I2cBench

MS = 1_000_000


class Bus:
    """Register devices as ZebroBus modules answer: a write's first byte sets the pointer, the rest is written from
    it on; a read returns bytes from the pointer. An absent address NACKs and stops the transaction."""

    def __init__(self, *addrs: int) -> None:
        self.regs = {a: bytearray(256) for a in addrs}
        self.ptr = dict.fromkeys(addrs, 0)
        self.txns: list[tuple[list, int]] = []

    def __call__(self, msgs: list, hz: int) -> tuple[int, list[bytes]]:
        self.txns.append((msgs, hz))
        reads = []
        for addr, read, data in msgs:
            if addr not in self.regs:
                return iss.EREMOTEIO, []
            if read:
                p = self.ptr[addr]
                reads.append(bytes(self.regs[addr][(p + k) % 256] for k in range(data)))
            elif data:
                self.ptr[addr] = data[0]
                for k, b in enumerate(data[1:]):
                    self.regs[addr][(data[0] + k) % 256] = b
        return 0, reads


def drive(m: iss.UsbIss, bus: Bus, data: bytes, t_ns: int = 0) -> bytes:
    """Feed ``data`` at ``t_ns`` and run the module's transactions on ``bus`` until it waits for more."""
    m.feed(t_ns, data)
    while (txn := m.poll(t_ns)) is not None:
        m.on_result(*bus(txn, m.scl_hz))
    return m.take_output()


def test_setup_commands() -> None:
    m, bus = iss.UsbIss(serial="00000042"), Bus()
    assert drive(m, bus, bytes([0x5A, 0x01])) == bytes([7, iss.FIRMWARE, 0x40])  # powers up in I2C, 100 kHz
    assert drive(m, bus, bytes([0x5A, 0x03])) == b"00000042"
    assert drive(m, bus, bytes([0x5A, 0x02, 0x70, 0x0A])) == bytes([0xFF, 0x00]) and m.scl_hz == 400_000
    assert drive(m, bus, bytes([0x5A, 0x02, 0x81, 0x00, 0x19])) == bytes([0xFF, 0x00]) and m.scl_hz == 1_000_000
    assert drive(m, bus, bytes([0x5A, 0x02, 0xEE])) == bytes([0x00, 0x05])  # an unknown mode
    assert drive(m, bus, bytes([0x5A, 0x09])) == bytes([0x00, 0x05])
    assert m.counters["bad_mode"] == 2 and not bus.txns
    with pytest.raises(ValueError, match="8 ASCII digits"):
        iss.UsbIss(serial="12")


def test_register_commands_and_nacks() -> None:
    m, bus = iss.UsbIss(), Bus(0x10)
    assert drive(m, bus, bytes([0x55, 0x20, 0x60, 0x02, 0xAA, 0xBB])) == b"\xff"  # I2C_AD1 write to 0x10
    assert bus.txns[-1] == ([[0x10, False, b"\x60\xaa\xbb"]], 100_000)
    assert drive(m, bus, bytes([0x55, 0x21, 0x60, 0x02])) == b"\xaa\xbb"  # register, repeated START, read
    assert bus.txns[-1][0] == [[0x10, False, b"\x60"], [0x10, True, 2]]
    assert drive(m, bus, bytes([0x56, 0x20, 0x00, 0x61, 0x01, 0x07])) == b"\xff"  # I2C_AD2: two register bytes
    assert drive(m, bus, bytes([0x53, 0x20, 0x62])) == b"\xff"  # I2C_SGL write: the pointer
    assert drive(m, bus, bytes([0x53, 0x21])) == b"\x00"  # ... and a single byte read from it
    assert drive(m, bus, bytes([0x54, 0x20, 0x03, 0x60, 0x01, 0x02])) == b"\xff"  # I2C_AD0
    assert drive(m, bus, bytes([0x54, 0x21, 0x02])) == b"\x01\x02"
    assert drive(m, bus, bytes([0x58, 0x20])) != b"\x00" and bus.txns[-1][0] == [[0x10, False, b""]]  # I2C_TEST
    # 0x70 is nobody: writes answer 00, reads as many zeros as asked, I2C_TEST 00
    assert drive(m, bus, bytes([0x55, 0xE0, 0x00, 0x01, 0x05])) == b"\x00"
    assert drive(m, bus, bytes([0x55, 0xE1, 0x00, 0x03])) == b"\x00\x00\x00"
    assert drive(m, bus, bytes([0x58, 0xE0])) == b"\x00"
    assert m.counters["nacks"] == 3 and m.counters["transactions"] == 11
    # over the module's buffer, a read of nothing: refused without touching the bus
    n = len(bus.txns)
    assert drive(m, bus, bytes([0x55, 0x20, 0x00, 61]) + bytes(61)) == b"\x00"
    assert drive(m, bus, bytes([0x55, 0x21, 0x00, 61])) == bytes(61)
    assert drive(m, bus, bytes([0x55, 0x21, 0x00, 0])) == b""
    assert len(bus.txns) == n and m.counters["overflow"] == 2 and m.counters["bad_length"] == 1


def test_direct_sequences() -> None:
    m, bus = iss.UsbIss(), Bus(0x10, 0x11)
    # two messages after a repeated START, then one read back: the locomotion layer's shape
    frame = bytes([0x57, 0x01, 0x32, 0x20, 0x60, 0x05, 0x02, 0x31, 0x22, 0x60, 0x03])
    assert drive(m, bus, frame) == bytes([0xFF, 0x00])
    assert bus.txns[-1][0] == [[0x10, False, b"\x60\x05"], [0x11, False, b"\x60"]]
    read = bytes([0x57, 0x01, 0x31, 0x20, 0x60, 0x02, 0x30, 0x21, 0x04, 0x20, 0x03])  # NACK before the last read
    assert drive(m, bus, read) == bytes([0xFF, 0x01, 0x05])
    two = bytes([0x57, 0x01, 0x30, 0x20, 0x03, 0x01, 0x30, 0x22, 0x03])  # two transactions in one frame
    assert drive(m, bus, two) == bytes([0xFF, 0x00]) and [t[0] for t in bus.txns[-2:]] == [
        [[0x10, False, b""]], [[0x11, False, b""]]]
    assert drive(m, bus, bytes([0x57, 0x01, 0x30, 0xE0, 0x03])) == bytes([0x00, 0x01])  # no ACK: device error
    n = len(bus.txns)
    long = bytes([0x57, 0x01, 0x3F, 0x20, *range(15)] + [0x3F, *range(16)] * 2 + [0x34, *range(5), 0x03])  # 60 bytes
    assert len(long) == 60 and drive(m, bus, long) == bytes([0x00, 0x02])
    for bad in ([0x57, 0x20, 0x03],  # a read outside START..STOP
                [0x57, 0x01, 0x30, 0x20, 0x20, 0x03],  # a read after a write address
                [0x57, 0x01, 0x30, 0x21, 0x30, 0x05, 0x03],  # data written after a read address
                [0x57, 0x01, 0x30, 0x21, 0x03]):  # a read of no bytes
        assert drive(m, bus, bytes(bad)) == bytes([0x00, 0x04]), bad
    assert drive(m, bus, bytes([0x57, 0x01, 0x30, 0x20, 0x7E, 0x03])) == bytes([0x00, 0x04])  # unknown sub-command
    assert len(bus.txns) == n
    # a WRITE short of its bytes, a sequence without its STOP: answered once nothing more came
    assert drive(m, bus, bytes([0x57, 0x01, 0x33, 0x20, 0x60]), t_ns=0) == b""
    assert drive(m, bus, b"", t_ns=iss.GAP_NS) == bytes([0x00, 0x03])
    assert drive(m, bus, bytes([0x57, 0x01, 0x30, 0x20]), t_ns=0) == b""
    assert drive(m, bus, b"", t_ns=iss.GAP_NS) == bytes([0x00, 0x04])
    assert m.counters["underflow"] == 1 and m.counters["bad_sequence"] == 6 and len(bus.txns) == n


def test_a_command_cut_short_is_dropped_and_the_next_one_answered() -> None:
    m, bus = iss.UsbIss(), Bus(0x10)
    assert drive(m, bus, bytes([0x55, 0x20, 0x60]), t_ns=0) == b""
    assert drive(m, bus, b"", t_ns=iss.GAP_NS - 1) == b""  # still within the gap
    assert drive(m, bus, b"", t_ns=iss.GAP_NS) == b"" and m.counters["truncated"] == 1
    assert drive(m, bus, bytes([0x99, 0x5A, 0x01]), t_ns=iss.GAP_NS) == bytes([7, iss.FIRMWARE, 0x40])
    assert m.counters["unknown_command"] == 1 and not bus.txns


def test_i2c_commands_outside_an_i2c_mode_touch_nothing() -> None:
    m, bus = iss.UsbIss(), Bus(0x10)
    assert drive(m, bus, bytes([0x5A, 0x02, 0x90, 0x01])) == bytes([0xFF, 0x00])  # SPI mode
    assert drive(m, bus, bytes([0x55, 0x20, 0x60, 0x01, 0x01])) == b"\x00"
    assert drive(m, bus, bytes([0x57, 0x01, 0x30, 0x20, 0x03])) == bytes([0x00, 0x04])
    assert m.counters["not_i2c_mode"] == 2 and not bus.txns


def test_nothing_a_host_sends_makes_it_raise() -> None:
    rng = random.Random(7)
    m, bus = iss.UsbIss(), Bus(0x10, 0x11)
    t = 0
    for _ in range(3000):
        alphabet = [0x01, 0x02, 0x03, 0x04, 0x20, 0x21, 0x30, 0x31, 0x53, 0x54, 0x55, 0x56, 0x57, 0x58, 0x5A, 0x60]
        data = bytes(rng.choice(alphabet) if rng.random() < 0.6 else rng.randrange(256)
                     for _ in range(rng.randrange(1, 40)))
        t += rng.choice([0, MS, iss.GAP_NS])
        out = drive(m, bus, data, t_ns=t)
        assert isinstance(out, bytes)
    assert drive(m, bus, b"", t_ns=t + iss.GAP_NS) is not None
    m.buf.clear()
    assert drive(m, bus, bytes([0x5A, 0x01]), t_ns=t + 2 * iss.GAP_NS)[0] == 7  # still answering


def test_the_client_s_frames() -> None:
    assert direct_frame([(0x10, False, b"\x60\x01"), (0x10, True, 2)]) == bytes(
        [0x57, 0x01, 0x32, 0x20, 0x60, 0x01, 0x02, 0x30, 0x21, 0x21, 0x03])
    five = [(0x10 + i, False, bytes([0x20, 1, 6, 0, 0, 0, 1])) for i in range(5)]
    assert len(direct_frame(five)) == 52
    with pytest.raises(OSError) as e:  # six legs' motion blocks do not fit one frame: Linux's adapter-quirk errno
        direct_frame([*five, (0x15, False, bytes([0x20, 1, 6, 0, 0, 0, 1]))])
    assert e.value.errno == errno.EOPNOTSUPP
    status = [m for i in range(6) for m in ((0x10 + i, False, b"\x11"), (0x10 + i, True, 1))]
    assert len(direct_frame(status)) == 50  # the quick-status read of all legs fits
    assert len(direct_frame([(0x10, False, bytes(40))])) < 60  # a write is cut into WRITEs of 16


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[tuple[I2cBench, Path]]:
    """The bench with a USB-ISS on its bus, its terminal at ``tmp_path/i2c``, stepped in a thread."""
    link = tmp_path / "i2c"
    b = I2cBench(adapter=UsbIssEntity(0, str(link)))
    stop = threading.Event()
    lock = threading.Lock()

    def spin() -> None:
        while not stop.is_set():
            with lock:
                b.step()
            stop.wait(0.0005)  # let the client run between quanta

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    try:
        yield b, link
    finally:
        stop.set()
        th.join(timeout=30)
        b.adapter.close()


def test_the_client_drives_leg_modules_through_the_terminal(bench: tuple[I2cBench, Path]) -> None:
    b, link = bench
    bus: Any = open_smbus(f"usb-iss://{link}", scl_hz=400_000, timeout_s=20)  # generous: a guard, not a wait
    try:
        assert isinstance(bus, UsbIssSMBus) and bus.firmware == iss.FIRMWARE
        bus.write_i2c_block_data(0x10, zb.TEST_FIELD, [0x5A])
        assert bus.read_byte_data(0x10, zb.TEST_FIELD) == 0x5A
        assert bus.read_i2c_block_data(0x11, 0x00, 7) == [1, 1, 1, 1, 1, 1, 0x11]  # ZebroBus header of leg 1
        msgs = [i2c_msg.write(0x10 + i, [zb.QUICK_STATUS]) for i in range(2)]
        reads = [i2c_msg.read(0x10 + i, 1) for i in range(2)]
        bus.i2c_rdwr(msgs[0], reads[0], msgs[1], reads[1])
        assert all(len(bytes(r)) == 1 for r in reads)
        with pytest.raises(OSError) as e:
            bus.read_byte_data(0x30, 0x00)  # nobody at 0x30
        assert e.value.errno == errno.EREMOTEIO
        with pytest.raises(OSError) as e:
            bus.read_block_data(0x10, 0x00)
        assert e.value.errno == errno.EOPNOTSUPP
    finally:
        bus.close()
    txns = b.transactions()
    assert {t["scl_hz"] for t in txns} == {400_000}  # the mode the client set
    assert [t["status"] for t in txns].count("nack") == 1
    assert b.adapter.counters["nacks"] == 1 and b.adapter.counters["transactions"] == len(txns)


def test_a_write_the_adapter_does_not_take_fails_instead_of_blocking(tmp_path: Path) -> None:
    """An adapter that stops reading (gone, or its program stuck) while its port's buffer is full: the command fails
    with ETIMEDOUT after the bus's timeout, and closing the bus returns, so a program stopping on Ctrl-C exits."""
    link = tmp_path / "i2c"
    b = I2cBench(adapter=UsbIssEntity(0, str(link)))
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            b.step()
            stop.wait(0.0005)

    th = threading.Thread(target=spin, daemon=True)
    th.start()
    try:
        bus: Any = open_smbus(f"usb-iss://{link}", scl_hz=400_000, timeout_s=0.05)
    finally:
        stop.set()
        th.join()
    try:
        fd = bus.port.fd  # pyserial keeps it non-blocking: fill the terminal until it takes no more
        for size in (4096, 1):
            with pytest.raises(BlockingIOError):
                for _ in range(1_000_000):
                    os.write(fd, bytes(size))
        with pytest.raises(OSError) as e:
            bus.write_byte_data(0x10, 0x20, 1)
        # the write times out ("took none"), or, when the kernel moved some of the terminal's buffer on after all,
        # the answer does: either way the command fails instead of blocking
        assert e.value.errno == errno.ETIMEDOUT
    finally:
        bus.close()
        b.adapter.close()
    assert bus.port is None
