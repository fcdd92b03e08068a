"""A robot as the swarm logic sees it: its devices, its clock, its parameters and its random stream.

``Robot.open`` builds the devices from a HAL config, the only thing that differs between SITL and a
real robot, e.g. in a session::

    {"llc_can": {"interface": "sitl", "channel": "can0"},
     "xbee": {"port": "sitl://xbee", "baudrate": 9600}, "uwb": {"port": "sitl://uwb", "baudrate": 115200}}

and on the robot ``{"llc_can": {"interface": "socketcan", "channel": "can0"}, "xbee": {"port": "/dev/ttyUSB0"},
"log": {"path": "robot.jsonl"}, "start_pose": [1.2, 0.4, 0.0]}``. A robot model's own devices (a Zebro's legs on
I2C and its UWB data radio) are HAL tables too, opened by the opener registered under the table's name
(``swarm_logic.devices.DEVICES``, entry-point group ``swarm_sitl.devices``) and reached as ``robot.device(name)``;
such a robot may have no LLC (``llc`` None). The XBee and UWB modules are optional: a robot
without them has ``xbee`` / ``uwb`` set to None. ``start_pose`` (x, y, yaw in the arena frame) is where the robot
was put down, as the operator or the deploying robot tells it; a session fills it in from the placement.

``mavlink`` (optional) gives the robot its MAVLink face (``swarm_logic.mavlink.face``; ``robot.mavlink``, else None):
``{"port": "sitl://mavlink"}`` (any pyserial URL or device, ``baudrate``) or ``{"url": "udpout:127.0.0.1:14550"}``
(a pymavlink connection), with ``system_id`` (default robot id + 1), ``boot`` ("auto", "hold" or "disarmed") and
``rates`` (message name -> Hz). ``llc_mavlink`` instead of ``llc_can`` drives a vehicle that speaks only MAVLink
(``swarm_logic.mavlink.low_level``): ``{"url": "udpin:0.0.0.0:14551", "target_system": 1}``.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import can
import numpy as np
import serial

from swarm_logic import devices
from swarm_logic.clock import Clock
from swarm_logic.log import JsonlLog, Sink

if TYPE_CHECKING:
    from swarm_logic.drivers.uwb import Uwb
    from swarm_logic.drivers.xbee import XBee
    from swarm_logic.hal import LowLevel, Radio
    from swarm_logic.mavlink.face import MavlinkFace


@dataclass
class Robot:
    id: int
    clock: Clock
    llc: LowLevel | None  # None for a robot without an LLC (its locomotion is one of its ``devices``)
    rng: np.random.Generator
    params: dict[str, Any] = field(default_factory=dict)
    buses: list[can.BusABC] = field(default_factory=list)
    xbee: XBee | Radio | None = None
    uwb: Uwb | None = None
    ports: list[serial.SerialBase] = field(default_factory=list)
    log_sink: Sink | None = None
    start_pose: tuple[float, float, float] | None = None
    mavlink: MavlinkFace | None = None
    payload: tuple[int, ...] = ()  # a carrier (TraxBot): the robots on its conveyor, in the order they drop off
    devices: dict[str, Any] = field(default_factory=dict)  # its own devices by HAL table name (swarm_logic.devices)
    faces: dict[str, Any] = field(default_factory=dict)  # what those devices serve besides themselves, by name
    rng_py: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        # the same stream for scalar draws in hot loops (random.Random is ~10x faster per number than numpy)
        self.rng_py = random.Random(int(self.rng.integers(1 << 62)))

    @classmethod
    def open(cls, robot_id: int, hal: dict[str, Any], clock: Clock, seed: int,
             params: dict[str, Any] | None = None, log_sink: Sink | None = None) -> Robot:
        """The robot a HAL config describes, its devices open (``swarm_logic.devices`` builds them)."""
        llc, buses = devices.open_low_level(hal, clock)
        rng = np.random.Generator(np.random.PCG64(seed))
        robot = cls(robot_id, clock, llc, rng, dict(params or {}), buses)
        if hal.get("start_pose") is not None:
            pose = tuple(float(v) for v in hal["start_pose"])
            if len(pose) != 3:
                raise ValueError(f"HAL config start_pose: [x, y, yaw] expected, got {hal['start_pose']!r}")
            robot.start_pose = pose  # type: ignore[assignment]
        if hal.get("payload"):
            robot.payload = tuple(int(v) for v in hal["payload"])
        try:
            if hal.get("xbee"):
                robot.xbee = devices.open_xbee(hal["xbee"], clock, robot.ports)
            if hal.get("uwb"):
                robot.uwb = devices.open_uwb(hal["uwb"], clock, robot.ports)
            if hal.get("mavlink") is not None:
                robot.mavlink = devices.open_mavlink(hal["mavlink"], robot_id, clock)
            robot.devices, robot.faces = devices.open_devices(hal, robot)
            if log_sink is None and (hal.get("log") or {}).get("path"):
                log_sink = JsonlLog(hal["log"]["path"], clock)
            robot.log_sink = log_sink
        except BaseException:
            robot.close()
            raise
        return robot

    def log(self, topic: str, **values: Any) -> None:
        """Record ``values`` under ``topic`` (a recording topic in SITL, a JSONL line on a robot)."""
        if self.log_sink is not None:
            self.log_sink(topic, values)

    def device(self, name: str) -> Any:
        """Its device called ``name`` (the HAL table that opened it, or a face one serves); KeyError naming the
        devices it has."""
        dev = self.devices.get(name, self.faces.get(name))
        if dev is None:
            raise KeyError(f"robot {self.id} has no device {name!r}; it has: "
                           f"{', '.join([*self.devices, *self.faces]) or 'none of its own'}")
        return dev

    def poll(self) -> None:
        """Drain every device's receive queue (non-blocking)."""
        if self.llc is not None:
            self.llc.poll()
        if self.xbee is not None:
            self.xbee.poll()
        for d in self.devices.values():
            poll = getattr(d, "poll", None)
            if poll is not None:
                poll()

    def close(self) -> None:
        for d in reversed(self.devices.values()):
            close = getattr(d, "close", None)
            if close is not None:
                close()
        if self.mavlink is not None:
            self.mavlink.close()
        close_llc = getattr(self.llc, "close", None)  # a MAVLink low level holds a connection
        if close_llc is not None:
            close_llc()
        for b in self.buses:
            b.shutdown()
        for p in self.ports:
            p.close()
        if isinstance(self.log_sink, JsonlLog):
            self.log_sink.close()

