"""The Zebro's utility sensor on its Raspberry Pi: the ``UtilitySensor`` device (``interfaces``) over the sensor
board's serial line (``utility_protocol``), ``sitl://utility`` in a session, a serial device on the robot.

HAL table ``utility``: ``{"port": "sitl://utility", "baudrate": 115200}``. ``read()`` and ``bearing()`` give the
latest report; ``consumed()`` the utilities eaten since the previous call, from the board's cumulative counter, so a
lost report loses no meal. Malformed frames are counted (``bad_frames``) and dropped.
"""

from __future__ import annotations

import math
from typing import Any

import serial

from swarm_logic.robots.decizebro import utility_protocol as P


class UtilityBoardDriver:
    def __init__(self, port: serial.SerialBase, clock: Any) -> None:
        self.port = port
        self.clock = clock
        self.parser = P.Parser()
        self.utility = 0
        self._bearing: float | None = None
        self._eaten_sum: int | None = None  # the board's cumulative sum at the last report
        self._taken_sum = 0  # ... as of the last consumed() call (the board counts from its power-up, as we do)
        self.reports = 0
        self.bad_frames = 0

    def poll(self) -> None:
        """Read the reports that arrived."""
        data = self.port.read(self.port.in_waiting or 0) if self.port.in_waiting else b""
        t_ns = round(self.clock.now() * 1e9)
        for item in self.parser.feed(t_ns, data):
            if isinstance(item, P.Bad):
                self.bad_frames += 1
                continue
            typ, body = item
            if typ != P.REPORT or len(body) != P.REPORT_BODY.size:
                self.bad_frames += 1
                continue
            utility, bearing, _eaten, eaten_sum = P.REPORT_BODY.unpack(body)
            self.utility = utility
            self._bearing = None if bearing == P.NO_BEARING else math.radians(bearing / 100)
            self._eaten_sum = eaten_sum
            self.reports += 1

    def read(self) -> int:
        self.poll()
        return self.utility

    def bearing(self) -> float | None:
        self.poll()
        return self._bearing

    def consumed(self) -> int:
        self.poll()
        if self._eaten_sum is None:
            return 0
        out = self._eaten_sum - self._taken_sum
        self._taken_sum = self._eaten_sum
        return out

    def close(self) -> None:
        self.port.close()


def open_utility(cfg: dict[str, Any], robot: Any) -> UtilityBoardDriver:
    """The ``utility`` HAL table's device: the board on its serial port (``port``, ``baudrate``)."""
    from swarm_logic.devices import open_port

    port = open_port(dict(cfg), "utility", P.BAUD)
    robot.ports.append(port)
    return UtilityBoardDriver(port, robot.clock)
