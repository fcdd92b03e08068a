"""Runs a controller on a robot at its fixed period: the same loop on a real robot and in SITL."""

from __future__ import annotations

from swarm_logic.controller import Controller
from swarm_logic.robot import Robot


def run_controller(controller: Controller, robot: Robot, duration_s: float | None = None) -> None:
    """``init``, then ``poll devices -> step -> sleep`` every ``controller.period_s`` until ``duration_s``."""
    controller.init(robot)
    clock = robot.clock
    start = clock.now()
    t_next = start
    try:
        while duration_s is None or clock.now() - start < duration_s:
            robot.poll()
            controller.step()
            t_next += controller.period_s
            clock.sleep_until(t_next)
    finally:
        controller.destroy()
