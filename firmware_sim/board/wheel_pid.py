"""A wheel's speed servo as the robots' motor boards run it: a position-tracking PI with velocity feed-forward, a motor
dead-band offset, anti-windup and a bounded tracking error, on quantised encoder counts (a velocity PI on coarse
encoders would see less than one pulse per loop). Each board compiles it with its own figures (``PidParams``)."""

from __future__ import annotations

import math
from typing import Protocol


class PidParams(Protocol):
    """The figures a board builds its wheel servo with."""

    encoder_cpr: int
    max_wheel_rad_s: float
    deadband_pwm: int
    motor_time_constant_s: float
    kp: float  # PWM per pulse of tracking error
    ki: float  # PWM per pulse-second
    max_err_pulses: float


class WheelPid:
    """Position-tracking PI with feed-forward for one wheel, on quantised encoder counts."""

    def __init__(self, p: PidParams) -> None:
        self.p = p
        self.kff = (255 - p.deadband_pwm) / (p.max_wheel_rad_s * p.encoder_cpr / (2 * math.pi))
        self.target_pos = 0.0
        self.integral = 0.0
        self.active = False

    def reset(self) -> None:
        """Forget the set-point: the next non-zero target starts from the wheel's count then."""
        self.active = False
        self.integral = 0.0

    def update(self, target_pps: float, count: int, dt: float) -> int:
        if target_pps == 0.0:
            self.active = False
            self.integral = 0.0
            return 0
        if not self.active:
            self.active = True
            self.target_pos = float(count)
        self.target_pos += target_pps * dt
        return self._servo(target_pps, count, dt)

    def follow(self, target_pos: float, target_pps: float, count: int, dt: float, accel_pps2: float = 0.0) -> int:
        """Track a set-point profile the caller computes (a MOVE's speed ramp): position ``target_pos`` (pulses)
        moving at ``target_pps`` and accelerating at ``accel_pps2``, which the feed-forward leads by the motor's
        time constant; at rest it holds the position."""
        self.active = True
        self.target_pos = target_pos
        return self._servo(target_pps, count, dt, target_pps + self.p.motor_time_constant_s * accel_pps2)

    def _servo(self, target_pps: float, count: int, dt: float, ff_pps: float | None = None) -> int:
        p = self.p
        ff = target_pps if ff_pps is None else ff_pps
        err = self.target_pos - count
        if abs(err) > p.max_err_pulses:  # do not lurch after a stall: drag the set-point along
            err = math.copysign(p.max_err_pulses, err)
            self.target_pos = count + err
        push = ff or err  # the dead-band offset goes the way the wheel has to turn
        u_pre = self.kff * ff + (math.copysign(p.deadband_pwm, push) if push else 0.0) + p.kp * err
        new_integral = self.integral + err * dt
        u = u_pre + p.ki * new_integral
        if -255 < u < 255 or (u >= 255 and err < 0) or (u <= -255 and err > 0):
            self.integral = new_integral  # anti-windup: integrate only while not saturated further
        u = u_pre + p.ki * self.integral
        return int(max(-255, min(255, round(u))))
