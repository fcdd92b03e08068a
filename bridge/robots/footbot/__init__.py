"""The foot-bot (the marXbot-based robot of the Swarmanoid project, ARGoS's ``foot-bot``; Khan's PFSM search): a
0.085 m-radius cylinder on two wheels, with a base board (motors and encoders, 24 infrared proximity sensors, 24
light sensors, 4 motor-ground sensors, the LED ring and beacon) and an infrared range-and-bearing board, both nodes
of the robot's 1 Mbit/s CAN bus, the robot's computer the third (``footbot.dbc``).

Figures (``docs/footbot.md``, with their sources): ARGoS's foot-bot (radius 0.085 m, height 0.147 m, 1.6 kg,
wheel radius 0.0291 m, 0.14 m between the wheels, sensor rings and ground sensors where ARGoS puts them, the
range-and-bearing link's 3 m and 10 bytes) and Enki's marXbot (30 cm/s at most); the motors, encoders and battery
are assumptions.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from bridge.core.profile import RobotProfile
from bridge.core.registry import RobotSpec
from bridge.models.differential_drive import DriveParams
from bridge.robots.footbot.base import BASE_PINS, BaseBoard
from bridge.robots.footbot.rab import ROLE as RAB
from bridge.robots.footbot.rab import RabEntity, RabParams
from bridge.robots.footbot.sensors import FootbotSensorsParams
from swarm_logic.robots.footbot import footbot_db

FOOTBOT = RobotProfile(
    name="footbot",
    radius_m=0.085,
    height_m=0.1469,
    mass_kg=1.6,  # ARGoS dynamics2d foot-bot model
    battery_capacity_mah=3900.0,  # assumed (a hot-swappable Li-Po; docs/footbot.md)
    battery_cells=1,
    battery_internal_ohm=0.05,
    current_idle_ma=600.0,  # the i.MX31 computer and the boards (assumed)
    llc_loop_hz=50.0,  # the base board's motor loop (assumed: ASEBA's simulated marXbot runs its timer at 50 Hz)
    parts=(
        DriveParams(
            wheel_radius_m=0.0291,  # ARGoS footbot_entity.cpp
            half_track_m=0.07,  # 0.14 m between the wheels (ARGoS)
            encoder_cpr=1024,  # assumed
            motor_max_wheel_rad_s=0.30 / 0.0291,  # 30 cm/s (Enki's marXbot)
            motor_time_constant_s=0.05,  # assumed
            motor_deadband_pwm=10,  # assumed
            motor_gain_spread=0.02,  # Enki's marXbot: 2 % motor noise
            wheel_radius_spread=0.002,  # assumed
            current_motor_max_ma=1000.0,  # assumed
        ),
        FootbotSensorsParams(),
        RabParams(),
    ),
)


class FootbotOptions(BaseModel):
    """A foot-bot group's options: the range-and-bearing link's errors (ARGoS's defaults are none)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    rab_range_noise_rel: float = Field(0.0, ge=0, le=1, description="std of the range error, relative to the range")
    rab_bearing_noise_deg: float = Field(0.0, ge=0, le=180, description="std of the bearing error (deg)")
    rab_loss: float = Field(0.0, ge=0, le=1, description="probability a reading is lost (ARGoS's packet_drop_prob)")
    rab_range_m: float = Field(3.0, gt=0, le=10, description="how far the board hears (ARGoS's rab_range)")
    proximity_noise: float = Field(0.0, ge=0, le=1, description="std of the proximity readings' noise")


def configure(profile: RobotProfile, o: FootbotOptions) -> RobotProfile:
    """The link's and the proximity ring's figures a group's options set."""
    parts = []
    for p in profile.parts:
        if isinstance(p, RabParams):
            p = p.model_copy(update={"range_noise_rel": o.rab_range_noise_rel, "bearing_noise_deg":
                                     o.rab_bearing_noise_deg, "loss": o.rab_loss, "range_m": o.rab_range_m})
        elif isinstance(p, FootbotSensorsParams):
            p = p.model_copy(update={"proximity_noise": o.proximity_noise})
        parts.append(p)
    return profile.model_copy(update={"parts": tuple(parts)})


def _roles(rp: Any) -> tuple[str, ...]:
    return (RAB,)


def _modules(rp: Any, cfg: Any) -> dict[str, Any]:
    from bridge.core.registry import robot_profile

    return {RAB: RabEntity(rp, cfg, robot_profile(rp.profile, rp.options).part(RabParams))}


# a program outside the session reaches both boards through the robot's CAN bus
EXTERNAL_PORTS = {"can.slcan_pty": "an external logic reaches the foot-bot's boards through its CAN bus: expose it, "
                                   "e.g. can = { slcan_pty = \"r{id}-can\" }"}

SPEC = RobotSpec(
    "footbot", FOOTBOT, footbot_db, "foot-bot: differential drive, base board and range-and-bearing board on CAN",
    BaseBoard, BASE_PINS, options=FootbotOptions, configure=configure, roles=_roles, modules=_modules,
    wiring=lambda role: None, can_roles=(RAB,), can_hal="footbot_can", external_ports=EXTERNAL_PORTS,
    refuses={"xbee": "a foot-bot talks through its range-and-bearing board, not an XBee",
             "uwb": "a foot-bot measures range and bearing with its infrared board, not a UWB module",
             "pose_source": "the foot-bot's base board reports no pose (the logic reads its encoders)"})
