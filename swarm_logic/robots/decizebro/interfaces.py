"""The Zebro's devices as the swarm layer sees them (Agrawal 2019; Table 3.1, section 4.2.1, App. B): typing
protocols in SI units, so the collective-decision controllers (``swarm_logic.families.zebro``) run unchanged on a
point-robot model and on a robot whose devices are HAL tables.

A robot reaches them as ``robot.device(name)`` under the HAL table names below; a Zebro has no LLC (``robot.llc``
is None): its locomotion is the ``legs`` device.

- ``uwb_radio`` (``ZebroRadio``): the DWM1001 UWB module through its driver. It ranges its neighbours (range and
  bearing relative to the robot's heading) and exchanges each robot's absolute heading with its ranging beacons,
  as the thesis assumes the UWB layer does (the swarm layer never sends headings); it carries the swarm layer's
  broadcast frames to the neighbours within the communication radius.
- ``utility`` (``UtilitySensor``): the fused forward sensor, a cone of 60 degrees (+-30) and 3 body lengths. It
  reads the integer sum of the utilities in the cone (0 nothing, < 0 an obstacle) and the direction of what it
  sees. Consumption is an event of this sensor: ``consumed()`` returns the utility of the particle the robot
  has just reached and eaten (the sensor sees it vanish in front of the mouth), once.
- ``imu`` (``Imu``): the absolute heading from the magnetometer.
- ``legs`` (``Locomotion``): forward walking at the one constant speed the gait has, with a turn rate; ``fast``
  is the mature leader's 3x pace. There is no way to walk backwards or to slow down.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

UWB_RADIO = "uwb_radio"
UTILITY = "utility"
IMU = "imu"
LEGS = "legs"
DEVICE_NAMES = (UWB_RADIO, UTILITY, IMU, LEGS)

BODY_LENGTH_M = 0.268  # the DeciZebro, 268 x 210 x 160 mm (App. B.4): the thesis' unit of length
FAST_FACTOR = 3.0  # the mature leader walks at three times the flocking speed (section 3.5.3)


@dataclass(frozen=True, slots=True)
class Neighbour:
    """A robot the UWB module ranges: its id, range (m), bearing relative to our heading (rad, + = left) and its
    absolute heading (rad), which the UWB layer carries with its ranging beacons (None when it has not)."""

    id: int
    range_m: float
    bearing_rad: float
    heading_rad: float | None


@dataclass(frozen=True, slots=True)
class Message:
    """A broadcast frame received from robot ``src``."""

    src: int
    data: bytes


@runtime_checkable
class ZebroRadio(Protocol):
    max_payload: int  # the most bytes one broadcast carries (a longer message goes in several)

    def neighbours(self) -> list[Neighbour]:
        """The robots within the communication radius, as of the latest ranging."""
        ...

    def broadcast(self, data: bytes) -> bool:
        """Send ``data`` to every neighbour; False when the module's transmit budget refuses it."""
        ...

    def receive(self) -> list[Message]:
        """The frames received since the last call, oldest first."""
        ...

    def wait_neighbourhood(self, timeout: float | None = None) -> None:
        """Block until the radio has heard its neighbourhood for one whole update period (every neighbour in range
        has been ranged once): what a program waits for before its first decision."""
        ...


@runtime_checkable
class UtilitySensor(Protocol):
    def read(self) -> int:
        """The sum of the utilities in the forward cone (0: nothing; negative: an obstacle)."""
        ...

    def bearing(self) -> float | None:
        """The direction of what the cone sees, relative to the heading (rad, + = left), utility-weighted; None
        when it sees nothing."""
        ...

    def consumed(self) -> int:
        """The utility of the particle(s) the robot ate since the last call (0: none)."""
        ...


@runtime_checkable
class Imu(Protocol):
    def heading(self) -> float:
        """The absolute heading (rad, counter-clockwise from east)."""
        ...


@runtime_checkable
class Locomotion(Protocol):
    speed_mps: float  # the gait's one walking speed

    def walk(self, turn_rate_rps: float, fast: bool = False) -> None:
        """Walk forward at ``speed_mps`` (3x with ``fast``) turning at ``turn_rate_rps`` (+ = left), until told
        otherwise."""
        ...

    def halt(self) -> None:
        """Stand still."""
        ...
