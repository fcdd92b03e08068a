"""A DeciZebro leg module (ATxmega32A4U class): a ZebroBus slave at 0x10 + its leg position that turns its C-leg
as the main computer commands, phase-locked to the controller's once-a-second sync writes.

Each control loop (``LOOP_HZ``, simulated time) it reads its leg's angle sensor and the battery, runs the motion
the controller activated and drives its motor's H-bridge (pin ``duty``, -1..1):

- idle: hold the leg where it was when idle was activated;
- walk / continuous rotation: the leg tracks ``phase + omega * tau``, where ``tau`` is the synchronised time (the
  sync counter in seconds plus the time since it was written) and ``omega`` the motion speed (10 rpm units; in walk
  mode plus the signed trim in ``motion extra``, 0.1 rpm units), clipped to the motor's 170 rpm. Legs given the same
  speed keep the phases the controller gave them (a gait); when the sync counter rolls over (0xFF -> 0) the module
  moves its phase on by ``omega * 256 s`` so the motion goes on without a jump;
- fixed position: turn to ``phase`` at the motion speed (its sign the direction; 0: the short way at 10 rpm), hold.

The position loop is a PI on the leg angle with the speed as feed-forward (scaled by the battery voltage against
the motor voltage field). Its error is taken within a window in the direction of motion (a leg ahead by more than a
quarter turn is not turned back, one behind catches up), so a leg never reverses to find its phase.

Emergency stop: the RTC counts 2048 ticks of 1.024 kHz from the last sync write (or power-up); when it overflows,
2 s without a sync, the H-bridge is switched off, the motion falls back to idle and ZEBROBUS_NO_TIMING_INFO is
recorded. It stays stopped until the controller writes 0x12 to the emergency stop field (and the motion anew).

The module gets its bus traffic from the I2C medium as items (``["i2c", txn, segments]``; it answers reads with
``["i2c", txn, [bytes...]]``) and announces itself on the bus when it powers up (``["i2c_attach", addr, True]``:
it answers its address and the general call from then on).
"""

from __future__ import annotations

import math
from typing import Any

from firmware_sim.robots.decizebro import zebrobus as zb

LOOP_HZ = 100
MAX_RPM = 170.0  # the leg motor's no-load speed at its rated voltage
TWO_PI = 2 * math.pi
KP = 0.5  # duty per rad of angle error
KI = 0.4  # duty per rad*s
I_MAX = 0.3  # the integral's share of the duty, at most
FIXED_DEFAULT_RPM = 10.0
AT_TARGET_RAD = math.radians(3)


def _s8(v: int) -> int:
    return v - 256 if v > 127 else v


def rpm_to_rad_s(rpm: float) -> float:
    return rpm * TWO_PI / 60.0


class LegModule(zb.ZebroBusSlave):
    """One leg module: ``run(t_ns, inputs)`` as the firmware host calls it; ``inputs["sens"]`` is its pins' reading
    (``angle`` rad, ``omega`` rad/s, ``battery_v`` V), ``inputs["in"]`` the bus traffic the medium delivered."""

    def __init__(self, position: int, serial_id: int = 1, loop_hz: float = LOOP_HZ) -> None:
        super().__init__(zb.leg_address(position), zb.LEG_CLASS, serial_id)
        self.position = position
        self.period_ns = round(1e9 / loop_hz)
        self.vregs[zb.MOTOR_VOLTAGE] = 12
        self.buffer = dict.fromkeys(zb.MOTION_FIELDS, 0)
        self.mode = zb.MODE_IDLE
        self.speed = 0  # int8, 10 rpm units
        self.phase = 0  # 0-239 as activated
        self.extra = 0
        self.phase_rad = 0.0  # the phase kept exactly (rollovers move it by fractions of a step)
        self.hold_rad: float | None = None  # idle: where to hold (None: not yet known)
        self.fixed_rad = 0.0  # fixed position: the moving set-point
        self.now = 0
        self.booted = False
        self.next_loop = 0
        self.sync_ns = 0  # when the sync counter was last written (the RTC's zero)
        self.rtc_deadline = 0  # when the RTC overflows: 2 s after sync_ns, then every 2 s
        self.estop = False
        self.integral = 0.0
        self.duty = 0.0
        self.last_loop_ns: int | None = None
        self.counters.update(loops=0, estops=0, motion_updates=0, sync_writes=0, malformed=0)

    # -- the firmware host's tick ------------------------------------------------------------------------------
    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        self.now = t_ns
        out: list[list] = []
        if not self.booted:  # power-up: the RTC starts counting, the TWI slave answers from now on
            self.booted = True
            self.next_loop = t_ns
            self.sync_ns = t_ns
            self.rtc_deadline = t_ns + zb.SYNC_TIMEOUT_COUNTS * 1_000_000_000 // zb.RTC_HZ
            out.append(["i2c_attach", self.address, True])
        for item in inputs.get("in", ()):
            try:
                segs = [(int(a), bool(rd), int(d) if rd else bytes(d)) for a, rd, d in item[2]]
                if item[0] != "i2c":
                    segs = None
            except (TypeError, ValueError, IndexError):
                segs = None
            if segs is None:  # not bus traffic as the medium sends it: dropped and counted
                self.counters["malformed"] += 1
                continue
            replies = self.receive(segs)
            if any(rd for _, rd, _ in segs):
                out.append(["i2c", item[1], replies])
        if t_ns >= self.rtc_deadline:
            self._overflow()
        res: dict[str, Any] = {"out": out, "wom": ["i2c"]}
        if t_ns >= self.next_loop:
            self._loop(t_ns, inputs.get("sens") or {})
            self.next_loop = max(self.next_loop + self.period_ns, t_ns + 1)
            res["pins"] = {"duty": self.duty}
        res["wake"] = min(self.next_loop, self.rtc_deadline)
        return res

    # -- fields the leg class handles --------------------------------------------------------------------------
    def read_reg(self, reg: int) -> int:
        if reg == zb.CLOCK or reg == zb.CLOCK + 1:  # the RTC, read live
            counts = min((self.now - self.sync_ns) * zb.RTC_HZ // 1_000_000_000, 0xFFFF)
            return (counts >> 8) & 0xFF if reg == zb.CLOCK else counts & 0xFF
        return self.vregs[reg]

    def write_field(self, reg: int, value: int) -> None:
        if reg in self.buffer:
            self.buffer[reg] = value
        elif reg == zb.MOTION_UPDATE:
            self._activate()
        elif reg == zb.SYNC_COUNTER:
            self._sync(value)
        elif reg == zb.EMERGENCY_STOP:
            if value == zb.ESTOP_CLEAR:
                self.estop = False
                self.vregs[zb.EMERGENCY_STOP] = 0
            else:
                self._stop()
                self.report(zb.ERR_EMERGENCY_STOP_RESET)
        else:
            self.vregs[reg] = value

    def _sync(self, value: int) -> None:
        self.counters["sync_writes"] += 1
        old = self.vregs[zb.SYNC_COUNTER]
        if old == 0xFF and value == 0 and self.mode in (zb.MODE_WALK, zb.MODE_ROTATE):
            # time rolls over: move the phase on by what 256 s of this motion turn, so the leg goes on smoothly
            self.phase_rad = (self.phase_rad + self._omega() * 256.0) % TWO_PI
            self.phase = round(self.phase_rad / TWO_PI * zb.PHASE_STEPS) % zb.PHASE_STEPS
            self.vregs[zb.MOTION_PHASE] = self.phase
        self.vregs[zb.SYNC_COUNTER] = value
        self.sync_ns = self.now
        self.rtc_deadline = self.now + zb.SYNC_TIMEOUT_COUNTS * 1_000_000_000 // zb.RTC_HZ

    def _activate(self) -> None:
        """Motion update: the buffered fields become active (if valid), and the buffer clears."""
        self.counters["motion_updates"] += 1
        buf = self.buffer
        self.buffer = dict.fromkeys(zb.MOTION_FIELDS, 0)
        mode, phase = buf[zb.MOTION_MODE], buf[zb.MOTION_PHASE]
        if mode > zb.MODE_ROTATE:
            self.report(zb.ERR_MOTION_MODE)
            return
        if phase >= zb.PHASE_STEPS:  # the spec: report an error and stop
            self.report(zb.ERR_MOTION_PHASE)
            mode, phase = zb.MODE_IDLE, 0
            buf = {**buf, zb.MOTION_MODE: zb.MODE_IDLE, zb.MOTION_SPEED: 0, zb.MOTION_PHASE: 0}
        self.mode, self.speed, self.phase, self.extra = mode, _s8(buf[zb.MOTION_SPEED]), phase, buf[zb.MOTION_EXTRA]
        self.phase_rad = phase * TWO_PI / zb.PHASE_STEPS
        for reg in zb.MOTION_FIELDS:
            self.vregs[reg] = buf[reg]
        self.hold_rad = None  # idle holds where the leg is now; fixed starts from there
        self.fixed_rad = math.nan
        self.integral = 0.0

    def _omega(self) -> float:
        """The commanded leg speed (rad/s), clipped to the motor's."""
        rpm = zb.SPEED_UNIT_RPM * self.speed
        if self.mode == zb.MODE_WALK:
            rpm += zb.TRIM_UNIT_RPM * _s8(self.extra)
        return rpm_to_rad_s(max(-MAX_RPM, min(MAX_RPM, rpm)))

    def _overflow(self) -> None:
        """The RTC overflowed: no sync write for 2 s."""
        self._stop()
        self.report(zb.ERR_ZEBROBUS_NO_TIMING_INFO)
        while self.rtc_deadline <= self.now:
            self.rtc_deadline += zb.SYNC_TIMEOUT_COUNTS * 1_000_000_000 // zb.RTC_HZ

    def _stop(self) -> None:
        """Emergency stop: H-bridge off, the motion back to idle."""
        if not self.estop:
            self.counters["estops"] += 1
        self.estop = True
        self.duty = 0.0
        self.integral = 0.0
        self.mode = zb.MODE_IDLE
        self.speed = 0
        self.hold_rad = None
        self.vregs[zb.EMERGENCY_STOP] = 1
        self.vregs[zb.MOTION_MODE] = zb.MODE_IDLE
        self.vregs[zb.MOTION_SPEED] = 0

    # -- the control loop ----------------------------------------------------------------------------------------
    def _loop(self, t_ns: int, sens: dict[str, Any]) -> None:
        self.counters["loops"] += 1
        dt = self.period_ns / 1e9 if self.last_loop_ns is None else (t_ns - self.last_loop_ns) / 1e9
        self.last_loop_ns = t_ns
        theta = float(sens.get("angle", 0.0)) % TWO_PI
        omega_meas = float(sens.get("omega", 0.0))
        battery = float(sens.get("battery_v", 0.0))
        at_target = False
        if self.estop:
            self.duty = 0.0
        else:
            target, ff, window = self._setpoint(theta, dt)
            err = _in_window(target - theta, window)
            at_target = abs(err) < AT_TARGET_RAD
            motor_v = self.vregs[zb.MOTOR_VOLTAGE] or 12
            full = rpm_to_rad_s(MAX_RPM) * min(battery / motor_v, 1.25) if battery > 0 else rpm_to_rad_s(MAX_RPM)
            self.integral = max(-I_MAX / KI, min(I_MAX / KI, self.integral + err * dt))
            self.duty = max(-1.0, min(1.0, ff / full + KP * err + KI * self.integral))
        self._telemetry(t_ns, theta, omega_meas, battery, at_target)

    def _setpoint(self, theta: float, dt: float) -> tuple[float, float, int]:
        """(target angle, feed-forward speed rad/s, error window: +1 forward, -1 backward, 0 the short way)."""
        if self.mode in (zb.MODE_WALK, zb.MODE_ROTATE):
            w = self._omega()
            tau = self.vregs[zb.SYNC_COUNTER] + (self.now - self.sync_ns) / 1e9
            return (self.phase_rad + w * tau) % TWO_PI, w, (w > 0) - (w < 0)
        if self.mode == zb.MODE_FIXED:
            if math.isnan(self.fixed_rad):
                self.fixed_rad = theta
            goal = self.phase_rad
            rpm = abs(zb.SPEED_UNIT_RPM * self.speed) or FIXED_DEFAULT_RPM
            step = rpm_to_rad_s(min(rpm, MAX_RPM)) * dt
            if self.speed > 0:
                left = (goal - self.fixed_rad) % TWO_PI
            elif self.speed < 0:
                left = -((self.fixed_rad - goal) % TWO_PI)
            else:
                left = _in_window(goal - self.fixed_rad, 0)
            move = max(-step, min(step, left))
            self.fixed_rad = (self.fixed_rad + move) % TWO_PI
            return self.fixed_rad, move / dt if dt > 0 else 0.0, 0
        if self.hold_rad is None:
            self.hold_rad = theta
        return self.hold_rad, 0.0, 0

    def _telemetry(self, t_ns: int, theta: float, omega: float, battery: float, at_target: bool) -> None:
        v = self.vregs
        v[zb.LOOP_COUNTER] = (v[zb.LOOP_COUNTER] + 1) & 0xFF
        v[zb.LEG_PHASE] = int(theta / TWO_PI * zb.PHASE_STEPS) % zb.PHASE_STEPS
        self.put16(zb.LEG_ANGLE, int(math.degrees(theta) * 100) % 36000)
        self.put16(zb.LEG_SPEED, max(-32768, min(32767, round(omega * 60 / TWO_PI * 10))))
        v[zb.HBRIDGE_DUTY] = round(self.duty * 127) & 0xFF
        self.put16(zb.BATTERY_MV, max(0, min(0xFFFF, round(battery * 1000))))
        timing = t_ns - self.sync_ns < zb.SYNC_TIMEOUT_COUNTS * 1_000_000_000 // zb.RTC_HZ
        v[zb.QUICK_STATUS] = ((zb.QS_ESTOP if self.estop else 0)
                              | (zb.QS_MOVING if self.mode != zb.MODE_IDLE and not self.estop else 0)
                              | (zb.QS_TIMING if timing else 0) | (zb.QS_ERROR if self.errors else 0)
                              | (zb.QS_AT_TARGET if at_target else 0))


def _in_window(err: float, window: int) -> float:
    """``err`` wrapped into the window: [-pi/2, 3pi/2) forward, (-3pi/2, pi/2] backward, [-pi, pi) otherwise."""
    if window > 0:
        return (err + math.pi / 2) % TWO_PI - math.pi / 2
    if window < 0:
        return -((-err + math.pi / 2) % TWO_PI - math.pi / 2)
    return (err + math.pi) % TWO_PI - math.pi
