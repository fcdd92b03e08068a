"""The SonPI's Arduino (ATmega328) sketch: an I2C slave at 0x20 on the robot's bus that fires the five HC-SR04s,
gathers their pings in 250 ms windows, drives the two wheels' motors with a speed loop on the encoders, and stops them
when the Pi stops commanding. The register map is ``swarm_logic.robots.sonpi.board_protocol`` (``docs/sonpi.md``).

**Sonars.** ``FIRING`` selects how the sketch triggers them:

- sequential (the default): one sensor per 60 ms slot (the HC-SR04's recommended measurement cycle), right to left,
  so each waits for its echo or the module's time-out before the next fires: 3.3 pings a second per sensor, and no
  sensor hears another's burst;
- simultaneous: all five fire at each 60 ms slot (16.7 per second each); a sensor may take a neighbour's echo
  (cross-talk, ``hcsr04.Rangers``);
- ideal: all five every 5 ms, the thesis' "200 Hz per sensor", without cross-talk.

The ECHO pulse is timed (4 us, ``micros()``) and converted as Arduino sketches do (``us / 5.8`` mm); a pulse that ran
to the module's time-out or beyond 4 m is "no echo" (0xFFFF), one under 2 cm reads 20 mm. A ping belongs to the window
in which its echo pulse ended. At each window's end the sketch latches, per sensor, its last result (kept from window
to window when a sensor had no ping in one), the nearest echo in the window, the pings and the echoes, and a window
sequence number: ``WINDOW``, read in one 32-byte block.

**Motors.** The Pi writes either speed set-points (``SPEED_SP``, mm/s per wheel: a position-tracking PI on the
encoders, ``firmware_sim.board.wheel_pid``) or signed PWM (``PWM_SP``, open loop), each pair in one transaction. A
watchdog stops both motors when no set-point has come for ``WATCHDOG`` x 10 ms (0.5 s by default) and says so in
``STATUS`` until the next one. Encoder counts (int32), measured speeds, the applied PWM, ``millis()`` and the battery
are latched each control loop (``LOOP_HZ``).

**Bad input.** The TWI slave ACKs every byte it is sent (the medium has no data NACK); a write the sketch refuses (a
read-only or missing register, a set-point pair written in part, a value out of range, more than its 32-byte buffer)
is dropped whole, recorded in ``ERROR_COUNT``/``LAST_ERROR`` and counted. A read whose pointer is at a missing
register is refused: the sketch clears TWEA, so the read's address is NACKed and the master's transfer fails
(``EREMOTEIO``); the pointer stays, the read is recorded (``BAD_REGISTER``) and counted (``refused_reads``), and the
sketch ignores the rest of that transaction (the master stopped there). A read that starts at a register and runs
past its block cannot be refused (a slave transmitter cannot NACK): the missing bytes read 0xFF, recorded
(``BAD_REGISTER``) and counted (``bad_reads``).

Items as a leg module's: ``["i2c", txn, segments]`` in, ``["i2c", txn, [bytes | None...]]`` out for reads (``None``: a
refused read, the last), ``["i2c_attach", 0x20, False, True]`` at power-up (it may refuse reads); pins in: ``ranges_m``
(the surface in each sensor's beam, m, ``inf`` beyond reach), ``encoders``, ``battery_v``; pins out: ``pwm`` (left,
right), and ``trig`` after power-up and after each change of firing mode: when each sensor's TRIG pin fires next and
how often it fires (``[[next_ns, period_ns]]`` right to left), so the world casts only the cones the sketch will read,
at its ping times.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any

from firmware_sim.board.wheel_pid import WheelPid
from firmware_sim.robots.sonpi.hcsr04 import BURST_US, ECHO_TIMEOUT_US, Echo, Rangers
from swarm_logic.robots.sonpi import board_protocol as P

LOOP_HZ = 100
WINDOW_MS = 250
SLOT_MS = 60  # sequential and simultaneous firing: one trigger per slot
IDEAL_PERIOD_US = 5_000  # the thesis' 200 Hz per sensor
MIN_MM, MAX_MM = 20, 4000  # the HC-SR04's rated 2-400 cm
TIMER_US = 4  # micros() resolution at 16 MHz


@dataclass(frozen=True)
class MotorParams:
    """Constants compiled into the sketch's wheel loop (``wheel_pid.PidParams``)."""

    wheel_radius_m: float
    encoder_cpr: int
    max_wheel_rad_s: float
    deadband_pwm: int
    motor_time_constant_s: float
    kp: float = 0.2  # PWM per pulse of tracking error (2048-count encoders)
    ki: float = 0.35
    max_err_pulses: float = 240.0

    @property
    def mm_per_count(self) -> float:
        return 2000 * math.pi * self.wheel_radius_m / self.encoder_cpr

    @property
    def max_speed_mm_s(self) -> int:
        return int(self.max_wheel_rad_s * self.wheel_radius_m * 1000)


def echo_mm(width_us: int) -> int:
    """What the sketch makes of an ECHO pulse: mm, or NO_ECHO."""
    if width_us >= ECHO_TIMEOUT_US:
        return P.NO_ECHO
    mm = round(width_us * 10 / 58)
    return P.NO_ECHO if mm > MAX_MM else max(MIN_MM, mm)


class _Acc:
    """One sensor's pings in the current window (and, for the summary only, the true range behind them)."""

    __slots__ = ("echoes", "min_mm", "pings", "true_min_m")

    def __init__(self) -> None:
        self.pings = 0
        self.echoes = 0
        self.min_mm = P.NO_ECHO
        self.true_min_m = math.inf


class SonarBoard:
    """The sketch: ``run(t_ns, inputs)`` as the firmware host calls it. ``rng`` draws the rangers' noise and
    cross-talk (a seeded stream of the robot's)."""

    def __init__(
        self,
        rangers: Rangers,
        motors: MotorParams,
        rng: Any,
        *,
        firing: int = P.FIRING_SEQUENTIAL,
        watchdog_ms: int = 500,
        loop_hz: float = LOOP_HZ,
    ) -> None:
        if firing not in (0, 1, 2):
            raise ValueError(f"firing mode must be 0-2, got {firing}")
        self.rangers = rangers
        self.m = motors
        self.rng = rng
        self.firing = firing
        self.watchdog = max(0, min(255, watchdog_ms // 10))
        self.period_ns = round(1e9 / loop_hz)
        self.pid = (WheelPid(motors), WheelPid(motors))
        self.booted = False
        self.t0 = 0
        self.now = 0
        self.pointer = 0
        self.txn: Any = None  # the transaction the last bus traffic belonged to (one may come in parts)
        self.error_count = 0
        self.last_error = 0
        # motors
        self.speed_loop = True
        self.speed_sp = (0, 0)  # mm/s
        self.pwm_sp = (0, 0)
        self.pwm = (0, 0)
        self.last_cmd_ns: int | None = None
        self.watchdog_stopped = False
        self.counts = (0, 0)
        self.prev_counts: tuple[int, int] | None = None
        self.speeds = (0, 0)  # mm/s measured
        self.millis = 0
        self.battery_mv = 0
        self.next_loop = 0
        # sonars
        self.next_fire = 0
        self.next_sensor = 0
        self.trig_due = True  # the sensors' firing times are to be told (pins "trig") at the next loop
        self.pending: list[tuple[int, int, Echo, float]] = []  # (echo end ns, sensor, echo, true range)
        self.window_end = 0
        self.acc = [_Acc() for _ in range(P.SENSORS)]
        self.last_mm = [P.NO_ECHO] * P.SENSORS
        self.seq = 0
        self.window = P.encode_window(0, [(P.NO_ECHO, P.NO_ECHO, 0, 0)] * P.SENSORS)
        self.stats: dict[str, int] = {
            "transactions": 0,
            "bytes_written": 0,
            "bytes_read": 0,
            "refused_writes": 0,
            "refused_reads": 0,
            "bad_reads": 0,
            "malformed": 0,
            "loops": 0,
            "watchdog_stops": 0,
            "pings": 0,
            "echoes": 0,
            "timeouts": 0,
            "crosstalk": 0,
            "windows": 0,
        }
        # the simulator's own record of each window against the true ranges (summary.json), not the sketch's
        self.score = {
            "sensor_windows": 0,
            "in_reach": 0,
            "valid_in_reach": 0,
            "phantom": 0,
            "err_n": 0,
            "err_sum_m": 0.0,
            "err_abs_m": 0.0,
            "err_sq_m2": 0.0,
        }

    # -- the firmware host's tick ------------------------------------------------------------------------------
    def run(self, t_ns: int, inputs: dict[str, Any]) -> dict[str, Any]:
        self.now = t_ns
        out: list[list] = []
        sens = inputs.get("sens") or {}
        if not self.booted:
            self.booted = True
            self.t0 = self.next_loop = self.next_fire = t_ns
            self.window_end = t_ns + WINDOW_MS * 1_000_000
            out.append(["i2c_attach", P.ADDRESS, False, True])
        self._sonars(t_ns, sens.get("ranges_m"))
        for item in inputs.get("in", ()):
            try:
                if item[0] != "i2c":
                    raise ValueError
                segs = [(int(a), bool(rd), int(d) if rd else bytes(d)) for a, rd, d in item[2]]
            except (TypeError, ValueError, IndexError):
                self.stats["malformed"] += 1
                continue
            replies = self.receive(segs, item[1])
            if any(rd for _, rd, _ in segs):
                out.append(["i2c", item[1], replies])
        res: dict[str, Any] = {"out": out, "wom": ["i2c"]}
        if t_ns >= self.next_loop:
            self._loop(t_ns, sens)
            self.next_loop = max(self.next_loop + self.period_ns, t_ns + 1)
            res["pins"] = {"pwm": list(self.pwm)}
            if self.trig_due:
                self.trig_due = False
                res["pins"]["trig"] = self.trig_schedule()
        res["wake"] = self.next_loop
        return res

    # -- the sonars ------------------------------------------------------------------------------------------------
    def trig_schedule(self) -> list[list[int]]:
        """Per sensor (right to left): the time its TRIG pin fires next and its period (ns) in the current mode."""
        if self.firing == P.FIRING_SEQUENTIAL:
            slot = SLOT_MS * 1_000_000
            return [
                [self.next_fire + ((i - self.next_sensor) % P.SENSORS) * slot, P.SENSORS * slot]
                for i in range(P.SENSORS)
            ]
        period = SLOT_MS * 1_000_000 if self.firing == P.FIRING_SIMULTANEOUS else IDEAL_PERIOD_US * 1000
        return [[self.next_fire, period] for _ in range(P.SENSORS)]

    def _sonars(self, t: int, ranges: Any) -> None:
        if ranges is None or len(ranges) != P.SENSORS:
            ranges = [math.inf] * P.SENSORS
        ranges = [float(r) for r in ranges]
        while self.next_fire <= t:
            at = self.next_fire
            if self.firing == P.FIRING_SEQUENTIAL:
                sensors = [self.next_sensor]
                self.next_sensor = (self.next_sensor + 1) % P.SENSORS
                self.next_fire += SLOT_MS * 1_000_000
            elif self.firing == P.FIRING_SIMULTANEOUS:
                sensors = list(range(P.SENSORS))
                self.next_fire += SLOT_MS * 1_000_000
            else:
                sensors = list(range(P.SENSORS))
                self.next_fire += IDEAL_PERIOD_US * 1000
            if self.firing == P.FIRING_IDEAL:  # no cross-talk: each as if alone
                echoes = {i: self.rangers.ping([i], ranges, self.rng)[i] for i in sensors}
            else:
                echoes = self.rangers.ping(sensors, ranges, self.rng)
            for i in sensors:
                e = echoes[i]
                self.pending.append((at + (BURST_US + e.width_us) * 1000, i, e, ranges[i]))
        self.pending.sort(key=lambda p: (p[0], p[1]))
        k = 0
        while True:
            end = self.pending[k][0] if k < len(self.pending) else None
            if self.window_end <= t and (end is None or self.window_end <= end):
                self._latch()
            elif end is not None and end <= t:
                self._ping_done(*self.pending[k][1:])
                k += 1
            else:
                break
        del self.pending[:k]

    def _ping_done(self, i: int, e: Echo, true_m: float) -> None:
        c = self.stats
        c["pings"] += 1
        a = self.acc[i]
        a.pings += 1
        a.true_min_m = min(a.true_min_m, true_m)
        mm = echo_mm(TIMER_US * round(e.width_us / TIMER_US))
        if e.source is None:
            c["timeouts"] += 1
        elif e.source != i:
            c["crosstalk"] += 1
        self.last_mm[i] = mm
        if mm != P.NO_ECHO:
            c["echoes"] += 1
            a.echoes += 1
            a.min_mm = min(a.min_mm, mm)

    def _latch(self) -> None:
        """The window ends: its figures go to WINDOW, a new one starts."""
        self.seq = self.seq % 0xFFFF + 1  # 1-65535: 0 is "no window yet"
        self.stats["windows"] += 1
        rows = []
        for i, a in enumerate(self.acc):
            rows.append((self.last_mm[i], a.min_mm, min(a.pings, 255), min(a.echoes, 255)))
            self._score(a)
        self.window = P.encode_window(self.seq, rows)
        self.acc = [_Acc() for _ in range(P.SENSORS)]
        self.window_end += WINDOW_MS * 1_000_000

    def _score(self, a: _Acc) -> None:
        if not a.pings:
            return
        s = self.score
        s["sensor_windows"] += 1
        if a.true_min_m <= MAX_MM / 1000:
            s["in_reach"] += 1
            if a.echoes:
                s["valid_in_reach"] += 1
                err = a.min_mm / 1000 - max(a.true_min_m, MIN_MM / 1000)
                s["err_n"] += 1
                s["err_sum_m"] += err
                s["err_abs_m"] += abs(err)
                s["err_sq_m2"] += err * err
        elif a.echoes:
            s["phantom"] += 1

    # -- the motors ------------------------------------------------------------------------------------------------
    def _loop(self, t: int, sens: dict[str, Any]) -> None:
        self.stats["loops"] += 1
        dt = self.period_ns / 1e9
        enc = sens.get("encoders") or self.counts
        self.counts = (int(enc[0]), int(enc[1]))
        if self.prev_counts is not None:
            self.speeds = tuple(
                round((c - p) * self.m.mm_per_count / dt)  # type: ignore[assignment]
                for c, p in zip(self.counts, self.prev_counts, strict=True)
            )
        self.prev_counts = self.counts
        self.millis = (t - self.t0) // 1_000_000
        self.battery_mv = round(float(sens.get("battery_v", 0.0)) * 1000)
        wd_ns = self.watchdog * 10_000_000
        active = self.speed_sp != (0, 0) if self.speed_loop else self.pwm_sp != (0, 0)
        if active and wd_ns and self.last_cmd_ns is not None and t - self.last_cmd_ns >= wd_ns:
            self.speed_sp, self.pwm_sp = (0, 0), (0, 0)
            self.watchdog_stopped = True
            self.stats["watchdog_stops"] += 1
        if self.speed_loop:
            pps = [sp / self.m.mm_per_count for sp in self.speed_sp]
            self.pwm = tuple(
                pid.update(v, c, dt)  # type: ignore[assignment]
                for pid, v, c in zip(self.pid, pps, self.counts, strict=True)
            )
        else:
            self.pwm = self.pwm_sp

    # -- the TWI slave ---------------------------------------------------------------------------------------------
    def receive(self, segments: list[tuple[int, bool, bytes | int]], txn: Any = None) -> list[bytes | None]:
        """One transaction's messages to this board (or a part of it, with the same ``txn``): writes applied whole,
        reads answered; a refused read (``None``) ends it, the master stops there."""
        if txn is None or txn != self.txn:
            self.stats["transactions"] += 1
        self.txn = txn
        replies: list[bytes | None] = []
        for _addr, read, data in segments:
            if read:
                got = self._read(int(data))  # type: ignore[arg-type]
                replies.append(got)
                if got is None:
                    break
                continue
            buf = bytes(data)  # type: ignore[arg-type]
            if not buf:
                continue
            self.stats["bytes_written"] += len(buf) - 1
            self.pointer = buf[0]
            if len(buf) > P.RX_BUFFER:
                self._refuse(P.ERR_OVERFLOW)
            elif len(buf) > 1:
                self._write(buf[0], buf[1:])
        return replies

    def _read(self, n: int) -> bytes | None:
        """A read of ``n`` bytes from the pointer; None: refused (the pointer is at a missing register)."""
        if self.pointer not in P.READABLE:
            self.stats["refused_reads"] += 1
            self._report(P.ERR_BAD_REGISTER)
            return None
        image = self._image()
        regs = [(self.pointer + k) & 0xFF for k in range(n)]
        self.pointer = (self.pointer + n) & 0xFF
        self.stats["bytes_read"] += n
        if any(r not in P.READABLE for r in regs):
            self.stats["bad_reads"] += 1
            self._report(P.ERR_BAD_REGISTER)
        return bytes(image[r] if r in P.READABLE else 0xFF for r in regs)

    def _write(self, reg: int, data: bytes) -> None:
        regs = [reg + k for k in range(len(data))]
        if any(r not in P.WRITABLE for r in regs):
            return self._refuse(P.ERR_READ_ONLY)
        touched = set(regs)
        for base, n in P.FIELDS.items():
            field = set(range(base, base + n))
            if touched & field and not field <= touched:
                return self._refuse(P.ERR_PARTIAL)
        vals = dict(zip(regs, data, strict=True))
        if P.FIRING in vals and vals[P.FIRING] > P.FIRING_IDEAL:
            return self._refuse(P.ERR_VALUE)
        pwm = speed = None
        if P.PWM_SP in vals:
            pwm = struct.unpack("<hh", bytes(vals[P.PWM_SP + k] for k in range(4)))
            if any(abs(v) > 255 for v in pwm):
                return self._refuse(P.ERR_VALUE)
        if P.SPEED_SP in vals:
            speed = struct.unpack("<hh", bytes(vals[P.SPEED_SP + k] for k in range(4)))
        if P.ERROR_COUNT in vals:
            self.error_count = self.last_error = 0
        if P.FIRING in vals:
            self.trig_due = self.trig_due or vals[P.FIRING] != self.firing
            self.firing = vals[P.FIRING]
        if P.WATCHDOG in vals:
            self.watchdog = vals[P.WATCHDOG]
        cap = self.m.max_speed_mm_s
        if speed is not None:
            self.speed_sp = tuple(max(-cap, min(cap, v)) for v in speed)  # type: ignore[assignment]
            if not self.speed_loop:
                for pid in self.pid:
                    pid.reset()
            self.speed_loop = True
        if pwm is not None:
            self.pwm_sp = pwm
            self.speed_loop = False
        if speed is not None or pwm is not None:
            self.last_cmd_ns = self.now
            self.watchdog_stopped = False
        return None

    def _refuse(self, code: int) -> None:
        self.stats["refused_writes"] += 1
        self._report(code)

    def _report(self, code: int) -> None:
        self.error_count = min(255, self.error_count + 1)
        self.last_error = code

    def _image(self) -> bytearray:
        """The registers as a read sees them now."""
        img = bytearray(b"\xff" * 256)
        status = (
            (P.ST_WATCHDOG if self.watchdog_stopped else 0)
            | (P.ST_ERROR if self.error_count else 0)
            | (P.ST_SPEED_LOOP if self.speed_loop else 0)
            | (P.ST_WINDOW if self.seq else 0)
        )
        img[P.WHO_AM_I : P.WATCHDOG + 1] = bytes(
            [P.WHO_AM_I_VALUE, P.VERSION_VALUE, status, self.error_count, self.last_error, self.firing, self.watchdog]
        )
        img[P.WINDOW_MS : P.WINDOW_MS + 2] = struct.pack("<H", WINDOW_MS)
        img[P.WINDOW : P.WINDOW + P.WINDOW_BYTES] = self.window
        img[P.SPEED_SP : P.SPEED_SP + 4] = P.pack_pair(*self.speed_sp)
        img[P.PWM_SP : P.PWM_SP + 4] = P.pack_pair(*self.pwm_sp)
        img[P.ODOMETRY : P.ODOMETRY + P.ODOMETRY_BYTES] = P.encode_odometry(
            P.OdometryBlock(*self.counts, *self.speeds, *self.pwm, self.millis, self.battery_mv)
        )
        return img

    # -- the summary ----------------------------------------------------------------------------------------------
    @property
    def counters(self) -> dict[str, Any]:
        """The counters, and the windows scored against the true ranges: the share of sensor-windows with a surface
        within 4 m that reported an echo, the window minimum's error (mean, mean absolute, RMS, mm), and echoes
        reported where nothing was within reach (cross-talk)."""
        s = self.score
        n = s["err_n"]
        sim_s = max(self.now - self.t0, 1) / 1e9
        return {
            **self.stats,
            "ping_hz_per_sensor": round(self.stats["pings"] / P.SENSORS / sim_s, 3),
            "sonar_windows": {
                "sensor_windows": s["sensor_windows"],
                "in_reach": s["in_reach"],
                "valid_fraction": round(s["valid_in_reach"] / s["in_reach"], 4) if s["in_reach"] else None,
                "phantom": s["phantom"],
                "error_mean_mm": round(1000 * s["err_sum_m"] / n, 2) if n else None,
                "error_abs_mm": round(1000 * s["err_abs_m"] / n, 2) if n else None,
                "error_rms_mm": round(1000 * math.sqrt(s["err_sq_m2"] / n), 2) if n else None,
            },
        }
