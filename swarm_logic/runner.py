"""Runs a controller on a robot at its fixed period: the same loop on a real robot and in SITL.

Without a MAVLink face (``robot.mavlink`` None) the loop is ``poll devices -> step -> sleep`` every
``controller.period_s``, nothing more. With one, ``swarm_logic.mavlink.supervisor`` runs the robot as a ground station
expects a rover to behave (arming, modes, go-to); it is imported only then, so a robot without MAVLink does not
load pymavlink.
"""

from __future__ import annotations

from swarm_logic.controller import Controller
from swarm_logic.robot import Robot


def run_controller(controller: Controller, robot: Robot, duration_s: float | None = None) -> None:
    """``init``, then ``poll devices -> step -> sleep`` every ``controller.period_s`` until ``duration_s``; with
    ``robot.mavlink``, the ``Supervisor``'s loop instead."""
    if robot.mavlink is not None:
        from swarm_logic.mavlink.supervisor import supervise

        supervise(controller, robot, duration_s)
        return
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


