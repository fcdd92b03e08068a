"""Whole sessions of DeciZebros talking over their UWB radios: robot programs exchange messages through
``robot.device("uwb_radio")`` and read their neighbours and IMU; faithful against realistic; the same seed gives the
same recording at any packing and speed; Z-H1 measured in a session of 16 robots."""

from __future__ import annotations

import json
import math
import signal
import struct
from pathlib import Path

import pytest
import serial

from bridge.core.recorder import file_digest, iter_messages
from swarm_logic.clock import WallClock
from swarm_logic.robots.decizebro.uwb_radio import ZebroUwbRadio
from tests.core.test_session import _check_messages_match_their_schemas, check_stopped_cleanly, start, wait_started
from tests.core.test_session import run as session_run

pytestmark = pytest.mark.session

CFG = """
[session]
name = "zebro-radio"
duration_s = {duration}
seed = {seed}
[arena]
width_m = 12
length_m = 12
[[robots]]
profile = "decizebro"
count = {count}
behaviour = "tests.support.zebro_radio_probe:Chatter"
{params}
placement = {{ kind = "grid", origin = [2.0, 2.0], spacing_m = 2.0, columns = {columns}, yaw_deg = 0 }}
{extra}
"""


def run(tmp_path: Path, name: str, *args: str, duration: float = 4, seed: int = 3, count: int = 4, burst: int = 2,
        extra: str = "") -> dict:
    cfg = tmp_path / f"{name}.toml"
    params = f"params = {{ burst = {burst} }}"
    if extra.startswith("params"):
        params, extra = extra, ""
    cfg.write_text(CFG.format(duration=duration, seed=seed, count=count, params=params,
                              columns=2 if count == 4 else 4, extra=extra))
    out = tmp_path / name
    code, s = session_run(cfg, out, *args, timeout=900)
    assert code == 0, s.get("error")
    s["_out"] = out
    return s


def chatter(out: Path, robot: int) -> list[dict]:
    return [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap")
            if topic == f"/r{robot:03d}/log/chatter"]


def test_zebros_exchange_messages_and_see_their_neighbours(tmp_path: Path) -> None:
    # two zebros a process: the recording of one a process (packing never changes a session's digest)
    s = run(tmp_path, "realistic", "--robots-per-process", "2", extra="params = { burst = 2, garbage = 1 }\n")
    for r in range(4):
        fw = s["per_robot"][r]["firmware"]
        # the program's junk and broken frame: counted and dropped, and the radio carried on
        assert {k: fw["uwb_radio"][k] for k in ("uart_bad_crc", "uart_truncated", "uart_unknown_type",
                                                "uart_bad_length", "uart_bad_param", "uart_junk_bytes")} == {
            "uart_bad_crc": 1, "uart_truncated": 0, "uart_unknown_type": 0, "uart_bad_length": 0,
            "uart_bad_param": 0, "uart_junk_bytes": 8}  # "junk", and the broken frame's bytes after its start byte
        assert fw["imu"]["errors"] == 0 and fw["imu"]["reads"] >= 3
        log = chatter(s["_out"], r)
        heard = {src for rec in log for src, _k in rec["got"]}
        assert heard == set(range(4)) - {r}  # every other robot's broadcasts arrived
        last = log[-1]
        assert {nb[0] for nb in last["nbs"]} == set(range(4)) - {r}
        assert all(1.5 < nb[1] < 3.3 for nb in last["nbs"])  # 2 m or 2.83 m, with the DW1000's errors
        assert all(nb[3] is not None and min(abs(nb[3]), abs(360 - nb[3])) < 10 for nb in last["nbs"])
        assert abs(last["heading"]) < 10  # every robot faces east, the IMU's bias and noise are a few degrees
    radio = s["radio"]["uwb_radio"]
    assert radio["off_slot"] == 0 and radio["modes"] == ["realistic"]
    assert radio["max_frames_per_robot_in_a_second"] <= radio["budget_per_robot_per_s"] == 128
    _check_messages_match_their_schemas(s["_out"] / "session.mcap", frozenset(
        {"swarm_sitl.Poses", "swarm_sitl.UwbRadioTx", "swarm_sitl.ImuPins", "swarm_sitl.Uart"}))
    assert file_digest(s["_out"] / "session.mcap") == (s["digest"], s["messages"])


@pytest.mark.long
def test_the_digest_holds_at_any_packing_and_speed(tmp_path: Path) -> None:
    a = run(tmp_path, "a")
    b = run(tmp_path, "b", "--robots-per-process", "4")
    c = run(tmp_path, "c", "--speed", "4")
    assert a["digest"] == b["digest"] == c["digest"] and a["messages"] == b["messages"] == c["messages"]
    assert a["radio"]["uwb_radio"]["modes"] == ["realistic"]


def test_faithful_mode_is_exact(tmp_path: Path) -> None:
    a = run(tmp_path, "faithful", extra='sensing = "faithful"\n')
    assert a["radio"]["uwb_radio"]["modes"] == ["faithful"] and a["radio"]["uwb_radio"]["data_lost"] == 0
    # robot 0 at (2, 2) facing east: 1 ahead at 2 m, 2 to its left at 2 m, 3 at 45 degrees, 2.83 m
    last = chatter(a["_out"], 0)[-1]
    assert last["heading"] == 0.0
    nbs = {nb[0]: nb[1:] for nb in last["nbs"]}
    assert nbs == {1: [2.0, 0.0, 0.0], 2: [2.0, 90.0, 0.0], 3: [pytest.approx(math.hypot(2, 2), abs=1e-3), 45.0, 0.0]}


def test_z_h1_a_session_of_16_zebros_keeps_to_32_frames_a_second_each(tmp_path: Path) -> None:
    # four zebros a process: the recording of one a process (packing never changes a session's digest), in 9 processes
    s = run(tmp_path, "z16", "--robots-per-process", "4", count=16, burst=16, duration=3)
    radio = s["radio"]["uwb_radio"]
    assert radio["budget_per_robot_per_s"] == 32 and radio["off_slot"] == 0
    assert radio["max_frames_per_robot_in_a_second"] == 32  # saturated, and never above
    assert radio["frames_per_robot_per_s"]["mean"] > 29  # the first frames wait for the programs to start


PTY_CFG = """
[session]
name = "zebro-radio-pty"
duration_s = 3600
speed = 1
[[robots]]
profile = "decizebro"
behaviour = "tests.support.zebro_radio_probe:Chatter"
params = { radio = 0 }
uwb_radio_pty = "r{id}-uwb"
placement = { kind = "explicit", poses = [[2.0, 2.0, 0.0]] }
[[robots]]
profile = "decizebro"
behaviour = "tests.support.zebro_radio_probe:Chatter"
placement = { kind = "explicit", poses = [[4.0, 2.0, 180.0]] }
"""


def test_a_program_outside_the_session_talks_over_the_radio_s_pseudo_terminal(tmp_path: Path) -> None:
    cfg = tmp_path / "pty.toml"
    cfg.write_text(PTY_CFG)
    out = tmp_path / "run"
    p = start(cfg, out)
    try:
        wait_started(p)
        link = out / "r0-uwb"
        assert link.is_symlink()
        clock = WallClock()
        with serial.Serial(str(link), 115200, timeout=0) as port:
            radio = ZebroUwbRadio(port, clock, timeout=30)
            assert radio.info["id"] == 0 and radio.info["n_slots"] == 2
            radio.set_heading(math.radians(30))
            t0, got, nbs = clock.now(), [], []
            while clock.now() - t0 < 60 and not (got and nbs):
                radio.broadcast(struct.pack("<HI", 0, 7))
                got += radio.receive()
                nbs = radio.neighbours()
                clock.sleep(0.2)
        assert {m.src for m in got} == {1} and nbs[0].id == 1 and 1.5 < nbs[0].range_m < 2.5
    finally:
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    check_stopped_cleanly(p, out)
    assert not link.exists()  # the link goes with the session
    heard = {src for rec in chatter(out, 1) for src, _k in rec.get("got", [])}
    assert heard == {0}  # robot 1's program got what the outside program broadcast
