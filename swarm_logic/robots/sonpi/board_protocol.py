"""The SonPI's sonar and motor board (an Arduino-class ATmega328) as its Raspberry Pi reaches it: an I2C slave at
``ADDRESS`` with one-byte registers. Both sides use this file: the board's sketch (``firmware_sim.robots.sonpi``) and
the Pi's driver (``swarm_logic.robots.sonpi.board``); ``docs/sonpi.md`` has the map with its reasons.

A write transaction's first byte sets the register pointer, every further byte is written at the pointer, which then
increments; the sketch applies a write at the STOP, whole: a multi-byte field must be written in full in one
transaction, and a write that touches a read-only or missing register, or gives a value out of range, is refused
whole and recorded as an error. A read returns bytes from the pointer on (the pointer stays where a write left it
after the STOP). Multi-byte values are little-endian (the AVR's own order, and SMBus words'). A range of 0xFFFF mm is
"no echo".
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

ADDRESS = 0x20  # the sketch's Wire.begin(0x20) (the session's I2C medium keeps 0x00-0x0F for multicast)
WHO_AM_I_VALUE = 0x53  # 'S'
VERSION_VALUE = 1

# -- registers ------------------------------------------------------------------------------------------------
WHO_AM_I = 0x00
VERSION = 0x01
STATUS = 0x02  # bits below
ERROR_COUNT = 0x03  # errors recorded (saturates at 255); any write clears them and LAST_ERROR
LAST_ERROR = 0x04
FIRING = 0x05  # the sonars' firing mode (FIRING_*)
WATCHDOG = 0x06  # the motor command watchdog, 10 ms units (0: off)
WINDOW_MS = 0x08  # uint16, the aggregation window (250)
WINDOW = 0x10  # the last complete window: seq uint16, then per sensor last, min (uint16 mm), pings, echoes (uint8)
SENSORS = 5
SENSOR_BYTES = 6
WINDOW_BYTES = 2 + SENSORS * SENSOR_BYTES  # 32: one SMBus block read
SPEED_SP = 0x40  # left, right int16 mm/s: the wheel speed loop's set-points (closed loop)
PWM_SP = 0x44  # left, right int16 -255..255: the motors' PWM (open loop)
ENCODERS = 0x50  # left, right int32 counts since power-up
WHEEL_SPEED = 0x58  # left, right int16 mm/s, as the speed loop measures them
PWM_OUT = 0x5C  # left, right int16: the PWM the board drives now
MILLIS = 0x60  # uint32: the board's millis() when the encoders were last latched (each control loop)
BATTERY_MV = 0x64  # uint16
ODOMETRY = ENCODERS  # one read of 0x50-0x65 (22 bytes): encoders, speeds, PWM, millis, battery
ODOMETRY_BYTES = 0x66 - ENCODERS

# registers a read may start at or run through (everything else is missing: a read starting there is refused, its
# address NACKed; one running into it reads 0xFF there)
READABLE = frozenset(
    [
        *range(WHO_AM_I, WATCHDOG + 1),
        WINDOW_MS,
        WINDOW_MS + 1,
        *range(WINDOW, WINDOW + WINDOW_BYTES),
        *range(SPEED_SP, PWM_SP + 4),
        *range(ENCODERS, BATTERY_MV + 2),
    ]
)
WRITABLE = frozenset([ERROR_COUNT, FIRING, WATCHDOG, *range(SPEED_SP, PWM_SP + 4)])
FIELDS = {SPEED_SP: 4, PWM_SP: 4}  # multi-byte set-points: written whole or refused

# STATUS bits
ST_WATCHDOG = 0x01  # the motors were stopped by the watchdog (no command within its period)
ST_ERROR = 0x02  # an error is recorded
ST_SPEED_LOOP = 0x04  # the wheels follow speed set-points (else open-loop PWM)
ST_WINDOW = 0x08  # a complete window is in WINDOW

FIRING_SEQUENTIAL, FIRING_SIMULTANEOUS, FIRING_IDEAL = 0, 1, 2
FIRING_NAMES = ("sequential", "simultaneous", "ideal")

# LAST_ERROR codes
ERR_READ_ONLY = 1  # a write to a read-only or missing register
ERR_PARTIAL = 2  # a multi-byte set-point written in part
ERR_VALUE = 3  # a value out of range (a firing mode, a PWM beyond 255)
ERR_BAD_REGISTER = 4  # a read of a missing register (refused, or run into)
ERR_OVERFLOW = 5  # more bytes in one write than the sketch's 32-byte buffer
ERROR_NAMES = {
    ERR_READ_ONLY: "READ_ONLY",
    ERR_PARTIAL: "PARTIAL_WRITE",
    ERR_VALUE: "VALUE",
    ERR_BAD_REGISTER: "BAD_REGISTER",
    ERR_OVERFLOW: "OVERFLOW",
}
RX_BUFFER = 32  # the sketch's receive buffer (Wire's BUFFER_LENGTH), pointer byte included

NO_ECHO = 0xFFFF
WINDOW_FMT = "<H" + "HHBB" * SENSORS
ODOMETRY_FMT = "<iihhhhIH"


@dataclass(frozen=True, slots=True)
class SensorWindow:
    """One sonar over one window: its last result (mm; None: no echo), the nearest echo in the window (None: none),
    the pings that ended in it and how many of them had an echo."""

    last_mm: int | None
    min_mm: int | None
    pings: int
    echoes: int


@dataclass(frozen=True, slots=True)
class Window:
    seq: int
    sensors: tuple[SensorWindow, ...]


def _mm(v: int) -> int | None:
    return None if v == NO_ECHO else v


def encode_window(seq: int, sensors: list[tuple[int, int, int, int]]) -> bytes:
    """The WINDOW block: ``seq`` and per sensor (last, min, pings, echoes), ranges in mm or NO_ECHO."""
    flat = [v for s in sensors for v in s]
    return struct.pack(WINDOW_FMT, seq & 0xFFFF, *flat)


def decode_window(data: bytes) -> Window:
    v = struct.unpack(WINDOW_FMT, bytes(data))
    sensors = tuple(
        SensorWindow(_mm(v[1 + 4 * k]), _mm(v[2 + 4 * k]), v[3 + 4 * k], v[4 + 4 * k]) for k in range(SENSORS)
    )
    return Window(v[0], sensors)


@dataclass(frozen=True, slots=True)
class OdometryBlock:
    """The board's 0x50-0x65: encoder counts, measured wheel speeds (mm/s), applied PWM, its millis() and battery."""

    left: int
    right: int
    left_mm_s: int
    right_mm_s: int
    pwm_left: int
    pwm_right: int
    millis: int
    battery_mv: int


def encode_odometry(b: OdometryBlock) -> bytes:
    return struct.pack(
        ODOMETRY_FMT,
        b.left,
        b.right,
        b.left_mm_s,
        b.right_mm_s,
        b.pwm_left,
        b.pwm_right,
        b.millis & 0xFFFFFFFF,
        b.battery_mv,
    )


def decode_odometry(data: bytes) -> OdometryBlock:
    return OdometryBlock(*struct.unpack(ODOMETRY_FMT, bytes(data)))


def pack_pair(left: int, right: int) -> bytes:
    """A left/right int16 set-point pair, as SPEED_SP and PWM_SP take it."""
    return struct.pack("<hh", left, right)
