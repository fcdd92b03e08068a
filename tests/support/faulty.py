"""Controllers that misbehave on purpose, for the session fault tests."""

from __future__ import annotations

from swarm_logic.families.demo.random_walk import RandomWalk


class RaisesAtOneSecond(RandomWalk):
    def step(self) -> None:
        if self.robot.id == 1 and self.robot.clock.now() >= 1.0:
            raise RuntimeError("controller bug on purpose")
        super().step()


class HangsAtOneSecond(RandomWalk):
    def step(self) -> None:
        if self.robot.id == 1 and self.robot.clock.now() >= 1.0:
            while True:  # never yields: the world must declare it hung, not wait forever
                pass
        super().step()

