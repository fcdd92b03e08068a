"""What a DeciZebro leg module's pins meet in the world: its leg's angle sensor and speed, the battery at its ADC, and
its motor's H-bridge (signed duty), as the legs' world model (``legs.py`` or ``contact_legs.py``) has them. The hub
asks the robot's plugin (``RobotSpec.wiring``) for each leg module's wiring, senses and actuates through it and
records its pins on ``/rNNN/legN/pins``."""

from __future__ import annotations

import math
from functools import cache
from typing import Any

from bridge.core.recorder import register_schema

SCHEMA = "swarm_sitl.LegPins"
register_schema(SCHEMA, {
    "type": "object",
    "description": "One control loop of a DeciZebro leg module: its leg's angle (rad, 0 = pointing down, growing as "
                   "it walks forward) and speed, the battery voltage, and the motor duty it wrote (acts from the "
                   "next quantum)",
    "properties": {"angle": {"type": "number"}, "omega": {"type": "number"}, "battery_v": {"type": "number"},
                   "duty": {"type": "number", "minimum": -1, "maximum": 1}},
})


class LegWiring:
    """Leg ``leg``'s module: its sensor and its motor."""

    schema = SCHEMA

    def __init__(self, leg: int) -> None:
        self.leg = leg

    def sense(self, world: Any, r: int, media: dict[str, Any], ideal_pose: bool) -> tuple[dict, dict]:
        legs = legs_of(world, r)
        reading = {"angle": legs.angle(r, self.leg), "omega": legs.omega(r, self.leg),
                   "battery_v": float(world.battery_v[r])}
        return reading, reading

    def valid(self, pins: Any) -> bool:
        """A signed duty in [-1, 1], nothing else."""
        if not isinstance(pins, dict) or set(pins) != {"duty"}:
            return False
        d = pins["duty"]
        return isinstance(d, int | float) and not isinstance(d, bool) and math.isfinite(d) and -1.0 <= d <= 1.0

    def actuate(self, world: Any, r: int, pins: dict[str, Any]) -> None:
        legs_of(world, r).set_duty(r, self.leg, pins["duty"])


def legs_of(world: Any, r: int) -> Any:
    """The world model of robot ``r``'s legs: the gait-level one (``legs``) or the contact-level one
    (``contact_legs``), as its group's ``body`` option chose; a session may have both."""
    legs = world.model("legs")
    return legs if legs is not None and r in legs.local else world.model("contact_legs")


@cache
def LEG_WIRING(role: str) -> LegWiring | None:
    """The wiring of the firmware entity ``role``: ``legN`` a leg module's, anything else none."""
    if role.startswith("leg") and role[3:].isdigit() and 0 <= int(role[3:]) < 6:
        return LegWiring(int(role[3:]))
    return None
