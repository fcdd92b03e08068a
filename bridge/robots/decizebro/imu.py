"""The Zebro's IMU heading in the world: what a 9-axis IMU's magnetometer-based fusion (a Bosch BNO055) reads as the
robot's absolute heading, sampled at its fusion rate, for every robot that carries one.

heading = true yaw + a constant bias per robot + white noise per sample. The bias stands for what calibration leaves
of hard- and soft-iron errors and the local declination; the thesis notes the Zebro's motors and nearby magnetic
objects disturb magnetic sensing (Agrawal 2019, App. B.2), which is why the bias can be set large. Figures: the
BMM150 magnetometer of the BNO055 states a heading accuracy of 2.5 degrees (Bosch BMM150 datasheet); we split it into a
bias of 2 degrees (1 sigma, seeded per robot) and a noise of 1 degree per sample (assumption). The faithful mode
(the robot option ``sensing = "faithful"``) sets both to zero: the true heading, as the thesis assumes (section 3.1).

Its accelerometer (the BNO055's BMA280-class part, axes x forward, y left, z up on the Zebro) reads the body's
acceleration in its own frame, the reaction to gravity included (+9.81 m/s^2 up at rest), from the body's velocity
change over each sample period (pybullet's base velocity and orientation), plus a zero-g offset per axis (seeded,
0.05 m/s^2 1 sigma: what calibration leaves of the datasheet's +-80 mg) and white noise (0.012 m/s^2 1 sigma: the
datasheet's 150 ug/sqrt(Hz) over its 62.5 Hz bandwidth); the faithful mode reads it without either. The gravity
vector in the body frame is what the fusion outputs as gravity (GRV), the rest as linear acceleration (LIA).

The readings reach the robot's computer through the IMU's own firmware entity and serial line
(``firmware_sim.robots.decizebro.imu``, ``sitl://imu``); ``ImuWiring`` is what that entity's pins meet here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pybullet as pb

from bridge.core.parts import Part, WorldModel
from bridge.core.recorder import register_schema
from bridge.core.rng import stream


class ImuParams(Part):
    rate_hz: float = 100.0  # BNO055 fusion output rate (datasheet: 100 Hz in the fusion modes)
    heading_bias_deg: float = 2.0
    heading_noise_deg: float = 1.0
    accel_bias_mps2: float = 0.05  # per axis, 1 sigma, seeded per robot
    accel_noise_mps2: float = 0.012  # per axis and sample, 1 sigma


GRAVITY = 9.81


class Imu(WorldModel):
    """Heading samples for every robot with an IMU, at each part's rate (one draw per robot per sample)."""

    name = "imu"

    def __init__(self, world: Any, robots: list[int], parts: list[ImuParams]) -> None:
        super().__init__(world, robots, parts)
        self._rng = [stream(world.seed, "robot", r, "imu") for r in robots]
        self.bias = np.array([math.radians(p.heading_bias_deg) * float(g.standard_normal())
                              for p, g in zip(parts, self._rng, strict=True)])
        self.noise = np.array([math.radians(p.heading_noise_deg) for p in parts])
        self.period_ns = [max(1, round(1e9 / p.rate_hz)) for p in parts]
        self.next_ns = [0] * len(robots)
        self.heading = np.array([float(world.yaw[r]) for r in robots]) + self.bias
        self.alive = [True] * len(robots)
        # the accelerometer's draws come from a stream of their own: the heading's are as without it
        self._acc_rng = [stream(world.seed, "robot", r, "imu", "accel") for r in robots]
        self.acc_bias = [p.accel_bias_mps2 * g.standard_normal(3) for p, g in zip(parts, self._acc_rng, strict=True)]
        self.acc_noise = [p.accel_noise_mps2 for p in parts]
        self.accel = [np.array([0.0, 0.0, GRAVITY]) for _ in robots]  # body frame, reaction to gravity included
        self.gravity = [np.array([0.0, 0.0, GRAVITY]) for _ in robots]
        self._vel: list[np.ndarray | None] = [None] * len(robots)
        self._t_ns = [0] * len(robots)

    def sample(self, t_end_ns: int) -> None:
        yaw = self.world.yaw
        for k, r in enumerate(self.robots):
            if not self.alive[k] or t_end_ns < self.next_ns[k]:
                continue
            while self.next_ns[k] <= t_end_ns:
                self.next_ns[k] += self.period_ns[k]
            z = float(self._rng[k].standard_normal())
            self.heading[k] = math.remainder(float(yaw[r]) + self.bias[k] + self.noise[k] * z, math.tau)
            self._accelerometer(k, r, t_end_ns)

    def _accelerometer(self, k: int, r: int, t_ns: int) -> None:
        """The body-frame specific force since the last sample: (dv/dt + g up) rotated into the body, with errors."""
        w = self.world
        v = np.array(pb.getBaseVelocity(w.bodies[r], physicsClientId=w.cid)[0])
        q = pb.getBasePositionAndOrientation(w.bodies[r], physicsClientId=w.cid)[1]
        rot = np.array(pb.getMatrixFromQuaternion(q)).reshape(3, 3)  # body to world
        prev, dt = self._vel[k], (t_ns - self._t_ns[k]) / 1e9
        a_world = (v - prev) / dt if prev is not None and dt > 0 else np.zeros(3)
        self._vel[k], self._t_ns[k] = v, t_ns
        up = rot.T @ np.array([0.0, 0.0, GRAVITY])
        noise = self.acc_noise[k] * self._acc_rng[k].standard_normal(3)
        self.gravity[k] = up
        self.accel[k] = rot.T @ a_world + up + self.acc_bias[k] + noise

    def sense(self, r: int) -> dict[str, Any]:
        k = self.local[r]
        return {"heading_rad": float(self.heading[k]), "accel_mps2": [round(float(a), 4) for a in self.accel[k]],
                "gravity_mps2": [round(float(g), 4) for g in self.gravity[k]]}

    def kill(self, r: int) -> None:
        self.alive[self.local[r]] = False


ImuParams.world_model = Imu

register_schema("swarm_sitl.ImuPins", {"type": "object", "properties": {
    "heading_rad": {"type": "number", "description": "the fused heading the IMU holds (rad, counter-clockwise from "
                                                     "east), true yaw plus its errors"},
    "accel_mps2": {"type": "array", "description": "the accelerometer: body-frame specific force (x forward, y left, "
                                                   "z up; +9.81 up at rest), with its errors"},
    "gravity_mps2": {"type": "array", "description": "gravity in the body frame (the fusion's GRV)"}}})


class ImuWiring:
    """What the IMU's firmware entity reads in the world: the heading its fusion holds now; it drives nothing."""

    schema = "swarm_sitl.ImuPins"

    def sense(self, world: Any, r: int, media: dict[str, Any], ideal_pose: bool) -> tuple[dict, dict]:
        model = world.model("imu")
        reading = model.sense(r) if model is not None and r in model.local else {
            "heading_rad": float(world.yaw[r]), "accel_mps2": [0.0, 0.0, GRAVITY], "gravity_mps2": [0.0, 0.0, GRAVITY]}
        return reading, dict(reading)

    def valid(self, pins: Any) -> bool:
        return pins is None or isinstance(pins, dict)

    def actuate(self, world: Any, r: int, pins: dict[str, Any]) -> None:
        pass
