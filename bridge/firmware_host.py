"""Hosts the firmware of one or more robots: one Arduino board and LLC sketch per robot.

Per tick the host sets each due board's clock and pin inputs from the world's physical values, hands it
the CAN frames the bus delivered, runs ``loop()`` (``setup()`` first, once) and returns the frames it
transmitted, its pin outputs when they changed, and its next loop time.
"""

from __future__ import annotations

from typing import Any

from bridge.plan import Plan, robot_of
from bridge.profiles import PROFILES, RobotProfile
from firmware_sim import sensors
from firmware_sim.arduino import Board
from firmware_sim.can_controller import Frame
from firmware_sim.llc import PIN_BATTERY, PIN_DIR, PIN_LDR, PIN_PWM, PIN_SONAR, LlcParams, LowLevelController


def llc_params(p: RobotProfile) -> LlcParams:
    return LlcParams(
        wheel_radius_m=p.wheel_radius_m,
        half_track_m=p.half_track_m,
        encoder_cpr=p.encoder_cpr,
        loop_hz=p.llc_loop_hz,
        max_wheel_rad_s=p.motor_max_wheel_rad_s,
        deadband_pwm=p.motor_deadband_pwm,
        battery_cells=p.battery_cells,
        sonar_min_mm=round(p.sonar_min_range_m * 1000),
        sonar_max_mm=round(p.sonar_max_range_m * 1000),
    )


class FirmwareHost:
    def __init__(self, plan: Plan, robots: tuple[int, ...]) -> None:
        self.boards: dict[int, Board] = {}
        self.llcs: dict[int, LowLevelController] = {}
        self.nominal_ns: dict[int, int] = {}  # the loop's own fixed-rate schedule (millis()-based, as on the board)
        self.last_pins: dict[int, tuple] = {}
        for r in robots:
            board = Board()
            self.boards[r] = board
            self.llcs[r] = LowLevelController(board, llc_params(PROFILES[plan.robots[r].profile]))

    def run(self, ent: str, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        r = robot_of(ent)
        b, llc = self.boards[r], self.llcs[r]
        b.time_us = t_ns // 1000
        s = inputs["sens"]
        b.encoder_counts = [s["enc"][0], s["enc"][1]]
        b.analog_volts[PIN_SONAR] = sensors.sonar_volts(s["sonar_m"])
        b.analog_volts[PIN_LDR] = sensors.ldr_volts(s["lux"])
        b.analog_volts[PIN_BATTERY] = sensors.battery_volts_at_pin(s["battery_v"])
        for _bus, arb_id, data, ext, ts in inputs["in"]:
            b.can.on_bus_frame(Frame(arb_id, data, ts // 1000, ext))
        if r not in self.nominal_ns:  # first tick: power-up
            self.nominal_ns[r] = t_ns
            llc.setup()
        llc.loop()
        # Next loop on the nominal schedule; the world rounds it up to a quantum boundary, so when the
        # quantum does not divide the period the loop jitters but keeps its average rate.
        period = llc.loop_period_us * 1000
        nominal = self.nominal_ns[r] + period
        while nominal <= t_ns:
            nominal += period
        self.nominal_ns[r] = nominal
        pwm = tuple(
            b.pwm.get(PIN_PWM[i], 0) * (1 if b.digital_read(PIN_DIR[i]) else -1) for i in (0, 1)
        )
        pins = (pwm, b.led_rgb)
        out: dict[str, Any] = {
            "out": [["can0", f.arbitration_id, f.data, f.is_extended_id] for f in b.can.take_tx()],
            "wake": nominal,
            "wom": False,
        }
        if pins != self.last_pins.get(r):
            self.last_pins[r] = pins
            out["pins"] = {"pwm": list(pwm), "led": list(b.led_rgb)}
        return out

    def stop(self) -> None:
        pass
