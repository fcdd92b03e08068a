"""Behaviours for the DeciZebro leg-bus session tests: walk through the locomotion layer, or walk and then freeze."""

from __future__ import annotations

from typing import Any, ClassVar

from swarm_logic.controller import Controller


class Walker(Controller):
    """Walks forward, turning at ``turn`` rad/s (``fast`` for the leader's speed), and logs the legs' counters."""

    defaults: ClassVar[dict[str, Any]] = {"turn": 0.0, "fast": False}

    def init(self, robot: Any) -> None:
        super().init(robot)
        p = self.with_defaults(robot.params)
        self.turn, self.fast = float(p["turn"]), bool(p["fast"])

    def step(self) -> None:
        legs = self.robot.device("legs")
        legs.walk(self.turn, fast=self.fast)
        self.robot.log("legs", t=self.robot.clock.now(), speed_mps=legs.speed_mps, **legs.counters)


class FreezesAtThree(Walker):
    """Walks, then at 3 s its program stops (blocked for good, as a hung program on the Pi would be): nothing writes
    the sync any more."""

    def step(self) -> None:
        if self.robot.clock.now() >= 3.0:
            self.robot.log("frozen", t=self.robot.clock.now())
            self.robot.clock.sleep(1e6)
        super().step()
