"""A ranger's program for tests: drive slowly forward, and unload scouts from the conveyor on a schedule."""

from __future__ import annotations

import math
from typing import Any, ClassVar

from swarm_logic.controller import Controller


class Unloader(Controller):
    """Drives forward at ``speed_mps``; at ``first_s`` asks the conveyor for ``first`` slots, at ``second_s`` for
    ``second`` more; logs the conveyor and the side sonars every second."""

    period_s = 0.1
    defaults: ClassVar[dict[str, Any]] = {"speed_mps": 0.05, "first_s": 1.0, "first": 2, "second_s": 8.0,
                                          "second": 3}

    def init(self, robot) -> None:
        super().init(robot)
        self.p = {**self.defaults, **robot.params}
        self.asked: list[int] = []
        self.next_log = 0.0

    def step(self) -> None:
        r, now = self.robot, self.robot.clock.now()
        r.llc.drive(self.p["speed_mps"], 0.0)
        for i, (at, n) in enumerate(((self.p["first_s"], self.p["first"]), (self.p["second_s"], self.p["second"]))):
            if now >= at and i not in self.asked:
                self.asked.append(i)
                r.llc.release(int(n))
        if now >= self.next_log:
            self.next_log += 1.0
            st = r.llc.state
            r.log("ranger", position=st.conveyor_position, pending=st.conveyor_pending, moving=st.conveyor_moving,
                  front=_m(st.sonar_m), left=_m(st.sonar_left_m), right=_m(st.sonar_right_m))


def _m(v: float) -> float | None:
    return None if math.isinf(v) else round(v, 3)
