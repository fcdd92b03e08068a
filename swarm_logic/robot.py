"""A robot as the swarm logic sees it: its devices, its clock, its parameters and its random stream.

``Robot.open`` builds the devices from a HAL config, the only thing that differs between SITL and a
real robot, e.g. ``{"llc_can": {"interface": "sitl", "channel": "can0"}}`` in a session, or
``{"llc_can": {"interface": "socketcan", "channel": "can0"}}`` on the robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import can
import numpy as np

from swarm_logic.clock import Clock
from swarm_logic.llc_client import LlcClient


@dataclass
class Robot:
    id: int
    clock: Clock
    llc: LlcClient
    rng: np.random.Generator
    params: dict[str, Any] = field(default_factory=dict)
    buses: list[can.BusABC] = field(default_factory=list)

    @classmethod
    def open(cls, robot_id: int, hal: dict[str, Any], clock: Clock, seed: int,
             params: dict[str, Any] | None = None) -> Robot:
        llc_cfg = dict(hal.get("llc_can") or {})
        if "interface" not in llc_cfg:
            raise ValueError("HAL config needs llc_can.interface (a python-can interface name)")
        bus = can.Bus(**llc_cfg)
        rng = np.random.Generator(np.random.PCG64(seed))
        return cls(robot_id, clock, LlcClient(bus), rng, dict(params or {}), [bus])

    def poll(self) -> None:
        """Drain every device's receive queue (non-blocking)."""
        self.llc.poll()

    def close(self) -> None:
        for b in self.buses:
            b.shutdown()
