"""A tiny Zebro behaviour for the utility sensor's session test: each step it logs what its utility sensor reads,
the direction of it, and what it has eaten."""

from __future__ import annotations

from typing import Any, ClassVar

from swarm_logic.controller import Controller


class Taster(Controller):
    """Reads ``robot.device("utility")`` and logs ``taste`` records."""

    defaults: ClassVar[dict[str, Any]] = {"period_s": 0.2}
    ranges: ClassVar[dict[str, str]] = {"period_s": "(0, 10]"}

    def init(self, robot: Any) -> None:
        super().init(robot)
        self.period_s = self.with_defaults(robot.params)["period_s"]
        self.sensor = robot.device("utility")

    def step(self) -> None:
        b = self.sensor.bearing()
        self.robot.log("taste", t=self.robot.clock.now(), utility=self.sensor.read(),
                       bearing=None if b is None else round(b, 3), ate=self.sensor.consumed())
