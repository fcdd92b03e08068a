"""A SonPI outside its session and on a real Pi. A session SonPI whose I2C bus is a Devantech USB-ISS on a
pseudo-terminal (``i2c_pty``) is driven by this test's own program through ``open_smbus("usb-iss://...")``: it reads
the Arduino board's registers, meets a NACK and a missing register, reads sonar windows and writes wheel speeds
through the Pi's driver, and the robot moves in the world; then ``python -m swarm_logic`` runs the robot's program on
the same port (``hil_configs/robots/sonpi_sitl_ports.toml``). And the real robot's HAL config: valid, and a missing
bus is named."""

from __future__ import annotations

import errno
import json
import math
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bridge.core.config import load_config
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from bridge.robots.sonpi import firmware
from swarm_logic.__main__ import load_hal, main
from swarm_logic.behaviours import load_behaviour
from swarm_logic.clock import WallClock
from swarm_logic.drivers.i2c import open_smbus
from swarm_logic.families.roy.controller import RoyApf
from swarm_logic.robot import Robot
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.board import SonpiBoard
from swarm_logic.robots.sonpi.interfaces import LOCALISATION, ODOMETRY, POSE, SONAR, VELOCITY
from tests.conftest import ROOT
from tests.core.test_session import check_stopped_cleanly, start, wait_line, wait_started
from tests.support.sonpi_bench import robot_with

GUARD_S = 120.0  # a failure guard on loops that wait for an event: never what passes them
START = (0.5, 1.0, 0.0)
GARBAGE = b"\x00 not a SonPI packet"

CONFIG = f"""
[session]
name = "sonpi-outside"
duration_s = 3600
seed = 2
speed = 1
[arena]
width_m = 3
length_m = 3
[[robots]]
profile = "sonpi"
logic = "external"
i2c_pty = "r{{id}}-i2c"
placement = {{ kind = "explicit", poses = [[{START[0]}, {START[1]}, {START[2]}]] }}
"""


def ports_hal(out: Path, rid: int, wifi_port: int | None = None) -> str:
    """hil_configs/robots/sonpi_sitl_ports.toml for robot ``rid`` of the session at ``out`` (its Wi-Fi node on
    ``wifi_port``)."""
    hal = (ROOT / "hil_configs" / "robots" / "sonpi_sitl_ports.toml").read_text()
    hal = hal.replace("runs/sonpi_outside/r2-", f"{out}/r{rid}-").replace("robot_id = 2", f"robot_id = {rid}")
    return hal if wifi_port is None else hal.replace("127.0.0.1:47801", f"127.0.0.1:{wifi_port}")


def without_table(toml: str, table: str) -> str:
    """``toml`` without ``[table]`` (up to the next table)."""
    head, _, rest = toml.partition(f"[{table}]")
    nxt = rest.find("\n[")
    return head + (rest[nxt + 1 :] if nxt >= 0 else "")


@pytest.mark.session
def test_a_session_sonpi_is_driven_from_outside_through_its_bus(tmp_path: Path) -> None:
    cfg = tmp_path / "outside.toml"
    cfg.write_text(CONFIG)
    out = tmp_path / "run"
    p = start(cfg, out)
    clock = WallClock()
    try:
        wait_started(p)
        bus: Any = open_smbus(f"usb-iss://{out / 'r0-i2c'}", scl_hz=100_000, timeout_s=20)  # 20 s: a guard
        try:
            assert bus.read_i2c_block_data(P.ADDRESS, P.WHO_AM_I, 2) == [P.WHO_AM_I_VALUE, P.VERSION_VALUE]
            with pytest.raises(OSError) as e:  # nobody at 0x30
                bus.write_byte_data(0x30, 0x00, 1)
            assert e.value.errno == errno.EREMOTEIO
            with pytest.raises(OSError) as e:  # a missing register: the sketch refuses the read, NACKs it
                bus.read_byte_data(P.ADDRESS, 0x07)
            assert e.value.errno == errno.EREMOTEIO
            assert bus.read_byte_data(P.ADDRESS, P.LAST_ERROR) == P.ERR_BAD_REGISTER
            # the Pi's own driver over the adapter: head east at 0.12 m/s for about 0.5 m, reading windows
            board = SonpiBoard(
                bus,
                clock,
                wheel_radius_m=0.0325,
                half_track_m=0.075,
                encoder_cpr=2048,
                robot=robot_with(start_pose=START),
            )
            board.faces()[VELOCITY].set_velocity(0.12, 0.0)
            t0 = clock.now()
            while board.faces()[ODOMETRY].read().x_m < START[0] + 0.5 and clock.now() - t0 < GUARD_S:
                board.poll()
                clock.sleep(0.05)
            odo = board.faces()[ODOMETRY].read()
            assert odo.x_m >= START[0] + 0.5 and abs(odo.y_m - START[1]) < 0.15
            board.faces()[VELOCITY].set_velocity(0.0, 0.0)
            board.poll()
            assert board.counters["windows"] >= 5 and board.counters["bus_errors"] == 0
            ranges = [r.range_m for r in board.faces()[SONAR].readings()]
            # the arena's walls, from sensors 0.09 m off the centre: 1 m to the right, 2 m to the left (the robot keeps
            # within 0.15 m of its line), the east wall ahead within 2 m
            assert 0.7 < ranges[0] < 1.1 and 1.7 < ranges[4] < 2.1
            assert math.isfinite(ranges[2]) and ranges[2] < 2.0
            window = board.window
            assert window is not None and window.seq >= 5
        finally:
            bus.close()

        # the robot's program, as it runs on the Pi, on the same port (sonpi_sitl_ports.toml with this session's)
        # this session has no Wi-Fi: the board alone, and a behaviour of the board alone
        hal = without_table(without_table(ports_hal(out, 0), "sonpi_wifi"), "params") + "[params]\nspeed_mps = 0.15\n"
        hal = re.sub(r"(?m)^start_pose = .*$", f"start_pose = {list(START)}", hal)  # where this session put it
        (tmp_path / "hal.toml").write_text(hal)
        program = [sys.executable, "-m", "swarm_logic", "--hal", str(tmp_path / "hal.toml"), "--duration", "3"]
        r = subprocess.run(
            [*program, "--behaviour", "sonar_wander"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 0, r.stderr
        logged = [json.loads(line) for line in (out / "r0-logic.jsonl").read_text().splitlines()]
        sonar = [rec for rec in logged if rec["topic"] == "sonar"]
        assert len(sonar) >= 8 and any(x is not None for rec in sonar for x in rec["ranges_m"])
    finally:
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    s = check_stopped_cleanly(p, out)
    r0 = s["per_robot"][0]
    adapter, arduino = r0["firmware"]["i2c_adapter"], r0["firmware"]["arduino"]
    assert r0["i2c"]["nacks"] == adapter["nacks"] == 2 and r0["i2c"]["transactions"] == adapter["transactions"]
    assert arduino["refused_reads"] == 1 and arduino["bad_reads"] == arduino["refused_writes"] == 0
    assert arduino["malformed"] == 0
    assert r0["distance_m"] > 0.5 and r0["final_pose"][0] > START[0] + 0.5  # it drove east


def test_the_real_sonpi_hal_config_is_valid_and_a_missing_bus_is_named() -> None:
    """The real robot runs the chapter 3 controller on its I2C bus 1 and the SonPI Wi-Fi port; its tables open (the
    Wi-Fi one here on loopback, any port); on a machine without the bus it stops at the bus, before binding the Wi-Fi
    port (the board's table comes first)."""
    p = ROOT / "hil_configs" / "robots" / "sonpi_real.toml"
    hal = load_hal(str(p))
    assert hal["behaviour"] == "roy_apf" and load_behaviour("roy_apf") is RoyApf
    assert hal["sonpi_board"]["bus"] == 1 and "llc_can" not in hal
    assert hal["sonpi_wifi"]["url"] == "udp://0.0.0.0:5005"
    assert [k for k in hal if k in ("sonpi_board", "sonpi_wifi")] == ["sonpi_board", "sonpi_wifi"]
    params = RoyApf.resolve(hal["params"])
    assert (params["target_x"] * params["unit_m"], params["target_y"] * params["unit_m"]) == (3.5, 3.5)
    wifi = {**hal["sonpi_wifi"], "url": "udp://127.0.0.1:0"}
    robot = Robot.open(hal["robot_id"], {"sonpi_wifi": wifi}, WallClock(), 1, hal["params"])
    try:
        assert set(robot.faces) >= {POSE, LOCALISATION}
    finally:
        robot.close()
    if Path("/dev/i2c-1").exists():
        pytest.skip("this machine has an I2C bus 1")
    with pytest.raises(SystemExit, match=r"sonpi_real\.toml: cannot open the robot's devices: .*i2c-1"):
        main(["--hal", str(p), "--duration", "1"])


def test_the_outside_session_and_its_ports_config_agree() -> None:
    """hil_configs/hil/sonpi_outside.toml and the HAL config its outside program runs name the same robot, port, start
    pose and wheels; the session gives its own programs the same table on the simulated bus."""
    outside = ROOT / "hil_configs" / "hil" / "sonpi_outside.toml"
    cfg = load_config(outside)
    ext = [g for g in cfg.robots if g.logic == "external"]
    assert len(ext) == 1 and ext[0].profile == "sonpi" and ext[0].model_extra["i2c_pty"] == "r{id}-i2c"
    hal = load_hal(str(ROOT / "hil_configs" / "robots" / "sonpi_sitl_ports.toml"))
    rid = sum(g.count for g in cfg.robots[: cfg.robots.index(ext[0])])
    assert hal["robot_id"] == rid and hal["sonpi_board"]["bus"] == f"usb-iss://runs/{cfg.session.name}/r{rid}-i2c"
    x, y, yaw_deg = ext[0].placement.poses[0]
    assert hal["start_pose"] == pytest.approx([x, y, math.radians(yaw_deg)]) and hal["behaviour"] == ext[0].behaviour
    # its Wi-Fi: what it sends goes to the robot's UDP port; the session's own robots have the camera and controller
    assert hal["sonpi_wifi"]["localisation"] == hal["sonpi_wifi"]["controller"] == ext[0].wifi_udp
    assert {s.kind for s in cfg.services} == {"overhead_camera", "global_controller"}
    # the same controller as the real robot's, with the same parameters, as the session's own robots
    real_hal = load_hal(str(ROOT / "hil_configs" / "robots" / "sonpi_real.toml"))
    assert hal["behaviour"] == real_hal["behaviour"] == "roy_apf" and hal["params"] == real_hal["params"]
    for g in cfg.robots:
        assert g.behaviour == "roy_apf" and RoyApf.resolve(g.params) == RoyApf.resolve(real_hal["params"])
    same = ("odometry_period_s", "status_period_s", "first_pose_timeout_s")
    assert {k: hal["sonpi_wifi"][k] for k in same} == {k: real_hal["sonpi_wifi"][k] for k in same}
    plan = make_plan(cfg, str(outside))
    session_table = firmware.hal(plan.robots[0], cfg)["sonpi_board"]
    assert session_table["bus"] == "sitl://i2c" and firmware.hal(plan.robots[rid], cfg) == {}
    for key in ("wheel_radius_m", "half_track_m", "encoder_cpr", "max_speed_mps"):
        assert hal["sonpi_board"][key] == session_table[key], key
    real = load_hal(str(ROOT / "hil_configs" / "robots" / "sonpi_real.toml"))["sonpi_board"]
    assert {k: real[k] for k in ("wheel_radius_m", "half_track_m", "encoder_cpr")} == {
        k: session_table[k] for k in ("wheel_radius_m", "half_track_m", "encoder_cpr")
    }


def _log_records(path: Path) -> list[dict[str, Any]]:
    """The outside program's log as far as it is written (a line being written is left for the next read)."""
    if not path.exists():
        return []
    lines = path.read_text().split("\n")[:-1]
    return [json.loads(line) for line in lines]


@pytest.mark.session
def test_a_session_sonpi_under_the_camera_is_driven_from_outside_through_both_ports(tmp_path: Path) -> None:
    """hil_configs/hil/sonpi_outside.toml (the UDP port any free one): robot 2's program, the real robot's controller
    (roy_apf) on hil_configs/robots/sonpi_sitl_ports.toml, reaches its board through the USB-ISS pseudo-terminal and
    the Wi-Fi network through its UDP port. It gets the camera's poses, its odometry is fused by the camera, its status
    reaches the controller, and it heads for the target. Bad datagrams on the port are counted and dropped."""
    text = (ROOT / "hil_configs" / "hil" / "sonpi_outside.toml").read_text()
    text = text.replace('wifi_udp = "127.0.0.1:47801"', 'wifi_udp = "127.0.0.1:0"').replace(
        "duration_s = 120", "duration_s = 3600"
    )
    cfg = tmp_path / "outside.toml"
    cfg.write_text(text)
    target = (3.5, 3.5)
    start_xy = (0.6, 1.05)
    out = tmp_path / "run"
    p = start(cfg, out)
    prog: subprocess.Popen | None = None
    try:
        wait_started(p)
        line = wait_line(p, "Wi-Fi (UDP):")
        host, port = line.rsplit(" ", 1)[1].strip().split(":")
        assert host == "127.0.0.1"
        # bad datagrams first: empty and over-long ones the network refuses, garbage it carries to every node
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as bad:
            for data in (b"", b"x" * 1473, GARBAGE):
                bad.sendto(data, (host, int(port)))
        (tmp_path / "hal.toml").write_text(ports_hal(out, 2, int(port)))
        prog = subprocess.Popen(
            [sys.executable, "-X", "faulthandler", "-m", "swarm_logic", "--hal", str(tmp_path / "hal.toml")],
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        # until the program's own pose estimate (the camera's broadcast) is 0.2 m nearer the target than where it began
        log = out / "r2-logic.jsonl"
        clock = WallClock()
        t0 = clock.now()
        first = last = None
        while clock.now() - t0 < GUARD_S:
            assert prog.poll() is None, prog.stderr.read() if prog.stderr else ""
            poses = [r for r in _log_records(log) if r["topic"] == "wifi_pose"]
            if poses:
                first, last = poses[0], poses[-1]
                if math.dist(target, (first["x"], first["y"])) - math.dist(target, (last["x"], last["y"])) > 0.2:
                    break
            clock.sleep(0.2)
        assert first is not None and last is not None
        assert math.dist(target, (first["x"], first["y"])) - math.dist(target, (last["x"], last["y"])) > 0.2
        assert math.dist(start_xy, (first["x"], first["y"])) < 0.1  # the camera put it where the session did
        assert last["fresh"] and last["others"] == 2 and last["malformed"] == 0
        prog.send_signal(signal.SIGINT)
        try:
            prog.wait(timeout=120)  # a guard against a hang, not a wait: it exits at once
        except subprocess.TimeoutExpired:  # a hang: its threads' stacks (faulthandler on SIGABRT) in the failure
            prog.send_signal(signal.SIGABRT)
            prog.wait()
        assert prog.returncode == 0, prog.stderr.read() if prog.stderr else ""
    finally:
        if prog is not None and prog.poll() is None:
            prog.kill()
            prog.wait()
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    s = check_stopped_cleanly(p, out)
    udp = s["wifi"]["udp"]["r002"]
    assert udp["endpoint"] == f"{host}:{port}" and udp["malformed"] == 2 and udp["dead"] == 0
    assert udp["received"] >= 20 and udp["sent"] >= 20  # its odometry and status in; poses and missions out
    cam, ctl = s["services"]["camera"], s["services"]["controller"]
    assert "2" in cam["clock_offsets_s"]  # its odometry came on the program's wall clock ...
    assert cam["fused_by_robot"]["2"] >= 10  # ... and the camera fused it
    assert cam["malformed"] == 1 and ctl["malformed"] == 1  # the garbage datagram, heard and dropped
    assert ctl["last_state"]["2"] == "running"  # its status reached the controller
    r2 = s["per_robot"][2]
    assert math.dist(target, start_xy) - math.dist(target, r2["final_pose"][:2]) > 0.2  # it moved towards the target
    # it drove its board through the adapter (how many transactions depends on the machine's load: the program runs
    # on its wall clock while the session keeps simulated time: 76 were seen on a loaded machine)
    assert s["per_robot"][2]["firmware"]["i2c_adapter"]["transactions"] >= 20
    # the recording: robot 2's odometry, as the network carried it from its port to every node
    odometry = []
    for topic, _, d in iter_messages(out / "session.mcap"):
        rec = json.loads(d)
        if topic == "/wifi/tx" and rec["src"] == "r002" and rec["data"] != GARBAGE.hex():
            head, content = pp.decode(bytes.fromhex(rec["data"]))
            if head.type == pp.ODOMETRY:
                odometry.append(content)
                assert rec["dest"] is None and "camera" in rec["heard"]
    assert len(odometry) >= 20 and {o.id for o in odometry} == {2}
