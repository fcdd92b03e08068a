"""Foot-bot devices set by hand, for one controller at a time: what the range-and-bearing board hears, where the
light is, whether the floor is grey."""

from __future__ import annotations

import numpy as np

from swarm_logic.clock import SteppedClock
from swarm_logic.controller import Controller
from swarm_logic.robot import Robot
from swarm_logic.robots.footbot.interfaces import (
    LEDS,
    LIGHT,
    MOTOR_GROUND,
    MOTOR_GROUND_OFFSETS_M,
    PROXIMITY,
    RANGE_AND_BEARING,
    WHEELS,
    GroundReading,
    RabPacket,
    RingReading,
    check_payload,
    ring_angles,
)


class Devices:
    def __init__(self) -> None:
        self.heard: list[RabPacket] = []
        self.sent: list[bytes] = []
        self.speeds = (0.0, 0.0)
        self.grey = False
        self.light_bearing = 0.0
        self.max_payload = 10
        self.range_m = 3.0
        self.max_speed_mps = 0.3

    # RangeAndBearing
    def readings(self) -> list[RabPacket]:
        return list(self.heard)

    def send(self, data: bytes) -> None:
        self.sent.append(check_payload(data, self.max_payload))

    # DifferentialSteering, Leds
    def set_speeds(self, left_mps: float, right_mps: float) -> None:
        self.speeds = (left_mps, right_mps)

    def set_all_colors(self, rgb: tuple[int, int, int]) -> None:
        pass


class Ring:
    def __init__(self, values: list[float] | None = None) -> None:
        self.values = values or [0.0] * 24

    def readings(self) -> list[RingReading]:
        return [RingReading(v, a) for v, a in zip(self.values, ring_angles(len(self.values)), strict=True)]


class Ground:
    def __init__(self, dev: Devices) -> None:
        self.dev = dev

    def readings(self) -> list[GroundReading]:
        return [GroundReading(0.5 if self.dev.grey else 1.0, o) for o in MOTOR_GROUND_OFFSETS_M]


def started(cls: type[Controller], params: dict[str, object] | None = None, seed: int = 1,
            robot_id: int = 0) -> tuple[Controller, Devices, SteppedClock]:
    dev = Devices()
    clock = SteppedClock()
    devices = {RANGE_AND_BEARING: dev, PROXIMITY: Ring(), LIGHT: Ring([1.0] + [0.0] * 23), MOTOR_GROUND: Ground(dev),
               WHEELS: dev, LEDS: dev}
    robot = Robot(robot_id, clock, None, np.random.Generator(np.random.PCG64(seed)), dict(params or {}),
                  devices=devices)
    c = cls()
    c.init(robot)
    return c, dev, clock


def tick(c: Controller, clock: SteppedClock) -> None:
    clock.t += c.period_s
    c.step()
