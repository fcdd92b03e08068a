"""The SonPI (Roy 2022, chapter 7): a locally built differential-drive UGV, two wheels and a caster, a Raspberry Pi
("1.4 GHz ARM quad-core") as its computer, and an Arduino (ATmega328) that reads five HC-SR04 sonars 45 degrees apart
over the front 180 degrees and hands them to the Pi over I2C; "high-precision" wheel encoders; a marker on its top for
the overhead camera that localises the swarm.

The thesis gives no size, mass, wheel or motor figure: ours are assumptions for a small two-wheeled robot of this kind,
listed with their reasons in ``docs/sonpi.md``. The Arduino is the robot's own firmware entity ``arduino``
(``firmware.py``: an I2C slave on the robot's bus, as a DeciZebro's leg modules are); its pins meet the world through
``wiring.py``.
"""

from __future__ import annotations

from typing import Any

from bridge.core.profile import RobotProfile
from bridge.core.registry import RobotSpec
from bridge.models.differential_drive import DriveParams
from bridge.models.marker import TopMarker
from bridge.models.sonar import SonarParams
from bridge.robots.sonpi import firmware
from bridge.robots.sonpi.options import SonpiOptions
from bridge.robots.sonpi.wiring import BOARD_WIRING, ROLE, SONAR_ANGLES_DEG

WHEEL_RADIUS_M = 0.0325  # 65 mm wheels (assumed)

SONPI = RobotProfile(
    name="sonpi",
    radius_m=0.09,  # assumed: a round chassis for a Pi, an Arduino and five sonars on a 180-degree arc
    height_m=0.12,
    mass_kg=0.9,
    battery_capacity_mah=2200.0,  # assumed: two Li-ion cells
    battery_cells=2,
    battery_internal_ohm=0.1,
    current_idle_ma=400.0,  # the Pi (a 3B+ class board) and the Arduino, at the battery (assumed)
    llc_loop_hz=100.0,  # the Arduino's control loop (assumed)
    parts=(
        DriveParams(
            wheel_radius_m=WHEEL_RADIUS_M,
            half_track_m=0.075,
            encoder_cpr=2048,  # "high-precision" encoders (assumed: 512 lines, quadrature)
            motor_max_wheel_rad_s=0.30 / WHEEL_RADIUS_M,  # 0.3 m/s at full PWM (assumed)
            motor_time_constant_s=0.06,
            motor_deadband_pwm=15,
            motor_gain_spread=0.03,
            wheel_radius_spread=0.003,
            current_motor_max_ma=800.0,
        ),
        SonarParams(  # the world's ray cones; the HC-SR04s' timing, noise and cross-talk are the board's (hcsr04.py)
            max_range_m=4.5,  # past the rated 4 m: the board decides what is out of range
            min_range_m=0.0,
            half_beam_deg=7.5,  # a 15-degree beam (datasheet)
            rays=5,
            rate_hz=100.0,  # every quantum until the board tells its sensors' firing times (pins "trig"), then those
            noise_m=0.0,
            noise_rel=0.0,
            outlier_p=0.0,
            angles_deg=SONAR_ANGLES_DEG,
        ),
        TopMarker(rgb=(255, 64, 0), radius_m=0.07),
    ),
)


def configure(profile: RobotProfile, o: SonpiOptions) -> RobotProfile:
    """The group's marker colour."""
    marker = profile.part(TopMarker)
    return profile.with_part(marker.model_copy(update={"rgb": tuple(o.marker_rgb)}))


def _wiring(role: str) -> Any:
    return BOARD_WIRING if role == ROLE else None


NO_CAN = "a SonPI has no CAN bus: its Arduino board is an I2C slave of the Pi"
# a program outside the session is the robot's logic through this (hil_configs/robots/sonpi_sitl_ports.toml)
EXTERNAL_PORTS = {
    "i2c_pty": "an external logic drives the SonPI through its Arduino board on the I2C bus: expose it, "
    'e.g. i2c_pty = "r{id}-i2c" (a USB-ISS adapter: usb-iss://PATH)'
}

SPEC = RobotSpec(
    "sonpi",
    SONPI,
    title="SonPI: differential drive, Arduino sonar and motor board (5 HC-SR04) on I2C",
    roles=firmware.roles,
    modules=firmware.modules,
    wiring=_wiring,
    hal=firmware.hal,
    options=SonpiOptions,
    configure=configure,
    external_ports=EXTERNAL_PORTS,
    refuses={
        "xbee": "a SonPI talks Wi-Fi (802.11), not XBee",
        "uwb": "a SonPI has no UWB module",
        "can": NO_CAN,
        "vehicle": NO_CAN,
        "pose_source": "a SonPI's board reports no pose: the overhead camera localises it",
    },
)
