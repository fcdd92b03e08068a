"""The DeciZebro's locomotion layer on its main computer: six ZebroBus leg modules on the I2C bus, driven as a gait.

What the swarm algorithms get (``robot.device("legs")``, the ``Locomotion`` interface): ``walk(turn_rate_rps,
fast=False)`` walks forward at the walking speed (``fast``: three times it, for the mature algorithm's leader, capped
by the motors' 170 rpm, the turn kept: at the cap the inner side slows) turning at ``turn_rate_rps`` (positive:
left) by a speed difference between the left and right legs; ``halt()`` stands still; ``speed_mps`` is the walking
speed. There is no way to walk backwards: a side's legs never turn backwards (a turn sharper than the walking speed
allows stops the inner side's legs, which bounds the turn rate at ``2 * speed / track``), as the thesis' Zebro
software walks forward only.

Underneath, the legs walk a gait (the tripod by default: legs 0, 2, 4 and 1, 3, 5 half a turn apart), each leg in
ZebroBus walk mode, phase-locked to the synchronised time: the layer writes the sync counter to every leg at once
(general call 0x00) once a second, when the robot polls its devices, and each leg module tracks ``phase + omega *
tau`` with ``tau`` that counter plus the time since it was written. A side's speed is ``10 rpm x motion speed + 0.1
rpm x motion extra`` (the trim); when it changes, each of its legs gets a new phase so that its target goes on
from where it was. The motion blocks of the legs that change go in one transaction (``i2c_rdwr``, a message to each
leg), so they start together. A leg module that has heard no sync for 2 s stops its leg (emergency stop); every
``check_every_s`` the layer reads the legs' quick status (one transaction) and clears an emergency stop it finds,
then resends that leg's motion.

The sync is written when the robot polls its devices, so the robot program must poll them at least once a second
(a controller period of 1 s or less): a late sync is counted (``late_syncs``), and two seconds without one stop the
legs, which is what the legs' emergency stop is for (a program that hangs).

The bus is anything with smbus2's ``write_i2c_block_data`` and ``read_byte_data``: a real ``smbus2.SMBus(1)`` on
the robot (HAL ``legs = {bus = 1}``), the simulated one in a session (``{bus = "sitl://i2c"}``). A bus error (a leg
that does not answer) is counted (``counters``) and retried at the next poll; it never reaches the algorithm.
"""

from __future__ import annotations

import errno
import math
from dataclasses import dataclass
from typing import Any

from smbus2 import i2c_msg

from swarm_logic.clock import Clock
from swarm_logic.drivers.i2c import open_smbus

# ZebroBus v1 as the leg modules answer it (the register map: firmware_sim/robots/decizebro/zebrobus.py)
GENERAL_CALL = 0x00
LEG_ADDRESS_BASE = 0x10
QUICK_STATUS, SYNC_COUNTER, EMERGENCY_STOP = 0x11, 0x12, 0x16
MOTION_MODE = 0x20  # then speed, phase, extra, CRC and update: one 6-byte block write activates a motion
MODE_IDLE, MODE_WALK = 0, 1
QS_ESTOP = 0x01
ESTOP_CLEAR = 0x12
PHASE_STEPS = 240
SPEED_UNIT_RPM, TRIM_UNIT_RPM = 10.0, 0.1
MAX_RPM = 170.0

LEGS = 6
LEFT, RIGHT = (0, 1, 2), (3, 4, 5)
TWO_PI = 2 * math.pi
GAITS = {  # each leg's phase offset (rad): 0-2 left front to back, 3-5 right front to back
    "tripod": (0.0, math.pi, 0.0, math.pi, 0.0, math.pi),  # 0-2-4 and 1-3-5 half a turn apart
}
RESEND_RPM = 0.3  # a side's speed is rewritten when it changes by this much (3 trim steps)
LATE_SYNC_S = 0.5  # a sync written this much after it was due is counted late


def rpm_to_rad_s(rpm: float) -> float:
    return rpm * TWO_PI / 60.0


def quantise(rpm: float) -> tuple[int, int]:
    """(motion speed, motion extra) for a leg speed in rpm: 10 rpm steps plus a signed trim in 0.1 rpm."""
    rpm = max(-MAX_RPM, min(MAX_RPM, rpm))
    speed = max(-17, min(17, round(rpm / SPEED_UNIT_RPM)))
    trim = max(-128, min(127, round((rpm - SPEED_UNIT_RPM * speed) / TRIM_UNIT_RPM)))
    return speed, trim


def leg_rpm(speed: int, trim: int) -> float:
    """What a leg module makes of (speed, trim) in walk mode."""
    return max(-MAX_RPM, min(MAX_RPM, SPEED_UNIT_RPM * speed + TRIM_UNIT_RPM * trim))


@dataclass
class _Leg:
    """What a leg module was last told (as it holds it: the phase as it keeps it after rollovers)."""

    mode: int = MODE_IDLE
    speed: int = 0
    trim: int = 0
    phase_rad: float = 0.0
    sent: bool = False  # False: to be (re)written

    @property
    def omega(self) -> float:
        return rpm_to_rad_s(leg_rpm(self.speed, self.trim)) if self.mode == MODE_WALK else 0.0


class ZebroLegs:
    """The six legs as one walking device (see the module docstring)."""

    def __init__(self, bus: Any, clock: Clock, *, walk_rpm: float = 60.0, leg_radius_m: float = 0.05,
                 track_m: float = 0.21, gait: str = "tripod", sync_period_s: float = 1.0,
                 check_every_s: float = 5.0) -> None:
        if gait not in GAITS:
            raise ValueError(f"gait {gait!r}: known gaits are {', '.join(GAITS)}")
        if not 0 < walk_rpm <= MAX_RPM:
            raise ValueError(f"walk_rpm must be in (0, {MAX_RPM:g}], got {walk_rpm}")
        self.bus = bus
        self.clock = clock
        self.walk_rpm = walk_rpm
        self.leg_radius_m = leg_radius_m
        self.track_m = track_m
        self.offsets = GAITS[gait]
        self.sync_period_s = sync_period_s
        self.check_every_s = check_every_s
        self.sync = True  # False stops the 1 Hz sync write (fault injection: the legs then stop within 2 s)
        self.legs = [_Leg() for _ in range(LEGS)]
        self.target_rpm: tuple[float, float] | None = None  # (left, right); None: halted
        self.sync_value = -1  # the last value written (-1: none yet)
        self.sync_at = 0.0  # when it was written (its transaction's end)
        now = clock.now()
        self.next_sync = now
        self.next_check = now + check_every_s
        self.halted_sent = False
        self.counters = {"sync_writes": 0, "late_syncs": 0, "motion_writes": 0, "bus_errors": 0, "estops_cleared": 0}
        self.last_error = ""
        self.combine = True  # the bus carries the legs' motion blocks in one transaction (a USB-ISS cannot: six
        # blocks overflow its 60-byte command frame, refused as Linux refuses what an adapter cannot do: EOPNOTSUPP)
        self.poll()

    # -- what the algorithms use -----------------------------------------------------------------------------
    @property
    def speed_mps(self) -> float:
        """The walking speed (forward, m/s): what ``walk(0)`` gives."""
        return self.leg_radius_m * rpm_to_rad_s(self.walk_rpm)

    def walk(self, turn_rate_rps: float, fast: bool = False) -> None:
        """Walk forward at the walking speed (3x if ``fast``), turning at ``turn_rate_rps`` (rad/s, left positive)."""
        if not math.isfinite(turn_rate_rps):
            raise ValueError(f"turn rate must be finite, got {turn_rate_rps}")
        v = self.speed_mps * (3.0 if fast else 1.0)
        dv = turn_rate_rps * self.track_m / 2
        rim = rpm_to_rad_s(1.0) * self.leg_radius_m  # m/s per rpm
        left, right = ((v + s * dv) / rim for s in (-1, 1))
        over = max(left, right) - MAX_RPM  # the motors' cap: slow both sides, so that the turn is kept
        if over > 0:
            left, right = left - over, right - over
        self.target_rpm = (max(0.0, left), max(0.0, right))  # forward only
        self._apply()

    def halt(self) -> None:
        """Stand still: every leg holds where it is (idle)."""
        if self.target_rpm is not None or not self.halted_sent:
            self.target_rpm = None
            self.halted_sent = False
            self._apply()

    def poll(self) -> None:
        """The robot's poll: the sync write when due, the legs' check when due, and what is still to be written."""
        now = self.clock.now()
        if self.sync and now >= self.next_sync:
            self._write_sync()
        if self.sync and now >= self.next_check:
            self.next_check = now + self.check_every_s
            self._check()
        self._apply()

    def close(self) -> None:
        """Stop the legs (best effort) and close the bus."""
        self.target_rpm = None
        self.halted_sent = False
        self._apply()
        close = getattr(self.bus, "close", None)
        if close is not None:
            close()

    # -- the bus ------------------------------------------------------------------------------------------------
    def _write(self, addr: int, reg: int, data: list[int]) -> bool:
        try:
            self.bus.write_i2c_block_data(addr, reg, data)
            return True
        except OSError as e:
            self.counters["bus_errors"] += 1
            self.last_error = f"write 0x{reg:02X} to 0x{addr:02X}: {e}"
            return False

    def _tau(self, t: float) -> float:
        """The synchronised time the legs keep at ``t`` (s): the sync counter plus the time since it was written."""
        return max(self.sync_value, 0) + (t - self.sync_at)

    def _write_sync(self) -> None:
        if self.sync_value >= 0 and self.clock.now() - self.next_sync > LATE_SYNC_S:
            self.counters["late_syncs"] += 1  # the robot polls its devices too rarely: the legs may stop
        value = (self.sync_value + 1) % 256
        if not self._write(GENERAL_CALL, SYNC_COUNTER, [value]):
            return
        if value == 0 and self.sync_value == 255:  # time rolled over: the legs moved their phases on by 256 s
            for leg in self.legs:
                if leg.mode == MODE_WALK:
                    leg.phase_rad = (leg.phase_rad + leg.omega * 256.0) % TWO_PI
        self.sync_value = value
        self.sync_at = self.clock.now()
        self.counters["sync_writes"] += 1
        while self.next_sync <= self.sync_at:
            self.next_sync += self.sync_period_s

    def _check(self) -> None:
        """Read each leg's quick status; clear an emergency stop and resend that leg's motion."""
        for i, status in enumerate(self._statuses()):
            addr = LEG_ADDRESS_BASE + i
            if status is not None and status & QS_ESTOP and self._write(addr, EMERGENCY_STOP, [ESTOP_CLEAR]):
                self.counters["estops_cleared"] += 1
                self.legs[i] = _Leg()  # the module fell back to idle: the motion is to be sent again
                self.halted_sent = False

    def _statuses(self) -> list[int | None]:
        """Every leg's quick status (None: it did not answer): in one transaction (the register, then a byte read, for
        each leg), or, if that fails, one read each."""
        if hasattr(self.bus, "i2c_rdwr"):
            msgs = []
            for i in range(LEGS):
                msgs += [i2c_msg.write(LEG_ADDRESS_BASE + i, [QUICK_STATUS]), i2c_msg.read(LEG_ADDRESS_BASE + i, 1)]
            try:
                self.bus.i2c_rdwr(*msgs)
                return [bytes(m)[0] for m in msgs[1::2]]
            except OSError as e:
                self.counters["bus_errors"] += 1
                self.last_error = f"read the legs' quick status: {e}"
        out: list[int | None] = []
        for i in range(LEGS):
            addr = LEG_ADDRESS_BASE + i
            try:
                out.append(self.bus.read_byte_data(addr, QUICK_STATUS))
            except OSError as e:
                self.counters["bus_errors"] += 1
                self.last_error = f"read quick status of 0x{addr:02X}: {e}"
                out.append(None)
        return out

    def _apply(self) -> None:
        """Write what the legs do not have yet: the halt (one general call), or each side's new speed."""
        if self.target_rpm is None:
            if not self.halted_sent and self._write(GENERAL_CALL, MOTION_MODE, [MODE_IDLE, 0, 0, 0, 0, 1]):
                self.halted_sent = True
                self.counters["motion_writes"] += 1
                self.legs = [_Leg(sent=True) for _ in range(LEGS)]
            return
        tau = self._tau(self.clock.now())  # one time for all the legs written now: they keep their gait's phases
        todo: list[tuple[int, _Leg, list[int]]] = []
        for side, rpm in zip((LEFT, RIGHT), self.target_rpm, strict=True):
            speed, trim = quantise(rpm)
            for i in side:
                leg = self.legs[i]
                same = leg.mode == MODE_WALK and abs(leg_rpm(leg.speed, leg.trim) - leg_rpm(speed, trim)) < RESEND_RPM
                if not (leg.sent and same):
                    todo.append((i, *self._walk_block(i, leg, speed, trim, tau)))
        if not todo:
            return
        for (i, new, _), ok in zip(todo, self._write_legs([(i, block) for i, _, block in todo]), strict=True):
            if ok:
                self.legs[i] = new
                self.halted_sent = False
                self.counters["motion_writes"] += 1

    def _walk_block(self, i: int, leg: _Leg, speed: int, trim: int, tau: float) -> tuple[_Leg, list[int]]:
        """Leg ``i`` walking at (speed, trim), its target going on at ``tau`` from where it is (or its gait offset):
        what the leg will hold, and the motion block that tells it."""
        where = (leg.phase_rad + leg.omega * tau) if leg.mode == MODE_WALK else self.offsets[i]
        new = _Leg(MODE_WALK, speed, trim, sent=True)
        steps = round(((where - new.omega * tau) % TWO_PI) / TWO_PI * PHASE_STEPS) % PHASE_STEPS
        new.phase_rad = steps * TWO_PI / PHASE_STEPS
        return new, [MODE_WALK, speed & 0xFF, steps, trim & 0xFF, 0, 1]

    def _write_legs(self, blocks: list[tuple[int, list[int]]]) -> list[bool]:
        """Motion blocks to several legs in one transaction (a message to each, repeated STARTs between them, one
        STOP), so they start together; if that fails (a leg does not answer: Linux does not tell which), one
        transaction each, and from then on if the adapter cannot carry them in one."""
        if len(blocks) > 1 and self.combine and hasattr(self.bus, "i2c_rdwr"):
            try:
                self.bus.i2c_rdwr(*(i2c_msg.write(LEG_ADDRESS_BASE + i, [MOTION_MODE, *b]) for i, b in blocks))
                return [True] * len(blocks)
            except OSError as e:
                if e.errno == errno.EOPNOTSUPP:  # not a bus error: this adapter writes them one leg at a time
                    self.combine = False
                else:
                    self.counters["bus_errors"] += 1
                    self.last_error = f"motion blocks to {len(blocks)} legs: {e}"
        return [self._write(LEG_ADDRESS_BASE + i, MOTION_MODE, b) for i, b in blocks]


def open_legs(cfg: dict[str, Any], robot: Any) -> ZebroLegs:
    """The HAL ``legs`` table's device: ``bus`` (1: the robot's /dev/i2c-1; ``"sitl://i2c"``: a session's simulated
    bus, at ``scl_hz``), and optionally ``walk_rpm``, ``gait``, ``check_every_s``."""
    bus = cfg.get("bus", 1)
    options = {"scl_hz": int(cfg.get("scl_hz", 100_000))} if isinstance(bus, str) and "://" in bus else {}
    return ZebroLegs(open_smbus(bus, **options), robot.clock, walk_rpm=float(cfg.get("walk_rpm", 60.0)),
                     gait=str(cfg.get("gait", "tripod")), check_every_s=float(cfg.get("check_every_s", 5.0)))
