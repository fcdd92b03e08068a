"""The LLC firmware against the pybullet plant: wheel PID, odometry, watchdog, telemetry, bad frames."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.config import Config
from firmware_sim.arduino import Board
from firmware_sim.can_controller import CanController, Frame
from firmware_sim.llc import LlcParams, LowLevelController
from swarm_logic.interfaces import eswarbot_llc_db
from tests.harness import Plant

DB = eswarbot_llc_db()
DRIVE = DB.get_message_by_name("DRIVE_CMD")


def plant(x: float = 2.0, y: float = 2.0, yaw: float = 0.0, seed: int = 3, **arena) -> Plant:
    cfg = Config.model_validate({
        "session": {"seed": seed}, "arena": arena or {"width_m": 10, "length_m": 10},
        "robots": [{"count": 1, "placement": {"kind": "explicit", "poses": [[x, y, yaw]]}}],
    })
    return Plant(cfg)


def drive(p: Plant, v: float, w: float, seconds: float) -> None:
    for i in range(round(seconds / 0.1)):
        cmd = {"v_mm_s": round(v * 1000), "w_mrad_s": round(w * 1000), "seq": i % 256}
        p.send(0, DRIVE.frame_id, DRIVE.encode(cmd))
        p.run_for(0.1)


def decoded(p: Plant, name: str) -> list[dict]:
    fid = DB.get_message_by_name(name).frame_id
    return [DB.decode_message(fid, f[2]) for f in p.tx[0] if f[1] == fid]


def test_pid_tracks_commanded_speed_on_quantised_encoders() -> None:
    p = plant()
    drive(p, 0.15, 0.0, 1.0)  # settle
    x0 = p.world.pos[0].copy()
    drive(p, 0.15, 0.0, 5.0)
    speed = math.dist(p.world.pos[0], x0) / 5.0
    assert speed == pytest.approx(0.15, rel=0.03)
    left, right = p.world.sensors(0).encoders
    assert abs(left - right) <= 2  # both wheels held to the same pulse rate despite gain spread


def test_turn_in_place_rate() -> None:
    p = plant()
    drive(p, 0.0, 1.0, 1.0)
    yaw0 = p.world.yaw[0]
    drive(p, 0.0, 1.0, 2.0)
    turned = math.atan2(math.sin(p.world.yaw[0] - yaw0), math.cos(p.world.yaw[0] - yaw0))
    assert turned == pytest.approx(2.0, rel=0.08)


def test_odometry_matches_ground_truth_over_a_short_run() -> None:
    p = plant()
    drive(p, 0.15, 0.3, 4.0)
    p.run_for(0.2)
    odo = decoded(p, "ODOMETRY")[-1]
    dx, dy = p.world.pos[0] - [2.0, 2.0]
    assert math.hypot(odo["x_mm"] / 1000 - dx, odo["y_mm"] / 1000 - dy) < 0.05
    assert odo["theta_mrad"] / 1000 == pytest.approx(float(p.world.yaw[0]), abs=0.1)


def test_watchdog_stops_motors_half_a_second_after_last_command() -> None:
    p = plant()
    drive(p, 0.15, 0.0, 1.0)
    assert abs(p.world.pwm[0]).sum() > 0
    p.run_for(0.35)
    assert abs(p.world.pwm[0]).sum() > 0  # still within 0.5 s of the last command (sent at 0.9 s)
    p.run_for(0.2)
    assert abs(p.world.pwm[0]).sum() == 0
    status = decoded(p, "STATUS")[-1]
    assert status["fault_watchdog"] == 1


def test_telemetry_rates() -> None:
    p = plant()
    p.run_for(2.0)
    assert len(decoded(p, "ODOMETRY")) == pytest.approx(40, abs=1)
    assert len(decoded(p, "SONAR")) == pytest.approx(40, abs=1)
    assert len(decoded(p, "LIGHT")) == pytest.approx(20, abs=1)
    assert len(decoded(p, "STATUS")) == pytest.approx(20, abs=1)
    assert len(decoded(p, "BATTERY")) == pytest.approx(2, abs=1)
    hb = [s["heartbeat"] for s in decoded(p, "STATUS")]
    assert hb == list(range(1, len(hb) + 1))


def test_sonar_sees_wall_through_the_adc() -> None:
    p = plant(x=1.0, y=5.0, yaw=180.0)  # facing the x=0 wall, body surface 0.937 m from it
    p.run_for(0.5)
    readings = [s["range_mm"] for s in decoded(p, "SONAR")[2:]]
    assert sorted(readings)[len(readings) // 2] == pytest.approx(937, abs=40)


def test_battery_and_light_reported() -> None:
    p = plant()
    p.run_for(1.1)
    batt = decoded(p, "BATTERY")[-1]
    assert 8000 < batt["voltage_mv"] < 8500 and batt["soc_pct"] > 90
    assert 0 < decoded(p, "LIGHT")[-1]["ldr_raw"] < 1023


def _llc() -> LowLevelController:
    b = Board()
    llc = LowLevelController(b, LlcParams())
    llc.setup()
    return llc


def test_malformed_frames_are_counted_and_dropped() -> None:
    llc = _llc()
    can = llc.board.can
    can.on_bus_frame(Frame(0x7FF, b"\x00"))  # unknown id
    can.on_bus_frame(Frame(DRIVE.frame_id, b"\x01\x02"))  # wrong length
    can.on_bus_frame(Frame(DB.get_message_by_name("ODOMETRY").frame_id, bytes(8)))  # a frame the LLC itself sends
    can.on_bus_frame(Frame(DRIVE.frame_id, bytes(12)))  # longer than classic CAN: controller error
    can.on_bus_frame(Frame(DRIVE.frame_id, DRIVE.encode({"v_mm_s": 100, "w_mrad_s": 0, "seq": 1}),
                           is_extended_id=True))  # right id and length, but an extended frame
    llc.loop()
    assert llc.rx_bad == 4 and can.rx_errors == 1
    assert llc.v_cmd == 0.0
    llc.board.time_us += 100_000
    llc.loop()
    status = [DB.decode_message(f.arbitration_id, f.data) for f in can.take_tx()
              if f.arbitration_id == DB.get_message_by_name("STATUS").frame_id][-1]
    assert status["rx_bad_frames"] == 5 and status["fault_bad_frame"] == 1


def test_receive_ring_overflow_is_counted() -> None:
    can = CanController(rx_depth=2)
    for _ in range(5):
        can.on_bus_frame(Frame(0x100, bytes(5)))
    assert len(can.rx) == 2 and can.rx_overflows == 3


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 0x7FF), st.binary(max_size=16)), max_size=20))
def test_random_frames_never_crash_the_llc(frames: list[tuple[int, bytes]]) -> None:
    llc = _llc()
    for arb, data in frames:
        llc.board.can.on_bus_frame(Frame(arb, data))
        llc.board.time_us += 20_000
        llc.loop()
    can = llc.board.can
    assert can.rx_frames + can.rx_errors + can.rx_overflows == len(frames)  # every frame accounted for
    assert llc.rx_bad <= can.rx_frames
    known = {m.frame_id: m.length for m in DB.messages if m.senders == ["HOST"]}
    wellformed = sum(1 for a, d in frames if known.get(a) == len(d))
    assert llc.rx_bad == sum(1 for a, d in frames if len(d) <= 8) - wellformed


def test_obstacle_inside_the_blind_zone_reads_as_close_not_clear() -> None:
    p = plant(x=0.08, y=5.0, yaw=180.0)  # body surface 1.7 cm from the wall
    p.run_for(0.5)
    last = decoded(p, "SONAR")[-1]
    assert last["valid"] == 1 and last["range_mm"] <= 160


@pytest.mark.parametrize("quantum_ms", [7, 10, 13])
def test_loop_keeps_its_rate_when_the_quantum_does_not_divide_the_period(quantum_ms: int) -> None:
    cfg = Config.model_validate({
        "session": {"quantum_ms": quantum_ms},
        "robots": [{"count": 1, "placement": {"kind": "explicit", "poses": [[2, 2, 0]]}}],
    })
    p = Plant(cfg)
    p.run_for(3.0)
    assert len(decoded(p, "STATUS")) == pytest.approx(30, abs=1)  # 10 Hz status from a 50 Hz loop
    assert len(decoded(p, "ODOMETRY")) == pytest.approx(60, abs=2)


def test_heading_drift_follows_the_wheel_radius_mismatch() -> None:
    """Both wheels held to the same pulse rate: unequal radii turn the robot, as real odometry drift."""
    p = plant(seed=11)
    drive(p, 0.15, 0.0, 1.0)
    yaw0 = float(p.world.yaw[0])
    drive(p, 0.15, 0.0, 8.0)
    r_left, r_right = p.world.wheel_r[0]
    expected = 0.15 * 2 * (r_right - r_left) / ((r_left + r_right) * 2 * p.world.half_track[0]) * 8.0
    assert abs(expected) > 0.02  # the seed gives a measurable mismatch
    assert float(p.world.yaw[0]) - yaw0 == pytest.approx(expected, rel=0.2)
