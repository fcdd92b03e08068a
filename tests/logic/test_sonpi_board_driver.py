"""The SonPI's Pi side: the tracking layer's law, and the ``sonpi_board`` driver on the bench's sketch (a bus wired
straight to it): the faces it serves, the world-frame velocity followed through the tracking layer with the heading
from odometry or from the robot's pose device, dead reckoning, the windows' readings, and bus errors."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi.board import SonpiBoard, open_sonpi_board
from swarm_logic.robots.sonpi.interfaces import (
    ODOMETRY,
    SONAR,
    SONAR_ANGLES_RAD,
    VELOCITY,
    HolonomicVelocity,
    NoPose,
    Odometry,
    Sonar,
)
from swarm_logic.robots.sonpi.tracking import TrackingParams, unicycle, wheel_speeds
from tests.support.sonpi_bench import HALF_TRACK_M, MOTORS, BenchClock, Board, WiredBus, robot_with

TRACK = TrackingParams(half_track_m=HALF_TRACK_M, max_speed_mps=0.2, max_wheel_mps=0.25, lookahead_m=0.1)


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.5, math.pi])
@pytest.mark.parametrize("cmd", [(0.1, 0.0), (0.0, -0.12), (-0.05, 0.08)])
def test_the_point_ahead_moves_at_the_commanded_velocity(yaw: float, cmd: tuple[float, float]) -> None:
    v, w = unicycle(*cmd, yaw, TRACK)
    l_ = TRACK.lookahead_m
    px = v * math.cos(yaw) - l_ * w * math.sin(yaw)  # the point ahead's velocity for (v, w)
    py = v * math.sin(yaw) + l_ * w * math.cos(yaw)
    assert (px, py) == pytest.approx(cmd, abs=1e-12)
    left, right = wheel_speeds(*cmd, yaw, TRACK)
    assert (left + right) / 2 == pytest.approx(v) and (right - left) / (2 * HALF_TRACK_M) == pytest.approx(w)


def test_saturation_keeps_the_turn_s_share_and_the_speed_is_clipped() -> None:
    slow = TrackingParams(half_track_m=HALF_TRACK_M, max_speed_mps=0.2, max_wheel_mps=0.1, lookahead_m=0.1)
    left, right = wheel_speeds(0.0, 0.2, 0.0, slow)  # straight left of the heading: a spin, 0.15 m/s rims asked
    assert (left, right) == pytest.approx((-0.1, 0.1))
    v, w = unicycle(1.0, 0.0, 0.0, TRACK)  # 1 m/s asked: 0.2 m/s
    assert (v, w) == pytest.approx((0.2, 0.0))
    l2, r2 = wheel_speeds(0.15, 0.1, 0.3, TRACK)
    v2, w2 = unicycle(0.15, 0.1, 0.3, TRACK)
    raw = (v2 - w2 * HALF_TRACK_M, v2 + w2 * HALF_TRACK_M)
    assert l2 / r2 == pytest.approx(raw[0] / raw[1])  # scaled together
    assert wheel_speeds(math.nan, math.inf, 0.0, TRACK) == (0.0, 0.0)
    with pytest.raises(ValueError, match="lookahead_m"):
        TrackingParams(0.075, 0.2, 0.25, lookahead_m=0.0)


def open_driver(board: Board, robot: object = None) -> SonpiBoard:
    clock = BenchClock(board)
    return SonpiBoard(
        WiredBus(board),
        clock,
        wheel_radius_m=MOTORS.wheel_radius_m,
        half_track_m=HALF_TRACK_M,
        encoder_cpr=MOTORS.encoder_cpr,
        robot=robot,
    )


def run(board: Board, dev: SonpiBoard, seconds: float, period_s: float = 0.1) -> None:
    for _ in range(round(seconds / period_s)):
        dev.poll()
        dev.clock.sleep(period_s)


def test_it_serves_its_faces_and_follows_a_world_frame_velocity_from_odometry() -> None:
    start = (1.0, 2.0, math.pi / 2)  # facing north, asked to go east
    board = Board([2.0] * 5, pose=start)
    dev = open_driver(board, robot_with(start_pose=start))
    faces = dev.faces()
    assert isinstance(faces[SONAR], Sonar) and isinstance(faces[VELOCITY], HolonomicVelocity)
    assert isinstance(faces[ODOMETRY], Odometry) and faces[VELOCITY].max_speed_mps == 0.2
    faces[VELOCITY].set_velocity(0.1, 0.0)
    run(board, dev, 8.0)
    x, y, yaw = board.pose
    assert abs(math.remainder(yaw, 2 * math.pi)) < 0.1  # it turned east
    assert x - 1.0 > 0.5 and abs(y - 2.0) < 0.25
    odo = faces[ODOMETRY].read()
    # dead reckoning from the start pose agrees with the body (the bench's wheels do not slip; the Pi integrates
    # at its 10 Hz poll, the bench every 10 ms)
    assert (odo.x_m, odo.y_m) == pytest.approx((x, y), abs=0.03) and odo.yaw_rad == pytest.approx(yaw, abs=0.01)
    assert odo.v_mps == pytest.approx(0.1, abs=0.015) and abs(odo.w_rps) < 0.1 and odo.t_s == pytest.approx(8.0, 0.02)
    assert odo.left_counts > 0 and odo.right_counts > 0
    assert dev.counters["bus_errors"] == 0 and board.b.counters["watchdog_stops"] == 0
    faces[VELOCITY].set_velocity(0.0, 0.0)
    run(board, dev, 1.0)
    assert board.pwm == [0, 0]


def test_the_heading_comes_from_the_robot_s_pose_device_when_it_has_one() -> None:
    # the odometry starts at 0 rad (no start pose), the pose device says the robot faces west: the driver trusts it
    board = Board([2.0] * 5, pose=(0.0, 0.0, math.pi))
    pose = SimpleNamespace(read=lambda: SimpleNamespace(yaw_rad=board.pose[2]))
    dev = open_driver(board, robot_with(sonpi_pose=pose))
    dev.set_velocity(-0.1, 0.0)  # west: straight ahead
    run(board, dev, 3.0)
    assert board.pose[0] < -0.2 and abs(board.pose[1]) < 0.05
    # without it, the odometry's 0 rad is believed: west means turning round first
    board2 = Board([2.0] * 5, pose=(0.0, 0.0, math.pi))
    dev2 = open_driver(board2, robot_with())
    dev2.set_velocity(-0.1, 0.0)
    run(board2, dev2, 3.0)
    assert board2.pose[0] > -0.1


def test_a_robot_the_camera_has_never_seen_steers_by_its_odometry() -> None:
    """The pose device has no pose for it (NoPose): the tracking layer takes the encoders' heading, no failure; once
    the camera sees it, the camera's heading steers again."""
    start = (0.0, 0.0, math.pi / 2)
    board = Board([2.0] * 5, pose=start)
    seen = {"now": False}

    def read() -> SimpleNamespace:
        if not seen["now"]:
            raise NoPose("never seen")
        return SimpleNamespace(yaw_rad=board.pose[2])

    dev = open_driver(board, robot_with(start_pose=start, sonpi_pose=SimpleNamespace(read=read)))
    dev.set_velocity(0.1, 0.0)  # east, the robot facing north
    run(board, dev, 6.0)
    x, y, yaw = board.pose
    assert x > 0.35 and abs(math.remainder(yaw, math.tau)) < 0.15  # it turned east and drove on by odometry
    n = dev.counters["heading_from_odometry"]
    assert n >= 55 and dev.counters["bus_errors"] == 0
    seen["now"] = True
    dev.set_velocity(0.0, 0.1)  # north
    run(board, dev, 4.0)
    assert board.pose[1] - y > 0.2 and dev.counters["heading_from_odometry"] == n


def test_sonar_readings_from_the_windows() -> None:
    board = Board([0.5, 1.0, math.inf, 4.2, 0.3])
    dev = open_driver(board)
    assert [r.range_m for r in dev.faces()[SONAR].readings()] == [math.inf] * 5  # no window yet
    run(board, dev, 1.0)
    got = dev.faces()[SONAR].readings()
    assert [r.angle_rad for r in got] == list(SONAR_ANGLES_RAD)
    assert got[0].range_m == pytest.approx(0.5, abs=0.005) and got[1].range_m == pytest.approx(1.0, abs=0.01)
    assert got[2].range_m == math.inf and got[3].range_m == math.inf  # nothing within 4 m
    assert got[4].range_m == pytest.approx(0.3, abs=0.005)
    w = dev.window
    assert w is not None and w.seq >= 3 and dev.counters["windows"] == w.seq and dev.counters["windows_missed"] == 0
    # a sensor without a ping in the latest window keeps its last result, rather than reading clear
    assert any(s.pings == 0 for s in w.sensors)
    assert all(math.isfinite(got[i].range_m) for i in (0, 1, 4))


def test_bus_errors_are_counted_and_never_reach_the_algorithm() -> None:
    board = Board([1.0] * 5)
    dev = open_driver(board)
    bus = dev.bus
    bus.unplugged = True
    run(board, dev, 0.5)
    dev.set_velocity(0.1, 0.1)
    assert not dev.identified and dev.counters["bus_errors"] == 5 and "Remote I/O" in dev.last_error
    bus.unplugged = False
    run(board, dev, 0.5)
    assert dev.identified and dev.version == P.VERSION_VALUE and dev.counters["writes"] >= 1
    bus.unplugged = True
    run(board, dev, 1.0)  # the board's watchdog stops the motors the Pi can no longer reach
    assert board.pwm == [0, 0] and board.b.counters["watchdog_stops"] == 1
    assert dev.counters["bus_errors"] >= 5 + 10  # every poll's read (and its keep-alive write) failed


def test_the_hal_table_names_what_is_missing() -> None:
    robot = SimpleNamespace(clock=None)
    with pytest.raises(ValueError, match="sonpi_board: half_track_m, encoder_cpr needed"):
        open_sonpi_board({"bus": 1, "wheel_radius_m": 0.03}, robot)
