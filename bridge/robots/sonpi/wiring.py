"""What the SonPI's Arduino board's pins meet in the world: the five HC-SR04s' beams (the surface in each one's cone,
from the world's sonar ray casts), the two wheel encoders and the battery; its two motor PWM outputs drive the
differential drive. The hub asks the robot's plugin (``RobotSpec.wiring``) for it, senses and actuates through it and
records its pins on ``/rNNN/arduino/pins``."""

from __future__ import annotations

import math
from typing import Any

from bridge.core.recorder import register_schema
from bridge.models.sonar import SonarParams

ROLE = "arduino"
SCHEMA = "swarm_sitl.SonpiBoardPins"
register_schema(
    SCHEMA,
    {
        "type": "object",
        "description": "One tick of the SonPI's Arduino board: the range to the surface in each sonar's beam "
        "(m, right to left, -90 to +90 degrees; null: none within the rays' reach), the encoder counts, the "
        "battery voltage, and the motor PWM it wrote (acts from the next quantum)",
        "properties": {
            "ranges_m": {"type": "array", "items": {"type": ["number", "null"]}},
            "encoders": {"type": "array", "items": {"type": "integer"}},
            "battery_v": {"type": "number"},
            "pwm": {"type": "array", "items": {"type": "integer", "minimum": -255, "maximum": 255}},
            "trig": {
                "type": "array",
                "description": "when each sonar's TRIG pin fires next and its period (ns), right to left: sent at "
                "power-up and when the firing mode changes; the world casts each cone at those times",
                "items": {"type": "array", "items": {"type": "integer"}},
            },
        },
    },
)

# the sonar part's angles (the front first, as the sonar model has it) -> the board's order, right to left
SONAR_ANGLES_DEG = (0.0, -90.0, -45.0, 45.0, 90.0)
BOARD_ORDER = tuple(SONAR_ANGLES_DEG.index(a) for a in (-90.0, -45.0, 0.0, 45.0, 90.0))


class BoardWiring:
    """The Arduino's pins (``RobotSpec.wiring("arduino")``)."""

    schema = SCHEMA

    def sense(self, world: Any, r: int, media: dict[str, Any], ideal_pose: bool) -> tuple[dict, dict]:
        sonar = world.model("sonar")
        k = sonar.local[r]
        reach = world.profiles[r].part(SonarParams).max_range_m
        raw = sonar.ranges[k]
        ranges = [float(raw[j]) if raw[j] < reach - 1e-9 else math.inf for j in BOARD_ORDER]
        enc = world.model("differential_drive").sense(r)["encoders"]
        battery = float(world.battery_v[r])
        sens = {"ranges_m": ranges, "encoders": list(enc), "battery_v": battery}
        rec = {
            "ranges_m": [round(v, 4) if math.isfinite(v) else None for v in ranges],
            "encoders": list(enc),
            "battery_v": round(battery, 4),
        }
        return sens, rec

    def valid(self, pins: Any) -> bool:
        """Signed 8-bit PWM per motor, and maybe the sonars' firing times (five [next, period] in ns)."""
        if not isinstance(pins, dict) or not {"pwm"} <= set(pins) <= {"pwm", "trig"}:
            return False
        pwm = pins["pwm"]
        if not (isinstance(pwm, list) and len(pwm) == 2 and all(type(v) is int and -255 <= v <= 255 for v in pwm)):
            return False
        trig = pins.get("trig")
        return trig is None or (
            isinstance(trig, list)
            and len(trig) == len(BOARD_ORDER)
            and all(
                isinstance(s, list) and len(s) == 2 and all(type(v) is int for v in s) and s[0] >= 0 and s[1] > 0
                for s in trig
            )
        )

    def actuate(self, world: Any, r: int, pins: dict[str, Any]) -> None:
        world.model("differential_drive").set_pwm(r, *pins["pwm"])
        trig = pins.get("trig")
        if trig is not None:  # the sonar part's order from the board's (right to left)
            by_part = [trig[BOARD_ORDER.index(j)] for j in range(len(BOARD_ORDER))]
            world.model("sonar").schedule(r, [s[0] for s in by_part], [s[1] for s in by_part])


BOARD_WIRING = BoardWiring()
