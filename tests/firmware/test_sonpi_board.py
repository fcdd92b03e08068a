"""The SonPI's Arduino sketch driven directly (no bus, no session): its identity and register map, the HC-SR04s' echo
timing and firing modes (sequential 3.3 Hz, simultaneous with cross-talk, ideal 200 Hz), the 250 ms windows, seeded
noise, the wheel speed loop on a motor model, the watchdog, and what it does with bad input."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from firmware_sim.robots.sonpi.hcsr04 import SPEED_OF_SOUND
from firmware_sim.robots.sonpi.sonar_board import echo_mm
from swarm_logic.robots.sonpi import board_protocol as P
from tests.support.sonpi_bench import MOTORS, MS, Board


def test_identity_and_the_attach() -> None:
    b = Board([1.0] * 5)
    assert b.out[0] == ["i2c_attach", P.ADDRESS, False, True]  # no general call; it may refuse reads
    assert b.read(P.WHO_AM_I, 2) == bytes([P.WHO_AM_I_VALUE, P.VERSION_VALUE])
    assert struct.unpack("<H", b.read(P.WINDOW_MS, 2))[0] == 250
    assert b.read(P.FIRING) == bytes([P.FIRING_SEQUENTIAL]) and b.read(P.WATCHDOG) == bytes([50])


def test_sequential_firing_pings_each_sensor_at_3_hz_and_windows_every_250_ms() -> None:
    ranges = [0.5, 1.0, 2.0, 3.0, 0.3]
    b = Board(ranges)
    assert b.window().seq == 0 and not b.read(P.STATUS)[0] & P.ST_WINDOW
    b.advance(240 * MS)
    assert b.window().seq == 0  # the first window is not complete yet
    b.advance(10 * MS)
    assert b.window().seq == 1 and b.read(P.STATUS)[0] & P.ST_WINDOW
    b.advance(30_000 * MS - 250 * MS)
    w = b.window()
    assert w.seq == 120
    c = b.b.counters
    assert c["pings"] == pytest.approx(30 / 0.06, abs=2)  # one ping per 60 ms slot
    assert c["ping_hz_per_sensor"] == pytest.approx(1000 / 60 / 5, rel=0.01)  # 3.3 Hz each
    pings = [s.pings for s in w.sensors]
    assert sum(pings) in (4, 5) and max(pings) == 1  # 250 ms holds four or five slots, one sensor each
    for s, r in zip(w.sensors, ranges, strict=True):
        # the sketch's us / 5.8 assumes 345 m/s: at 20 C (343 m/s) it reads 0.5 % long
        assert s.last_mm == pytest.approx(r * 1000 * 344.8 / SPEED_OF_SOUND, abs=2)
        if s.pings:
            assert s.min_mm == s.last_mm and s.echoes == 1
        else:
            assert s.min_mm is None and s.echoes == 0  # no ping in this window: only the last result stands


def test_the_echo_pulse_is_the_round_trip_and_ends_at_the_time_out_without_an_echo() -> None:
    b = Board([3.4, math.inf, 4.2, 0.01, 1.0])
    b.advance(350 * MS)  # each of the five fired once (0, 60, ..., 240 ms)
    last = [s.last_mm for s in b.window().sensors]
    assert last[0] == pytest.approx(3400 * 344.8 / SPEED_OF_SOUND, abs=3)
    assert last[1] is None  # nothing in its beam: ECHO ran to the module's 38 ms time-out
    assert last[2] is None  # 4.2 m: heard, but beyond the rated 4 m
    assert last[3] == 20  # inside the blind zone: the sketch's 2 cm minimum
    assert b.b.counters["timeouts"] == 1
    # the 3.4 m echo takes 19.8 ms: a ping fired at 0 ends after 20 ms, in the first window; one at 240 ms at 1 m
    # (5.8 ms) ends at 246 ms, in the first too; one fired at 1.44 s on sensor 4 ends in the sixth
    assert echo_mm(19_813) == pytest.approx(3416, abs=1) and echo_mm(38_000) == P.NO_ECHO


def test_a_ping_belongs_to_the_window_its_echo_ends_in() -> None:
    b = Board([math.inf, math.inf, math.inf, math.inf, 3.9])  # sensor 4 fires at 240 ms; its echo ends at 263 ms
    b.advance(260 * MS)
    assert b.window().sensors[4].pings == 0
    b.advance(250 * MS)
    w = b.window()
    assert w.seq == 2 and w.sensors[4].pings == 1 and w.sensors[4].echoes == 1


def test_simultaneous_firing_cross_talk() -> None:
    # sensor 2 looks at a far wall, its neighbours at near ones: with cross-talk certain, it hears their echoes first
    ranges = [3.0, 0.4, 3.5, 0.4, 3.0]
    b = Board(ranges, firing=P.FIRING_SIMULTANEOUS, crosstalk=1.0)
    b.advance(1000 * MS)
    c = b.b.counters
    assert c["pings"] == 5 * 17  # all five per 60 ms slot
    assert c["crosstalk"] >= 3 * 17 - 3  # sensors 0, 2, 4 each take a neighbour's nearer echo
    s = b.window().sensors
    assert s[2].min_mm is not None and s[2].min_mm < 1000  # far less than its 3.5 m wall
    # the same without cross-talk: each hears its own
    quiet = Board(ranges, firing=P.FIRING_SIMULTANEOUS, crosstalk=0.0)
    quiet.advance(1000 * MS)
    assert quiet.b.counters["crosstalk"] == 0
    assert quiet.window().sensors[2].min_mm == pytest.approx(3500 * 344.8 / SPEED_OF_SOUND, abs=3)
    # and sequential firing never cross-talks
    seq = Board(ranges, firing=P.FIRING_SEQUENTIAL, crosstalk=1.0)
    seq.advance(1000 * MS)
    assert seq.b.counters["crosstalk"] == 0


def test_the_ideal_profile_pings_each_sensor_at_200_hz() -> None:
    b = Board([1.0] * 5, firing=P.FIRING_IDEAL, crosstalk=1.0)
    b.advance(1000 * MS)
    w = b.window()
    assert all(s.pings == 50 and s.echoes == 50 for s in w.sensors)  # 250 ms at 200 Hz
    assert b.b.counters["crosstalk"] == 0


def test_the_pi_may_change_the_firing_mode() -> None:
    b = Board([1.0] * 5)
    b.write(P.FIRING, P.FIRING_IDEAL)
    b.advance(600 * MS)
    assert b.read(P.FIRING) == bytes([P.FIRING_IDEAL]) and b.window().sensors[0].pings == 50


@pytest.mark.parametrize("firing", [P.FIRING_SEQUENTIAL, P.FIRING_SIMULTANEOUS, P.FIRING_IDEAL])
def test_the_trig_pins_tell_when_each_sensor_fires(firing: int) -> None:
    """At power-up and at a change of firing mode the sketch tells each sensor's next firing time and period (pins
    "trig"): the world casts a cone at the first quantum end at or after each, and those are the ticks it pings."""
    b = Board([1.0] * 5, firing=firing)
    pinged: dict[int, set[int]] = {i: set() for i in range(5)}
    real = b.b.rangers.ping

    def ping(sensors: list[int], ranges: list[float], rng: np.random.Generator) -> dict:
        for i in sensors:
            pinged[i].add(b.b.now)
        return real(sensors, ranges, rng)

    b.b.rangers.ping = ping  # type: ignore[method-assign]
    assert b.trig is not None
    told, start = b.trig, b.t
    b.advance(1000 * MS)
    q = 10 * MS
    for i, (nxt, period) in enumerate(told):
        assert nxt > start
        casts = {-(-(nxt + k * period) // q) * q for k in range(2000) if nxt + k * period <= b.t}
        assert pinged[i] == casts and casts
    # the Pi changes the mode: the next loop tells the new times
    b.trig = None
    b.write(P.FIRING, P.FIRING_SIMULTANEOUS if firing != P.FIRING_SIMULTANEOUS else P.FIRING_IDEAL)
    b.advance(10 * MS)
    assert b.trig is not None and b.trig[0][1] != told[0][1]
    b.trig = None
    b.advance(100 * MS)
    assert b.trig is None  # told once


def test_noise_is_seeded() -> None:
    def run(seed: int) -> tuple[bytes, list[int]]:
        b = Board([1.5] * 5, firing=P.FIRING_IDEAL, seed=seed, noise_m=0.01)
        mins = []
        for _ in range(20):
            b.advance(250 * MS)
            mins += [s.min_mm for s in b.window().sensors]
        return b.read(P.WINDOW, P.WINDOW_BYTES), mins

    a, mins = run(3)
    assert run(3)[0] == a and run(4)[0] != a
    # the window's minimum of 50 noisy pings lies below the true range by about two sigma
    assert 1500 - 40 < np.mean(mins) < 1500


def drive_and_measure(b: Board, seconds: float) -> float:
    """The left wheel's rim speed (m/s) over the last half of ``seconds``."""
    b.advance(int(seconds * 500) * MS)
    a0 = b.angle[0]
    b.advance(int(seconds * 500) * MS)
    return (b.angle[0] - a0) * MOTORS.wheel_radius_m / (seconds / 2)


def test_the_speed_loop_holds_the_set_point_and_the_watchdog_stops_it() -> None:
    b = Board([1.0] * 5, watchdog_ms=500)
    v = 0.0
    for _ in range(4):  # a set-point every 200 ms keeps it going
        b.write(P.SPEED_SP, *P.pack_pair(150, -100))
        v = drive_and_measure(b, 0.2)
    assert v == pytest.approx(0.150, abs=0.01)
    assert b.read(P.STATUS)[0] & P.ST_SPEED_LOOP
    odo = P.decode_odometry(b.read(P.ODOMETRY, P.ODOMETRY_BYTES))
    assert odo.left_mm_s == pytest.approx(150, abs=15) and odo.right_mm_s == pytest.approx(-100, abs=15)
    assert odo.left > 0 > odo.right and odo.battery_mv == 7400 and odo.millis == pytest.approx(b.t / MS, abs=10)
    b.advance(600 * MS)  # no set-point for 0.6 s: stopped
    assert b.pwm == [0, 0] and b.read(P.STATUS)[0] & P.ST_WATCHDOG and b.b.counters["watchdog_stops"] == 1
    assert b.read(P.SPEED_SP, 4) == P.pack_pair(0, 0)
    b.write(P.SPEED_SP, *P.pack_pair(100, 100))
    assert not b.read(P.STATUS)[0] & P.ST_WATCHDOG


def test_open_loop_pwm_and_the_speed_clip() -> None:
    b = Board([1.0] * 5, watchdog_ms=0)  # no watchdog
    b.write(P.PWM_SP, *P.pack_pair(-200, 255))
    b.advance(2000 * MS)
    assert b.pwm == [-200, 255] and not b.read(P.STATUS)[0] & P.ST_SPEED_LOOP
    b.write(P.SPEED_SP, *P.pack_pair(5000, -5000))  # clipped to the motors' 0.3 m/s
    assert b.read(P.SPEED_SP, 4) == P.pack_pair(300, -300)


def test_bad_input_is_refused_whole_and_counted() -> None:
    b = Board([1.0] * 5)
    # a read after the pointer was set to a missing register: refused (its address NACKed), recorded and counted;
    # the transaction ends there, so a write after it in the same transaction never arrives
    assert b.read(0x07) is None
    assert b.transfer([[P.ADDRESS, False, b"\x30"], [P.ADDRESS, True, 2], [P.ADDRESS, False, b"\x05\x02"]]) == [None]
    assert b.read(P.FIRING) == bytes([P.FIRING_SEQUENTIAL])
    assert b.transfer([[P.ADDRESS, True, 1]]) == [bytes([50])]  # a bare read goes on at WATCHDOG
    c = b.b.counters
    assert c["refused_reads"] == 2 and c["bytes_read"] == 2 and c["bad_reads"] == 0
    assert b.read(P.ERROR_COUNT, 2) == bytes([2, P.ERR_BAD_REGISTER])
    # a read that starts at a register and runs off its block cannot be refused: the pull-ups read 0xFF, counted
    assert b.read(0x2E, 4) == bytes(b.read(0x2E, 2)) + b"\xff\xff"
    assert b.b.counters["bad_reads"] == 1 and b.b.counters["refused_reads"] == 2
    assert b.transfer([[P.ADDRESS, True, 1]]) == [None]  # that read left the pointer at 0x32, a missing register
    assert b.read(P.LAST_ERROR) == bytes([P.ERR_BAD_REGISTER]) and b.read(P.STATUS)[0] & P.ST_ERROR
    b.write(P.WHO_AM_I, 0x00)  # read-only
    assert b.read(P.WHO_AM_I) == bytes([P.WHO_AM_I_VALUE]) and b.read(P.LAST_ERROR) == bytes([P.ERR_READ_ONLY])
    b.write(P.SPEED_SP, 100, 0)  # half a set-point pair
    assert b.read(P.SPEED_SP, 4) == bytes(4) and b.read(P.LAST_ERROR) == bytes([P.ERR_PARTIAL])
    b.write(P.FIRING, 7)
    assert b.read(P.FIRING) == bytes([0]) and b.read(P.LAST_ERROR) == bytes([P.ERR_VALUE])
    b.write(P.PWM_SP, *P.pack_pair(300, 0))  # beyond 255
    assert b.read(P.PWM_SP, 4) == bytes(4) and b.read(P.LAST_ERROR) == bytes([P.ERR_VALUE])
    b.write(P.SPEED_SP, *([0] * 40))  # more than the 32-byte buffer
    assert b.read(P.LAST_ERROR) == bytes([P.ERR_OVERFLOW])
    c = b.b.counters
    assert c["refused_writes"] == 5 and b.read(P.ERROR_COUNT) == bytes([9])
    b.tick([["i2c", 99, "not segments"], ["can0", 1, b""], []])  # not bus traffic: dropped, counted
    assert b.b.counters["malformed"] == 3
    b.write(P.ERROR_COUNT, 0)  # any write clears the errors
    assert b.read(P.ERROR_COUNT, 2) == bytes(2) and not b.read(P.STATUS)[0] & P.ST_ERROR
    assert b.read(P.WHO_AM_I) == bytes([P.WHO_AM_I_VALUE])  # still answering


def test_the_fuzzed_bus_never_crashes_it() -> None:
    rng = np.random.default_rng(5)
    b = Board([1.0, 2.0, math.inf, 0.5, 0.2])
    for _ in range(400):
        segs = []
        for _ in range(int(rng.integers(1, 4))):
            if rng.random() < 0.5:
                segs.append([P.ADDRESS, True, int(rng.integers(1, 40))])
            else:
                segs.append([P.ADDRESS, False, bytes(rng.integers(0, 256, int(rng.integers(0, 40))).tolist())])
        b.txn += 1
        b.tick([["i2c", b.txn, segs]])
        b.advance(10 * MS)
    assert b.b.counters["transactions"] == 400
