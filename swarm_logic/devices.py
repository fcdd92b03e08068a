"""The robot's devices, built from the parts of a HAL config that name them (``Robot.open`` calls these).

The low level is an LLC on a python-can bus (``llc_can``) or a vehicle that speaks only MAVLink (``llc_mavlink``);
the XBee, the UWB module and the MAVLink face each sit on a serial port (a pyserial URL or device) or, for the face,
a pymavlink connection. A driver is imported when its device is built, so a robot without an XBee or a MAVLink face
does not load their libraries. Nothing here knows the robot: the dependency runs from ``swarm_logic.robot`` to here
and on to the drivers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import can
import serial

from swarm_logic.clock import Clock
from swarm_logic.drivers.llc_client import LlcClient
from swarm_logic.plugins import Registry

if TYPE_CHECKING:
    from swarm_logic.drivers.uwb import Uwb
    from swarm_logic.drivers.xbee import XBee
    from swarm_logic.hal import LowLevel
    from swarm_logic.mavlink.face import MavlinkFace


# A robot's own devices beyond the built-in ones (a Zebro's legs on I2C, its UWB data radio): HAL table name ->
# ``open(cfg, robot)``, which returns the device (its ``poll()`` and ``close()``, when it has them, are called with
# the robot's). A device that serves several faces over one link (a foot-bot's boards on its CAN bus: the wheels,
# the proximity ring, the range-and-bearing board) lists them in ``faces()`` (name -> object), and the robot reaches
# each as ``robot.device(name)`` too; the faces' own ``poll``/``close`` are not called, the device's are. Found by
# entry point (group ``swarm_sitl.devices``) or ``DEVICES.register``.
DEVICES: Registry[Any] = Registry("swarm_sitl.devices", "device", callable)
BUILT_IN = ("llc_can", "llc_mavlink", "xbee", "uwb", "mavlink")  # the HAL tables Robot.open opens itself
NOT_DEVICES = ("start_pose", "payload", "log", "robot_id", "behaviour", "seed", "params", "clock")


def open_low_level(hal: dict[str, Any], clock: Clock) -> tuple[LowLevel | None, list[can.BusABC]]:
    """The low level the HAL config names, and the CAN buses it holds (none for a MAVLink vehicle); None for a robot
    without an LLC (a Zebro's legs are a device of their own)."""
    if hal.get("llc_mavlink") is not None:
        if hal.get("llc_can"):
            raise ValueError("HAL config llc_mavlink: the robot has one low-level controller; give llc_can or "
                             "llc_mavlink, not both")
        from swarm_logic.mavlink.low_level import open_low_level as open_mavlink_low_level

        return open_mavlink_low_level(hal["llc_mavlink"], clock), []
    if hal.get("llc_can") is None:
        return None, []
    llc_cfg = dict(hal.get("llc_can") or {})
    if "interface" not in llc_cfg:
        raise ValueError("HAL config needs llc_can.interface (a python-can interface name) or llc_mavlink")
    bus = can.Bus(**llc_cfg)
    return LlcClient(bus), [bus]


def open_xbee(cfg: dict[str, Any], clock: Clock, ports: list[serial.SerialBase]) -> XBee:
    """The XBee a HAL ``xbee`` table describes; its port goes into ``ports`` as soon as it is open."""
    from swarm_logic.drivers.xbee import XBee

    x = dict(cfg)
    port = open_port(x, "xbee", 9600)
    ports.append(port)
    return XBee(port, clock, api_mode=int(x.get("api_mode", 1)), rssi_from_db=bool(x.get("rssi_from_db", False)))


def open_uwb(cfg: dict[str, Any], clock: Clock, ports: list[serial.SerialBase]) -> Uwb:
    """The UWB module a HAL ``uwb`` table describes; its port goes into ``ports`` as soon as it is open."""
    from swarm_logic.drivers.uwb import Uwb

    u = dict(cfg)
    port = open_port(u, "uwb", 115200)
    ports.append(port)
    return Uwb(port, clock)


def open_mavlink(cfg: dict[str, Any], robot_id: int, clock: Clock) -> MavlinkFace:
    """The MAVLink face a HAL ``mavlink`` table describes (``swarm_logic.mavlink.face.open_face``)."""
    from swarm_logic.mavlink.face import open_face

    return open_face(cfg, robot_id, clock)


def open_devices(hal: dict[str, Any], robot: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """The robot's own devices its HAL config names (``DEVICES``), in the config's order, and the faces they serve
    (``faces()``); a table that is neither a built-in device, a robot setting nor a registered device is a ValueError
    naming what there is."""
    out: dict[str, Any] = {}
    served: dict[str, Any] = {}
    for name, cfg in hal.items():
        if name in BUILT_IN or name in NOT_DEVICES:
            continue
        if not isinstance(cfg, dict):
            raise ValueError(f"HAL config {name}: a table of the device's settings expected, got {cfg!r}")
        try:
            opener = DEVICES.get(name)
        except LookupError:
            raise ValueError(f"HAL config {name}: not a device; devices: "
                             f"{', '.join([*BUILT_IN, *DEVICES.names()])}") from None
        dev = out[name] = opener(cfg, robot)
        faces = getattr(dev, "faces", None)
        for face, obj in (faces() if callable(faces) else {}).items():
            if face in out or face in served or face in hal:
                raise ValueError(f"HAL config {name}: its device's face {face!r} is also another device's name")
            served[face] = obj
    return out, served


def open_port(cfg: dict[str, Any], what: str, default_baud: int) -> serial.SerialBase:
    """The serial port of a HAL table (``port``, ``baudrate``), non-blocking; ``what`` names the table."""
    url = cfg.get("port")
    if not url:
        raise ValueError(f"HAL config {what}.port: a serial device or URL is needed (e.g. /dev/ttyUSB0, sitl://{what})")
    return serial.serial_for_url(str(url), baudrate=int(cfg.get("baudrate", default_baud)), timeout=0)
