"""Random walk with sonar obstacle avoidance; the LED strip shows the state.

Run straight for an exponentially distributed time, then tumble (turn in place by a random angle).
When the front sonar reads closer than ``avoid_m`` on two consecutive steps (one reading alone may be a
spurious echo), turn in place, in a random direction, until it reads clear. Green: running, blue:
tumbling, red: avoiding.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

from swarm_logic.controller import MAX_SPEED_MPS, MAX_TURN_RATE_RPS, Controller
from swarm_logic.robot import Robot

GREEN, BLUE, RED = (0, 255, 0), (0, 0, 255), (255, 0, 0)
STATES = ("run", "tumble", "avoid")  # telemetry: the state's number


class RandomWalk(Controller):
    defaults: ClassVar[dict[str, float]] = {
        "speed_mps": 0.15,
        "turn_rate_rps": 1.5,
        "avoid_m": 0.45,
        "clear_m": 0.7,
        "mean_run_s": 5.0,
        "period_s": 0.1,
    }
    ranges: ClassVar[dict[str, str]] = {
        "speed_mps": f"[0, {MAX_SPEED_MPS:g}]",
        "turn_rate_rps": f"(0, {MAX_TURN_RATE_RPS:g}]",
        "avoid_m": "[0, inf)",
        "clear_m": "[0, inf)",
        "mean_run_s": "(0, inf)",
        "period_s": "(0, inf)",
    }

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.p = self.with_defaults(robot.params)
        self.period_s = float(self.p["period_s"])
        self.reset()

    def reset(self) -> None:
        self.state = "run"
        self.until = self.robot.clock.now() + self._run_time()
        self.turn_dir = 1.0
        self.close_count = 0
        self.led: tuple[int, int, int] | None = None

    def _run_time(self) -> float:
        return float(self.robot.rng.exponential(self.p["mean_run_s"]))

    def step(self) -> None:
        r = self.robot
        now = r.clock.now()
        sonar = r.llc.state.sonar_m
        self.close_count = self.close_count + 1 if sonar < self.p["avoid_m"] else 0
        if self.state != "avoid" and self.close_count >= 2:
            self.state = "avoid"
            self.turn_dir = 1.0 if r.rng.random() < 0.5 else -1.0
            self.until = now + 0.5
        elif self.state == "avoid":
            if sonar > self.p["clear_m"] and now >= self.until:
                self.state = "run"
                self.until = now + self._run_time()
        elif now >= self.until:
            if self.state == "run":
                self.state = "tumble"
                angle = float(r.rng.uniform(-math.pi, math.pi))
                self.turn_dir = math.copysign(1.0, angle)
                self.until = now + abs(angle) / self.p["turn_rate_rps"]
            else:
                self.state = "run"
                self.until = now + self._run_time()
        if self.state == "run":
            r.llc.drive(self.p["speed_mps"], 0.0)
            self._show(GREEN)
        else:
            r.llc.drive(0.0, self.turn_dir * self.p["turn_rate_rps"])
            self._show(RED if self.state == "avoid" else BLUE)

    def set_param(self, name: str, value: Any) -> None:
        super().set_param(name, value)
        if name == "period_s":
            self.period_s = float(value)

    def telemetry(self) -> dict[str, float | int]:
        """``state``: 0 run, 1 tumble, 2 avoid; ``left_s``: time to the state's planned end."""
        return {"state": STATES.index(self.state), "left_s": max(0.0, self.until - self.robot.clock.now())}

    def _show(self, rgb: tuple[int, int, int]) -> None:
        if rgb != self.led:
            self.led = rgb
            self.robot.llc.set_led(*rgb)

    def destroy(self) -> None:
        self.robot.llc.stop()
