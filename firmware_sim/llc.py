"""The eSwarBot's Arduino low-level controller (LLC), as a sketch: ``setup()`` and a fixed-rate ``loop()``.

Each loop: read CAN commands, read the quantised encoder counts, update odometry, run one wheel-speed PID
step per wheel, apply the command watchdog (motors stop 0.5 s after the last DRIVE_CMD), sample the
sonar, light sensor and battery through the 10-bit ADC, set the LED strip and send telemetry on the
robot's CAN bus at fixed rates. The CAN interface is described by ``eswarbot_llc.dbc``.

The PID tracks an integrated position set-point in encoder pulses (a velocity PID on 48-CPR encoders
at 100 Hz would see less than one pulse per loop), with velocity feed-forward, a motor dead-band
offset, anti-windup and a bounded tracking error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_sim import sensors
from firmware_sim.arduino import Board
from firmware_sim.xbee import rssi_dbm_from_pwm
from swarm_logic.interfaces import eswarbot_llc_db

PIN_SONAR, PIN_LDR, PIN_BATTERY = "A0", "A1", "A2"
PIN_PWM = ("D5", "D6")
PIN_DIR = ("D7", "D8")
PIN_RSSI = "D2"  # the XBee's RSSI PWM output (pin 6), wired to a digital input

RSSI_PWM_HZ = 120.0  # the XBee's RSSI PWM frequency (Couceiro 2013, section 3.2.3)

WATCHDOG_MS = 500
PERIOD_ODOM_MS = 50
PERIOD_SONAR_MS = 50
PERIOD_LIGHT_MS = 100
PERIOD_STATUS_MS = 100
PERIOD_BATTERY_MS = 1000
PERIOD_RSSI_MS = 100
RSSI_KEEPALIVE_MS = 1000
STALL_MS = 1000
SONAR_NO_ECHO_MARGIN_MM = 30  # about two ADC steps below full range


@dataclass(frozen=True)
class LlcParams:
    """Constants compiled into the firmware for one robot model."""

    wheel_radius_m: float = 0.02109
    half_track_m: float = 0.0439
    encoder_cpr: int = 48
    loop_hz: float = 100.0
    max_wheel_rad_s: float = 16.6
    deadband_pwm: int = 25
    battery_cells: int = 2
    sonar_min_mm: int = 150
    sonar_max_mm: int = 6000
    kp: float = 18.0  # PWM per pulse of tracking error
    ki: float = 30.0  # PWM per pulse-second
    max_err_pulses: float = 6.0
    rssi_pwm_input: bool = False  # an XBee's RSSI PWM output is wired to PIN_RSSI (eSwarBot radio hack)
    xbee_sensitivity_dbm: float = -94.0  # the module's sensitivity, as eq. 3.9 uses it (Series 2; Series 1: -92)


class WheelPid:
    """Position-tracking PI with feed-forward for one wheel, on quantised encoder counts."""

    def __init__(self, p: LlcParams) -> None:
        self.p = p
        self.kff = (255 - p.deadband_pwm) / (p.max_wheel_rad_s * p.encoder_cpr / (2 * math.pi))
        self.target_pos = 0.0
        self.integral = 0.0
        self.active = False

    def update(self, target_pps: float, count: int, dt: float) -> int:
        p = self.p
        if target_pps == 0.0:
            self.active = False
            self.integral = 0.0
            return 0
        if not self.active:
            self.active = True
            self.target_pos = float(count)
        self.target_pos += target_pps * dt
        err = self.target_pos - count
        if abs(err) > p.max_err_pulses:  # do not lurch after a stall: drag the set-point along
            err = math.copysign(p.max_err_pulses, err)
            self.target_pos = count + err
        u_pre = self.kff * target_pps + math.copysign(p.deadband_pwm, target_pps) + p.kp * err
        new_integral = self.integral + err * dt
        u = u_pre + p.ki * new_integral
        if -255 < u < 255 or (u >= 255 and err < 0) or (u <= -255 and err > 0):
            self.integral = new_integral  # anti-windup: integrate only while not saturated further
        u = u_pre + p.ki * self.integral
        return int(max(-255, min(255, round(u))))


class LowLevelController:
    """The LLC sketch. ``board`` is its hardware; the runtime calls ``loop()`` every ``loop_period_us``."""

    def __init__(self, board: Board, params: LlcParams | None = None) -> None:
        self.board = board
        self.p = params or LlcParams()
        self.loop_period_us = round(1e6 / self.p.loop_hz)
        self.db = eswarbot_llc_db()
        self.pid = (WheelPid(self.p), WheelPid(self.p))
        self.m_per_pulse = 2 * math.pi * self.p.wheel_radius_m / self.p.encoder_cpr

    # -- Arduino entry points -------------------------------------------------------------------------
    def setup(self) -> None:
        b = self.board
        self.v_cmd = 0.0
        self.w_cmd = 0.0
        self.last_cmd_ms: int | None = None
        self.last_counts = (b.encoder(0), b.encoder(1))
        self.x = self.y = self.theta = 0.0
        self.v_est = 0.0
        self.sonar_mm = 0
        self.sonar_valid = False
        self.ldr_raw = 0
        self.batt_mv = 0
        self.heartbeat = 0
        self.rx_bad = 0
        self.fault_watchdog = False
        self.fault_stall = False
        self.fault_battery_low = False
        self.fault_bad_frame = False
        self.stall_since_ms: list[int | None] = [None, None]
        self.stalled = [False, False]
        self.last_loop_us: int | None = None
        self.overflows_reported = 0
        self.led = (0, 0, 0)
        self.rssi_pulse_us = -1
        self.rssi_sent_ms = 0
        now = b.millis()
        self.next_ms = {"odom": now, "sonar": now, "light": now, "status": now, "battery": now, "rssi": now}
        self._set_motor(0, 0)
        self._set_motor(1, 0)
        self._sample_battery()

    def loop(self) -> None:
        b = self.board
        now = b.millis()
        now_us = b.micros()
        dt = (now_us - self.last_loop_us) * 1e-6 if self.last_loop_us is not None else self.loop_period_us * 1e-6
        self.last_loop_us = now_us
        if dt <= 0:
            dt = self.loop_period_us * 1e-6
        self._read_can(now)
        counts = (b.encoder(0), b.encoder(1))
        prev = self.last_counts
        dl = (counts[0] - prev[0]) * self.m_per_pulse
        dr = (counts[1] - prev[1]) * self.m_per_pulse
        self.last_counts = counts
        self._odometry(dl, dr, dt)

        if self.last_cmd_ms is None or now - self.last_cmd_ms > WATCHDOG_MS:
            if self.last_cmd_ms is not None and (self.v_cmd or self.w_cmd):
                self.fault_watchdog = True
            self.v_cmd = self.w_cmd = 0.0
        pps_per_mps = 1.0 / self.m_per_pulse
        target = (
            (self.v_cmd - self.w_cmd * self.p.half_track_m) * pps_per_mps,
            (self.v_cmd + self.w_cmd * self.p.half_track_m) * pps_per_mps,
        )
        for i in (0, 1):
            pwm = self.pid[i].update(target[i], counts[i], dt)
            self._set_motor(i, pwm)
            self._stall_check(i, pwm, counts[i] != prev[i], now)

        if now >= self.next_ms["sonar"]:
            self.next_ms["sonar"] += PERIOD_SONAR_MS
            mm = sensors.sonar_mm_from_adc(b.analog_read(PIN_SONAR))
            # a reading at the top of the scale means no echo (the ranger outputs its maximum); anything
            # nearer than its minimum range reads as the minimum, which is a valid "very close"
            self.sonar_valid = 0 < mm < self.p.sonar_max_mm - SONAR_NO_ECHO_MARGIN_MM
            self.sonar_mm = mm
            self._send("SONAR", range_mm=min(mm, 65535), valid=int(self.sonar_valid))
        if now >= self.next_ms["odom"]:
            self.next_ms["odom"] += PERIOD_ODOM_MS
            self._send("ENCODERS", left=counts[0], right=counts[1])
            self._send(
                "ODOMETRY",
                x_mm=_clamp16(round(self.x * 1000)),
                y_mm=_clamp16(round(self.y * 1000)),
                theta_mrad=round(self.theta * 1000),
                v_mm_s=_clamp16(round(self.v_est * 1000)),
            )
        if now >= self.next_ms["light"]:
            self.next_ms["light"] += PERIOD_LIGHT_MS
            self.ldr_raw = b.analog_read(PIN_LDR)
            self._send("LIGHT", ldr_raw=self.ldr_raw)
        if self.p.rssi_pwm_input and now >= self.next_ms["rssi"]:
            # sampled at 10 Hz, sent when it changed (a new packet came in, or the output went off) and
            # at least once a second
            self.next_ms["rssi"] += PERIOD_RSSI_MS
            period_us = round(1e6 / RSSI_PWM_HZ)
            high_us = b.pulse_in(PIN_RSSI, timeout_us=2 * period_us)
            if high_us == 0 and b.digital_read(PIN_RSSI):  # no edge but held high: the duty saturated at 100 %
                high_us = period_us
            if high_us != self.rssi_pulse_us or now >= self.rssi_sent_ms + RSSI_KEEPALIVE_MS:
                self.rssi_pulse_us = high_us
                self.rssi_sent_ms = now
                duty = min(1.0, high_us * RSSI_PWM_HZ / 1e6)
                dbm = rssi_dbm_from_pwm(duty, self.p.xbee_sensitivity_dbm)
                self._send("RADIO_RSSI", pulse_us=min(high_us, 65535), duty_permille=min(1000, round(duty * 1000)),
                           rssi_dbm=max(-128, min(0, round(dbm))) if high_us else -128, valid=int(high_us > 0))
        if now >= self.next_ms["battery"]:
            self.next_ms["battery"] += PERIOD_BATTERY_MS
            self._sample_battery()
            self._send("BATTERY", voltage_mv=self.batt_mv, soc_pct=self._soc_pct())
        if now >= self.next_ms["status"]:
            self.next_ms["status"] += PERIOD_STATUS_MS
            self.heartbeat = (self.heartbeat + 1) & 0xFF
            can = b.can
            self._send(
                "STATUS",
                heartbeat=self.heartbeat,
                fault_watchdog=int(self.fault_watchdog),
                fault_stall=int(self.fault_stall),
                fault_battery_low=int(self.fault_battery_low),
                fault_can_overflow=int(can.rx_overflows > self.overflows_reported),
                fault_bad_frame=int(self.fault_bad_frame),
                rx_bad_frames=min(255, self.rx_bad + can.rx_errors),
                rx_overflows=min(255, can.rx_overflows),
                uptime_s=min(65535, now // 1000),
            )
            self.overflows_reported = can.rx_overflows
        b.led_strip(*self.led)

    # -- helpers ------------------------------------------------------------------------------------
    def _read_can(self, now: int) -> None:
        can = self.board.can
        while (frame := can.read()) is not None:
            if frame.is_extended_id:  # the robot's interface uses standard (11-bit) IDs only
                self._bad_frame()
                continue
            try:
                msg = self.db.get_message_by_frame_id(frame.arbitration_id)
            except KeyError:
                self._bad_frame()
                continue
            if len(frame.data) != msg.length or msg.senders == ["LLC"]:
                self._bad_frame()
                continue
            sig = msg.decode(frame.data, decode_choices=False, scaling=True)
            if msg.name == "DRIVE_CMD":
                self.v_cmd = sig["v_mm_s"] / 1000.0
                self.w_cmd = sig["w_mrad_s"] / 1000.0
                self.last_cmd_ms = now
                self.fault_watchdog = False
            elif msg.name == "LED_CMD":
                self.led = (int(sig["red"]), int(sig["green"]), int(sig["blue"]))
            elif msg.name == "ODOM_SET":
                self.x = sig["x_mm"] / 1000.0
                self.y = sig["y_mm"] / 1000.0
                self.theta = sig["theta_mrad"] / 1000.0

    def _bad_frame(self) -> None:
        self.rx_bad += 1
        self.fault_bad_frame = True

    def _odometry(self, dl: float, dr: float, dt: float) -> None:
        ds = 0.5 * (dl + dr)
        dth = (dr - dl) / (2 * self.p.half_track_m)
        mid = self.theta + 0.5 * dth
        self.x += ds * math.cos(mid)
        self.y += ds * math.sin(mid)
        self.theta = math.atan2(math.sin(self.theta + dth), math.cos(self.theta + dth))
        self.v_est += 0.2 * (ds / dt - self.v_est)  # first-order filtered speed

    def _set_motor(self, i: int, pwm: int) -> None:
        self.board.digital_write(PIN_DIR[i], 1 if pwm >= 0 else 0)
        self.board.analog_write(PIN_PWM[i], abs(pwm))

    def _stall_check(self, i: int, pwm: int, moved: bool, now: int) -> None:
        """A wheel is stalled after STALL_MS of high PWM without a single encoder pulse."""
        if abs(pwm) >= 200 and not moved:
            if self.stall_since_ms[i] is None:
                self.stall_since_ms[i] = now
            self.stalled[i] = now - self.stall_since_ms[i] >= STALL_MS
        else:
            self.stall_since_ms[i] = None
            self.stalled[i] = False
        self.fault_stall = self.stalled[0] or self.stalled[1]

    def _sample_battery(self) -> None:
        self.batt_mv = sensors.battery_mv_from_adc(self.board.analog_read(PIN_BATTERY))
        self.fault_battery_low = self.batt_mv < 3300 * self.p.battery_cells

    def _soc_pct(self) -> int:
        per_cell = self.batt_mv / 1000.0 / self.p.battery_cells
        return int(max(0, min(100, round((per_cell - 3.3) / (4.2 - 3.3) * 100))))

    def _send(self, name: str, **signals: float) -> None:
        msg = self.db.get_message_by_name(name)
        self.board.can.write(msg.frame_id, msg.encode(signals, scaling=True), self.board.micros())


def _clamp16(v: int) -> int:
    return max(-32768, min(32767, v))
