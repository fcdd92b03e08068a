"""The foot-bot's base board in a session: its firmware (``firmware_sim.robots.footbot.base_board``) as the firmware
host runs it, and its wiring in the world (what reaches its pins: encoders, the proximity and light rings and the
ground sensors as ADC voltages, the battery; what its pins do: the motors' signed PWM and the LED ring's colour).
The hub asks the robot's plugin for both (``RobotSpec.board``, ``RobotSpec.pins``)."""

from __future__ import annotations

from typing import Any

from bridge.core.plan import RobotPlan
from bridge.core.profile import RobotProfile
from bridge.core.recorder import register_schema
from bridge.core.registry import PluginError
from bridge.models.differential_drive import DriveParams
from bridge.robots.footbot.sensors import FootbotSensorsParams
from firmware_sim.board.arduino import Board, next_loop_ns
from firmware_sim.robots.footbot.base_board import (
    PIN_DIR,
    PIN_PWM,
    BaseParams,
    FootbotBase,
    base_ground_pin,
    ground_pin,
    light_pin,
    proximity_pin,
)

SCHEMA = "swarm_sitl.FootbotBasePins"
register_schema(SCHEMA, {
    "type": "object",
    "description": "One loop() of the foot-bot's base board: encoders and battery at its pins, a new sample of its "
                   "sensor rings when there is one (0..1 each), and its pin writes (signed motor PWM, LED colour; "
                   "only when they changed), which act from the next quantum",
    "properties": {
        "enc": {"type": "array", "items": {"type": "integer"}},
        "battery_v": {"type": "number"},
        "proximity": {"type": "array", "items": {"type": "number"}},
        "light": {"type": "array", "items": {"type": "number"}},
        "ground": {"type": "array", "items": {"type": "number"}},
        "base_ground": {"type": "array", "items": {"type": "integer"}},
        "pwm": {"type": "array", "items": {"type": "integer"}},
        "led": {"type": "array", "items": {"type": "integer"}},
    },
})


def base_params(p: RobotProfile) -> BaseParams:
    """The base board's build for a robot of profile ``p``: its drive's and its sensors' figures."""
    d, s = p.part(DriveParams), p.part(FootbotSensorsParams)
    if d is None or s is None:
        raise PluginError(f"robot {p.name!r}: the foot-bot's base board drives a differential drive and reads the "
                          "foot-bot's sensor rings")
    return BaseParams(wheel_radius_m=d.wheel_radius_m, half_track_m=d.half_track_m, encoder_cpr=d.encoder_cpr,
                      loop_hz=p.llc_loop_hz, max_wheel_rad_s=d.motor_max_wheel_rad_s,
                      deadband_pwm=d.motor_deadband_pwm, motor_time_constant_s=d.motor_time_constant_s,
                      sensor_period_ms=round(1000 / s.rate_hz), proximity_count=s.proximity_count,
                      light_count=s.light_count, ground_count=len(s.ground_offsets_m),
                      base_ground_count=len(s.base_ground_offsets_m))


class BaseBoard:
    """One foot-bot's base board: each tick sets its clock and pins from the world, hands it the CAN frames the bus
    delivered, runs ``loop()`` (``setup()`` first) and answers with its frames, its pin writes when they changed and
    its next loop time."""

    def __init__(self, profile: RobotProfile, rp: RobotPlan) -> None:
        self.board = Board(can_rx_depth=16)
        self.fw = FootbotBase(self.board, base_params(profile))
        self.nominal_ns: int | None = None
        self.last_pins: tuple | None = None

    def off_pins(self) -> dict[str, Any]:
        """Its outputs while it is held in reset (a reboot, a brown-out): the motor driver's inputs and the LEDs low."""
        return {"pwm": [0, 0], "led": [0, 0, 0]}

    @property
    def counters(self) -> dict[str, int]:
        c = self.board.can
        return {"bad_frames": self.fw.bad_frames, "can_rx_overflows": c.rx_overflows, "can_rx_frames": c.rx_frames,
                "can_tx_frames": c.tx_frames}

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        b = self.board
        b.time_us = t_ns // 1000
        s = inputs["sens"]
        b.encoder_counts = [s["enc"][0], s["enc"][1]]
        b.analog_volts["VBAT"] = s["battery_v"] / self.fw.p.battery_divider
        for key, pin in (("proximity", proximity_pin), ("light", light_pin), ("ground", ground_pin)):
            for i, v in enumerate(s.get(key, ())):  # a new sample: the sensors' outputs hold until the next
                b.analog_volts[pin(i)] = v * b.VREF
        for i, v in enumerate(s.get("base_ground", ())):  # the comparators' outputs: white high, black low
            b.digital[base_ground_pin(i)] = 1 if v else 0
        b.feed_can(inputs["in"])
        if self.nominal_ns is None:
            self.nominal_ns = t_ns
            self.fw.setup()
        self.fw.loop()
        self.nominal_ns = nominal = next_loop_ns(self.nominal_ns, self.fw.loop_period_us * 1000, t_ns)
        pwm = tuple(b.pwm.get(PIN_PWM[i], 0) * (1 if b.digital_read(PIN_DIR[i]) else -1) for i in (0, 1))
        pins = (pwm, b.led_rgb)
        out: dict[str, Any] = {
            "out": [["can0", f.arbitration_id, f.data, f.is_extended_id] for f in b.can.take_tx()],
            "wake": nominal,
            "wom": False,
        }
        if pins != self.last_pins:
            self.last_pins = pins
            out["pins"] = {"pwm": list(pwm), "led": list(b.led_rgb)}
        return out


class BasePins:
    """What the base board's pins meet in the world (``RobotSpec.pins``)."""

    schema = SCHEMA

    def sense(self, world: Any, r: int, media: dict[str, Any], ideal_pose: bool) -> tuple[dict, dict]:
        s = world.sensors(r)
        sens: dict[str, Any] = {"enc": list(s["encoders"]), "battery_v": s["battery_v"]}
        sens.update(world.model("footbot_sensors").take_new(r))
        return sens, sens

    def valid(self, pins: Any) -> bool:
        """Signed 8-bit PWM per motor and an RGB colour."""
        if not isinstance(pins, dict) or set(pins) != {"pwm", "led"}:
            return False
        pwm, led = pins["pwm"], pins["led"]
        return (isinstance(pwm, list) and len(pwm) == 2 and all(type(v) is int and -255 <= v <= 255 for v in pwm)
                and isinstance(led, list) and len(led) == 3 and all(type(v) is int and 0 <= v <= 255 for v in led))

    def actuate(self, world: Any, r: int, pins: dict[str, Any]) -> None:
        world.model("differential_drive").set_pwm(r, *pins["pwm"])
        world.set_led(r, tuple(pins["led"]))


BASE_PINS = BasePins()
