"""The utility sensor board's protocol: a report every 100 ms, the reading, the bearing (or none), the cumulative
meals; the driver turns them into ``read``, ``bearing``, ``consumed`` and counts what it cannot parse."""

from __future__ import annotations

import math

import serial

from firmware_sim.robots.decizebro.utility_board import UtilityBoard
from swarm_logic.clock import SteppedClock
from swarm_logic.robots.decizebro import utility_protocol as P
from swarm_logic.robots.decizebro.utility import UtilityBoardDriver


def test_reports_stream_at_10_hz_and_the_driver_reads_them() -> None:
    board = UtilityBoard()
    port = serial.serial_for_url("loop://", timeout=0)
    clock = SteppedClock()
    drv = UtilityBoardDriver(port, clock)
    sent = b""
    for k in range(32):  # 310 ms in 10 ms steps (the 300 ms report takes a millisecond on the line)
        t = k * 10_000_000
        sens = {"utility": 95 if k < 20 else 0, "bearing_rad": math.radians(12.5) if k < 20 else None,
                "eaten": 0 if k < 25 else 1, "eaten_sum": 0 if k < 25 else 40}
        sent += board.step(t, sens)
    assert board.counters["reports"] == 4  # at 0, 100, 200 and 300 ms
    n = len(P.frame(P.REPORT, bytes(P.REPORT_BODY.size)))
    port.write(b"\x00junk" + sent[:n] + P.frame(P.REPORT, b"\x01") + sent[n:])  # junk, and a report too short
    clock.t = 0.31
    assert drv.read() == 0 and drv.bearing() is None  # the last report: nothing in the cone
    assert drv.consumed() == 40 and drv.consumed() == 0  # the meal once
    assert drv.reports == 4 and drv.bad_frames == 1 and drv.parser.junk >= 5


def test_a_reading_in_the_cone_has_its_direction() -> None:
    board = UtilityBoard()
    port = serial.serial_for_url("loop://", timeout=0)
    assert board.step(0, {"utility": -20, "bearing_rad": math.radians(-25.0), "eaten": 0, "eaten_sum": 0}) == b""
    board_bytes = board.step(2_000_000, None)  # 13 bytes at 115200 baud: 1.1 ms
    port.write(board_bytes)
    drv = UtilityBoardDriver(port, SteppedClock())
    assert drv.read() == -20 and math.degrees(drv.bearing()) == -25.0
