"""The foot-bot's boards: the range-and-bearing board's hand-packed report frames against the DBC (cantools), its
emissions and scans in time, and the base board in the world (wheel servo, watchdog, clipping)."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.world import World
from bridge.robots.footbot.base import BASE_PINS, BaseBoard
from bridge.robots.footbot.rab import RabEntity, RabParams
from firmware_sim.robots.footbot.rab_board import RabBoard
from swarm_logic.robots.footbot import footbot_db

DB = footbot_db()
MSG = {m.name: m for m in DB.messages}
MS = 1_000_000
LSB_DEG = 360 / 1024


def rab_frames(out: Any) -> list[tuple[str, dict]]:
    return [(DB.get_message_by_frame_id(i).name, DB.decode_message(i, d)) for i, d in out.can]


def data_frames(payload: bytes) -> list[tuple[int, bytes]]:
    """RAB_DATA_0 (and RAB_DATA_1 for a payload beyond 7 bytes), as the robot's computer sends them."""
    frames = [(MSG["RAB_DATA_0"].frame_id, bytes([len(payload)]) + payload[:7] + bytes(max(0, 7 - len(payload))))]
    if len(payload) > 7:
        frames.append((MSG["RAB_DATA_1"].frame_id, payload[7:10] + bytes(10 - len(payload))))
    return frames


# -- the report frames ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("length", range(11))
def test_rab_rx_frames_decode_with_the_dbc_to_what_the_board_was_given(length: int) -> None:
    rng = np.random.default_rng(length)
    bearings = [-math.pi, -3.0, -math.pi / 2, -0.001, 0.0, 0.001, 1.0, math.pi / 2, 3.1, math.pi,
                *rng.uniform(-math.pi, math.pi, 20)]
    heard = [{"src": k, "range_m": float(rng.uniform(0, 3.2)), "bearing_rad": float(b),
              "data": bytes(rng.integers(0, 256, length, dtype=np.uint8))} for k, b in enumerate(bearings)]
    board = RabBoard(period_ms=100, phase_ms=0)
    out = board.step(0, [], heard)
    frames = rab_frames(out)
    per = 2 if length > 4 else 1  # a payload of up to 4 bytes fits in RAB_RX_0 beside the range and bearing
    assert [n for n, _ in frames] == ["RAB_RX_0", "RAB_RX_1"][:per] * len(heard) + ["RAB_SCAN"]
    assert frames[-1][1]["count"] == len(heard) and frames[-1][1]["scan"] == 1
    for k, ev in enumerate(heard):
        a = frames[per * k][1]
        b = frames[per * k + 1][1] if per == 2 else {"index": k, **{f"d{i}": 0 for i in range(4, 10)}}
        assert a["index"] == b["index"] == k
        assert a["range_cm"] == round(ev["range_m"] * 100)
        err = math.remainder(math.radians(a["bearing"]) - ev["bearing_rad"], math.tau)
        assert abs(math.degrees(err)) <= LSB_DEG + 1e-9  # +-1 LSB (the board rounds; +pi saturates at 511)
        assert a["length"] == length
        data = bytes([a["d0"], a["d1"], a["d2"], a["d3"], *(b[f"d{i}"] for i in range(4, 10))])
        assert data[:length] == ev["data"] and data[length:] == bytes(10 - length)


def test_rab_rx_range_saturates_at_the_fields_top() -> None:
    out = RabBoard().step(0, [], [{"src": 1, "range_m": 12.0, "bearing_rad": 0.0, "data": b""}])
    assert rab_frames(out)[0][1]["range_cm"] == 1023


# -- emissions and scans in time ----------------------------------------------------------------------------------


def run_board(board: RabBoard, until_ms: int, can_at: dict[int, list[tuple[int, bytes]]] | None = None,
              air_at: dict[int, list[dict]] | None = None) -> tuple[list[tuple[int, bytes]], list[int]]:
    """Steps the board every millisecond: (when it emitted what, when it sent RAB_SCAN)."""
    emitted, scans = [], []
    for t in range(until_ms):
        out = board.step(t * MS, (can_at or {}).get(t, []), (air_at or {}).get(t, []))
        emitted += [(t, a["data"]) for a in out.air]
        scans += [t for i, _ in out.can if i == MSG["RAB_SCAN"].frame_id]
    return emitted, scans


def test_the_board_is_silent_until_given_a_payload_then_emits_once_a_period_at_its_phase() -> None:
    board = RabBoard(period_ms=100, phase_ms=37)
    emitted, scans = run_board(board, 1000, can_at={250: data_frames(b"hi")})
    assert scans == [37 + 100 * k for k in range(10)]  # a scan every period, heard no one or not
    assert emitted == [(t, b"hi") for t in (337, 437, 537, 637, 737, 837, 937)]
    assert board.counters["emitted"] == 7 and board.counters["scans"] == 10


def test_empty_scans_report_a_count_of_zero() -> None:
    board = RabBoard(period_ms=100, phase_ms=0)
    for k in range(3):
        frames = rab_frames(board.step(k * 100 * MS, [], []))
        assert frames == [("RAB_SCAN", {"count": 0, "scan": k + 1, "bad_frames": 0})]


@pytest.mark.parametrize("length", [0, 1, 7, 8, 10])
def test_a_payload_of_any_length_goes_out_as_given_until_replaced(length: int) -> None:
    board = RabBoard(period_ms=100, phase_ms=10)
    payload = bytes(range(100, 100 + length))
    emitted, _ = run_board(board, 400, can_at={0: data_frames(payload), 150: data_frames(b"new")})
    assert emitted == [(10, payload), (110, payload), (210, b"new"), (310, b"new")]


def test_bad_payload_frames_are_counted_and_the_last_good_payload_stays() -> None:
    board = RabBoard(period_ms=100, phase_ms=50)
    d0, d1 = MSG["RAB_DATA_0"].frame_id, MSG["RAB_DATA_1"].frame_id
    bad = [(d0, bytes([11]) + bytes(7)),  # longer than 10 bytes
           (d0, bytes([2, 1, 2])),  # a short frame
           (d1, bytes(3))]  # bytes 7-9 with no RAB_DATA_0 before them
    emitted, _ = run_board(board, 200, can_at={0: data_frames(b"ok"), 10: bad})
    assert emitted == [(50, b"ok"), (150, b"ok")]
    assert board.counters["bad_frames"] == 3
    assert rab_frames(board.step(250 * MS, [], []))[-1][1]["bad_frames"] == 3


def test_a_scan_reports_the_latest_reading_per_sender_and_then_forgets_them() -> None:
    board = RabBoard(period_ms=100, phase_ms=0)
    ev = [{"src": 2, "range_m": 1.0, "bearing_rad": 0.5, "data": b"a"},
          {"src": 1, "range_m": 0.5, "bearing_rad": -0.5, "data": b"b"},
          {"src": 2, "range_m": 1.2, "bearing_rad": 0.6, "data": b"c"}]
    board.step(0, [], [])
    board.step(30 * MS, [], ev[:2])
    board.step(60 * MS, [], ev[2:])
    frames = rab_frames(board.step(100 * MS, [], []))
    rx0 = [f for n, f in frames if n == "RAB_RX_0"]
    assert [(f["range_cm"], f["d0"]) for f in rx0] == [(50, ord("b")), (120, ord("c"))]  # in the senders' order
    assert rab_frames(board.step(200 * MS, [], []))[-1][1]["count"] == 0


def test_each_board_runs_at_its_own_phase_from_the_seed() -> None:
    q = RabParams()
    cfg = SimpleNamespace(session=SimpleNamespace(seed=5))
    phases = [RabEntity(SimpleNamespace(id=r), cfg, q).board.next_wake() for r in range(8)]
    assert all(0 <= p < q.period_ms * MS for p in phases) and len(set(phases)) > 4
    assert phases == [RabEntity(SimpleNamespace(id=r), cfg, q).board.next_wake() for r in range(8)]


# -- the base board in the world ------------------------------------------------------------------------------------


class BaseBench:
    """One foot-bot's base board against the world at the session's quantum (no hub): its pin writes act from the
    next quantum, as in a session."""

    def __init__(self, x: float = 2.0, y: float = 2.0, yaw: float = 0.0, **cfg: Any) -> None:
        c = Config.model_validate({"session": {"seed": 3}, "arena": {"width_m": 10, "length_m": 10}, **cfg,
                                   "robots": [{"profile": "footbot", "count": 1,
                                               "placement": {"kind": "explicit", "poses": [[x, y, yaw]]}}]})
        plan = make_plan(c)
        self.world = World(c, plan.robots)
        self.board = BaseBoard(self.world.profiles[0], plan.robots[0])
        self.q, self.t, self.wake = c.session.quantum_ns, 0, 0
        self.inbox: list = []
        self.tx: list = []
        self.pins: dict | None = None

    def send(self, name: str, **signals: int) -> None:
        m = MSG[name]
        self.inbox.append(["can0", m.frame_id, m.encode(signals), False, self.t])

    def step(self) -> None:
        if self.pins is not None:
            BASE_PINS.actuate(self.world, 0, self.pins)
            self.pins = None
        if self.wake <= self.t:
            sens, _ = BASE_PINS.sense(self.world, 0, {}, False)
            res = self.board.run(self.t, {"in": self.inbox, "sens": sens})
            self.inbox = []
            self.tx += res["out"]
            self.wake = res["wake"]
            self.pins = res.get("pins")
        self.world.step_quantum(self.t, self.q)
        self.t += self.q

    def run_for(self, seconds: float) -> None:
        end = self.t + round(seconds * 1e9)
        while self.t < end:
            self.step()

    def drive(self, left_mm_s: int, right_mm_s: int, seconds: float) -> None:
        for _ in range(round(seconds / 0.1)):
            self.send("WHEELS_CMD", left_mm_s=left_mm_s, right_mm_s=right_mm_s, seq=0)
            self.run_for(0.1)

    def pwm(self) -> np.ndarray:
        return np.asarray(self.world.model("differential_drive").pwm[0])

    def decoded(self, name: str) -> list[dict]:
        fid = MSG[name].frame_id
        return [DB.decode_message(fid, f[2]) for f in self.tx if f[1] == fid]


@pytest.mark.parametrize("speed", [0.1, 0.2])
def test_wheels_cmd_drives_the_wheels_at_the_commanded_speed(speed: float) -> None:
    b = BaseBench()
    mm = round(speed * 1000)
    b.drive(mm, mm, 1.0)  # settle
    x0 = b.world.pos[0].copy()
    b.drive(mm, mm, 3.0)
    assert math.dist(b.world.pos[0], x0) / 3.0 == pytest.approx(speed, rel=0.03)
    assert abs(math.remainder(float(b.world.yaw[0]), math.tau)) < 0.05  # both wheels held to the same speed


def test_the_watchdog_stops_the_motors_half_a_second_after_the_last_command() -> None:
    b = BaseBench()
    b.drive(150, 150, 1.0)  # the last command at 0.9 s
    b.run_for(0.4)
    assert np.abs(b.pwm()).sum() > 0  # 1.4 s: still within 0.5 s of it
    b.run_for(0.05)  # its first loop beyond 0.5 s (1.42 s) stops the motors
    assert np.abs(b.pwm()).sum() == 0
    b.run_for(1.0)
    assert b.decoded("BASE_STATUS")[-1]["fault_watchdog"] == 1
    b.drive(100, 100, 0.2)
    assert np.abs(b.pwm()).sum() > 0


def test_commands_beyond_30_cm_s_are_clipped() -> None:
    b = BaseBench()
    b.drive(800, 800, 1.0)
    x0 = b.world.pos[0].copy()
    b.drive(800, 800, 2.0)
    per_m = b.board.fw.pulses_per_m
    assert b.board.fw.target_pps == pytest.approx([0.3 * per_m, 0.3 * per_m])
    assert math.dist(b.world.pos[0], x0) / 2.0 == pytest.approx(0.3, rel=0.04)
    b.drive(-800, -800, 0.1)
    assert b.board.fw.target_pps == pytest.approx([-0.3 * per_m, -0.3 * per_m])


def test_the_base_reports_its_sensors_every_100_ms_and_its_status_every_second() -> None:
    b = BaseBench()
    b.run_for(2.0)
    assert len(b.decoded("ENCODERS")) == pytest.approx(20, abs=1)
    assert len(b.decoded("PROXIMITY_2")) == len(b.decoded("LIGHT_0")) == len(b.decoded("ENCODERS"))
    assert [g["scan"] for g in b.decoded("GROUND")][:3] == [1, 2, 3]
    status = b.decoded("BASE_STATUS")
    assert len(status) == pytest.approx(2, abs=1) and status[-1]["battery_mv"] > 3000
