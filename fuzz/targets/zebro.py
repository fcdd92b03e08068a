"""The Zebro's devices, both ends of each link: the UWB radio's data protocol (``uwb_protocol``: the module's firmware
on its UART, and the Pi's driver), the BNO055 IMU's UART protocol (the chip's emulation, and the Pi's driver), the
utility board's stream (the Pi's driver), and the ZebroBus leg modules on I2C (a master's transactions)."""

from __future__ import annotations

import struct

from firmware_sim.robots.decizebro import zebrobus as zb
from firmware_sim.robots.decizebro.imu import Bno055
from firmware_sim.robots.decizebro.leg_module import LegModule
from firmware_sim.robots.decizebro.uwb_radio import UwbRadio
from fuzz.harness import Cursor, FakeClock, ScriptedPort, Target, chunks, lp
from swarm_logic.robots.decizebro import utility_protocol as U
from swarm_logic.robots.decizebro import uwb_protocol as P
from swarm_logic.robots.decizebro.imu import Bno055Error, Bno055Imu
from swarm_logic.robots.decizebro.utility import UtilityBoardDriver
from swarm_logic.robots.decizebro.uwb_radio import UwbRadioError, ZebroUwbRadio

MS = 1_000_000


def _framed(body: bytes) -> bytes:
    """A chunk as one protocol frame: its first byte the type, the rest the body (CRC computed)."""
    return P.frame(body[0], body[1:]) if body else b""


# -- the UWB radio's firmware ------------------------------------------------------------------------------------------
def _radio(data: bytes) -> None:
    """Chunks: header bit 0 frames the chunk (type, body; CRC added), bit 1 has a neighbour's beacon and broadcast
    heard before it, the rest is time passing in ms (a frame left incomplete 50 ms is dropped as truncated)."""
    c = Cursor(data)
    radio = UwbRadio(robot=0, slot=0, n_slots=4, queue_frames=4)
    t = 0
    radio.step(t, b"", [])
    while c.more():
        head = c.u8()
        t += (head >> 2) * MS
        body = c.chunk()
        events = []
        if head & 2:
            src = 1 + c.u8() % 4
            events = [{"ev": "beacon", "src": src, "t_ns": t, "range_m": c.u8() / 10.0, "rx_dbm": -80.0,
                       "fp_dbm": -80.0 - c.u8() / 10.0, "heading_cdeg": c.u16(), "aoa_sin": (c.u8() - 128) / 100.0},
                      {"ev": "data", "src": src, "t_ns": t, "seq": c.u8(), "data": c.chunk()}]
        radio.step(t, _framed(body) if head & 1 else body, events)
    for _ in range(32):
        w = radio.next_wake()
        if w is None or w > t + 2000 * MS:
            break
        t = max(t, w)
        radio.step(t, b"", [])


def _radio_seeds() -> list[bytes]:
    reqs = [bytes((P.INFO_GET,)), bytes((P.SET_HEADING,)) + struct.pack("<H", 9000), bytes((P.SEND, 1)) + b"hello",
            bytes((P.NEIGHBOURS_GET,)), bytes((P.STATUS_GET,)), bytes((P.SET_HEADING,)) + struct.pack("<H", 40000),
            bytes((P.SEND, 2)) + bytes(P.MAX_PAYLOAD + 1), bytes((0x7E,)), bytes((P.SEND,))]
    heard = bytes((2 | 0x40,)) + lp(b"") + bytes((1, 25, 30)) + struct.pack("<H", 18000) + bytes((150, 7)) + lp(b"hi")
    return [
        chunks(*((0x05, r) for r in reqs)),
        heard + chunks((0x05, bytes((P.NEIGHBOURS_GET,))), (0x05, bytes((P.SEND, 3)) + b"x" * 20)) + heard,
        chunks((0x04, P.frame(P.INFO_GET)[:3]), (0xFC, b""), (0x04, b"\xa5\x00junk\xa5"),
               (0x04, P.frame(P.STATUS_GET))),
    ]


# -- the Pi's UWB radio driver -----------------------------------------------------------------------------------------
INFO = P.frame(P.INFO, P.INFO_BODY.pack(0, 0, 4, 512, P.MAX_PAYLOAD, 16, 1000, 0))


def _radio_driver(data: bytes) -> None:
    """The module's first chunk answers the driver's INFO request; then each chunk arrives before an operation
    (header bits 0-2: poll, neighbours, broadcast, receive, wait for a neighbourhood), bit 3 frames it."""
    c = Cursor(data)
    clock = FakeClock()
    port = ScriptedPort(clock, [c.chunk()])
    try:
        radio = ZebroUwbRadio(port, clock, timeout=0.2)
    except UwbRadioError:  # no INFO answer: the driver's documented error
        return
    while c.more():
        head = c.u8()
        body = c.chunk()
        port.feed(_framed(body) if head & 8 else body)
        op = head & 7
        try:
            if op == 0:
                radio.poll()
            elif op == 1:
                radio.neighbours()
            elif op == 2:
                radio.broadcast(b"b" * (1 + head % P.MAX_PAYLOAD))
            elif op == 3:
                radio.receive()
            elif op == 4:
                radio.wait_neighbourhood(timeout=0.3)
            else:
                radio.set_heading(head / 40.0)
                clock.sleep(1.0)
                radio.poll()
        except UwbRadioError:
            pass


def _radio_driver_seeds() -> list[bytes]:
    nb = P.NEIGHBOUR.pack(3, 1500, -4500, 9000, P.F_BEARING | P.F_HEADING, 20)
    report = bytes((P.NEIGHBOURS,)) + bytes((0, 1, 1)) + nb
    two = [bytes((P.NEIGHBOURS,)) + bytes((0, 2, 1)) + nb, bytes((P.NEIGHBOURS,)) + bytes((1, 2, 0))]
    return [
        lp(INFO) + chunks((0x08, report), (0x09, bytes((P.RX_DATA,)) + struct.pack("<HB", 3, 9) + b"payload"),
                          (0x0A, bytes((P.TX_STATUS, 1, 15))), (0x0B, bytes((P.ACK, P.SEND, P.QUEUE_FULL))),
                          (0x08, bytes((P.STATUS,)) + bytes(48)), (0x0C, two[0]), (0x08, two[1]), (0x0D, b"")),
        lp(INFO) + chunks((0x08, bytes((P.TX_STATUS, 0))), (0x08, bytes((P.NEIGHBOURS, 0, 1, 2)) + nb),
                          (0x00, b"\xa5\x05\x84junk"), (0x08, bytes((P.INFO,)) + b"\x00")),
        lp(INFO[:-1] + b"\x00"),
    ]


# -- the BNO055's UART -------------------------------------------------------------------------------------------------
def _bno055(data: bytes) -> None:
    """Chunks: header bits 1-7 the time before it in ms (a request incomplete 20 ms is dropped), bit 0 a new
    heading from the world."""
    c = Cursor(data)
    chip = Bno055()
    t = 0
    while c.more():
        head = c.u8()
        t += (head >> 1) * MS
        heading = c.u16() / 1000.0 if head & 1 else None
        chip.step(t, c.chunk(), heading, (0.1, 0.0, 9.81), (0.0, 0.0, 9.81))
    chip.step(t + 100 * MS, b"", None)


def _bno055_seeds() -> list[bytes]:
    reqs = [b"\xaa\x01\x00\x01", b"\xaa\x00\x3d\x01\x0c", b"\xaa\x01\x1a\x06", b"\xaa\x01\x08\x06", b"\xaa\x01\x28\x06",
            b"\xaa\x01\x2e\x06", b"\xaa\x01\x35\x01", b"\xaa\x00\x00\x01\x01", b"\xaa\x01\x7f\x02", b"\xaa\x02\x00\x01",
            b"\x55", b"\xaa\x01\x00\x00", b"\xaa\x01\x00\x81", b"\xaa\x00\x3b\x01\xff"]
    return [chunks(*((0x02, r) for r in reqs)), chunks((0x02, b"\xaa\x00\x3d"), (0x40, b"\x01\x0c"), (0x02, b"\xaa"))]


# -- the Pi's BNO055 driver --------------------------------------------------------------------------------------------
def _bno055_driver(data: bytes) -> None:
    """The chip answers the driver's chip-id read and its mode write with the first two chunks, then one chunk per
    read the header picks (heading, acceleration, linear acceleration, gravity)."""
    c = Cursor(data)
    clock = FakeClock()
    port = ScriptedPort(clock, [c.chunk(), c.chunk()])
    try:
        imu = Bno055Imu(port, clock, timeout=0.05)
    except Bno055Error:  # not a BNO055, no answer, an error status: the driver's documented error
        return
    reads = (imu.heading, imu.acceleration, imu.linear_acceleration, imu.gravity)
    while c.more():
        op = c.u8()
        port.answers.append(c.chunk())
        reads[op % 4]()


def _bno055_driver_seeds() -> list[bytes]:
    chip, ok = b"\xbb\x01\xa0", b"\xee\x01"
    vec = b"\xbb\x06" + struct.pack("<hhh", 10, -20, 981)
    return [
        lp(chip) + lp(ok) + bytes((0,)) + lp(b"\xbb\x02" + struct.pack("<h", 1440)) + bytes((1,)) + lp(vec)
        + bytes((2,)) + lp(b"\xee\x07") + bytes((3,)) + lp(b"\xbb\x06\x00") + bytes((0,)) + lp(b"\xbb\x03abc"),
        lp(b"\xbb\x01\xa1") + lp(ok),
        lp(chip) + lp(b"\xee\x03"),
    ]


# -- the Pi's utility board driver -------------------------------------------------------------------------------------
def _utility_driver(data: bytes) -> None:
    """The board's stream in chunks (header bit 0 frames the chunk: type and body, CRC added); each chunk is read with
    one of the driver's calls (header bits 1-2)."""
    c = Cursor(data)
    clock = FakeClock()
    port = ScriptedPort(clock)
    drv = UtilityBoardDriver(port, clock)
    while c.more():
        head = c.u8()
        body = c.chunk()
        port.feed(_framed(body) if head & 1 else body)
        clock.sleep(0.01 * (head >> 3))
        (drv.read, drv.bearing, drv.consumed, drv.poll)[head >> 1 & 3]()


def _utility_driver_seeds() -> list[bytes]:
    report = bytes((U.REPORT,)) + U.REPORT_BODY.pack(12, -3000, 3, 40)
    return [chunks((0x01, report), (0x03, bytes((U.REPORT,)) + U.REPORT_BODY.pack(-5, U.NO_BEARING, 4, 35)),
                   (0x05, report[:5]), (0x00, U.frame(U.REPORT, report[1:])[:4]), (0x06, b"")),
            chunks((0x01, bytes((0x91,)) + bytes(10)), (0x00, b"\xa5\x00\xa5"))]


# -- a ZebroBus leg module on I2C --------------------------------------------------------------------------------------
def _leg(data: bytes) -> None:
    """Transactions as the I2C medium delivers them to leg 2 (its own messages and the general calls): per
    transaction a header (bits 0-5 the time before it in 10 ms, bit 6 the leg's angle moves), a message count, then
    per message a selector (bit 0 read, bit 1 to the general call, bits 2-7 a read's length - 1) and a write's data.
    The medium refuses reads of a multicast address before they reach a module; so does this harness."""
    c = Cursor(data)
    leg = LegModule(2)
    t, txn, angle = 0, 0, 0.0
    leg.run(t, {"in": [], "sens": {}})
    while c.more():
        head = c.u8()
        t += (head & 0x3F) * 10 * MS
        if head & 0x40:
            angle = c.u8() / 40.0
        segs = []
        for _ in range(1 + c.u8() % 4):
            sel = c.u8()
            read, addr = bool(sel & 1), zb.GENERAL_CALL if sel & 2 else leg.address
            if read:
                if addr == zb.GENERAL_CALL:
                    continue
                segs.append([addr, True, 1 + (sel >> 2)])
            else:
                segs.append([addr, False, c.chunk()])
        txn += 1
        items = [["i2c", txn, segs]] if segs else []
        leg.run(t, {"in": items, "sens": {"angle": angle, "omega": 0.5, "battery_v": 11.5}})


def _leg_seeds() -> list[bytes]:
    def write(reg: int, *values: int, gc: bool = False) -> bytes:
        return bytes((2 if gc else 0,)) + lp(bytes((reg, *values)))

    def read(reg: int, n: int) -> bytes:
        return bytes((0,)) + lp(bytes((reg,))) + bytes((1 | (n - 1) << 2,))

    walk = write(zb.MOTION_MODE, zb.MODE_WALK, 6, 120, 0x05, 0, 1)
    return [
        bytes((1, 0)) + write(zb.SYNC_COUNTER, 0) + bytes((1, 0)) + walk + bytes((10, 1)) + read(zb.QUICK_STATUS, 8)
        + bytes((0x50, 40, 1)) + read(zb.LEG_PHASE, 10) + bytes((1, 0)) + write(zb.SYNC_COUNTER, 0xFF)
        + bytes((1, 0)) + write(zb.SYNC_COUNTER, 0),
        bytes((1, 0)) + write(zb.EMERGENCY_STOP, 0x12) + bytes((1, 1)) + write(zb.SERIAL_ID, zb.SERIAL_GUARD)
        + write(zb.SERIAL_ID, 9) + bytes((1, 0)) + write(zb.MOTOR_VOLTAGE, 67, gc=True)
        + bytes((1, 0)) + write(zb.MOTION_PHASE, 250, 0, 0, 1) + bytes((1, 0)) + write(zb.ERROR_COUNTER, 0)
        + bytes((0x3F, 0)) + write(zb.TEST_FIELD, *range(60)) + bytes((1, 0)) + read(0xF0, 64),
    ]


TARGETS = [
    Target("zebro_radio", "Zebro UWB radio firmware (DWM1001, AN-TDMA): the Pi's frames on its UART", _radio,
           _radio_seeds),
    Target("zebro_radio_driver", "the Zebro Pi's UWB radio driver: the module's frames (INFO, neighbours, data...)",
           _radio_driver, _radio_driver_seeds),
    Target("bno055", "Zebro IMU emulation (BNO055 UART protocol): the Pi's read and write requests", _bno055,
           _bno055_seeds),
    Target("bno055_driver", "the Zebro Pi's BNO055 driver: the chip's answers", _bno055_driver, _bno055_driver_seeds),
    Target("zebro_utility_driver", "the Zebro Pi's utility board driver: the board's report stream", _utility_driver,
           _utility_driver_seeds),
    Target("zebrobus_leg", "a ZebroBus leg module (I2C slave): a master's transactions, general calls included",
           _leg, _leg_seeds),
]
