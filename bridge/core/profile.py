"""A robot model's physical and electrical figures, as the world, the firmware host and the config checks read them.

Each robot plugin (``bridge/robots/<robot>/``) declares one; the figures and their sources are in ``docs/models.md``.
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
