"""What the searcher and the target share: the foot-bot's devices, turning a motion vector into wheel speeds,
obstacle avoidance from the proximity ring, the vector to the light and "in base" from the ground sensors, all as
ARGoS's foot-bot examples (foraging, flocking) do them (digest 2.7, 2.9)."""

from __future__ import annotations

import math
from typing import Any, ClassVar

from swarm_logic.controller import Controller
from swarm_logic.robot import Robot
from swarm_logic.robots.footbot.interfaces import (
    LEDS,
    LIGHT,
    MOTOR_GROUND,
    PROXIMITY,
    RANGE_AND_BEARING,
    WHEELS,
    DifferentialSteering,
    Leds,
    Light,
    MotorGround,
    Proximity,
    RangeAndBearing,
)

ANGLE = "[0, 180]"
NO_TURN, SOFT_TURN, HARD_TURN = 0, 1, 2


class FootbotController(Controller):
    """The common part of ``PfsmSearcher`` and ``PfsmTarget`` (abstract: ``step`` is theirs)."""

    period_s = 0.1
    defaults: ClassVar[dict[str, Any]] = {
        "period_s": 0.1,  # 10 control steps per second: the ARGoS examples' tick (digest 2.9)
        "max_speed_mps": 0.1,  # ARGoS flocking and foraging examples' max_speed 10 cm/s (digest 2.9)
        "no_turn_deg": 10.0,  # heading-error thresholds of the ARGoS examples' wheel turning (digest 2.7)
        "soft_turn_deg": 70.0,
        "hard_turn_deg": 90.0,
        "avoid_angle_deg": 5.0,  # ARGoS foraging go_straight_angle_range +-5 deg
        "avoid_delta": 0.1,  # ARGoS foraging diffusion delta: the proximity vector's length that means "obstacle"
        "base_grey_min": 0.25,  # the base is a grey patch: ARGoS foraging's nest test, 0.25 < value < 0.75
        "base_grey_max": 0.75,
    }
    ranges: ClassVar[dict[str, str]] = {
        "period_s": "(0, 10]", "max_speed_mps": "(0, 2]", "no_turn_deg": ANGLE, "soft_turn_deg": ANGLE,
        "hard_turn_deg": ANGLE, "avoid_angle_deg": ANGLE, "avoid_delta": "[0, 1]", "base_grey_min": "[0, 1]",
        "base_grey_max": "[0, 1]",
    }
    static_params = frozenset({"period_s"})

    rab: RangeAndBearing
    proximity: Proximity
    light: Light
    ground: MotorGround
    wheels: DifferentialSteering
    leds: Leds

    @classmethod
    def resolve(cls, params: dict[str, Any]) -> dict[str, Any]:
        """``defaults`` overlaid with ``params`` (each option one of its ``choices``), the turning thresholds in
        order (ValueError otherwise)."""
        p = cls.with_defaults(params)
        if not p["no_turn_deg"] <= p["soft_turn_deg"] <= p["hard_turn_deg"]:
            raise ValueError("turning thresholds: expected no_turn_deg <= soft_turn_deg <= hard_turn_deg")
        return p

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.p = self.resolve(robot.params)
        self.period_s = float(self.p["period_s"])
        self.rab = robot.device(RANGE_AND_BEARING)
        self.proximity = robot.device(PROXIMITY)
        self.light = robot.device(LIGHT)
        self.ground = robot.device(MOTOR_GROUND)
        self.wheels = robot.device(WHEELS)
        self.leds = robot.device(LEDS)
        self.turning = NO_TURN
        self.reset()

    def set_wheels_from_vector(self, vx: float, vy: float) -> None:
        """ARGoS's SetWheelSpeedsFromVector: the base speed is min(|v|, max); no turn within ``no_turn_deg``, a soft
        turn (inner wheel slowed in proportion to the error) up to ``hard_turn_deg``, on the spot beyond, with
        hysteresis (a hard turn softens only within ``soft_turn_deg``). (vx, vy) in the robot's frame, x ahead."""
        p = self.p
        vmax = float(p["max_speed_mps"])
        base = min(math.hypot(vx, vy), vmax)
        angle = math.degrees(math.atan2(vy, vx)) if base > 0 else 0.0
        a = abs(angle)
        if self.turning == HARD_TURN:
            if a <= p["soft_turn_deg"]:
                self.turning = SOFT_TURN
        elif self.turning == SOFT_TURN:
            if a > p["hard_turn_deg"]:
                self.turning = HARD_TURN
            elif a <= p["no_turn_deg"]:
                self.turning = NO_TURN
        elif a > p["hard_turn_deg"]:
            self.turning = HARD_TURN
        elif a > p["soft_turn_deg"]:
            self.turning = SOFT_TURN
        if self.turning == NO_TURN:
            s1 = s2 = base
        elif self.turning == SOFT_TURN:
            factor = (p["hard_turn_deg"] - a) / p["hard_turn_deg"] if p["hard_turn_deg"] > 0 else 0.0
            s1, s2 = base - base * (1.0 - factor), base + base * (1.0 - factor)
        else:
            s1, s2 = -vmax, vmax
        if angle > 0:
            self.wheels.set_speeds(s1, s2)
        else:
            self.wheels.set_speeds(s2, s1)

    def avoidance(self) -> tuple[float, float] | None:
        """ARGoS foraging's diffusion: the mean proximity vector; None (the way is clear) when it points within
        +-``avoid_angle_deg`` and is shorter than ``avoid_delta``, else max speed away from it."""
        readings = self.proximity.readings()
        sx = sy = 0.0
        for r in readings:
            if r.value > 0.0:
                sx += r.value * math.cos(r.angle_rad)
                sy += r.value * math.sin(r.angle_rad)
        if not readings or (sx == 0.0 and sy == 0.0):
            return None
        sx, sy = sx / len(readings), sy / len(readings)
        length = math.hypot(sx, sy)
        if abs(math.degrees(math.atan2(sy, sx))) <= self.p["avoid_angle_deg"] and length < self.p["avoid_delta"]:
            return None
        v = float(self.p["max_speed_mps"])
        return -v * sx / length, -v * sy / length

    def to_light(self) -> tuple[float, float]:
        """A unit vector towards the light (ARGoS foraging: the sum of the light readings' vectors); (0, 0) in the
        dark."""
        sx = sy = 0.0
        for r in self.light.readings():
            sx += r.value * math.cos(r.angle_rad)
            sy += r.value * math.sin(r.angle_rad)
        n = math.hypot(sx, sy)
        return (sx / n, sy / n) if n > 0 else (0.0, 0.0)

    def in_base(self) -> bool:
        """ARGoS foraging's nest test: motor-ground sensors 2 and 3 both read grey."""
        g = self.ground.readings()
        lo, hi = self.p["base_grey_min"], self.p["base_grey_max"]
        return all(lo < g[k].value < hi for k in (2, 3))

    def destroy(self) -> None:
        """Stop the wheels."""
        wheels = getattr(self, "wheels", None)
        if wheels is not None:
            wheels.set_speeds(0.0, 0.0)
