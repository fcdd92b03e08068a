"""The Zebro's IMU: a Bosch BNO055 9-axis sensor with on-chip fusion, on a UART to the Raspberry Pi, sans-IO.

Its UART protocol is the BNO055's own (Bosch BNO055 datasheet BST-BNO055-DS000, section 4.7, "UART protocol"):

- write: ``AA 00 reg len data...`` -> ``EE status`` (01 write success);
- read: ``AA 01 reg len`` -> ``BB len data...`` or ``EE status``;
- status codes: 02 read fail, 03 write fail, 04 invalid register address, 05 register write disabled, 06 wrong
  start byte, 07 bus over-run, 08 max length, 09 min length, 0A receive character timeout.

Registers (page 0) emulated: CHIP_ID 0x00 = 0xA0, ACC_ID 0x01 = 0xFB, MAG_ID 0x02 = 0x32, GYR_ID 0x03 = 0x0F, ACC_DATA
0x08-0x0D (x, y, z, little-endian int16, 1 m/s^2 = 100 LSB: the accelerometer, gravity's reaction included; in every
mode but CONFIG), LIA_DATA 0x28-0x2D (linear acceleration: the accelerometer less gravity) and GRV_DATA 0x2E-0x33
(gravity) in the fusion modes (from 0x08: IMU and above), EUL_Heading 0x1A-0x1B (then roll 0x1C, pitch 0x1E: zero, the
Zebro walks on a plane), in 1/16 degree, 0..360 clockwise from magnetic north as the datasheet's Windows orientation
gives it; CALIB_STAT 0x35 = 0xFF (calibrated), SYS_STATUS 0x39 (5: fusion running, 0: idle), UNIT_SEL 0x3B (only
degrees and m/s^2: bits 2 and 0 clear), OPR_MODE 0x3D (power-on CONFIG 0x00; the Euler registers hold the absolute
heading in COMPASS 0x09, M4G 0x0A, NDOF_FMC_OFF 0x0B and NDOF 0x0C, and zero in the other modes), PWR_MODE 0x3E,
SYS_TRIGGER 0x3F and PAGE_ID 0x07 writable and otherwise ignored. Other registers read as zero; writing an
identification or data register answers 05. A request not complete within ``CHAR_TIMEOUT_NS`` of its first byte is
answered 0A and dropped.

The heading it reports comes from the world (``bridge.robots.decizebro.imu``: true yaw plus the magnetometer's
errors), counter-clockwise from east in radians, converted here, and so do the accelerations (m/s^2 in the chip's
axes: x forward, y left, z up on the Zebro). Left out: gyroscope and magnetometer raw data, quaternions, calibration
offsets, page 1, interrupts, the I2C interface.
"""

from __future__ import annotations

import math
import struct
from typing import Any

from firmware_sim.modules.uwb import PacedTx

START, WRITE, READ = 0xAA, 0x00, 0x01
READ_OK, STATUS = 0xBB, 0xEE
WRITE_SUCCESS, READ_FAIL, WRITE_FAIL, INVALID_ADDRESS, WRITE_DISABLED = 0x01, 0x02, 0x03, 0x04, 0x05
WRONG_START_BYTE, BUS_OVER_RUN, MAX_LENGTH, MIN_LENGTH, CHAR_TIMEOUT = 0x06, 0x07, 0x08, 0x09, 0x0A
CHIP_ID, EUL_HEADING, CALIB_STAT, SYS_STATUS, UNIT_SEL, OPR_MODE = 0x00, 0x1A, 0x35, 0x39, 0x3B, 0x3D
ACC_DATA, LIA_DATA, GRV_DATA = 0x08, 0x28, 0x2E
FUSION_MIN = 0x08  # OPR_MODE IMU: the first fusion mode
LSB_PER_MPS2 = 100.0
WRITABLE = (0x07, UNIT_SEL, OPR_MODE, 0x3E, 0x3F)
ABSOLUTE_MODES = (0x09, 0x0A, 0x0B, 0x0C)
CHAR_TIMEOUT_NS = 20_000_000
MAX_LEN = 128


def _vec3(v: Any) -> tuple[float, float, float] | None:
    """Three finite numbers, or None."""
    if not isinstance(v, list | tuple) or len(v) != 3:
        return None
    try:
        x, y, z = (float(c) for c in v)
    except (TypeError, ValueError):
        return None
    return (x, y, z) if all(math.isfinite(c) for c in (x, y, z)) else None


class Bno055:
    """The BNO055's register file and UART. ``step(t_ns, uart_rx, heading_rad)`` returns the bytes it clocks out by
    ``t_ns``; ``heading_rad`` is what its fusion holds now (None: unchanged)."""

    def __init__(self, baud: int = 115200) -> None:
        self.tx = PacedTx(baud)
        self.regs = bytearray(0x80)
        self.regs[0:4] = bytes((0xA0, 0xFB, 0x32, 0x0F))
        self.regs[CALIB_STAT] = 0xFF
        self._buf = bytearray()
        self._start: int | None = None
        self.heading_rad = 0.0
        self.accel = (0.0, 0.0, 9.81)  # m/s^2, the chip's axes
        self.gravity = (0.0, 0.0, 9.81)
        self.counters: dict[str, int] = dict.fromkeys(
            ("reads", "writes", "errors", "wrong_start_bytes", "timeouts", "uart_rx_bytes", "uart_tx_bytes"), 0)

    def _answer(self, t: int, data: bytes) -> None:
        self.counters["uart_tx_bytes"] += len(data)
        self.tx.send(t, data)

    def _error(self, t: int, status: int) -> None:
        self.counters["errors"] += 1
        self._answer(t, bytes((STATUS, status)))

    def _euler(self) -> bytes:
        if self.regs[OPR_MODE] not in ABSOLUTE_MODES:
            return bytes(6)
        cw_north = (90.0 - math.degrees(self.heading_rad)) % 360.0  # the datasheet's heading: clockwise from north
        return struct.pack("<hhh", round(cw_north * 16) % 5760, 0, 0)

    @staticmethod
    def _vector(v: tuple[float, float, float] | None) -> bytes:
        if v is None:
            return bytes(6)
        return struct.pack("<hhh", *(max(-32768, min(32767, round(c * LSB_PER_MPS2))) for c in v))

    def _read(self, reg: int, n: int) -> bytes:
        mode = self.regs[OPR_MODE]
        self.regs[SYS_STATUS] = 5 if mode else 0
        self.regs[EUL_HEADING:EUL_HEADING + 6] = self._euler()
        fusion = mode >= FUSION_MIN
        self.regs[ACC_DATA:ACC_DATA + 6] = self._vector(self.accel if mode else None)
        lin = tuple(a - g for a, g in zip(self.accel, self.gravity, strict=True))
        self.regs[LIA_DATA:LIA_DATA + 6] = self._vector(lin if fusion else None)  # type: ignore[arg-type]
        self.regs[GRV_DATA:GRV_DATA + 6] = self._vector(self.gravity if fusion else None)
        return bytes(self.regs[reg:reg + n])

    def _request(self, t: int) -> None:
        """Take every complete request off the buffer, answering each."""
        buf = self._buf
        while buf:
            if buf[0] != START:
                self.counters["wrong_start_bytes"] += 1
                del buf[:1]
                self._error(t, WRONG_START_BYTE)
                continue
            if len(buf) < 4:
                return
            cmd, reg, n = buf[1], buf[2], buf[3]
            if cmd not in (WRITE, READ):
                del buf[:4]
                self._error(t, READ_FAIL)
                continue
            if cmd == WRITE and len(buf) < 4 + n:
                return
            req = bytes(buf[:4 + (n if cmd == WRITE else 0)])
            del buf[:len(req)]
            if n == 0:
                self._error(t, MIN_LENGTH)
            elif n > MAX_LEN:
                self._error(t, MAX_LENGTH)
            elif reg + n > len(self.regs):
                self._error(t, INVALID_ADDRESS)
            elif cmd == READ:
                self.counters["reads"] += 1
                self._answer(t, bytes((READ_OK, n)) + self._read(reg, n))
            elif any(a not in WRITABLE for a in range(reg, reg + n)):
                self._error(t, WRITE_DISABLED)
            else:
                self.counters["writes"] += 1
                self.regs[reg:reg + n] = req[4:]
                self.regs[UNIT_SEL] &= ~0x05 & 0xFF  # degrees and m/s^2 only
                self._answer(t, bytes((STATUS, WRITE_SUCCESS)))
        self._start = None

    def step(self, t_ns: int, uart_rx: bytes, heading_rad: float | None, accel_mps2: Any = None,
             gravity_mps2: Any = None) -> bytes:
        """``heading_rad``, ``accel_mps2`` and ``gravity_mps2``: what the chip's sensors and fusion hold now (None:
        unchanged; a malformed vector is ignored)."""
        t = int(t_ns)
        if heading_rad is not None and math.isfinite(heading_rad):
            self.heading_rad = heading_rad
        if (a := _vec3(accel_mps2)) is not None:
            self.accel = a
        if (g := _vec3(gravity_mps2)) is not None:
            self.gravity = g
        if self._buf and self._start is not None and t - self._start >= CHAR_TIMEOUT_NS:
            self.counters["timeouts"] += 1
            self._buf.clear()
            self._start = None
            self._error(t, CHAR_TIMEOUT)
        if uart_rx:
            self.counters["uart_rx_bytes"] += len(uart_rx)
            if not self._buf:
                self._start = t
            self._buf += uart_rx
            self._request(t)
            if self._buf and self._start is None:
                self._start = t
        return self.tx.clock_out(t)

    def next_wake(self) -> int | None:
        cands = [w for w in (self.tx.next_wake(), None if self._start is None else self._start + CHAR_TIMEOUT_NS)
                 if w is not None]
        return min(cands) if cands else None
