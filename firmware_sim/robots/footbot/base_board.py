"""The foot-bot's base board (the marXbot's base microcontrollers, lumped into one node of the robot's CAN bus), as a
sketch: ``setup()`` and a fixed-rate ``loop()``.

Each loop: read CAN commands (WHEELS_CMD: the wheels' linear speeds; LEDS_CMD: the ring and beacon colour), run the
wheel speed servo on the encoders (``firmware_sim.board.wheel_pid``), stop the motors 0.5 s after the last
WHEELS_CMD (watchdog) and at once while bus-off; every ``sensor_period_ms`` read the proximity ring, the light ring
and the motor-ground sensors through the ADC (their values reach the board as pin voltages, 0 V to VREF for 0 to 1)
and the 8 base ground sensors as digital inputs (a comparator each: high on white)
and send them on the bus with the encoder counts, at 8 bits a sensor; a status frame every second. The CAN
interface is ``swarm_logic/robots/footbot/footbot.dbc``. Its acceptance filter passes only its two commands; one of
the wrong length is counted (BASE_STATUS.bad_frames) and dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_sim.board.arduino import Board
from firmware_sim.board.wheel_pid import WheelPid
from swarm_logic.robots.footbot import footbot_db

PIN_PWM = ("PWM_L", "PWM_R")
PIN_DIR = ("DIR_L", "DIR_R")
WATCHDOG_MS = 500
STATUS_PERIOD_MS = 1000


def proximity_pin(i: int) -> str:
    return f"PROX{i}"


def base_ground_pin(i: int) -> str:
    return f"GNDB{i}"


def light_pin(i: int) -> str:
    return f"LIGHT{i}"


def ground_pin(i: int) -> str:
    return f"GND{i}"


@dataclass(frozen=True)
class BaseParams:
    """Constants compiled into the base board's firmware."""

    wheel_radius_m: float = 0.0291
    half_track_m: float = 0.07
    encoder_cpr: int = 1024
    loop_hz: float = 50.0
    max_wheel_rad_s: float = 10.3
    deadband_pwm: int = 10
    motor_time_constant_s: float = 0.05
    kp: float = 0.4  # PWM per pulse of tracking error (1024-pulse encoders)
    ki: float = 0.7
    max_err_pulses: float = 120.0
    max_speed_mm_s: int = 300  # commands beyond are clipped
    sensor_period_ms: int = 100
    proximity_count: int = 24
    light_count: int = 24
    ground_count: int = 4
    base_ground_count: int = 8
    battery_divider: float = 4.0  # the battery reaches its ADC pin through a 4:1 divider


class FootbotBase:
    def __init__(self, board: Board, params: BaseParams | None = None) -> None:
        self.b = board
        self.p = p = params or BaseParams()
        self.db = footbot_db()
        self.accepts = {m.frame_id: m for m in self.db.messages if m.name in ("WHEELS_CMD", "LEDS_CMD")}
        self.ids = {m.name: m.frame_id for m in self.db.messages}
        self.pid = (WheelPid(p), WheelPid(p))
        self.target_pps = [0.0, 0.0]
        self.last_cmd_ms: int | None = None
        self.last_loop_us: int | None = None
        self.next_sensor_ms = 0
        self.next_status_ms = 0
        self.heartbeat = 0
        self.scan = 0
        self.bad_frames = 0
        self.watchdog_tripped = False
        self.pulses_per_m = p.encoder_cpr / (2 * math.pi * p.wheel_radius_m)

    @property
    def loop_period_us(self) -> int:
        return round(1e6 / self.p.loop_hz)

    def setup(self) -> None:
        for i in (0, 1):
            self._set_motor(i, 0)
        self.b.led_strip(0, 0, 0)

    def loop(self) -> None:
        b, p = self.b, self.p
        now_us = b.micros()
        now = now_us // 1000
        dt = 0.0 if self.last_loop_us is None else (now_us - self.last_loop_us) / 1e6
        self.last_loop_us = now_us
        self._read_can(now)
        if b.can.bus_off or (self.last_cmd_ms is not None and now - self.last_cmd_ms > WATCHDOG_MS):
            if self.target_pps != [0.0, 0.0]:
                self.watchdog_tripped = not b.can.bus_off
            self.target_pps = [0.0, 0.0]
        for i in (0, 1):
            pwm = self.pid[i].update(self.target_pps[i], b.encoder(i), dt) if dt > 0 else 0
            self._set_motor(i, pwm)
        if now >= self.next_sensor_ms:
            self.next_sensor_ms = now + p.sensor_period_ms
            self._report_sensors()
        if now >= self.next_status_ms:
            self.next_status_ms = now + STATUS_PERIOD_MS
            self._report_status()

    def _read_can(self, now: int) -> None:
        b = self.b
        while (f := b.can.read()) is not None:
            m = self.accepts.get(f.arbitration_id)
            if m is None:  # its acceptance filter passes only its commands: the bus carries the other boards' too
                continue
            if len(f.data) != m.length:
                self.bad_frames += 1
                continue
            s = m.decode(f.data)
            if m.name == "WHEELS_CMD":
                lim = self.p.max_speed_mm_s
                for i, key in enumerate(("left_mm_s", "right_mm_s")):
                    v = max(-lim, min(lim, int(s[key])))
                    self.target_pps[i] = v / 1000.0 * self.pulses_per_m
                self.last_cmd_ms = now
                self.watchdog_tripped = False
            else:
                b.led_strip(int(s["red"]), int(s["green"]), int(s["blue"]))

    def _adc8(self, pin: str) -> int:
        """The pin's 10-bit conversion as the 8 bits the bus carries."""
        return self.b.analog_read(pin) >> 2

    def _report_sensors(self) -> None:
        p = self.p
        self.scan = (self.scan + 1) & 0xFF
        self._send("ENCODERS", left=self.b.encoder(0), right=self.b.encoder(1))
        prox = [self._adc8(proximity_pin(i)) for i in range(p.proximity_count)]
        for k in range(3):
            self._raw("PROXIMITY_" + str(k), bytes(prox[8 * k:8 * k + 8]))
        light = [self._adc8(light_pin(i)) for i in range(p.light_count)]
        for k in range(3):
            self._raw("LIGHT_" + str(k), bytes(light[8 * k:8 * k + 8]))
        ground = [self._adc8(ground_pin(i)) for i in range(p.ground_count)]
        base = sum(self.b.digital_read(base_ground_pin(i)) << i for i in range(self.p.base_ground_count))
        self._raw("GROUND", bytes([*ground, base, self.scan]))

    def _report_status(self) -> None:
        self.heartbeat = (self.heartbeat + 1) & 0xFF
        mv = round(self.b.analog_read("VBAT") / self.b.ADC_MAX * self.b.VREF * self.p.battery_divider * 1000)
        self._send("BASE_STATUS", heartbeat=self.heartbeat, fault_watchdog=int(self.watchdog_tripped),
                   fault_can_overflow=int(self.b.can.rx_overflows > 0), bad_frames=min(self.bad_frames, 65535),
                   battery_mv=min(mv, 65535))

    def _set_motor(self, i: int, pwm: int) -> None:
        self.b.analog_write(PIN_PWM[i], abs(pwm))
        self.b.digital_write(PIN_DIR[i], 1 if pwm >= 0 else 0)

    def _send(self, name: str, **signals: float) -> None:
        m = self.db.get_message_by_name(name)
        self.b.can.write(m.frame_id, m.encode(signals), self.b.micros())

    def _raw(self, name: str, data: bytes) -> None:
        """A frame whose signals are whole bytes in order (the rings): its bytes as they are."""
        self.b.can.write(self.ids[name], data, self.b.micros())
