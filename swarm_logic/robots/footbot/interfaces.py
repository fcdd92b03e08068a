"""The foot-bot's devices as the swarm layer sees them (the marXbot-based robot of ARGoS; Khan's PFSM search):
typing protocols in SI units, so the PFSM controllers (``swarm_logic.families.pfsm``) run unchanged on a point-robot
model and, later, on a robot whose devices are HAL tables.

A robot reaches them as ``robot.device(name)`` under the names below (ARGoS's sensor and actuator names). Angles are
relative to the robot's heading (rad, + = left, counter-clockwise).

- ``range_and_bearing`` (``RangeAndBearing``): the infrared range-and-bearing board. Each control step it reads,
  for every robot in line of sight within its range, the range, the bearing and the last payload that robot sent
  (ARGoS carries no sender id: an id, when needed, is in the payload); ``send`` sets the payload this robot
  broadcasts from then on, at most ``RAB_PAYLOAD_BYTES``.
- ``footbot_proximity`` (``Proximity``): 24 infrared sensors in a ring, each a value in [0, 1] (0 nothing within
  range, 1 touching) at its angle.
- ``footbot_light`` (``Light``): 24 light sensors in a ring, each a value >= 0 at its angle (phototaxis: the base
  has a light above it).
- ``footbot_motor_ground`` (``MotorGround``): 4 grey-level sensors under the body (0 black, 1 white) at their
  offsets in the robot's frame; the base is a grey patch.
- ``footbot_base_ground`` (``BaseGround``): 8 black-or-white sensors on a ring under the base (0 black, 1 white).
- ``differential_steering`` (``DifferentialSteering``): the two wheels' linear speeds.
- ``leds`` (``Leds``): the 12 ring LEDs and the beacon, one colour for all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

RANGE_AND_BEARING = "range_and_bearing"
PROXIMITY = "footbot_proximity"
LIGHT = "footbot_light"
MOTOR_GROUND = "footbot_motor_ground"
BASE_GROUND = "footbot_base_ground"
WHEELS = "differential_steering"
LEDS = "leds"
DEVICE_NAMES = (RANGE_AND_BEARING, PROXIMITY, LIGHT, MOTOR_GROUND, BASE_GROUND, WHEELS, LEDS)

# ARGoS foot-bot (footbot_entity.cpp, dynamics2d footbot model)
BODY_RADIUS_M = 0.085
BODY_HEIGHT_M = 0.1469
WHEEL_BASE_M = 0.14  # inter-wheel distance
WHEEL_RADIUS_M = 0.0291
PROXIMITY_COUNT = 24
PROXIMITY_RANGE_M = 0.1  # from the body's surface
LIGHT_COUNT = 24
RAB_RANGE_M = 3.0  # ARGoS's range-and-bearing default range
RAB_PAYLOAD_BYTES = 10  # ARGoS's foot-bot default message size
# the 4 motor-ground sensors (x forward, y left), m
MOTOR_GROUND_OFFSETS_M = ((0.063, 0.0116), (-0.063, 0.0116), (-0.063, -0.0116), (0.063, -0.0116))
# the 8 base ground sensors: a ring of radius 0.08 m, every 45 degrees from straight ahead (ARGoS footbot_entity.cpp)
BASE_GROUND_OFFSETS_M = tuple((round(0.08 * math.cos(k * math.pi / 4), 6), round(0.08 * math.sin(k * math.pi / 4), 6))
                              for k in range(8))


def ring_angles(count: int) -> tuple[float, ...]:
    """The angles of a ring of ``count`` sensors, the first straight ahead, evenly spaced counter-clockwise (rad)."""
    return tuple(2 * math.pi * k / count for k in range(count))


def check_payload(data: bytes, max_payload: int = RAB_PAYLOAD_BYTES) -> bytes:
    """``data`` as bytes when a range-and-bearing message can carry it; ValueError otherwise (every implementation of
    ``RangeAndBearing.send`` refuses the same way)."""
    b = bytes(data)
    if len(b) > max_payload:
        raise ValueError(f"range-and-bearing payload of {len(b)} bytes: at most {max_payload} fit in one message")
    return b


@dataclass(frozen=True, slots=True)
class RabPacket:
    """What the range-and-bearing board read from one robot: range (m), bearing (rad, + = left) and its payload."""

    range_m: float
    bearing_rad: float
    data: bytes


@dataclass(frozen=True, slots=True)
class RingReading:
    """One sensor of a ring: its value and its angle (rad, + = left of the heading)."""

    value: float
    angle_rad: float


@dataclass(frozen=True, slots=True)
class GroundReading:
    """One motor-ground sensor: the floor's grey level (0 black, 1 white) at its offset (m, x forward, y left)."""

    value: float
    offset_m: tuple[float, float]


@runtime_checkable
class RangeAndBearing(Protocol):
    max_payload: int  # bytes one message carries
    range_m: float

    def readings(self) -> list[RabPacket]:
        """The robots heard at the latest update: range, bearing and the payload each last sent."""
        ...

    def send(self, data: bytes) -> None:
        """Broadcast ``data`` from now on (each update carries the latest); ValueError when longer than
        ``max_payload``."""
        ...


@runtime_checkable
class Proximity(Protocol):
    def readings(self) -> list[RingReading]:
        """The 24 infrared sensors, counter-clockwise from straight ahead (0 nothing, 1 touching)."""
        ...


@runtime_checkable
class Light(Protocol):
    def readings(self) -> list[RingReading]:
        """The 24 light sensors, counter-clockwise from straight ahead (0 dark)."""
        ...


@runtime_checkable
class MotorGround(Protocol):
    def readings(self) -> list[GroundReading]:
        """The 4 grey-level sensors under the body."""
        ...


@runtime_checkable
class BaseGround(Protocol):
    def readings(self) -> list[GroundReading]:
        """The 8 black-or-white sensors under the base (0 black, 1 white), counter-clockwise from straight ahead."""
        ...


@runtime_checkable
class DifferentialSteering(Protocol):
    max_speed_mps: float  # the fastest a wheel turns, as linear speed

    def set_speeds(self, left_mps: float, right_mps: float) -> None:
        """Drive the wheels at these linear speeds (m/s, clipped to +-``max_speed_mps``) until told otherwise."""
        ...


@runtime_checkable
class Leds(Protocol):
    def set_all_colors(self, rgb: tuple[int, int, int]) -> None:
        """Light the ring and the beacon in one colour (0-255 each; (0, 0, 0) off)."""
        ...
