"""The eSwarBot (Couceiro 2013): a 126 mm differential-drive robot with an Arduino LLC on CAN.

Its figures come from Couceiro (2013), Table 3.2 and section 4.6.1: diameter 126 mm, height
100 mm, 600 g, wheel radius 21.09 mm, 48 encoder pulses per wheel revolution (2.76 mm per pulse).
3.6 degrees of rotation per pulse implies a half wheel separation of 43.9 mm. Values the thesis does not
give (motor speed, battery, sonar beam) are marked as assumptions in ``docs/models.md``.
"""

from __future__ import annotations

from bridge.core.profile import RobotProfile
from bridge.core.registry import RobotSpec
from bridge.models.differential_drive import DriveParams
from bridge.models.light import LightParams
from bridge.models.sonar import SonarParams
from bridge.robots.eswarbot.board import LlcBoard
from bridge.robots.eswarbot.pins import LLC_PINS
from swarm_logic.robots.eswarbot import eswarbot_llc_db

ESWARBOT = RobotProfile(
    name="eswarbot",
    radius_m=0.063,
    height_m=0.100,
    mass_kg=0.600,
    battery_capacity_mah=1500.0,  # about 3 h typical (Table 3.2)
    battery_cells=2,
    battery_internal_ohm=0.15,
    current_idle_ma=250.0,
    llc_loop_hz=50.0,  # the thesis digest recommends a 50-100 Hz motor/encoder loop
    parts=(
        DriveParams(
            wheel_radius_m=0.02109,
            half_track_m=0.0439,
            encoder_cpr=48,
            motor_max_wheel_rad_s=16.6,  # ~0.35 m/s at full PWM (assumed; thesis peaks ~0.45 m/s relative)
            motor_time_constant_s=0.06,
            motor_deadband_pwm=25,
            motor_gain_spread=0.04,
            wheel_radius_spread=0.005,
            current_motor_max_ma=400.0,
        ),
        SonarParams(
            max_range_m=6.0,  # "readings up to about 6 m" (Table 3.2)
            min_range_m=0.15,
            half_beam_deg=15.0,
            rays=5,
            rate_hz=20.0,
            noise_m=0.01,
            noise_rel=0.01,
            outlier_p=0.02,  # "outliers while moving" (section 3.2.1)
        ),
        LightParams(
            noise_rel=0.01,
        ),
    ),
)

# a program outside the session reaches the LLC through the robot's CAN bus, as the companion computer does
EXTERNAL_PORTS = {"can.slcan_pty": "an external logic reaches the robot's LLC through its CAN bus: expose it, e.g. "
                                   "can = { slcan_pty = \"r{id}-can\" }"}

SPEC = RobotSpec("eswarbot", ESWARBOT, eswarbot_llc_db, "eSwarBot: differential drive, Arduino LLC on CAN, XBee, UWB",
                 LlcBoard, LLC_PINS, default=True,  # a group without a profile is eSwarBots
                 external_ports=EXTERNAL_PORTS)
