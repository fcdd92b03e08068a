"""A global controller that raises at its step at 1 s or later: a service's failure in a session."""

from __future__ import annotations

from bridge.services.global_controller import MissionController
from swarm_logic.robots.sonpi import pose_packet as pp


class FailsAtOneSecond(MissionController):
    def step(self, t_s: float) -> pp.Mission:
        if t_s >= 1.0:
            raise RuntimeError("controller fault at 1 s")
        return super().step(t_s)
