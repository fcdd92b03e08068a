"""The SonPI's devices as the swarm layer sees them (Roy 2022, digest 001 §0, §3.2, §5.1): typing protocols in SI
units, so the chapter 3 controller (``swarm_logic.families.roy``) runs unchanged on a point-agent model and, later,
on the robot.

A robot reaches them as ``robot.device(name)`` under the names below. Poses are in the arena's world frame (m, rad,
counter-clockwise); sonar angles are relative to the robot's heading (+ = left).

- ``sonpi_pose`` (``OwnPose``): this robot's pose and velocity, as the localisation service (overhead camera fused
  with odometry in the thesis) estimates it; ``read`` raises ``NoPose`` while the service has never given one (a
  robot the camera has not seen), and a reader falls back to the odometry (``own_pose``).
- ``sonpi_localisation`` (``Localisation``): the other robots' poses and velocities as the service broadcasts them
  (the thesis' controllers need all agents' positions, ch.3 also their velocities; digest §5.1 item 3).
- ``sonpi_sonar`` (``Sonar``): the 5 HC-SR04 sonars, 45 degrees apart over the front 180 degrees (digest §3.2).
- ``sonpi_velocity`` (``HolonomicVelocity``): the holonomic velocity the tracking layer is to follow (the thesis'
  point-agent command; the differential-drive mapping lies below this protocol, digest §5.1 item 4).
- ``sonpi_odometry`` (``Odometry``): the pose dead-reckoned from the wheel encoders (from the robot's start pose when
  it is known), its speeds and the raw encoder counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

POSE = "sonpi_pose"
LOCALISATION = "sonpi_localisation"
SONAR = "sonpi_sonar"
VELOCITY = "sonpi_velocity"
ODOMETRY = "sonpi_odometry"
DEVICE_NAMES = (POSE, LOCALISATION, SONAR, VELOCITY, ODOMETRY)

# 5 sonars, -90..+90 degrees step 45 (digest §0 item 5, §3.2)
SONAR_ANGLES_RAD = tuple(math.radians(a) for a in (-90.0, -45.0, 0.0, 45.0, 90.0))


@dataclass(frozen=True, slots=True)
class AgentPose:
    """One robot's pose and velocity in the world frame (m, rad, m/s)."""

    id: int
    x_m: float
    y_m: float
    yaw_rad: float
    vx_mps: float
    vy_mps: float


@dataclass(frozen=True, slots=True)
class SonarReading:
    """One sonar: the range to the nearest echo (m; ``math.inf`` when nothing echoes within its range) at its
    mounting angle (rad, relative to the heading, + = left)."""

    range_m: float
    angle_rad: float


@dataclass(frozen=True, slots=True)
class OdometryReading:
    """The encoders' dead reckoning at ``t_s`` (the robot's clock): pose (m, rad), forward speed (m/s) and turn rate
    (rad/s, + = left), and the raw encoder counts since the board powered up."""

    t_s: float
    x_m: float
    y_m: float
    yaw_rad: float
    v_mps: float
    w_rps: float
    left_counts: int
    right_counts: int


class NoPose(LookupError):
    """The localisation service has given this robot no pose yet (the camera has never seen it)."""


@runtime_checkable
class OwnPose(Protocol):
    def read(self) -> AgentPose:
        """This robot's latest pose and velocity estimate (``NoPose`` when there is none yet)."""
        ...


@runtime_checkable
class Localisation(Protocol):
    def poses(self) -> list[AgentPose]:
        """The other robots' latest broadcast poses and velocities (this robot excluded)."""
        ...


@runtime_checkable
class Sonar(Protocol):
    max_range_m: float

    def readings(self) -> list[SonarReading]:
        """The 5 sonars' latest ranges, right to left (-90 to +90 degrees)."""
        ...


@runtime_checkable
class HolonomicVelocity(Protocol):
    max_speed_mps: float  # the fastest the tracking layer follows

    def set_velocity(self, vx_mps: float, vy_mps: float) -> None:
        """Track this world-frame velocity (m/s, clipped to ``max_speed_mps``) until told otherwise."""
        ...


@runtime_checkable
class Odometry(Protocol):
    def read(self) -> OdometryReading:
        """The latest dead-reckoned pose and speeds."""
        ...


def odometry_pose(robot_id: int, o: OdometryReading) -> AgentPose:
    """The odometry's reading as a pose (its frame: the world's when the robot's start pose was known)."""
    return AgentPose(robot_id, o.x_m, o.y_m, o.yaw_rad, o.v_mps * math.cos(o.yaw_rad), o.v_mps * math.sin(o.yaw_rad))


def own_pose(pose: OwnPose | None, odometry: Odometry | None, robot_id: int) -> tuple[AgentPose | None, str]:
    """This robot's pose and where it came from: ``"camera"`` (the service's fresh estimate), ``"carried"`` (the
    service's last one carried on: the camera has lost the robot; ``fresh`` False), ``"odometry"`` (the service has
    none, ``NoPose``: the encoders' dead reckoning) or ``"none"`` (neither: the pose is None)."""
    if pose is not None:
        try:
            p = pose.read()
        except NoPose:
            pass
        else:
            return p, ("camera" if getattr(pose, "fresh", True) else "carried")
    if odometry is not None:
        return odometry_pose(robot_id, odometry.read()), "odometry"
    return None, "none"
