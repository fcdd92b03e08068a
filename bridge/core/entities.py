"""Entity ids: one emulated component of one robot (``r003/llc``, ``r003/xbee``, ``r003/logic``), the address every
key, inbox and recording topic of a session uses."""

from __future__ import annotations

__all__ = ["entity", "robot_of", "uwb_addr16", "xbee_serial64"]


def entity(robot: int, role: str) -> str:
    """Entity id of one emulated component of one robot, e.g. ``r003/llc``."""
    return f"r{robot:03d}/{role}"


def robot_of(ent: str) -> int:
    """Robot index of an entity id (``r003/llc`` -> 3, ``r1234/logic`` -> 1234)."""
    return int(ent[1:ent.index("/")])


def xbee_serial64(robot: int) -> int:
    """The 64-bit serial number (SH:SL) of a robot's XBee: Digi's OUI block 0013A200, then a unique low word."""
    return 0x0013A200_40A00000 + robot


def uwb_addr16(robot: int) -> int:
    """A robot's UWB short address (DWM1001 modules carry a unique 16-bit id)."""
    return 0x1000 + robot
