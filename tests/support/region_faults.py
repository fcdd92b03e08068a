"""Region planners and a region controller with faults at known times, for the region controller's bad-input and
failure tests: a planner that raises, one whose plan is too large for a datagram, a controller that dies."""

from __future__ import annotations

import dataclasses

from bridge.services.global_controller.regions import RegionController
from swarm_logic.families.roy.regions.converge import ConvergePlanner
from swarm_logic.families.roy.regions.planner import Observation, Plan


class FaultyPlanner(ConvergePlanner):
    """The convergence phase, keeping every observation; it raises for 1.5 <= t < 2 s and at t = 2.5 s plans a
    parameter table that no datagram holds."""

    def __init__(self, **params: object) -> None:
        super().__init__(**params)
        self.observations: list[Observation] = []

    def plan(self, obs: Observation) -> Plan:
        self.observations.append(obs)
        if 1.5 <= obs.t < 2.0:
            raise ZeroDivisionError("planner fault")
        plan = super().plan(obs)
        if obs.t == 2.5:
            return dataclasses.replace(plan, params={**plan.params, "table": [1.0] * 200})
        return plan


class DiesAtThreeSeconds(RegionController):
    """The region controller, raising at its step at 3 s or later: the service fails and broadcasts no more."""

    def step(self, t_s: float) -> None:
        if t_s >= 3.0:
            raise RuntimeError("controller fault at 3 s")
        return super().step(t_s)
