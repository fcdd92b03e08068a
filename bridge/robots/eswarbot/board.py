"""The eSwarBot's Arduino board with its LLC sketch, wired as the real robot is: which physical value reaches which
pin (encoders, the sonars' analog outputs, the light-dependent resistor, the battery divider, the XBee's RSSI PWM
output, a motion-capture receiver), which pins drive the motors, the LED strip and a conveyor's stepper (the TraxBot's).

The firmware host runs one per robot whose LLC the session simulates (``RobotSpec.make_board``); the sketch itself
is ``firmware_sim.robots.eswarbot.llc``.
"""

from __future__ import annotations

from typing import Any

from bridge.core.plan import RobotPlan
from bridge.core.profile import RobotProfile
from bridge.core.registry import PluginError
from bridge.models.differential_drive import DriveParams
from bridge.models.sonar import SonarParams
from firmware_sim.board import sensors
from firmware_sim.board.arduino import Board, next_loop_ns
from firmware_sim.robots.eswarbot.llc import (
    PIN_BATTERY,
    PIN_DIR,
    PIN_LDR,
    PIN_PWM,
    PIN_RSSI,
    PIN_SONAR,
    PIN_SONAR_LEFT,
    PIN_SONAR_RIGHT,
    RSSI_PWM_HZ,
    LlcParams,
    LowLevelController,
)


def llc_params(p: RobotProfile, xbee: dict | None = None) -> LlcParams:
    """The sketch's build for a robot of profile ``p``: its drive's figures, its sonars, a conveyor if it has one."""
    d, s = p.part(DriveParams), p.part(SonarParams)
    if d is None or s is None:
        raise PluginError(f"robot {p.name!r}: the eSwarBot's LLC sketch drives a differential drive and reads sonars")
    belt = p.part_named("conveyor")
    # the wheel PI was tuned on the eSwarBot's 48-pulse encoders: the same gains per radian of wheel angle
    per_pulse = 48 / d.encoder_cpr
    return LlcParams(
        kp=LlcParams.kp * per_pulse,
        ki=LlcParams.ki * per_pulse,
        max_err_pulses=LlcParams.max_err_pulses / per_pulse,
        wheel_radius_m=d.wheel_radius_m,
        half_track_m=d.half_track_m,
        encoder_cpr=d.encoder_cpr,
        loop_hz=p.llc_loop_hz,
        max_wheel_rad_s=d.motor_max_wheel_rad_s,
        deadband_pwm=d.motor_deadband_pwm,
        motor_time_constant_s=d.motor_time_constant_s,
        battery_cells=p.battery_cells,
        sonar_min_mm=round(s.min_range_m * 1000),
        sonar_max_mm=round(s.max_range_m * 1000),
        side_sonars=len(s.angles_deg) == 3,
        **({} if belt is None else {"conveyor_slots": belt.slots, "conveyor_pitch_mm": belt.pitch_m * 1000,
                                    "conveyor_speed_mm_s": belt.speed_m_s * 1000,
                                    "belt_mm_per_step": belt.m_per_step * 1000}),
        rssi_pwm_input=xbee is not None,
        # the firmware inverts eq. 3.9 with the sensitivity of the module it is built for
        xbee_sensitivity_dbm=-92.0 if xbee is not None and xbee["series"] == 1 else -94.0,
    )


class LlcBoard:
    """One robot's board: each tick sets its clock and pins from the world's physical values, hands it the CAN
    frames the bus delivered, runs ``loop()`` (``setup()`` first, once) and answers with the frames it sent, its pin
    outputs when they changed, and its next loop time."""

    def __init__(self, profile: RobotProfile, rp: RobotPlan) -> None:
        self.board = Board()
        self.llc = LowLevelController(self.board, llc_params(profile, rp.xbee if rp.sim_xbee else None))
        self.nominal_ns: int | None = None  # the loop's own fixed-rate schedule (millis()-based, as on the board)
        self.last_pins: tuple | None = None

    def off_pins(self) -> dict[str, Any]:
        """Its outputs while it is held in reset (a reboot, a brown-out): the motor driver's inputs and the LEDs low."""
        return {"pwm": [0, 0], "led": [0, 0, 0]}

    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        b, llc = self.board, self.llc
        b.time_us = t_ns // 1000
        s = inputs["sens"]
        b.encoder_counts = [s["enc"][0], s["enc"][1]]
        b.analog_volts[PIN_SONAR] = sensors.sonar_volts(s["sonar_m"])
        for pin, m in zip((PIN_SONAR_LEFT, PIN_SONAR_RIGHT), s.get("sides", ()), strict=False):
            b.analog_volts[pin] = sensors.sonar_volts(m)
        b.analog_volts[PIN_LDR] = sensors.ldr_volts(s["lux"])
        b.analog_volts[PIN_BATTERY] = sensors.battery_volts_at_pin(s["battery_v"])
        b.pwm_inputs[PIN_RSSI] = (s.get("rssi_pwm", 0.0), RSSI_PWM_HZ)
        pose = s.get("pose")  # a ground-truth robot's motion-capture receiver: the world pose (x, y, yaw)
        b.external_pose = (float(pose[0]), float(pose[1]), float(pose[2])) if pose is not None else None
        b.feed_can(inputs["in"])
        if self.nominal_ns is None:  # first tick: power-up
            self.nominal_ns = t_ns
            llc.setup()
        llc.loop()
        self.nominal_ns = nominal = next_loop_ns(self.nominal_ns, llc.loop_period_us * 1000, t_ns)
        pwm = tuple(
            b.pwm.get(PIN_PWM[i], 0) * (1 if b.digital_read(PIN_DIR[i]) else -1) for i in (0, 1)
        )
        pins = (pwm, b.led_rgb, b.stepper_steps)
        out: dict[str, Any] = {
            "out": [["can0", f.arbitration_id, f.data, f.is_extended_id] for f in b.can.take_tx()],
            "wake": nominal,
            "wom": False,
        }
        if pins != self.last_pins:
            self.last_pins = pins
            out["pins"] = {"pwm": list(pwm), "led": list(b.led_rgb)}
            if llc.p.conveyor_slots:  # the belt's stepper: how far it has turned
                out["pins"]["belt_steps"] = b.stepper_steps
        return out
