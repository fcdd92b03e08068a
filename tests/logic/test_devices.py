"""A robot model's own devices: HAL tables opened by the opener registered under their name, reached as
``robot.device(name)``, polled and closed with the robot; a robot may have no LLC."""

from __future__ import annotations

from typing import Any

import pytest

from swarm_logic.clock import SteppedClock
from swarm_logic.devices import DEVICES
from swarm_logic.robot import Robot


class Thermometer:
    def __init__(self, cfg: dict[str, Any], robot: Robot) -> None:
        self.cfg, self.robot_id = cfg, robot.id
        self.polls = 0
        self.closed = False

    def poll(self) -> None:
        self.polls += 1

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def thermometer():
    DEVICES.register("thermometer", Thermometer)
    yield
    DEVICES.unregister("thermometer")


def test_a_robot_opens_polls_and_closes_its_own_devices(thermometer) -> None:
    robot = Robot.open(4, {"thermometer": {"port": "x"}}, SteppedClock(), seed=1)
    t = robot.device("thermometer")
    assert robot.llc is None and t.cfg == {"port": "x"} and t.robot_id == 4
    robot.poll()
    robot.poll()
    assert t.polls == 2
    robot.close()
    assert t.closed


def test_a_table_that_is_no_device_is_named(thermometer) -> None:
    with pytest.raises(ValueError, match=r"HAL config thermostat: not a device; devices: .*thermometer"):
        Robot.open(0, {"thermostat": {}}, SteppedClock(), seed=1)
    robot = Robot.open(0, {"thermometer": {}}, SteppedClock(), seed=1)
    with pytest.raises(KeyError, match="has no device 'legs'; it has: thermometer"):
        robot.device("legs")


class Station(Thermometer):
    """One link serving two faces (as a foot-bot's CAN bus serves its boards' devices)."""

    def __init__(self, cfg: dict[str, Any], robot: Robot) -> None:
        super().__init__(cfg, robot)
        self.inside, self.outside = Thermometer(cfg, robot), Thermometer(cfg, robot)

    def faces(self) -> dict[str, Any]:
        return {"inside": self.inside, "outside": self.outside}


def test_a_device_serves_its_faces_and_is_polled_once() -> None:
    DEVICES.register("station", Station)
    try:
        robot = Robot.open(1, {"station": {}}, SteppedClock(), seed=1)
        s = robot.device("station")
        assert robot.device("inside") is s.inside and robot.device("outside") is s.outside
        robot.poll()
        robot.close()
        assert s.polls == 1 and s.closed and s.inside.polls == 0 and not s.inside.closed
        with pytest.raises(ValueError, match="HAL config station: its device's face 'inside' is also"):
            Robot.open(1, {"station": {}, "inside": {}}, SteppedClock(), seed=1)
    finally:
        DEVICES.unregister("station")
