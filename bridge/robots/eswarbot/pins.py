"""What the eSwarBot's LLC board meets in the world: the physical values at its pins each tick (wheel encoders, the
sonars' ranges, illuminance at the light sensor, battery voltage, what media put on its pins such as the XBee's
RSSI PWM output, and with ``pose_source = "ground_truth"`` a motion-capture receiver's pose), and what its pin
writes do (signed motor PWM, the LED strip's colour, a TraxBot's conveyor stepper count). The hub asks the robot's
plugin (``RobotSpec.pins``), so it knows no robot's wiring."""

from __future__ import annotations

from typing import Any

from bridge.core.recorder import register_schema

SCHEMA = "swarm_sitl.LlcPins"
register_schema(SCHEMA, {
    "type": "object",
    "description": "One loop() of the LLC board: physical values at its input pins, and its pin writes "
                   "(signed motor PWM, LED colour; only when they changed), which act from the next quantum",
    "properties": {
        "enc": {"type": "array", "items": {"type": "integer"}},
        "sonar_m": {"type": "number"},
        "lux": {"type": "number"},
        "battery_v": {"type": "number"},
        "rssi_pwm": {"type": "number", "description": "XBee RSSI PWM duty (0..1) at the board's pin"},
        "pwm": {"type": "array", "items": {"type": "integer"}},
        "led": {"type": "array", "items": {"type": "integer"}},
        "sides": {"type": "array", "items": {"type": "number"},
                  "description": "a robot with three sonars: the left and right ranges (m)"},
        "belt_steps": {"type": "integer", "description": "a carrier's conveyor stepper, steps since power-up"},
    },
})


class LlcPins:
    schema = SCHEMA  # what the hub records each loop() under

    def sense(self, world: Any, r: int, media: dict[str, Any], ideal_pose: bool) -> tuple[dict, dict]:
        """(what the board is sent, what is recorded as its pins' values: the pose is in /world/poses)."""
        s = world.sensors(r)
        sens: dict[str, Any] = {"enc": list(s["encoders"]), "sonar_m": s["sonar_m"], "lux": s["lux"],
                                "battery_v": s["battery_v"]}
        if s.get("side_sonars_m"):
            sens["sides"] = list(s["side_sonars_m"])
        if media:  # what media put on its pins (an XBee's RSSI PWM output)
            sens.update(media)
        recorded = sens
        if ideal_pose:  # its mocap receiver: the true pose in the world frame
            sens = {**sens, "pose": [float(world.pos[r, 0]), float(world.pos[r, 1]), float(world.yaw[r])]}
        return sens, recorded

    def valid(self, pins: Any) -> bool:
        """Signed 8-bit PWM per motor, an RGB LED colour, and a stepper count that only grows."""
        if not isinstance(pins, dict):
            return False
        pwm, led, belt = pins.get("pwm"), pins.get("led"), pins.get("belt_steps", 0)
        return (isinstance(pwm, list) and len(pwm) == 2 and all(isinstance(v, int) and -255 <= v <= 255 for v in pwm)
                and isinstance(led, list) and len(led) == 3 and all(isinstance(v, int) and 0 <= v <= 255 for v in led)
                and type(belt) is int and belt >= 0)

    def actuate(self, world: Any, r: int, pins: dict[str, Any]) -> None:
        """The pin writes of the LLC's previous loop take effect: motors, LEDs, a conveyor's stepper."""
        world.model("differential_drive").set_pwm(r, *pins["pwm"])
        world.set_led(r, tuple(pins["led"]))
        if "belt_steps" in pins:
            world.model("conveyor").set_belt(r, pins["belt_steps"])


LLC_PINS = LlcPins()
