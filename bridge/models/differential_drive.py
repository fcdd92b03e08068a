"""Two DC motors driving two wheels (or tracks), modelled in numpy for every robot that has them.

First-order speed response to PWM and battery voltage, a dead band, per-wheel gain and wheel-radius spread from the
robot's seeded stream; the differential-drive twist is imposed on the body every physics step and pybullet resolves
contacts with walls, obstacles and other robots. Encoders count the wheels' rotation in CPR pulses (a wheel that
spins against a wall keeps counting, as a real one slips).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.parts import Part, WorldModel
from bridge.core.rng import stream

V_NOMINAL_PER_CELL = 3.7


class DriveParams(Part):
    wheel_radius_m: float
    half_track_m: float
    encoder_cpr: int
    motor_max_wheel_rad_s: float  # no-load wheel speed at full PWM and nominal battery voltage
    motor_time_constant_s: float
    motor_deadband_pwm: int
    motor_gain_spread: float  # relative 1-sigma spread of motor gain between wheels/robots
    wheel_radius_spread: float
    current_motor_max_ma: float  # both motors at full PWM

    @property
    def metres_per_pulse(self) -> float:
        return 2 * math.pi * self.wheel_radius_m / self.encoder_cpr


class DifferentialDrive(WorldModel):
    name = "differential_drive"
    sensors = ("encoder",)
    faults = ("wheel_slip", "motor_stall")

    def __init__(self, world: Any, robots: list[int], parts: list[DriveParams]) -> None:
        super().__init__(world, robots, parts)
        n, p = len(robots), parts
        self.wheel_r = np.empty((n, 2))
        self.gain = np.empty((n, 2))
        for k, (r, q) in enumerate(zip(robots, p, strict=True)):
            g = stream(world.seed, "robot", r, "drivetrain")
            self.wheel_r[k] = q.wheel_radius_m * (1 + q.wheel_radius_spread * g.standard_normal(2))
            self.gain[k] = 1 + q.motor_gain_spread * g.standard_normal(2)
        self.half_track = np.array([q.half_track_m for q in p])
        self.cpr = np.array([q.encoder_cpr for q in p], dtype=float)
        self.w_max = np.array([q.motor_max_wheel_rad_s for q in p])
        self.tau = np.array([q.motor_time_constant_s for q in p])
        self.deadband = np.array([q.motor_deadband_pwm for q in p], dtype=float)
        self.i_motor = np.array([q.current_motor_max_ma for q in p]) / 1000.0
        self.nominal_r = np.array([q.wheel_radius_m for q in p])
        self.pwm = np.zeros((n, 2))
        self.omega = np.zeros((n, 2))
        self.angle = np.zeros((n, 2))
        self._w_ss = np.zeros((n, 2))
        self._decay = np.exp(-world.dt / self.tau)[:, None]
        self._tau_1ma = self.tau[:, None] * (1 - self._decay)
        self._bodies = [world.bodies[r] for r in robots]
        self._yaw = np.zeros(n)
        self._counts: list | None = None
        self._t_ns = 0
        self.grip = np.ones((n, 2))  # the share of a wheel's rim speed that moves the robot (wheel_slip: less)
        self.stalled = np.zeros((n, 2), dtype=bool)  # motors that turn no more (motor_stall)

    def wheel_fault(self, r: int, wheels: tuple[int, ...], kind: str, slip: float, on: bool) -> None:
        """A ``wheel_slip`` (the wheel loses ``slip`` of its rim speed to the floor; its encoder counts on) or a
        ``motor_stall`` (the motor turns no more: the wheel stops, its encoder too) on robot ``r``'s ``wheels``
        (0 left, 1 right), or its end (``on`` False)."""
        k = self.local[r]
        for i in wheels:
            if kind == "wheel_slip":
                self.grip[k, i] = 1.0 - slip if on else 1.0
            else:
                self.stalled[k, i] = on
                if on:
                    self.omega[k, i] = 0.0

    def set_pwm(self, r: int, left: int, right: int) -> None:
        """The board's signed 8-bit PWM per motor (a dead robot's motors stay off)."""
        if self.world.alive[r]:
            self.pwm[self.local[r]] = (left, right)

    def kill(self, r: int) -> None:
        self.pwm[self.local[r]] = 0

    def start_quantum(self, t_ns: int, q_ns: int) -> None:
        """Steady-state wheel speeds for the current PWM and battery voltage (constant over a quantum)."""
        w = self.world
        duty = np.abs(self.pwm)
        frac = np.clip((duty - self.deadband[:, None]) / (255.0 - self.deadband[:, None]), 0.0, 1.0)
        vscale = (w.battery_v[self.ids] / (V_NOMINAL_PER_CELL * w.cells[self.ids]))[:, None]
        self._w_ss = np.sign(self.pwm) * frac * self.w_max[:, None] * self.gain * vscale
        self._w_ss[self.stalled] = 0.0
        self._t_ns = t_ns + q_ns
        self._yaw = w.yaw[self.ids].copy()
        self._counts = None

    def before_step(self) -> None:
        """Exact first-order motor response over one physics step (the wheel angle is its exact integral), and the
        resulting twist imposed on each body at the heading of mid-step."""
        dt = self.world.dt
        w_ss = self._w_ss
        dev = self.omega - w_ss
        self.angle += w_ss * dt + dev * self._tau_1ma
        self.omega = w_ss + dev * self._decay
        if self.stalled.any():  # a stalled motor's wheel is held still
            self.omega[self.stalled] = 0.0
            self.angle[self.stalled] -= (w_ss * dt + dev * self._tau_1ma)[self.stalled]
        rim = self.omega * self.wheel_r * self.grip
        v = 0.5 * (rim[:, 0] + rim[:, 1])
        self._w = w = (rim[:, 1] - rim[:, 0]) / (2 * self.half_track)
        # the true pose is read back once per quantum, so a collision's effect on the heading is picked up within one
        mid = self._yaw + 0.5 * w * dt
        vx = (v * np.cos(mid)).tolist()
        vy = (v * np.sin(mid)).tolist()
        wl = w.tolist()
        reset, c = pb.resetBaseVelocity, self.world.cid
        for k, body in enumerate(self._bodies):
            reset(body, (vx[k], vy[k], 0.0), (0.0, 0.0, wl[k]), physicsClientId=c)

    def after_step(self) -> None:
        self._yaw += self._w * self.world.dt

    def load_a(self, load: np.ndarray) -> None:
        load[self.ids] += self.i_motor * np.abs(self.pwm).sum(axis=1) / 510.0

    def drive_speed(self, speed: np.ndarray) -> None:
        """Each robot's faster wheel's rim speed (m/s, nominal radius): how hard it is driving."""
        speed[self.ids] = np.abs(self.omega).max(axis=1) * self.nominal_r

    def sense(self, r: int) -> dict[str, Any]:
        """The two encoders' pulse counts since power-up."""
        if self._counts is None:  # once per physics state
            self._counts = np.floor(self.angle * (self.cpr / (2 * math.pi))[:, None]).astype(np.int64).tolist()
        left, right = self._counts[self.local[r]]
        if (r, "encoder") in self.world.sensor_faults.faults:  # a faulty encoder (bridge.core.faults)
            left, right = self.world.sensor_faults.apply(r, "encoder", (left, right), self._t_ns)
        return {"encoders": (left, right)}


DriveParams.world_model = DifferentialDrive
