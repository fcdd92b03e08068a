"""A DeciZebro leg module's ZebroBus registers and its motion, driven directly (no bus, no session): what a write
transaction does, guards, auto-increment, buffering until motion update, the general call, errors, the loss-of-sync
emergency stop, and the leg tracking its phase-locked target with a motor model."""

from __future__ import annotations

import math

import pytest

from firmware_sim.robots.decizebro import zebrobus as zb
from firmware_sim.robots.decizebro.leg_module import LegModule

MS = 1_000_000
S = 1_000_000_000


class Leg:
    """A leg module on a first-order motor (as the world's legs model has it), stepped every 10 ms."""

    def __init__(self, position: int = 0) -> None:
        self.m = LegModule(position)
        self.t = 0
        self.angle = 0.0
        self.omega = 0.0
        self.duty = 0.0
        self.txn = 0
        self.out: list[list] = []
        self.tick([])

    def sens(self) -> dict:
        return {"angle": self.angle % (2 * math.pi), "omega": self.omega, "battery_v": 14.4}

    def tick(self, items: list) -> dict:
        res = self.m.run(self.t, {"in": items, "sens": self.sens()})
        self.out += res["out"]
        if "pins" in res:
            self.duty = res["pins"]["duty"]
        return res

    def advance(self, dt_ns: int) -> None:
        """Let time pass in 10 ms quanta: the motor moves, the module runs its loops."""
        end = self.t + dt_ns
        while self.t < end:
            w_ss = self.duty * 170 * 2 * math.pi / 60 * 1.2
            decay = math.exp(-0.01 / 0.08)
            self.angle += w_ss * 0.01 + (self.omega - w_ss) * 0.08 * (1 - decay)
            self.omega = w_ss + (self.omega - w_ss) * decay
            self.t += 10 * MS
            self.tick([])

    def write(self, reg: int, *data: int, addr: int | None = None) -> None:
        self.txn += 1
        self.tick([["i2c", self.txn, [[self.m.address if addr is None else addr, False, bytes([reg, *data])]]]])

    def read(self, reg: int, n: int = 1) -> bytes:
        self.txn += 1
        self.out.clear()
        self.tick([["i2c", self.txn, [[self.m.address, False, bytes([reg])], [self.m.address, True, n]]]])
        (reply,) = [o for o in self.out if o[0] == "i2c"]
        assert reply[1] == self.txn
        return reply[2][0]

    def sync(self, value: int) -> None:
        self.write(zb.SYNC_COUNTER, value, addr=zb.GENERAL_CALL)


def test_the_shared_fields_and_the_attach() -> None:
    leg = Leg(3)
    assert leg.out[0] == ["i2c_attach", 0x13, True]  # it answers 0x10 + its position, and the general call
    assert leg.read(zb.ZEBROBUS_VERSION, 7) == bytes([1, zb.LEG_CLASS, 1, 1, 1, 1, 0x13])
    assert leg.read(zb.MOTOR_VOLTAGE) == bytes([12])
    with pytest.raises(ValueError):
        zb.leg_address(6)


def test_auto_increment_and_the_pointer_reset_after_stop() -> None:
    leg = Leg()
    leg.write(zb.TEST_FIELD, 0x42, 0x43)  # 0x60 <- 0x42, then 0x61 (read-only) <- 0x43: refused
    assert leg.read(zb.TEST_FIELD) == b"\x42"
    assert leg.m.vregs[zb.LAST_ERROR] == zb.ERR_READ_ONLY and leg.m.vregs[zb.ERROR_COUNTER] == 1
    # START 0x60 0x44 STOP, then START READ STOP: the read starts at 0x60 again (the spec's example)
    leg.write(zb.TEST_FIELD, 0x44)
    leg.txn += 1
    leg.out.clear()
    leg.tick([["i2c", leg.txn, [[0x10, True, 2]]]])
    assert leg.out[-1][2] == [bytes([0x44, 0])]
    assert leg.read(0xFF, 2) == bytes([0, 1])  # the pointer wraps from 0xFF to 0x00 (ZebroBus version 1)


def test_multi_byte_fields_are_big_endian() -> None:
    leg = Leg()
    leg.angle = math.radians(123.45)
    leg.advance(10 * MS)
    assert int.from_bytes(leg.read(zb.LEG_ANGLE, 2), "big") == 12345
    assert int.from_bytes(leg.read(zb.BATTERY_MV, 2), "big") == 14400


def test_write_guards() -> None:
    leg = Leg()
    serial = leg.m.vregs[zb.SERIAL_ID]
    leg.write(zb.SERIAL_ID, 99)  # without the guard value first: refused, an error
    assert leg.m.vregs[zb.SERIAL_ID] == serial and leg.m.vregs[zb.LAST_ERROR] == zb.ERR_WRITE_GUARD
    leg.write(zb.SERIAL_ID, zb.SERIAL_GUARD)
    assert leg.m.vregs[zb.SERIAL_ID] == serial  # armed, not yet written
    leg.write(zb.SERIAL_ID, 99)
    assert leg.read(zb.SERIAL_ID) == bytes([99])
    leg.write(zb.MOTOR_VOLTAGE, 14)
    assert leg.read(zb.MOTOR_VOLTAGE) == bytes([12])
    leg.write(zb.MOTOR_VOLTAGE, zb.MOTOR_VOLTAGE_GUARD)
    leg.write(zb.MOTOR_VOLTAGE, 14)
    assert leg.read(zb.MOTOR_VOLTAGE) == bytes([14])
    assert leg.m.counters["refused_writes"] == 2


def test_errors_count_distinct_codes_and_any_write_clears_them() -> None:
    leg = Leg()
    leg.write(zb.CLASS_ID, 5)
    leg.write(zb.PRODUCT_ID, 5)
    leg.write(zb.SERIAL_ID, 5)
    assert leg.read(zb.ERROR_COUNTER, 2) == bytes([2, zb.ERR_WRITE_GUARD])  # two distinct errors, the last one
    assert leg.read(zb.QUICK_STATUS)[0] & zb.QS_ERROR == 0  # quick status is updated by the loop
    leg.advance(10 * MS)
    assert leg.read(zb.QUICK_STATUS)[0] & zb.QS_ERROR
    leg.write(zb.ERROR_COUNTER, 0x77)
    assert leg.read(zb.ERROR_COUNTER, 2) == b"\x00\x00"


def test_motion_fields_are_buffered_until_motion_update() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 120, 0)  # mode, speed, phase, extra: buffered
    assert leg.read(zb.MOTION_MODE, 4) == bytes(4)  # reads show the active values
    leg.write(zb.MOTION_UPDATE, 0xAB)  # any value activates
    assert leg.read(zb.MOTION_MODE, 4) == bytes([zb.MODE_WALK, 6, 120, 0])
    assert (leg.m.mode, leg.m.speed, leg.m.phase) == (zb.MODE_WALK, 6, 120)
    leg.write(zb.MOTION_UPDATE, 0)  # the buffer cleared after the update: this activates zeros (idle)
    assert leg.read(zb.MOTION_MODE, 4) == bytes(4)


def test_one_block_write_activates_a_motion_and_speed_is_signed() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_ROTATE, 0xFE, 10, 0, 0, 1)  # speed -2 (backwards 20 rpm), then update
    assert leg.m.speed == -2 and leg.m.mode == zb.MODE_ROTATE


def test_general_call_reaches_the_leg_and_reads_there_are_refused() -> None:
    leg = Leg()
    leg.write(zb.TEST_FIELD, 7, addr=zb.GENERAL_CALL)
    assert leg.m.vregs[zb.TEST_FIELD] == 7 and leg.m.counters["general_calls"] == 1
    leg.out.clear()
    leg.tick([["i2c", 99, [[zb.GENERAL_CALL, True, 1]]]])
    assert leg.m.counters["reads_refused"] == 1


def test_out_of_range_phase_and_unknown_mode_are_errors() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 0, 0, 0, 1)
    leg.write(zb.MOTION_MODE, 9, 6, 0, 0, 0, 1)  # unknown mode: refused, the walk goes on
    assert leg.m.mode == zb.MODE_WALK and leg.m.vregs[zb.LAST_ERROR] == zb.ERR_MOTION_MODE
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 240, 0, 0, 1)  # phase 240-255: an error, and the leg stops
    assert leg.m.mode == zb.MODE_IDLE and leg.m.vregs[zb.LAST_ERROR] == zb.ERR_MOTION_PHASE


def test_malformed_bus_items_are_counted_and_dropped() -> None:
    leg = Leg()
    leg.tick([["i2c", 1, [[0x10, False, "text"]]], ["i2c", 2], ["other"], ["i2c", 3, [[0x10, True, "n"]]]])
    assert leg.m.counters["malformed"] == 4 and leg.m.counters["transactions"] == 0


def test_a_write_queue_overflow_is_an_error() -> None:
    leg = Leg()
    leg.write(zb.TEST_FIELD, *range(60))  # 49 are queued (0x61 on are read-only), the rest is lost
    assert leg.m.counters["queue_overflows"] == 1 and leg.m.errors == {zb.ERR_WRITE_QUEUE_FULL, zb.ERR_READ_ONLY}


def test_the_leg_walks_phase_locked_to_the_sync() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 60, 0, 0, 1)  # 60 rpm, a quarter turn ahead at tau = 0
    for k in range(1, 5):
        leg.advance(S - 10 * MS)
        leg.sync(k)
        leg.advance(10 * MS)
    # at tau = 4 s + 10 ms the target is 90 deg + 4.01 turns
    target = (math.pi / 2 + 2 * math.pi * 4.01) % (2 * math.pi)
    err = (leg.angle - target + math.pi) % (2 * math.pi) - math.pi
    assert abs(err) < math.radians(5), math.degrees(err)
    assert abs(leg.omega - 2 * math.pi) < 0.3
    assert leg.m.vregs[zb.QUICK_STATUS] & (zb.QS_MOVING | zb.QS_TIMING) == zb.QS_MOVING | zb.QS_TIMING
    assert leg.duty > 0 and leg.m.estop is False


def test_walk_trim_is_a_fine_speed() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 0, 0xCE, 0, 1)  # 60 rpm - 5.0 rpm
    leg.advance(900 * MS)
    assert math.isclose(leg.m._omega(), 55 * 2 * math.pi / 60)
    assert abs(leg.omega - 55 * 2 * math.pi / 60) < 0.3


def test_fixed_position_goes_the_commanded_way_and_holds() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_FIXED, 3, 180, 0, 0, 1)  # to 270 deg, forward at 30 rpm
    lowest = 0.0
    for _ in range(25):
        leg.sync(0)
        leg.advance(200 * MS)
        lowest = min(lowest, leg.angle)
    assert lowest > -0.05  # never went backwards (the short way would have been)
    assert abs(leg.angle - 1.5 * math.pi) < math.radians(3) and abs(leg.omega) < 0.1


def test_sync_rollover_keeps_the_motion_continuous() -> None:
    leg = Leg()
    leg.sync(254)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 5, 0, 7, 0, 1)  # 50.7 rpm
    leg.advance(S)
    leg.sync(255)
    leg.advance(S)
    before = (leg.m.phase_rad + leg.m._omega() * 256) % (2 * math.pi)
    leg.sync(0)
    assert math.isclose(leg.m.phase_rad, before)  # the phase moved on by what 256 s turn
    jump = leg.duty
    leg.advance(500 * MS)
    assert abs(leg.omega - leg.m._omega()) < 0.3 and -0.5 < jump < 1


def test_no_sync_for_two_seconds_stops_the_leg() -> None:
    leg = Leg()
    leg.sync(0)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 0, 0, 0, 1)
    leg.advance(S)
    leg.sync(1)
    last_sync = leg.t
    while not leg.m.estop:
        leg.advance(10 * MS)
    assert leg.t - last_sync == 2 * S  # the RTC overflows 2048 / 1024 Hz after the sync write
    assert leg.duty == 0.0 and leg.m.mode == zb.MODE_IDLE
    assert leg.read(zb.LAST_ERROR) == bytes([zb.ERR_ZEBROBUS_NO_TIMING_INFO])
    assert leg.read(zb.EMERGENCY_STOP) == b"\x01"
    leg.advance(600 * MS)
    assert abs(leg.omega) < 0.05  # the motor has run down
    # the sync comes back: still stopped until the controller clears the stop and sends a motion again
    leg.sync(2)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 0, 0, 0, 1)
    leg.advance(100 * MS)
    assert leg.duty == 0.0
    leg.write(zb.EMERGENCY_STOP, 0x13)  # the wrong value: an error, stays stopped
    assert leg.m.estop and leg.m.vregs[zb.LAST_ERROR] == zb.ERR_EMERGENCY_STOP_RESET
    leg.write(zb.EMERGENCY_STOP, zb.ESTOP_CLEAR)
    leg.write(zb.MOTION_MODE, zb.MODE_WALK, 6, 0, 0, 0, 1)
    leg.advance(100 * MS)
    assert not leg.m.estop and leg.duty > 0


def test_the_module_stops_two_seconds_after_power_up_without_any_sync() -> None:
    leg = Leg()
    leg.advance(2 * S - 10 * MS)
    assert not leg.m.estop
    leg.advance(10 * MS)
    assert leg.m.estop and leg.m.counters["estops"] == 1
