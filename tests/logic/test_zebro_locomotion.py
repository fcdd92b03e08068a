"""The DeciZebro's locomotion layer: what it writes on the bus (a recording stand-in bus), and the legs it drives (leg
modules on the simulated bus, on the lock-step bench): the tripod gait, the 1 Hz sync by general call, turning by a
left/right speed difference, forward only, the fast mode's cap, halting, bus errors counted, and the legs stopping
when the sync stops."""

from __future__ import annotations

import ctypes
import errno
import math
from typing import Any

import pytest

from bridge.sitl.smbus import SMBus
from firmware_sim.robots.decizebro import zebrobus as zb
from swarm_logic.robots.decizebro import locomotion as loco
from swarm_logic.robots.decizebro.locomotion import ZebroLegs, open_legs, quantise
from tests.support.i2c_bench import I2cBench, Q

TWO_PI = 2 * math.pi


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


class Bus:
    """Records block writes; addresses in ``absent`` raise what the Linux driver raises for a NACK."""

    def __init__(self, absent: set[int] = frozenset()) -> None:  # type: ignore[assignment]
        self.writes: list[tuple[int, int, list[int]]] = []
        self.transactions = 0  # i2c_rdwr calls
        self.absent = set(absent)
        self.status = dict.fromkeys(range(0x10, 0x16), 0)

    def write_i2c_block_data(self, addr: int, reg: int, data: list[int]) -> None:
        if addr in self.absent:
            raise OSError(121, "Remote I/O error")
        self.writes.append((addr, reg, list(data)))

    def i2c_rdwr(self, *msgs: Any) -> None:
        """One transaction; as on Linux, the messages before a NACKed one went out, then it fails."""
        self.transactions += 1
        pointer: dict[int, int] = {}
        for m in msgs:
            if m.addr in self.absent:
                raise OSError(121, "Remote I/O error")
            if m.flags & 1:  # a read: at the register last written to that address
                value = self.read_byte_data(m.addr, pointer.get(m.addr, 0))
                ctypes.memmove(m.buf, bytes([value]), 1)
                continue
            data = list(bytes(m))
            pointer[m.addr] = data[0]
            if len(data) > 1:
                self.writes.append((m.addr, data[0], data[1:]))

    def read_byte_data(self, addr: int, reg: int) -> int:
        if addr in self.absent:
            raise OSError(121, "Remote I/O error")
        return self.status[addr] if reg == loco.QUICK_STATUS else 0

    def motions(self) -> dict[int, list[int]]:
        return {a: d for a, r, d in self.writes if r == loco.MOTION_MODE and a != loco.GENERAL_CALL}


def rpm_of(block: list[int]) -> float:
    """A leg's speed as a motion block (mode, speed, phase, extra, CRC, update) sets it."""
    return loco.leg_rpm(block[1] - 256 * (block[1] > 127), block[3] - 256 * (block[3] > 127))


def test_the_register_map_is_the_firmwares() -> None:
    assert (loco.QUICK_STATUS, loco.SYNC_COUNTER, loco.EMERGENCY_STOP, loco.MOTION_MODE) == (
        zb.QUICK_STATUS, zb.SYNC_COUNTER, zb.EMERGENCY_STOP, zb.MOTION_MODE)
    assert (loco.MODE_WALK, loco.QS_ESTOP, loco.ESTOP_CLEAR, loco.PHASE_STEPS) == (
        zb.MODE_WALK, zb.QS_ESTOP, zb.ESTOP_CLEAR, zb.PHASE_STEPS)
    assert zb.MOTION_UPDATE == loco.MOTION_MODE + 5  # the 6-byte block ends on motion update


def test_speeds_are_quantised_to_10_rpm_plus_a_fine_trim() -> None:
    assert quantise(60.0) == (6, 0) and quantise(57.3) == (6, -27) and quantise(0.0) == (0, 0)
    assert quantise(500.0) == (17, 0)
    for rpm in (12.34, 55.5, 169.9):
        s, trim = quantise(rpm)
        assert abs(loco.leg_rpm(s, trim) - rpm) <= 0.05


def test_it_syncs_once_a_second_by_general_call_and_starts_the_tripod() -> None:
    clock, bus = Clock(), Bus()
    legs = ZebroLegs(bus, clock)
    legs.walk(0.0)
    for _ in range(35):
        clock.sleep(0.1)
        legs.poll()
    syncs = [d[0] for a, r, d in bus.writes if r == loco.SYNC_COUNTER]
    assert syncs == [0, 1, 2, 3] and all(a == 0x00 for a, r, _ in bus.writes if r == loco.SYNC_COUNTER)
    m = bus.motions()
    assert sorted(m) == list(range(0x10, 0x16))
    assert all(d[:2] == [loco.MODE_WALK, 6] and d[3:] == [0, 0, 1] for d in m.values())  # 60 rpm, update
    phases = [m[0x10 + i][2] for i in range(6)]
    assert phases == [0, 120, 0, 120, 0, 120]  # 0-2-4 and 1-3-5 half a turn apart
    assert math.isclose(legs.speed_mps, 0.05 * TWO_PI)  # 60 rpm of a 50 mm leg
    assert legs.counters["motion_writes"] == 7  # the halt it starts with (one general call), then one per leg
    assert bus.transactions == 1  # the six legs' blocks in one transaction: they start together
    assert legs.counters["late_syncs"] == 0
    clock.sleep(1.5)  # the program did not poll for 2 s
    legs.poll()
    assert legs.counters["late_syncs"] == 1


def test_turning_is_a_speed_difference_and_never_backwards() -> None:
    clock, bus = Clock(), Bus()
    legs = ZebroLegs(bus, clock)
    legs.walk(0.5)  # left turn: the right legs faster
    m = bus.motions()
    rpm = {a: rpm_of(d) for a, d in m.items()}
    v = legs.speed_mps
    dv_rpm = 0.5 * 0.21 / 2 / (0.05 * TWO_PI / 60)
    assert all(abs(rpm[0x10 + i] - (60 - dv_rpm)) < 0.06 for i in loco.LEFT)
    assert all(abs(rpm[0x10 + i] - (60 + dv_rpm)) < 0.06 for i in loco.RIGHT)
    for turn in (-100.0, 100.0, -1e9):
        legs.walk(turn)
        assert all(rpm_of(d) >= 0 for d in bus.motions().values())
    assert v == legs.speed_mps
    assert not hasattr(legs, "backwards") and "fast" in ZebroLegs.walk.__code__.co_varnames
    with pytest.raises(ValueError):
        legs.walk(math.nan)


def test_fast_is_three_times_capped_by_the_motor() -> None:
    clock, bus = Clock(), Bus()
    legs = ZebroLegs(bus, clock, walk_rpm=50.0)
    legs.walk(0.0, fast=True)
    assert {tuple(d[1:4:2]) for d in bus.motions().values()} == {(15, 0)}  # 150 rpm
    ZebroLegs(bus2 := Bus(), clock).walk(0.0, fast=True)
    assert {tuple(d[1:4:2]) for d in bus2.motions().values()} == {(17, 0)}  # 180 rpm asked, 170 the motor's


def test_at_the_motors_cap_the_turn_is_kept() -> None:
    """The fast leader still steers: the outer side at the cap, the inner side slower by the turn's difference."""
    clock, bus = Clock(), Bus()
    legs = ZebroLegs(bus, clock)
    legs.walk(0.5, fast=True)  # left: the right legs at 170 rpm, the left ones slower
    rpm = {a: rpm_of(d) for a, d in bus.motions().items()}
    dv_rpm = 0.5 * 0.21 / 2 / (0.05 * TWO_PI / 60)
    assert all(abs(rpm[0x10 + i] - 170) < 0.06 for i in loco.RIGHT)
    assert all(abs(rpm[0x10 + i] - (170 - 2 * dv_rpm)) < 0.06 for i in loco.LEFT)
    legs.walk(-0.5, fast=True)
    rpm = {a: rpm_of(d) for a, d in bus.motions().items()}
    assert all(abs(rpm[0x10 + i] - 170) < 0.06 for i in loco.LEFT)
    assert all(rpm[0x10 + i] < 170 - 2 * dv_rpm + 0.06 for i in loco.RIGHT)


def test_a_speed_change_keeps_each_legs_target_continuous() -> None:
    clock, bus = Clock(), Bus()
    legs = ZebroLegs(bus, clock)
    legs.walk(0.0)
    for _ in range(23):
        clock.sleep(0.1)
        legs.poll()
    before = [(leg.phase_rad + leg.omega * legs._tau(clock.now())) % TWO_PI for leg in legs.legs]
    legs.walk(0.3)
    after = [(leg.phase_rad + leg.omega * legs._tau(clock.now())) % TWO_PI for leg in legs.legs]
    half = TWO_PI / 240 / 2  # the phase is written in 1.5 degree steps
    assert all(abs((a - b + math.pi) % TWO_PI - math.pi) <= half + 1e-9 for a, b in zip(after, before, strict=True))
    writes = len(bus.writes)
    legs.walk(0.3001)  # below the resend threshold: nothing written
    assert len(bus.writes) == writes


def test_halt_is_one_general_call_and_bus_errors_are_counted() -> None:
    clock, bus = Clock(), Bus(absent={0x12})
    legs = ZebroLegs(bus, clock)
    legs.walk(0.0)  # the six blocks in one transaction fail; then one each: leg 2's fails
    assert legs.counters["bus_errors"] == 2 and "0x12" in legs.last_error
    assert sorted(bus.motions()) == [0x10, 0x11, 0x13, 0x14, 0x15]
    legs.poll()  # retried at each poll
    assert legs.counters["bus_errors"] == 3
    bus.absent.clear()
    legs.poll()
    assert 0x12 in bus.motions()
    legs.halt()
    assert bus.writes[-1] == (0x00, loco.MOTION_MODE, [loco.MODE_IDLE, 0, 0, 0, 0, 1])
    n = len(bus.writes)
    legs.halt()
    assert len(bus.writes) == n


def test_an_emergency_stop_found_is_cleared_and_the_motion_resent() -> None:
    clock, bus = Clock(), Bus()
    legs = ZebroLegs(bus, clock, check_every_s=1.0)
    legs.walk(0.0)
    bus.status[0x13] = loco.QS_ESTOP
    bus.writes.clear()
    clock.sleep(1.0)
    legs.poll()
    assert (0x13, loco.EMERGENCY_STOP, [loco.ESTOP_CLEAR]) in bus.writes and 0x13 in bus.motions()
    assert legs.counters["estops_cleared"] == 1 and set(bus.motions()) == {0x13}
    assert bus.transactions == 2  # the six legs' statuses were read in one transaction
    bus.absent.add(0x15)
    clock.sleep(1.0)
    legs.poll()  # the transaction fails; then one read each: five answer
    assert legs.counters["bus_errors"] == 2 and "0x15" in legs.last_error


def test_open_legs_takes_the_hal_table() -> None:
    with pytest.raises(FileNotFoundError):
        open_legs({"bus": "sitl://i2c"}, type("R", (), {"clock": Clock()})())  # no session here
    with pytest.raises(ValueError, match="gait"):
        ZebroLegs(Bus(), Clock(), gait="gallop")


# -- on the bench: the leg modules on the simulated bus, their legs on motors ------------------------------------

def walk_bench(seconds: float, turn: float = 0.0, stop_sync_at: float | None = None,
               resume_sync_at: float | None = None) -> tuple[I2cBench, dict[str, Any]]:
    got: dict[str, Any] = {}

    def program(rt, clock) -> None:
        legs = ZebroLegs(SMBus("sitl://i2c"), clock, check_every_s=1.0)
        got["legs"] = legs
        legs.walk(turn)
        t_next = clock.now()
        while True:
            t = clock.now()
            if stop_sync_at is not None and t >= stop_sync_at:
                legs.sync = resume_sync_at is not None and t >= resume_sync_at
            legs.poll()
            t_next += 0.1
            clock.sleep_until(t_next)

    b = I2cBench(program)
    try:
        b.run_until(round(seconds * 1e9))
    finally:
        b.close()
    return b, got


def test_the_legs_walk_a_tripod_at_the_walking_speed() -> None:
    b, got = walk_bench(6.0)
    a = b.angle
    for i in (2, 4):
        assert abs((a[i] - a[0] + math.pi) % TWO_PI - math.pi) < math.radians(8)
    for i in (1, 3, 5):
        assert abs((a[i] - a[0]) % TWO_PI - math.pi) < math.radians(8)
    assert all(abs(w - TWO_PI) < 0.4 for w in b.omega)  # 60 rpm each
    assert all(not m.estop for m in b.modules.values())
    assert min(a) > 4 * TWO_PI  # over 4 turns in 6 s (with the first second's catching up)
    assert got["legs"].counters["bus_errors"] == 0
    syncs = [t for t in b.transactions() if t["msgs"][0]["addr"] == 0 and t["msgs"][0]["data"][:2] == "12"]
    assert len(syncs) == 6


def test_the_right_legs_turn_faster_for_a_left_turn() -> None:
    b, _ = walk_bench(4.0, turn=1.0)
    left, right = sum(b.omega[i] for i in loco.LEFT) / 3, sum(b.omega[i] for i in loco.RIGHT) / 3
    assert math.isclose(0.05 * (right - left) / 0.21, 1.0, rel_tol=0.1)


def test_the_legs_stop_within_two_seconds_of_the_last_sync_and_walk_again_after() -> None:
    b, got = walk_bench(10.0, stop_sync_at=3.05, resume_sync_at=7.0)
    syncs = [t["end_ns"] for t in b.transactions() if t["msgs"][0]["addr"] == 0 and t["msgs"][0]["data"][:2] == "12"]
    last = max(s for s in syncs if s < 3.05e9)
    off = {leg: min((t for t, d in b.duty_log if t > last and d[leg] == 0.0), default=None) for leg in range(6)}
    for t_off in off.values():  # every leg's motor was off 2 s after the last sync (+ its loop and the pin write)
        assert t_off is not None and t_off - last <= 2e9 + 2 * Q
    assert all(m.counters["estops"] == 1 for m in b.modules.values())
    assert got["legs"].counters["estops_cleared"] == 6  # the check after the sync came back
    assert all(abs(w - TWO_PI) < 0.5 for w in b.omega)  # walking again at 10 s


def test_an_adapter_that_cannot_combine_the_legs_gets_them_one_by_one() -> None:
    """A USB-ISS refuses six motion blocks in one transaction (EOPNOTSUPP, as Linux for an adapter's limits): not a
    bus error; the layer writes each leg on its own from then on."""

    class Narrow(Bus):
        def i2c_rdwr(self, *msgs: Any) -> None:
            if sum(not m.flags & 1 for m in msgs) > 5 and all(not m.flags & 1 for m in msgs):
                raise OSError(errno.EOPNOTSUPP, "Operation not supported")
            super().i2c_rdwr(*msgs)

    clock, bus = Clock(), Narrow()
    legs = ZebroLegs(bus, clock)
    legs.walk(0.0)
    assert sorted(bus.motions()) == list(range(0x10, 0x16)) and legs.counters["bus_errors"] == 0
    assert not legs.combine and bus.transactions == 0
    legs.walk(0.5)  # a turn changes both sides: written leg by leg at once, without trying the combined write again
    assert legs.counters["bus_errors"] == 0 and bus.transactions == 0
