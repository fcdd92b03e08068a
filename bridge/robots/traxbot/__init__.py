"""The TraxBot (Couceiro 2013, Table 3.4): a tracked ranger with three sonars and a five-slot conveyor that carries
and drops eSwarBot scouts. Its LLC speaks the eSwarBot's CAN interface plus the conveyor's frames."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from bridge.core.profile import RobotProfile
from bridge.core.registry import RobotSpec
from bridge.models.differential_drive import DriveParams
from bridge.models.light import LightParams
from bridge.models.sonar import SonarParams
from bridge.robots.eswarbot import EXTERNAL_PORTS
from bridge.robots.eswarbot.board import LlcBoard
from bridge.robots.eswarbot.pins import LLC_PINS
from bridge.robots.traxbot.conveyor import ConveyorParams
from swarm_logic.robots.eswarbot import eswarbot_llc_db

TRAXBOT = RobotProfile(
    name="traxbot",
    # 203 x 229 mm (Table 3.4): the cylinder circumscribing the footprint's inscribed ellipse is too large for a
    # chassis this square; 0.11 m is the radius of a disc of the same area (assumed, docs/models.md)
    radius_m=0.11,
    height_m=0.25,  # chassis, conveyor on top (assumed)
    mass_kg=4.2,  # unladen (Table 3.4); the scouts it carries are not added to its mass
    battery_capacity_mah=2200.0,  # about 2 h (Table 3.4)
    battery_cells=3,
    battery_internal_ohm=0.1,
    current_idle_ma=300.0,
    llc_loop_hz=50.0,
    parts=(
        DriveParams(
            wheel_radius_m=0.0325,  # the Traxster II drive sprocket, tracks as wheels (assumed)
            half_track_m=0.085,
            encoder_cpr=624,  # "624 pulses/rev" (Table 3.4)
            motor_max_wheel_rad_s=9.2,  # ~0.3 m/s at full PWM (assumed)
            motor_time_constant_s=0.12,
            motor_deadband_pwm=30,
            motor_gain_spread=0.04,
            wheel_radius_spread=0.01,  # tracks slip more than wheels
            current_motor_max_ma=1500.0,
        ),
        SonarParams(
            max_range_m=6.0,  # 3 Maxbotix MB1300, "range about 6 m" (Table 3.4)
            min_range_m=0.20,
            half_beam_deg=15.0,
            rays=5,
            rate_hz=10.0,
            noise_m=0.01,
            noise_rel=0.01,
            outlier_p=0.02,
            angles_deg=(0.0, 45.0, -45.0),  # front, left, right (the thesis does not give the angles; assumed)
        ),
        LightParams(noise_rel=0.01),
        ConveyorParams(
            slots=5,  # "carries 5 eSwarBots" (Table 3.4)
            pitch_m=0.15,  # one eSwarBot (126 mm) and a gap per slot (assumed)
            speed_m_s=0.05,  # stepper-driven belt, step resolution < 1 mm (Table 3.4; speed assumed)
        ),
    ),
)



class TraxbotOptions(BaseModel):
    """What a session config may set on a group of TraxBots."""

    model_config = ConfigDict(extra="forbid")

    conveyor_slots: int | None = Field(None, ge=1, le=255, description="scouts each robot of this group carries "
                                       "(overrides its profile's conveyor, e.g. 20 to put 60 scouts on 3 rangers)")


def configure(profile: RobotProfile, options: TraxbotOptions) -> RobotProfile:
    """A conveyor of ``conveyor_slots`` slots, if the group sets it."""
    belt = profile.part(ConveyorParams)
    if options.conveyor_slots is None or belt is None:
        return profile
    return profile.with_part(belt.model_copy(update={"slots": options.conveyor_slots}))


SPEC = RobotSpec("traxbot", TRAXBOT, eswarbot_llc_db, "TraxBot: tracked ranger, three sonars, conveyor of five scouts",
                 LlcBoard, LLC_PINS,  # the eSwarBot's LLC sketch, with its side sonars and conveyor
                 options=TraxbotOptions, configure=configure, external_ports=EXTERNAL_PORTS)
