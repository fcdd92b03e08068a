"""The Raspberry Pi's driver of the Zebro's IMU (``Imu``): a Bosch BNO055 on a UART (``sitl://imu`` in a session,
``/dev/ttyAMA1`` or a USB adapter on the robot), in its own UART protocol (datasheet BST-BNO055-DS000, section 4.7:
``AA 01 reg len`` reads, ``BB len data`` answers, ``EE status`` errors).

``open`` puts the chip in NDOF fusion mode (absolute heading from the magnetometer); ``heading()`` reads the Euler
heading (1/16 degree, clockwise from north) and returns it counter-clockwise from east in radians, as the swarm
layer wants it; ``acceleration()``, ``linear_acceleration()`` and ``gravity()`` read the accelerometer, its part
beyond gravity and gravity (m/s^2, the chip's axes: x forward, y left, z up on the Zebro). A read that times out or
fails returns the last value read (counted).
"""

from __future__ import annotations

import math
import struct
from typing import Any

from swarm_logic.clock import Clock
from swarm_logic.devices import open_port

CHIP_ID, EUL_HEADING, OPR_MODE, NDOF = 0x00, 0x1A, 0x3D, 0x0C
ACC_DATA, LIA_DATA, GRV_DATA = 0x08, 0x28, 0x2E
LSB_PER_MPS2 = 100.0  # UNIT_SEL's power-on m/s^2


class Bno055Error(Exception):
    """The chip did not answer, or answered an error status."""


class Bno055Imu:
    """A BNO055 on ``port``; waits in ``clock`` time."""

    def __init__(self, port: Any, clock: Clock, *, timeout: float = 0.1) -> None:
        self.port = port
        self.clock = clock
        self.timeout = timeout
        self.last = 0.0
        self.last_vectors: dict[str, tuple[float, float, float]] = {}
        self.counters = {"reads": 0, "failed": 0}
        if self._read(CHIP_ID, 1) != b"\xa0":
            raise Bno055Error("the device on the IMU port is not a BNO055 (chip id)")
        self._write(OPR_MODE, bytes((NDOF,)))

    def _reply(self, n: int, status: bool = False) -> bytes:
        deadline = self.clock.now() + self.timeout
        buf = bytearray()
        while len(buf) < n:
            left = deadline - self.clock.now()
            self.port.timeout = max(left, 0)  # past the deadline: one look at what already arrived
            got = self.port.read(n - len(buf))
            if left <= 0 and len(buf) + len(got) < n:
                raise Bno055Error("no answer from the IMU")
            buf += got
            if status and buf[:1] == b"\xee" and len(buf) >= 2:  # an error status instead of data
                raise Bno055Error(f"IMU status 0x{buf[1]:02x}")
        self.port.timeout = 0
        return bytes(buf)

    def _read(self, reg: int, n: int) -> bytes:
        self.port.reset_input_buffer()
        self.port.write(bytes((0xAA, 0x01, reg, n)))
        head = self._reply(2, status=True)
        if head[0] != 0xBB or head[1] != n:
            raise Bno055Error(f"IMU read answered {head.hex(' ')}")
        return self._reply(n)

    def _write(self, reg: int, data: bytes) -> None:
        self.port.reset_input_buffer()
        self.port.write(bytes((0xAA, 0x00, reg, len(data))) + data)
        if self._reply(2) != b"\xee\x01":
            raise Bno055Error("IMU write failed")

    def heading(self) -> float:
        """The absolute heading (rad, counter-clockwise from east)."""
        try:
            (h16,) = struct.unpack("<h", self._read(EUL_HEADING, 2))
        except Bno055Error:
            self.counters["failed"] += 1
            return self.last
        self.counters["reads"] += 1
        self.last = math.remainder(math.radians(90.0 - h16 / 16.0), math.tau)
        return self.last

    def _vector(self, reg: int, which: str) -> tuple[float, float, float]:
        try:
            raw = struct.unpack("<hhh", self._read(reg, 6))
        except Bno055Error:
            self.counters["failed"] += 1
            return self.last_vectors.get(which, (0.0, 0.0, 0.0))
        self.counters["reads"] += 1
        v = (raw[0] / LSB_PER_MPS2, raw[1] / LSB_PER_MPS2, raw[2] / LSB_PER_MPS2)
        self.last_vectors[which] = v
        return v

    def acceleration(self) -> tuple[float, float, float]:
        """The accelerometer (m/s^2): the body's acceleration plus the reaction to gravity (about +9.81 on z at
        rest)."""
        return self._vector(ACC_DATA, "acc")

    def linear_acceleration(self) -> tuple[float, float, float]:
        """The fusion's linear acceleration (m/s^2): the accelerometer less gravity."""
        return self._vector(LIA_DATA, "lia")

    def gravity(self) -> tuple[float, float, float]:
        """The fusion's gravity vector in the chip's axes (m/s^2): how the body is tilted."""
        return self._vector(GRV_DATA, "grv")

    def close(self) -> None:
        self.port.close()


def open_imu(cfg: dict[str, Any], robot: Any) -> Bno055Imu:
    """The HAL ``imu`` table: ``port`` (``sitl://imu``), ``baudrate`` (115200)."""
    port = open_port(dict(cfg), "imu", 115200)
    try:
        return Bno055Imu(port, robot.clock)
    except BaseException:
        port.close()
        raise
