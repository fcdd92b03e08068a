"""The LLC firmware against the pybullet plant: wheel PID, odometry, watchdog, telemetry, bad frames,
rotate-then-go moves (thesis eq. 4.21-4.22, digest target U15) and the ground-truth pose source."""

from __future__ import annotations

import json
import math
import statistics
from pathlib import Path

import cantools
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from bridge.core.config import Config
from bridge.core.registry import robot_profile
from bridge.robots.eswarbot.board import llc_params
from firmware_sim.board.arduino import Board
from firmware_sim.board.can_controller import CanController, Frame
from firmware_sim.robots.eswarbot import llc as llc_fw
from firmware_sim.robots.eswarbot.llc import LlcParams, LowLevelController, forward_pulses, rotation_pulses
from swarm_logic.robots.eswarbot import ESWARBOT_LLC_DBC, eswarbot_llc_db
from tests.core.test_session import run as session_run
from tests.support.harness import Plant

DB = eswarbot_llc_db()
DRIVE = DB.get_message_by_name("DRIVE_CMD")
MOVE = DB.get_message_by_name("MOVE_CMD")
IDLE, ROTATING, FORWARD, DONE, ABORTED = range(5)


def _pwm(p) -> object:
    """The PWM the LLC's motors get now."""
    return p.world.model("differential_drive").pwm[0]


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
    left, right = p.world.sensors(0)["encoders"]
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
    assert abs(_pwm(p)).sum() > 0
    p.run_for(0.35)
    assert abs(_pwm(p)).sum() > 0  # still within 0.5 s of the last command (sent at 0.9 s)
    p.run_for(0.2)
    assert abs(_pwm(p)).sum() == 0
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


def _valid_move(arb: int, data: bytes) -> bool:
    """A MOVE_CMD needs a distance >= 0 and a speed > 0; a CONVEYOR_CMD is bad on a robot without a conveyor (the
    eSwarBot); every other well-sized command is valid."""
    if arb == DB.get_message_by_name("CONVEYOR_CMD").frame_id:
        return False
    if arb != MOVE.frame_id:
        return True
    sig = MOVE.decode(data)
    return sig["dist_mm"] >= 0 and sig["speed_mm_s"] > 0


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
    wellformed = sum(1 for a, d in frames if known.get(a) == len(d) and _valid_move(a, d))
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
    wheels = p.world.model("differential_drive")
    r_left, r_right = wheels.wheel_r[0]
    expected = 0.15 * 2 * (r_right - r_left) / ((r_left + r_right) * 2 * wheels.half_track[0]) * 8.0
    assert abs(expected) > 0.02  # the seed gives a measurable mismatch
    assert float(p.world.yaw[0]) - yaw0 == pytest.approx(expected, rel=0.2)


# -- rotate-then-go (thesis section 4.6.1) ------------------------------------------------------------------

def test_u15_pulses_of_a_rotation_and_a_forward_run() -> None:
    """Digest target U15: eq. 4.21-4.22 with the eSwarBot's 48 CPR, 21.09 mm wheels and 43.9 mm half-track."""
    p = llc_params(robot_profile("eswarbot"))
    assert rotation_pulses(math.pi / 2, p) == pytest.approx(25.0, abs=0.05)
    assert rotation_pulses(-math.pi / 2, p) == pytest.approx(-25.0, abs=0.05)
    assert forward_pulses(0.1, p) == pytest.approx(36.2, abs=0.05)
    assert rotation_pulses(math.radians(3.6), p) == pytest.approx(1.0, abs=0.01)  # 3.6 deg per pulse
    assert forward_pulses(0.00276, p) == pytest.approx(1.0, abs=0.01)  # 2.76 mm per pulse
    assert p.rot_threshold_deg == 3.6  # theta_T: one pulse (digest A12)


def move(p: Plant, rot_rad: float, dist_m: float, speed: float, seq: int) -> None:
    p.send(0, MOVE.frame_id, MOVE.encode({"rot_mrad": round(rot_rad * 1000), "dist_mm": round(dist_m * 1000),
                                          "speed_mm_s": round(speed * 1000), "seq": seq}))


def test_move_rotates_then_drives_by_the_pulse_counts() -> None:
    p = plant()
    p.run_for(0.2)
    e0 = p.world.sensors(0)["encoders"]
    yaw0, pos0 = float(p.world.yaw[0]), p.world.pos[0].copy()
    move(p, math.pi / 2, 0.1, 0.1, seq=7)
    p.run_for(3.5)  # about 2 s of moving, no DRIVE_CMD: the watchdog does not stop a move
    left, right = (e - s for e, s in zip(p.world.sensors(0)["encoders"], e0, strict=True))
    assert left == pytest.approx(-25 + 36, abs=2) and right == pytest.approx(25 + 36, abs=2)
    status = decoded(p, "MOVE_STATUS")
    states = [s["state"] for s in status]
    assert {s["seq"] for s in status} == {7}
    assert states[0] == "rotating" and states[-1] == "done" and states.count("done") == 1
    assert states.index("forward") > states.index("rotating")  # rotate first, then go
    assert states.count("rotating") + states.count("forward") >= 15  # 10 Hz while it runs (about 2 s)
    assert status[-1]["rot_pulses"] == pytest.approx(25, abs=1) and status[-1]["fwd_pulses"] == pytest.approx(36, abs=1)
    turned = float(p.world.yaw[0]) - yaw0
    assert math.degrees(turned) == pytest.approx(90, abs=5)
    assert math.dist(p.world.pos[0], pos0) == pytest.approx(0.1, abs=0.01)
    assert abs(_pwm(p)).sum() == 0 and decoded(p, "STATUS")[-1]["fault_watchdog"] == 0


def test_a_new_move_aborts_the_running_one() -> None:
    p = plant()
    move(p, -math.pi / 2, 0.3, 0.1, seq=1)
    p.run_for(0.5)
    move(p, 0.0, 0.05, 0.1, seq=2)
    p.run_for(2.0)
    status = [(s["seq"], s["state"]) for s in decoded(p, "MOVE_STATUS")]
    first_new = status.index((2, "forward"))
    assert status[first_new - 1] == (1, "aborted")  # the old one reported aborted, then the new one starts
    assert (1, "done") not in status and status[-1] == (2, "done")
    aborted = next(s for s in decoded(p, "MOVE_STATUS") if s["state"] == "aborted")
    assert -25 < aborted["rot_pulses"] < -3  # clockwise, part of the way
    assert decoded(p, "MOVE_STATUS")[-1]["fwd_pulses"] == pytest.approx(18, abs=1)


def test_drive_cmd_aborts_a_move_and_takes_over() -> None:
    p = plant()
    move(p, 0.0, 0.5, 0.15, seq=3)
    p.run_for(0.6)
    drive(p, 0.0, 0.0, 0.2)
    status = decoded(p, "MOVE_STATUS")
    assert (status[-1]["seq"], status[-1]["state"]) == (3, "aborted") and status[-1]["fwd_pulses"] > 5
    n = len(status)
    p.run_for(1.0)
    assert len(decoded(p, "MOVE_STATUS")) == n  # no more reports once it is over
    assert abs(_pwm(p)).sum() == 0


def _move_frames(llc: LowLevelController) -> list[dict]:
    fid = DB.get_message_by_name("MOVE_STATUS").frame_id
    return [DB.decode_message(f.arbitration_id, f.data, decode_choices=False) for f in llc.board.can.take_tx()
            if f.arbitration_id == fid]


def _cmd(llc: LowLevelController, rot_mrad: int, dist_mm: int, speed_mm_s: int, seq: int = 1) -> None:
    data = MOVE.encode({"rot_mrad": rot_mrad, "dist_mm": dist_mm, "speed_mm_s": speed_mm_s, "seq": seq},
                       strict=False)
    llc.board.can.on_bus_frame(Frame(MOVE.frame_id, data))


def test_move_with_a_negative_distance_or_no_speed_is_a_bad_frame() -> None:
    llc = _llc()
    _cmd(llc, 0, -100, 100)
    _cmd(llc, 0, 100, 0)
    llc.board.time_us += 20_000
    llc.loop()
    assert llc.rx_bad == 2 and llc.fault_bad_frame and llc.move_state == IDLE
    assert _move_frames(llc) == []


def test_rotation_below_the_threshold_is_skipped() -> None:
    llc = _llc()
    _cmd(llc, round(math.radians(3.0) * 1000), 50, 100)  # under theta_T = 3.6 deg: forward only
    llc.board.time_us += 20_000
    llc.loop()
    assert [(f["state"], f["rot_pulses"]) for f in _move_frames(llc)] == [(FORWARD, 0)]
    assert llc.move_pulses == (0, round(forward_pulses(0.05, llc.p)))
    _cmd(llc, round(math.radians(-5.0) * 1000), 0, 100, seq=2)  # above it: one pulse clockwise
    llc.board.time_us += 20_000
    llc.loop()
    assert [(f["seq"], f["state"]) for f in _move_frames(llc)] == [(1, ABORTED), (2, ROTATING)]
    assert llc.move_pulses == (1, 0) and llc.move_dir == -1
    _cmd(llc, 0, 0, 100, seq=3)  # nothing to do: done at once
    llc.board.time_us += 20_000
    llc.loop()
    assert [(f["seq"], f["state"]) for f in _move_frames(llc)] == [(2, ABORTED), (3, DONE)]


def test_a_stalled_move_is_aborted_after_three_times_its_duration() -> None:
    llc = _llc()  # the wheels never turn: no encoder pulses
    _cmd(llc, 0, 100, 200)  # 36 pulses at 72 pulses/s on a 200 pulses/s^2 ramp: about 0.86 s nominal
    llc.board.time_us += 20_000
    llc.loop()
    t_ms = 0
    while llc.move_state == FORWARD and t_ms < 10_000:
        llc.board.time_us += 20_000
        t_ms += 20
        llc.loop()
    assert llc.move_state == ABORTED and 3_400 <= t_ms <= 3_800
    assert llc.board.pwm["D5"] == 0 and llc.board.pwm["D6"] == 0
    assert _move_frames(llc)[-1]["state"] == ABORTED


def test_external_pose_replaces_dead_reckoning_and_is_flagged() -> None:
    llc = _llc()
    b = llc.board
    for pose, ideal in ((None, 0), ((3.25, -1.5, 4.0), 1)):
        b.external_pose = pose
        b.time_us += 100_000
        llc.loop()
        frames = {f.arbitration_id: DB.decode_message(f.arbitration_id, f.data) for f in b.can.take_tx()}
        odo = frames[DB.get_message_by_name("ODOMETRY").frame_id]
        assert frames[DB.get_message_by_name("STATUS").frame_id]["pose_ideal"] == ideal
        if pose is None:
            assert (odo["x_mm"], odo["y_mm"], odo["theta_mrad"]) == (0, 0, 0)
        else:  # the yaw wrapped into +/- pi
            assert (odo["x_mm"], odo["y_mm"], odo["theta_mrad"]) == (3250, -1500, round((4.0 - 2 * math.pi) * 1000))


GROUND_TRUTH = """
[session]
name = "pose-source"
duration_s = 3
seed = 4
[arena]
width_m = 4
length_m = 4
[[robots]]
count = 1
pose_source = "ground_truth"
[robots.placement]
kind = "explicit"
poses = [[1.0, 1.0, 30.0]]
[[robots]]
count = 1
[robots.placement]
kind = "explicit"
poses = [[3.0, 3.0, -90.0]]
"""


@pytest.mark.session
def test_ground_truth_pose_source_reports_the_world_pose(tmp_path: Path) -> None:
    cfg = tmp_path / "pose.toml"
    cfg.write_text(GROUND_TRUTH)
    code, s = session_run(cfg, tmp_path / "run")
    assert code == 0, s
    assert [r["pose_source"] for r in s["per_robot"]] == ["ground_truth", "odometry"]
    assert s["per_robot"][0]["distance_m"] > 0.1  # it moved: the pose it reports has to follow
    odo_id, status_id = (DB.get_message_by_name(n).frame_id for n in ("ODOMETRY", "STATUS"))
    poses: dict[int, tuple[float, float, float]] = {}
    frames: dict[int, list[tuple[int, dict]]] = {0: [], 1: []}
    with open(tmp_path / "run" / "session.mcap", "rb") as f:
        for _, ch, m in make_reader(f).iter_messages(topics=["/world/poses", "/r000/can0", "/r001/can0"]):
            d = json.loads(m.data)
            if ch.topic == "/world/poses":
                poses[m.log_time] = (d["x"][0], d["y"][0], d["yaw"][0])
            elif d["id"] in (odo_id, status_id):
                frames[int(ch.topic[2:5])].append((m.log_time, DB.decode_message(d["id"], bytes.fromhex(d["data"]))))
    status = [fr for _, fr in frames[0] if "pose_ideal" in fr]
    assert status and all(fr["pose_ideal"] == 1 for fr in status)
    assert all(fr["pose_ideal"] == 0 for _, fr in frames[1] if "pose_ideal" in fr)
    odo = [(t, fr) for t, fr in frames[0] if "x_mm" in fr]
    assert len(odo) > 40
    q = 10_000_000
    for t, fr in odo:  # the true pose of the quantum the LLC ran in, a quantum or two before delivery
        err = min(math.hypot(fr["x_mm"] / 1000 - poses[t - j * q][0], fr["y_mm"] / 1000 - poses[t - j * q][1])
                  + abs(math.remainder(fr["theta_mrad"] / 1000 - poses[t - j * q][2], 2 * math.pi))
                  for j in (1, 2, 3) if t - j * q in poses)
        assert err < 0.0015, (t, fr)
    first = odo[0][1]
    assert (first["x_mm"], first["y_mm"], first["theta_mrad"]) == pytest.approx((1000, 1000, 524), abs=2)
    odo1 = [fr for _, fr in frames[1] if "x_mm" in fr]
    assert (odo1[0]["x_mm"], odo1[0]["y_mm"], odo1[0]["theta_mrad"]) == (0, 0, 0)  # dead reckoning: its own frame


# -- the DBC's cycle times ---------------------------------------------------------------------------------------
# each periodic frame and the firmware constant it is sent by (RADIO_RSSI: on change, and at least this often)
SEND_PERIODS_MS = {"ENCODERS": llc_fw.PERIOD_ODOM_MS, "ODOMETRY": llc_fw.PERIOD_ODOM_MS,
                   "SONAR": llc_fw.PERIOD_SONAR_MS, "SONAR_SIDES": llc_fw.PERIOD_SONAR_MS,
                   "LIGHT": llc_fw.PERIOD_LIGHT_MS, "BATTERY": llc_fw.PERIOD_BATTERY_MS,
                   "STATUS": llc_fw.PERIOD_STATUS_MS, "RADIO_RSSI": llc_fw.RSSI_KEEPALIVE_MS,
                   "MOVE_STATUS": llc_fw.PERIOD_MOVE_STATUS_MS, "CONVEYOR_STATUS": llc_fw.PERIOD_CONVEYOR_STATUS_MS}


def test_the_dbc_declares_the_firmware_send_periods_as_cycle_times() -> None:
    db = cantools.database.load_file(str(ESWARBOT_LLC_DBC), database_format="dbc")  # as `cantools dump` reads it
    assert {m.name: m.cycle_time for m in db.messages if m.cycle_time} == SEND_PERIODS_MS
    kinds = {m.name: m.send_type for m in db.messages}
    assert {n for n, k in kinds.items() if k == "Spontaneous"} == {m.name for m in db.messages if m.senders == ["HOST"]}
    assert kinds["RADIO_RSSI"] == "CyclicAndSpontaneous"  # on change, and at least once a second
    assert kinds["MOVE_STATUS"] == kinds["CONVEYOR_STATUS"] == "CyclicIfActiveAndSpontaneous"
    assert all(kinds[n] == "Cyclic" for n in SEND_PERIODS_MS if n not in ("RADIO_RSSI", "MOVE_STATUS",
                                                                         "CONVEYOR_STATUS"))


def test_the_firmware_sends_at_the_dbc_cycle_times() -> None:
    """Every frame the LLC sends, with everything fitted (side sonars, RSSI input, conveyor) and a move and a belt
    advance running: cyclic frames keep their cycle time exactly, the others while they are active."""
    b = Board()
    llc = LowLevelController(b, LlcParams(side_sonars=True, rssi_pwm_input=True, conveyor_slots=5))
    b.pwm_inputs[llc_fw.PIN_RSSI] = (0.5, llc_fw.RSSI_PWM_HZ)  # a steady RSSI: sent only as the keep-alive
    llc.setup()
    _cmd(llc, 0, 1000, 200)  # the wheels never turn: the move runs until its stall timeout
    conveyor = DB.get_message_by_name("CONVEYOR_CMD")
    b.can.on_bus_frame(Frame(conveyor.frame_id, conveyor.encode({"slots": 1, "seq": 1})))
    sent: dict[str, list[int]] = {}
    while b.time_us < 5_000_000:
        llc.loop()
        for f in b.can.take_tx():
            sent.setdefault(DB.get_message_by_frame_id(f.arbitration_id).name, []).append(f.timestamp_us)
        b.time_us += llc.loop_period_us
    for m in DB.messages:
        if m.senders != ["LLC"]:
            continue
        gaps = {round(g / 1000) for g in np.diff(sent[m.name])}
        if m.send_type == "Cyclic" or m.name == "RADIO_RSSI":
            assert gaps == {m.cycle_time}, m.name
        else:  # active for a while: the cycle time is the usual gap, state changes add frames in between
            assert statistics.mode(np.diff(sent[m.name])) == m.cycle_time * 1000 and len(sent[m.name]) > 10, m.name
