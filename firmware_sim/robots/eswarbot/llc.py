"""The eSwarBot's Arduino low-level controller (LLC), as a sketch: ``setup()`` and a fixed-rate ``loop()``.

Each loop: read CAN commands, read the quantised encoder counts, update odometry, run one wheel-speed PID
step per wheel, apply the command watchdog (motors stop 0.5 s after the last DRIVE_CMD, and at once while the
CAN controller is bus-off; a running MOVE_CMD is aborted then), sample the
sonar, light sensor and battery through the 10-bit ADC, set the LED strip and send telemetry on the
robot's CAN bus at fixed rates. The CAN interface is described by ``eswarbot_llc.dbc``.

Besides wheel speeds (DRIVE_CMD) the LLC executes the thesis' "rotate-then-go" displacement (MOVE_CMD,
Couceiro 2013 section 4.6.1): it turns the rotation and the distance into wheel pulses (eq. 4.21, 4.22),
skips rotations below one encoder pulse, turns in place, then drives straight, counting pulses, and reports
the pulses it executed (MOVE_STATUS).

The PID tracks an integrated position set-point in encoder pulses (a velocity PID on 48-CPR encoders
at 100 Hz would see less than one pulse per loop), with velocity feed-forward, a motor dead-band
offset, anti-windup and a bounded tracking error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_sim.board import sensors
from firmware_sim.board.arduino import Board
from firmware_sim.board.wheel_pid import WheelPid
from firmware_sim.modules.xbee import rssi_dbm_from_pwm
from swarm_logic.robots.eswarbot import eswarbot_llc_db

PIN_SONAR, PIN_LDR, PIN_BATTERY = "A0", "A1", "A2"
PIN_SONAR_LEFT, PIN_SONAR_RIGHT = "A3", "A4"  # a robot with three sonars (TraxBot)
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
PERIOD_MOVE_STATUS_MS = 100
PERIOD_CONVEYOR_STATUS_MS = 100
MOVE_TIMEOUT_FACTOR = 3.0  # a move not finished within 3x its nominal duration + 1 s is aborted (stall safety)
MOVE_TIMEOUT_MARGIN_MS = 1000
MOVE_ACCEL_PPS2 = 200.0  # the wheels' set-point ramps up and down at this rate (pulses/s^2, about 0.55 m/s^2)

MOVE_IDLE, MOVE_ROTATING, MOVE_FORWARD, MOVE_DONE, MOVE_ABORTED = range(5)  # MOVE_STATUS.state


@dataclass(frozen=True)
class LlcParams:
    """Constants compiled into the firmware for one robot model."""

    wheel_radius_m: float = 0.02109
    half_track_m: float = 0.0439
    encoder_cpr: int = 48
    loop_hz: float = 100.0
    max_wheel_rad_s: float = 16.6
    deadband_pwm: int = 25
    motor_time_constant_s: float = 0.06  # the drive's response time, for the MOVE ramp's acceleration feed-forward
    battery_cells: int = 2
    sonar_min_mm: int = 150
    sonar_max_mm: int = 6000
    kp: float = 18.0  # PWM per pulse of tracking error
    ki: float = 30.0  # PWM per pulse-second
    max_err_pulses: float = 6.0
    rssi_pwm_input: bool = False  # an XBee's RSSI PWM output is wired to PIN_RSSI (eSwarBot radio hack)
    xbee_sensitivity_dbm: float = -94.0  # the module's sensitivity, as eq. 3.9 uses it (Series 2; Series 1: -92)
    rot_threshold_deg: float = 3.6  # theta_T: smaller rotations of a MOVE are skipped (one pulse, digest A12)
    side_sonars: bool = False  # left and right sonars on PIN_SONAR_LEFT / PIN_SONAR_RIGHT (TraxBot)
    conveyor_slots: int = 0  # a conveyor belt for scouts (TraxBot: 5); 0: none, CONVEYOR_CMD is a bad frame
    conveyor_pitch_mm: float = 150.0  # belt per slot
    conveyor_speed_mm_s: float = 50.0
    belt_mm_per_step: float = 0.5  # the stepper's resolution ("< 1 mm", Table 3.4)


def rotation_pulses(theta_rad: float, p: LlcParams) -> float:
    """Pulses per wheel for an in-place rotation by ``theta_rad`` (thesis eq. 4.21, R_robot the half-track,
    digest A26); signed like ``theta_rad``, unrounded."""
    return p.encoder_cpr * theta_rad / (2 * math.pi) * p.half_track_m / p.wheel_radius_m


def forward_pulses(h_m: float, p: LlcParams) -> float:
    """Pulses per wheel for a straight run of ``h_m`` metres (thesis eq. 4.22), unrounded."""
    return p.encoder_cpr * h_m / (2 * math.pi * p.wheel_radius_m)


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
        self.fault_bus_off = False  # latched until a STATUS carries it (a bus-off node cannot send one)
        self.stall_since_ms: list[int | None] = [None, None]
        self.stalled = [False, False]
        self.last_loop_us: int | None = None
        self.overflows_reported = 0
        self.led = (0, 0, 0)
        self.rssi_pulse_us = -1
        self.rssi_sent_ms = 0
        self.move_seq = 0
        self.move_state = MOVE_IDLE
        self.move_dir = 1  # +1: counter-clockwise (left wheel back, right forward), -1: clockwise
        self.move_pulses = (0, 0)  # the pulse targets (eq. 4.21, 4.22), rounded
        self.move_pps = 0.0
        self.move_start = (0, 0)  # encoder counts when the current phase began
        self.move_start_us = 0  # micros() then
        self.move_done = [0, 0]  # executed rotation and forward pulses
        self.move_deadline_ms = 0
        now = b.millis()
        self.next_ms = {"odom": now, "sonar": now, "light": now, "status": now, "battery": now, "rssi": now,
                        "move": now, "conveyor": now}
        self.belt_steps = 0  # stepper steps emitted since power-up
        self.belt_target = 0.0  # where the belt is going, in steps
        self.belt_frac = 0.0  # steps owed to the speed ramp, below one
        self.conveyor_seq = 0
        self.conveyor_reported: tuple[int, int, int] | None = None
        self._set_motor(0, 0)
        self._set_motor(1, 0)
        self._sample_battery()

    def loop(self) -> None:
        """One fixed-rate pass: commands in, dead reckoning, the motors, then the telemetry that is due."""
        now = self.board.millis()
        now_us = self.board.micros()
        dt = self._loop_dt(now_us)
        self._read_can(now)
        self._bus_off_stop(now)
        counts, prev = self._dead_reckon(dt)
        self._watchdog(now)
        self._drive_wheels(counts, prev, now, now_us, dt)
        self._report_sonar(now)
        if self.p.conveyor_slots:
            self._conveyor(now, dt)
        self._report_odometry(now, counts)
        if self.move_state in (MOVE_ROTATING, MOVE_FORWARD) and now >= self.next_ms["move"]:
            self._move_status(now)
        self._report_light(now)
        self._report_rssi(now)
        self._report_battery(now)
        self._report_status(now)
        self.board.led_strip(*self.led)

    # -- the loop's steps, in its order ---------------------------------------------------------------
    def _loop_dt(self, now_us: int) -> float:
        """Seconds since the last loop (the nominal period on the first one, or if the clock did not advance)."""
        dt = (now_us - self.last_loop_us) * 1e-6 if self.last_loop_us is not None else self.loop_period_us * 1e-6
        self.last_loop_us = now_us
        if dt <= 0:
            dt = self.loop_period_us * 1e-6
        return dt

    def _bus_off_stop(self, now: int) -> None:
        """Stop at once while bus-off: nothing the host sends can arrive, so no waiting for the watchdog."""
        if self.board.can.bus_off:
            self.fault_bus_off = True
            self._abort_move(now)
            self.v_cmd = self.w_cmd = 0.0

    def _dead_reckon(self, dt: float) -> tuple[tuple[int, int], tuple[int, int]]:
        """Read the encoders and update the odometry; returns this loop's and the last loop's counts."""
        b = self.board
        counts = (b.encoder(0), b.encoder(1))
        prev = self.last_counts
        dl = (counts[0] - prev[0]) * self.m_per_pulse
        dr = (counts[1] - prev[1]) * self.m_per_pulse
        self.last_counts = counts
        self._odometry(dl, dr, dt)
        return counts, prev

    def _watchdog(self, now: int) -> None:
        """Zero the wheel-speed command WATCHDOG_MS after the last DRIVE_CMD (a fault if it was moving)."""
        if self.last_cmd_ms is None or now - self.last_cmd_ms > WATCHDOG_MS:
            if self.last_cmd_ms is not None and (self.v_cmd or self.w_cmd):
                self.fault_watchdog = True
            self.v_cmd = self.w_cmd = 0.0

    def _drive_wheels(self, counts: tuple[int, int], prev: tuple[int, int], now: int, now_us: int,
                      dt: float) -> None:
        """One PID step per wheel (the running move's, else the wheel-speed command's), then the stall check."""
        pps_per_mps = 1.0 / self.m_per_pulse
        if self.move_state in (MOVE_ROTATING, MOVE_FORWARD):
            pwms = self._move_step(counts, now, now_us, dt)
        else:
            target = (
                (self.v_cmd - self.w_cmd * self.p.half_track_m) * pps_per_mps,
                (self.v_cmd + self.w_cmd * self.p.half_track_m) * pps_per_mps,
            )
            pwms = tuple(self.pid[i].update(target[i], counts[i], dt) for i in (0, 1))
        for i in (0, 1):
            pwm = pwms[i]
            self._set_motor(i, pwm)
            self._stall_check(i, pwm, counts[i] != prev[i], now)

    def _report_sonar(self, now: int) -> None:
        """Sample the sonar (and the side ones, if fitted) and send SONAR (SONAR_SIDES) every PERIOD_SONAR_MS."""
        if now < self.next_ms["sonar"]:
            return
        b = self.board
        self.next_ms["sonar"] += PERIOD_SONAR_MS
        mm = sensors.sonar_mm_from_adc(b.analog_read(PIN_SONAR))
        # a reading at the top of the scale means no echo (the ranger outputs its maximum); anything
        # nearer than its minimum range reads as the minimum, which is a valid "very close"
        self.sonar_valid = 0 < mm < self.p.sonar_max_mm - SONAR_NO_ECHO_MARGIN_MM
        self.sonar_mm = mm
        self._send("SONAR", range_mm=min(mm, 65535), valid=int(self.sonar_valid))
        if self.p.side_sonars:
            left, right = (sensors.sonar_mm_from_adc(b.analog_read(pin)) for pin in (PIN_SONAR_LEFT,
                                                                                     PIN_SONAR_RIGHT))
            limit = self.p.sonar_max_mm - SONAR_NO_ECHO_MARGIN_MM
            self._send("SONAR_SIDES", left_mm=min(left, 65535), right_mm=min(right, 65535),
                       left_valid=int(0 < left < limit), right_valid=int(0 < right < limit))

    def _report_odometry(self, now: int, counts: tuple[int, int]) -> None:
        """Send ENCODERS and ODOMETRY every PERIOD_ODOM_MS (the motion-capture pose instead, when fitted)."""
        if now < self.next_ms["odom"]:
            return
        b = self.board
        self.next_ms["odom"] += PERIOD_ODOM_MS
        self._send("ENCODERS", left=counts[0], right=counts[1])
        # a motion-capture receiver, when fitted, replaces the dead-reckoned pose in the report
        x, y, theta = self.x, self.y, self.theta
        if b.external_pose is not None:
            x, y, yaw = b.external_pose
            theta = math.atan2(math.sin(yaw), math.cos(yaw))
        self._send(
            "ODOMETRY",
            x_mm=_clamp16(round(x * 1000)),
            y_mm=_clamp16(round(y * 1000)),
            theta_mrad=round(theta * 1000),
            v_mm_s=_clamp16(round(self.v_est * 1000)),
        )

    def _report_light(self, now: int) -> None:
        """Sample the light sensor and send LIGHT every PERIOD_LIGHT_MS."""
        if now < self.next_ms["light"]:
            return
        self.next_ms["light"] += PERIOD_LIGHT_MS
        self.ldr_raw = self.board.analog_read(PIN_LDR)
        self._send("LIGHT", ldr_raw=self.ldr_raw)

    def _report_rssi(self, now: int) -> None:
        """Measure the XBee's RSSI PWM output (if wired) at 10 Hz; send RADIO_RSSI on a change and at least at 1 Hz."""
        # a change: a new packet came in, or the output went off
        if not (self.p.rssi_pwm_input and now >= self.next_ms["rssi"]):
            return
        b = self.board
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

    def _report_battery(self, now: int) -> None:
        """Sample the battery and send BATTERY every PERIOD_BATTERY_MS."""
        if now < self.next_ms["battery"]:
            return
        self.next_ms["battery"] += PERIOD_BATTERY_MS
        self._sample_battery()
        self._send("BATTERY", voltage_mv=self.batt_mv, soc_pct=self._soc_pct())

    def _report_status(self, now: int) -> None:
        """Send STATUS (heartbeat, faults, CAN counters) every PERIOD_STATUS_MS, so the host sees the faults."""
        if now < self.next_ms["status"]:
            return
        b = self.board
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
            pose_ideal=int(b.external_pose is not None),
            fault_bus_off=int(self.fault_bus_off),
            rx_bad_frames=min(255, self.rx_bad + can.rx_errors),
            rx_overflows=min(255, can.rx_overflows),
            uptime_s=min(65535, now // 1000),
        )
        self.overflows_reported = can.rx_overflows
        if not can.bus_off:  # sent: the host has been told
            self.fault_bus_off = False

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
                self._abort_move(now)
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
            elif msg.name == "CONVEYOR_CMD":
                if not self.p.conveyor_slots or sig["slots"] < 1:
                    self._bad_frame()
                    continue
                self.conveyor_seq = int(sig["seq"])
                self.belt_target += sig["slots"] * self.p.conveyor_pitch_mm / self.p.belt_mm_per_step
            elif msg.name == "MOVE_CMD":
                if sig["dist_mm"] < 0 or sig["speed_mm_s"] <= 0:  # forward only, and it must get somewhere
                    self._bad_frame()
                    continue
                self._abort_move(now)
                self._start_move(int(sig["seq"]), sig["rot_mrad"] / 1000.0, sig["dist_mm"] / 1000.0,
                                 sig["speed_mm_s"] / 1000.0, now)

    # -- conveyor ----------------------------------------------------------------------------------------
    def _conveyor(self, now: int, dt: float) -> None:
        """Step the belt toward its target at the belt's speed; report on each change and 10 Hz while moving."""
        p = self.p
        left = self.belt_target - self.belt_steps
        if left >= 1:
            self.belt_frac += p.conveyor_speed_mm_s * dt / p.belt_mm_per_step
            n = min(int(self.belt_frac), int(left))
            self.belt_frac -= n
            self.belt_steps += n
            self.board.stepper_pulses(n)
        else:
            self.belt_frac = 0.0
        steps_per_slot = p.conveyor_pitch_mm / p.belt_mm_per_step
        moving = int(self.belt_target - self.belt_steps >= 1)
        pos = int(self.belt_steps // steps_per_slot + 1e-9)
        pending = max(0, round((self.belt_target - self.belt_steps) / steps_per_slot + 0.4999))
        state = (moving, pos, pending)
        if state != self.conveyor_reported or (moving and now >= self.next_ms["conveyor"]):
            self.conveyor_reported = state
            self.next_ms["conveyor"] = now + PERIOD_CONVEYOR_STATUS_MS
            self._send("CONVEYOR_STATUS", seq=self.conveyor_seq, moving=moving, position_slots=min(pos, 255),
                       pending_slots=min(pending, 255))

    # -- rotate-then-go -------------------------------------------------------------------------------
    def _start_move(self, seq: int, theta: float, h: float, speed: float, now: int) -> None:
        p = self.p
        if abs(theta) > math.pi + 1e-3:  # beyond +/- pi (and its rounding to mrad): the shorter way round
            theta = math.atan2(math.sin(theta), math.cos(theta))
        tau1 = round(rotation_pulses(abs(theta), p)) if abs(theta) >= math.radians(p.rot_threshold_deg) else 0
        tau2 = round(forward_pulses(h, p))
        speed = min(speed, p.max_wheel_rad_s * p.wheel_radius_m)  # the wheels' top speed
        self.v_cmd = self.w_cmd = 0.0  # a move replaces any wheel-speed command
        self.move_seq = seq
        self.move_dir = 1 if theta >= 0 else -1
        self.move_pulses = (tau1, tau2)
        self.move_pps = speed / self.m_per_pulse
        self.move_start = (self.board.encoder(0), self.board.encoder(1))
        self.move_start_us = self.board.micros()
        self.move_done = [0, 0]
        nominal_s = _ramp_duration(tau1, self.move_pps) + _ramp_duration(tau2, self.move_pps)
        self.move_deadline_ms = now + round(MOVE_TIMEOUT_FACTOR * nominal_s * 1000) + MOVE_TIMEOUT_MARGIN_MS
        for pid in self.pid:
            pid.reset()
        self.move_state = MOVE_ROTATING if tau1 else MOVE_FORWARD if tau2 else MOVE_DONE
        self._move_status(now)

    def _abort_move(self, now: int) -> None:
        if self.move_state in (MOVE_ROTATING, MOVE_FORWARD):
            self._move_progress((self.board.encoder(0), self.board.encoder(1)))
            self.move_state = MOVE_ABORTED
            for pid in self.pid:
                pid.reset()
            self._move_status(now)

    def _move_step(self, counts: tuple[int, int], now: int, now_us: int, dt: float) -> tuple[int, int]:
        """One loop of the running move: the wheels' PWM. Both wheels follow the same set-point ramp (so the
        robot turns in place, or runs straight); a wheel stops when it has counted its pulses, and the phase
        ends when both have."""
        if now >= self.move_deadline_ms:  # stall safety: the move is bounded
            self._abort_move(now)
            return (0, 0)
        while True:
            signs, left = self._move_progress(counts)
            if left[0] > 0 or left[1] > 0:
                break
            rotating = self.move_state == MOVE_ROTATING
            self.move_state = MOVE_FORWARD if rotating and self.move_pulses[1] else MOVE_DONE
            self.move_start = counts
            self.move_start_us = now_us
            for pid in self.pid:
                pid.reset()
            self._move_status(now)
            if self.move_state == MOVE_DONE:
                return (0, 0)
        goal = self.move_pulses[0 if self.move_state == MOVE_ROTATING else 1]
        pos, pps, acc = _ramp(goal, self.move_pps, (now_us - self.move_start_us) * 1e-6)
        pwm = [0, 0]
        for i in (0, 1):
            if left[i] > 0:
                pwm[i] = self.pid[i].follow(self.move_start[i] + signs[i] * pos, signs[i] * pps, counts[i], dt,
                                            signs[i] * acc)
            else:
                self.pid[i].reset()
        return pwm[0], pwm[1]

    def _move_progress(self, counts: tuple[int, int]) -> tuple[tuple[int, int], tuple[int, int]]:
        """The current phase's wheel directions and pulses still to go per wheel; updates the executed pulses
        (what the pose is recomputed from): rotation (right - left) / 2, distance (left + right) / 2."""
        rotating = self.move_state == MOVE_ROTATING
        signs = (-self.move_dir, self.move_dir) if rotating else (1, 1)
        goal = self.move_pulses[0 if rotating else 1]
        d = (counts[0] - self.move_start[0], counts[1] - self.move_start[1])
        self.move_done[0 if rotating else 1] = _clamp16(int((d[1] - d[0] if rotating else d[0] + d[1]) / 2))
        return signs, (goal - signs[0] * d[0], goal - signs[1] * d[1])

    def _move_status(self, now: int) -> None:
        self.next_ms["move"] = now + PERIOD_MOVE_STATUS_MS
        self._send("MOVE_STATUS", seq=self.move_seq, state=self.move_state, rot_pulses=self.move_done[0],
                   fwd_pulses=self.move_done[1])

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


def _ramp_duration(goal: float, v: float, a: float = MOVE_ACCEL_PPS2) -> float:
    """Seconds a trapezoidal ramp (top speed ``v``, acceleration ``a``) takes to cover ``goal`` pulses."""
    if goal <= 0:
        return 0.0
    return goal / v + v / a if goal >= v * v / a else 2 * math.sqrt(goal / a)


def _ramp(goal: float, v: float, t: float, a: float = MOVE_ACCEL_PPS2) -> tuple[float, float, float]:
    """Position, speed and acceleration at ``t`` s of a trapezoidal ramp from 0 to ``goal`` pulses (a triangle
    when too short to reach ``v``)."""
    v = min(v, math.sqrt(goal * a))
    ta = v / a
    end = goal / v + ta
    if t <= 0:
        return 0.0, 0.0, 0.0
    if t < ta:
        return 0.5 * a * t * t, a * t, a
    if t < end - ta:
        return 0.5 * a * ta * ta + v * (t - ta), v, 0.0
    if t < end:
        return goal - 0.5 * a * (end - t) ** 2, a * (end - t), -a
    return float(goal), 0.0, 0.0


def _clamp16(v: int) -> int:
    return max(-32768, min(32767, v))
