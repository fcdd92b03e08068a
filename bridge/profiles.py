"""Robot profiles: the physical and electrical figures of each robot model.

The eSwarBot figures come from Couceiro (2013), Table 3.2 and section 4.6.1: diameter 126 mm, height
100 mm, 600 g, wheel radius 21.09 mm, 48 encoder pulses per wheel revolution (2.76 mm per pulse).
3.6 degrees of rotation per pulse implies a half wheel separation of 43.9 mm. Values the thesis does not
give (motor speed, battery, sonar beam) are marked as assumptions in ``docs/models.md``.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict


class RobotProfile(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    # body (world)
    radius_m: float
    height_m: float
    mass_kg: float
    # drive train
    wheel_radius_m: float
    half_track_m: float
    encoder_cpr: int
    motor_max_wheel_rad_s: float  # no-load wheel speed at full PWM and nominal battery voltage
    motor_time_constant_s: float
    motor_deadband_pwm: int
    motor_gain_spread: float  # relative 1-sigma spread of motor gain between wheels/robots
    wheel_radius_spread: float
    # sonar (front ultrasonic, analog output)
    sonar_max_range_m: float
    sonar_min_range_m: float
    sonar_half_beam_deg: float
    sonar_rays: int
    sonar_rate_hz: float
    sonar_noise_m: float
    sonar_noise_rel: float
    sonar_outlier_p: float  # probability of a spurious echo per reading while the robot moves
    sonar_angles_deg: tuple[float, ...] = (0.0,)  # one sonar per angle from the heading; the first is the front
    # light sensor
    light_noise_rel: float
    # battery
    battery_capacity_mah: float
    battery_cells: int
    battery_internal_ohm: float
    current_idle_ma: float
    current_motor_max_ma: float
    # firmware
    llc_loop_hz: float
    # marsupial carrier: a conveyor belt of ``conveyor_slots`` scouts, ``conveyor_pitch_m`` of belt each
    conveyor_slots: int = 0
    conveyor_pitch_m: float = 0.15
    conveyor_speed_m_s: float = 0.05
    conveyor_m_per_step: float = 0.0005  # belt travel per stepper step

    @property
    def metres_per_pulse(self) -> float:
        return 2 * math.pi * self.wheel_radius_m / self.encoder_cpr


ESWARBOT = RobotProfile(
    name="eswarbot",
    radius_m=0.063,
    height_m=0.100,
    mass_kg=0.600,
    wheel_radius_m=0.02109,
    half_track_m=0.0439,
    encoder_cpr=48,
    motor_max_wheel_rad_s=16.6,  # ~0.35 m/s at full PWM (assumed; thesis peaks ~0.45 m/s relative)
    motor_time_constant_s=0.06,
    motor_deadband_pwm=25,
    motor_gain_spread=0.04,
    wheel_radius_spread=0.005,
    sonar_max_range_m=6.0,  # "readings up to about 6 m" (Table 3.2)
    sonar_min_range_m=0.15,
    sonar_half_beam_deg=15.0,
    sonar_rays=5,
    sonar_rate_hz=20.0,
    sonar_noise_m=0.01,
    sonar_noise_rel=0.01,
    sonar_outlier_p=0.02,  # "outliers while moving" (section 3.2.1)
    light_noise_rel=0.01,
    battery_capacity_mah=1500.0,  # about 3 h typical (Table 3.2)
    battery_cells=2,
    battery_internal_ohm=0.15,
    current_idle_ma=250.0,
    current_motor_max_ma=400.0,
    llc_loop_hz=50.0,  # the thesis digest recommends a 50-100 Hz motor/encoder loop
)

TRAXBOT = RobotProfile(
    name="traxbot",
    # 203 x 229 mm (Table 3.4): the cylinder circumscribing the footprint's inscribed ellipse is too large for a
    # chassis this square; 0.11 m is the radius of a disc of the same area (assumed, docs/models.md)
    radius_m=0.11,
    height_m=0.25,  # chassis, conveyor on top (assumed)
    mass_kg=4.2,  # unladen (Table 3.4); the scouts it carries are not added to its mass
    wheel_radius_m=0.0325,  # the Traxster II drive sprocket, tracks as wheels (assumed)
    half_track_m=0.085,
    encoder_cpr=624,  # "624 pulses/rev" (Table 3.4)
    motor_max_wheel_rad_s=9.2,  # ~0.3 m/s at full PWM (assumed)
    motor_time_constant_s=0.12,
    motor_deadband_pwm=30,
    motor_gain_spread=0.04,
    wheel_radius_spread=0.01,  # tracks slip more than wheels
    sonar_max_range_m=6.0,  # 3 Maxbotix MB1300, "range about 6 m" (Table 3.4)
    sonar_min_range_m=0.20,
    sonar_half_beam_deg=15.0,
    sonar_rays=5,
    sonar_rate_hz=10.0,
    sonar_noise_m=0.01,
    sonar_noise_rel=0.01,
    sonar_outlier_p=0.02,
    sonar_angles_deg=(0.0, 45.0, -45.0),  # front, left, right (the thesis does not give the angles; assumed)
    light_noise_rel=0.01,
    battery_capacity_mah=2200.0,  # about 2 h (Table 3.4)
    battery_cells=3,
    battery_internal_ohm=0.1,
    current_idle_ma=300.0,
    current_motor_max_ma=1500.0,
    llc_loop_hz=50.0,
    conveyor_slots=5,  # "carries 5 eSwarBots" (Table 3.4)
    conveyor_pitch_m=0.15,  # one eSwarBot (126 mm) and a gap per slot (assumed)
    conveyor_speed_m_s=0.05,  # stepper-driven belt, step resolution < 1 mm (Table 3.4; speed assumed)
)

PROFILES: dict[str, RobotProfile] = {ESWARBOT.name: ESWARBOT, TRAXBOT.name: TRAXBOT}
