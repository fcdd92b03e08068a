"""A SonPI wanders and keeps clear of what its sonars see: the simplest program that exercises its sonar board and its
drive through the robot's own faces (``sonpi_sonar``, ``sonpi_velocity``, ``sonpi_odometry``).

It heads in a world-frame direction that drifts at random (``turn_sd_rps``, a random walk of the heading), and each
sonar closer than ``avoid_m`` pushes that direction away from it in proportion to how close it is; the holonomic
velocity goes to the robot's tracking layer. Each step it logs the five readings it acted on (``sonar``).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from swarm_logic.controller import Controller
from swarm_logic.robot import Robot
from swarm_logic.robots.sonpi.interfaces import ODOMETRY, POSE, SONAR, VELOCITY


class SonarWander(Controller):
    defaults: ClassVar[dict[str, Any]] = {"speed_mps": 0.15, "avoid_m": 0.5, "turn_sd_rps": 0.3, "period_s": 0.25}
    ranges: ClassVar[dict[str, str]] = {
        "speed_mps": "[0, 1]",
        "avoid_m": "[0, 4]",
        "turn_sd_rps": "[0, 10]",
        "period_s": "(0, 10]",
    }

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.p = self.with_defaults(robot.params)
        self.period_s = float(self.p["period_s"])
        self.sonar = robot.device(SONAR)
        self.velocity = robot.device(VELOCITY)
        try:  # the heading: the robot's pose estimate if it has one, else its odometry
            self.heading_source = robot.device(POSE)
        except KeyError:
            self.heading_source = robot.device(ODOMETRY)
        self.reset()

    def reset(self) -> None:
        self.direction = float(self.robot.rng.uniform(-math.pi, math.pi))

    def step(self) -> None:
        p, r = self.p, self.robot
        yaw = self.heading_source.read().yaw_rad
        self.direction += float(r.rng.normal(0.0, p["turn_sd_rps"] * math.sqrt(self.period_s)))
        ux, uy = math.cos(self.direction), math.sin(self.direction)
        readings = self.sonar.readings()
        avoid = float(p["avoid_m"])
        for s in readings:
            if s.range_m < avoid:
                a = yaw + s.angle_rad
                push = 2.0 * (avoid - s.range_m) / avoid
                ux -= push * math.cos(a)
                uy -= push * math.sin(a)
        norm = math.hypot(ux, uy)
        if norm > 1e-9:
            self.direction = math.atan2(uy, ux)
            speed = float(p["speed_mps"]) * min(1.0, norm)
            self.velocity.set_velocity(speed * ux / norm, speed * uy / norm)
        else:
            self.velocity.set_velocity(0.0, 0.0)
        r.log("sonar", t=r.clock.now(), ranges_m=[s.range_m if math.isfinite(s.range_m) else None for s in readings])
