"""The DeciZebro's six C-shaped legs, RHex-style, as the world simulates them (a gait-level body model).

Each leg is a DC motor turning a C-leg of ``leg_radius_m``: its angular speed follows a first-order response to the
leg module's signed duty, scaled by battery voltage; its angle (0 = pointing down, growing as the robot walks
forward) is integrated exactly per physics step. A leg is in stance while its angle is within ``stance_half_rad``
of pointing down; each side of the body moves at the mean rim speed of its legs in stance (none in stance: that side
drags), times a per-leg traction factor (the robot's seeded spread, about 1: legs slip), and the two sides' speeds
make the body's twist over ``track_m``, imposed on the body every physics step as a drive's is; pybullet resolves
contacts with walls, obstacles and other robots. Walking therefore emerges from the legs' phases: a tripod gait
keeps a stance leg on each side, a gait with no stance leg on a side turns the robot, legs turned backwards walk it
backwards (the locomotion layer on the robot never asks for that).

Legs are numbered 0-5: 0-2 left, front to back; 3-5 right, front to back. The contact-level model, slower to
simulate, is ``contact_legs.py`` (the robot option ``body = "contact"``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.parts import Part, WorldModel
from bridge.core.rng import stream

LEGS = 6
LEFT = (0, 1, 2)
RIGHT = (3, 4, 5)
TWO_PI = 2 * math.pi


class LegsParams(Part):
    leg_radius_m: float  # the C-leg's radius: its rim speed is leg_radius_m x angular speed
    track_m: float  # between the left and right legs' contact lines
    max_rad_s: float  # no-load leg speed at full duty and nominal voltage (170 rpm: 17.8 rad/s)
    nominal_v: float  # the motors' rated voltage
    time_constant_s: float
    stance_half_rad: float  # a leg is on the ground within this angle of pointing down
    traction_spread: float  # relative 1-sigma spread of the legs' traction (slip), per leg and robot
    current_per_leg_ma: float  # one leg at full duty, walking


class LegMotors(WorldModel):
    """What a leg module's pins meet, whatever the body model: each leg's signed duty in, its angle and speed out.
    A body model keeps ``duty``, ``theta`` and ``rate`` (robots x legs) and ``leg_r`` (per robot)."""

    duty: np.ndarray
    theta: np.ndarray
    rate: np.ndarray
    leg_r: np.ndarray

    def set_duty(self, r: int, leg: int, duty: float) -> None:
        """Leg ``leg``'s motor gets signed duty ``duty`` (-1..1); a dead robot's legs stay off."""
        if self.world.alive[r]:
            self.duty[self.local[r], leg] = min(1.0, max(-1.0, float(duty)))

    def angle(self, r: int, leg: int) -> float:
        """The leg's angle (rad, 0 = pointing down, growing as it walks forward), wrapped to [0, 2 pi)."""
        return float(self.theta[self.local[r], leg] % TWO_PI)

    def omega(self, r: int, leg: int) -> float:
        """The leg's angular speed (rad/s)."""
        return float(self.rate[self.local[r], leg])

    def drive_speed(self, speed: np.ndarray) -> None:
        speed[self.ids] = np.abs(self.rate).max(axis=1) * self.leg_r

    def sense(self, r: int) -> dict[str, Any]:
        """The six legs' angles (rad, wrapped) and speeds (rad/s)."""
        k = self.local[r]
        return {"leg_angles": (self.theta[k] % TWO_PI).tolist(), "leg_omegas": self.rate[k].tolist()}


class Legs(LegMotors):
    name = "legs"

    def __init__(self, world: Any, robots: list[int], parts: list[LegsParams]) -> None:
        super().__init__(world, robots, parts)
        n, p = len(robots), parts
        self.duty = np.zeros((n, LEGS))
        self.rate = np.zeros((n, LEGS))
        self.theta = np.zeros((n, LEGS))
        self.traction = np.empty((n, LEGS))
        for k, r in enumerate(robots):
            g = stream(world.seed, "robot", r, "legs")
            self.traction[k] = np.clip(1 + p[k].traction_spread * g.standard_normal(LEGS), 0.5, 1.2)
        self.leg_r = np.array([q.leg_radius_m for q in p])
        self.track = np.array([q.track_m for q in p])
        self.w_max = np.array([q.max_rad_s for q in p])
        self.v_nom = np.array([q.nominal_v for q in p])
        self.tau = np.array([q.time_constant_s for q in p])
        self.stance = np.array([q.stance_half_rad for q in p])
        self.i_leg = np.array([q.current_per_leg_ma for q in p]) / 1000.0
        self._decay = np.exp(-world.dt / self.tau)[:, None]
        self._tau_1ma = self.tau[:, None] * (1 - self._decay)
        self._w_ss = np.zeros((n, LEGS))
        self._bodies = [world.bodies[r] for r in robots]
        self._yaw = np.zeros(n)
        self._w = np.zeros(n)

    # -- what the leg modules' pins do and read ----------------------------------------------------------
    def kill(self, r: int) -> None:
        self.duty[self.local[r]] = 0.0

    # -- the quantum -------------------------------------------------------------------------------------
    def start_quantum(self, t_ns: int, q_ns: int) -> None:
        w = self.world
        vscale = np.minimum(w.battery_v[self.ids] / self.v_nom, 1.25)[:, None]
        self._w_ss = self.duty * self.w_max[:, None] * vscale
        self._yaw = w.yaw[self.ids].copy()

    def before_step(self) -> None:
        """The legs' exact first-order response over one step, then the body's twist from the legs in stance."""
        dt = self.world.dt
        dev = self.rate - self._w_ss
        self.theta += self._w_ss * dt + dev * self._tau_1ma
        self.rate = self._w_ss + dev * self._decay
        down = np.abs((self.theta + math.pi) % TWO_PI - math.pi) <= self.stance[:, None]
        rim = self.rate * self.leg_r[:, None] * self.traction
        sides = []
        for legs in (LEFT, RIGHT):
            on = down[:, legs]
            count = on.sum(axis=1)
            sides.append(np.where(count > 0, (rim[:, legs] * on).sum(axis=1) / np.maximum(count, 1), 0.0))
        v = 0.5 * (sides[0] + sides[1])
        self._w = (sides[1] - sides[0]) / self.track
        mid = self._yaw + 0.5 * self._w * dt
        vx, vy, wl = (v * np.cos(mid)).tolist(), (v * np.sin(mid)).tolist(), self._w.tolist()
        reset, c = pb.resetBaseVelocity, self.world.cid
        for k, body in enumerate(self._bodies):
            reset(body, (vx[k], vy[k], 0.0), (0.0, 0.0, wl[k]), physicsClientId=c)

    def after_step(self) -> None:
        self._yaw += self._w * self.world.dt

    def load_a(self, load: np.ndarray) -> None:
        load[self.ids] += self.i_leg * np.abs(self.duty).sum(axis=1)



LegsParams.world_model = Legs
