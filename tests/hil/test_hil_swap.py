"""Swapping real hardware into a simulated swarm, without hardware: a robot whose LLC is a real board on a CAN
interface (python-can's ``slcan`` on a pseudo-terminal, an LLC board on the far side), a robot that is a MAVLink
vehicle (a MAVLink face on UDP, driven in wall time), a real XBee joined to the simulated channel through a gateway
(two XBee modules on pseudo-terminals sharing a desk's air). Each stand-in speaks the real byte protocol; the
session reaches it only through its port."""

from __future__ import annotations

import json
import math
import signal
import struct
import subprocess
import time
from pathlib import Path

import can
import numpy as np
import pytest
import serial

from bridge.core.config import Config, ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from bridge.core.world import path_pose
from bridge.hosts.firmware import CanBridge
from swarm_logic.clock import WallClock
from swarm_logic.drivers.xbee import XBee
from tests.conftest import ROOT
from tests.core.test_session import cli, wait_line
from tests.support.standins import DESK64, GATEWAY64, DeskRadios, LlcStand, RoverStand

pytestmark = pytest.mark.timeout(300)


def run(cfg: Path, out: Path, timeout: float = 240) -> dict:
    r = subprocess.run(cli("run", str(cfg), "--out", str(out)), cwd=ROOT, capture_output=True, text=True,
                       timeout=timeout)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads((out / "summary.json").read_text())


def run_until_failed(cfg: Path, out: Path, robot: int) -> dict:
    """Run a session (far longer than the test) until robot ``robot`` failed and the session went on (a progress line
    after the failure), then stop it as Ctrl-C does; its summary. The session cannot end before the failure."""
    p = subprocess.Popen(cli("run", str(cfg), "--out", str(out), "--duration", "3600"), cwd=ROOT,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_line(p, f"robot {robot} failed at sim t=")
        wait_line(p, "rtf")
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=240) == 130
    finally:
        if p.poll() is None:
            p.kill()
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] and s["sim_time_s"] > max(f["t_s"] for f in s["failures"])
    return s


def header(duration_s: float) -> str:
    return f"""[session]
duration_s = {duration_s}
speed = 1
seed = 3
[arena]
width_m = 6
length_m = 6
"""


def swarm(count: int, behaviour: str = "random_walk", xbee: str = "") -> str:
    poses = [[1.0 + 0.8 * i, 1.0, 90.0] for i in range(count)]
    return (f'[[robots]]\ncount = {count}\nbehaviour = "{behaviour}"\n{xbee}'
            f'placement = {{ kind = "explicit", poses = {poses} }}\n')


# -- config and plan ----------------------------------------------------------------------------------------------


def test_stated_motion_is_required_and_checked(tmp_path: Path) -> None:
    dev = '{ interface = "virtual", channel = "x" }'
    cases = {
        f"can = {{ device = {dev} }}": "motion: with can.device the robot moves in the real world",
        'vehicle = { url = "udpin:127.0.0.1:14551" }': "motion: with vehicle the robot moves",
        'motion = { kind = "fixed" }': "the session drives this robot's body",
        f'can = {{ device = {dev} }}\nmotion = {{ kind = "scripted", waypoints = [[0, 1, 1, 0], [2, 9, 1, 0]] }}':
            r"robots\[0\].motion.waypoints\[1\]: \(9.0, 1.0\) is outside the arena",
        f'count = 2\ncan = {{ device = {dev} }}\nmotion = {{ kind = "scripted", waypoints = [[0, 1, 1, 0]] }}':
            "scripted waypoints are one body's path",
        'can = { device = { interface = "sitl", channel = "can0" } }\nmotion = { kind = "fixed" }':
            "the session's own simulated bus",
        f'can = {{ device = {dev} }}\nvehicle = {{ url = "udpin:127.0.0.1:1" }}\nmotion = {{ kind = "fixed" }}':
            "a MAVLink vehicle has no LLC on a CAN bus",
        f'can = {{ device = {dev} }}\nmotion = {{ kind = "fixed" }}\npose_source = "ground_truth"':
            "pose_source: with can.device",
    }
    for body, match in cases.items():
        p = tmp_path / "c.toml"
        p.write_text(header(5) + "[[robots]]\n" + body + "\n")
        with pytest.raises(ConfigError, match=match):
            load_config(p)
    p.write_text(header(5).replace("speed = 1", 'speed = "max"') + '[[robots]]\nvehicle = { url = "udpin:h:1" }\n'
                 'motion = { kind = "fixed" }\n')
    with pytest.raises(ConfigError, match=r"session.speed = 'max': .*robots\[0\].vehicle"):
        load_config(p)
    p.write_text(header(5) + '[[robots]]\n[[xbee_gateways]]\ndevice = "/dev/x"\npose = [7, 1]\n')
    with pytest.raises(ConfigError, match=r"xbee_gateways\[0\].pose: \(7.0, 1.0\) is outside the arena"):
        load_config(p)
    p.write_text(header(5) + '[[robots]]\n[[xbee_gateways]]\ndevice = "/dev/x"\npose = [1, 1]\npeer = "12"\n')
    with pytest.raises(ConfigError, match=r"xbee_gateways\[0\]\.peer: '12' is not a 64-bit address"):
        load_config(p)


def test_plan_roles_of_real_parts() -> None:
    cfg = Config.model_validate({
        "session": {"speed": 1}, "arena": {"width_m": 6, "length_m": 6},
        "robots": [{"count": 2, "xbee": {}},
                   {"can": {"device": {"interface": "virtual", "channel": "x"}}, "motion": {"kind": "fixed"}},
                   {"vehicle": {"url": "udpin:127.0.0.1:1"}, "xbee": {},
                    "motion": {"kind": "scripted", "waypoints": [[0, 2, 2, 90], [5, 3, 2, 90]]}}],
        "xbee_gateways": [{"device": "/dev/x", "pose": [4, 4]}]})
    plan = make_plan(cfg)
    board, vehicle, gw = plan.robots[2], plan.robots[3], plan.robots[4]
    assert board.modules() == ("can_bridge",) and board.can_nodes() == ("can_bridge", "logic")
    assert vehicle.modules() == ("xbee",) and vehicle.can_nodes() == ("logic",)
    assert vehicle.pose == pytest.approx((2, 2, math.pi / 2))  # a scripted body starts where its path starts
    assert gw.modules() == ("xbee",) and not gw.has_logic and gw.gateway["device"] == "/dev/x"
    assert [p.name for p in plan.procs if p.kind == "logic"] == ["lg0", "lg1", "lg2", "lg3"]  # no gateway logic


def test_path_pose_interpolates_and_holds() -> None:
    path = np.array([[1.0, 0.0, 0.0, 0.0], [3.0, 2.0, 0.0, math.pi / 2], [4.0, 2.0, 1.0, -math.pi + 0.1]])
    assert path_pose(path, 0.0) == (0.0, 0.0, 0.0)
    assert path_pose(path, 2.0) == pytest.approx((1.0, 0.0, math.pi / 4))
    assert path_pose(path, 3.5) == pytest.approx((2.0, 0.5, 0.75 * math.pi + 0.05))  # the short way round
    assert path_pose(path, 9.0) == pytest.approx((2.0, 1.0, -math.pi + 0.1))


def test_a_scripted_body_follows_its_path_and_pushes_through() -> None:
    from bridge.core.world import World

    cfg = Config.model_validate({
        "session": {"speed": 1}, "arena": {"width_m": 6, "length_m": 6},
        "robots": [{"placement": {"kind": "explicit", "poses": [[3.0, 2.0, 0.0]]}},
                   {"can": {"device": {"interface": "virtual", "channel": "x"}},
                    "motion": {"kind": "scripted", "waypoints": [[0, 1, 2, 0], [4, 5, 2, 0]]}},
                   {"can": {"device": {"interface": "virtual", "channel": "x"}}, "motion": {"kind": "fixed"},
                    "placement": {"kind": "explicit", "poses": [[1.0, 4.0, 30.0]]}}]})
    plan = make_plan(cfg)
    w = World(cfg, plan.robots)
    q = cfg.session.quantum_ns
    for k in range(200):  # 2 s: the scripted robot runs into the simulated one standing in its way
        w.step_quantum(k * q, q)
    assert w.pos[1] == pytest.approx([3.0, 2.0], abs=0.01)  # on its path, not stopped by the other
    assert abs(w.pos[0, 1] - 2.0) > 0.05 or abs(w.pos[0, 0] - 3.0) > 0.05  # the other was pushed aside
    assert w.pos[2] == pytest.approx([1.0, 4.0], abs=1e-6) and w.yaw[2] == pytest.approx(math.radians(30), abs=1e-6)
    assert w.odometer[1] == pytest.approx(2.0, abs=0.02)
    w.close()


# -- a real LLC board on a CAN interface -------------------------------------------------------------------------


def test_can_bridge_carries_frames_both_ways_on_a_python_can_interface(request: pytest.FixtureRequest) -> None:
    channel = f"bridge-{request.node.name}"
    board = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    bridge = CanBridge({"interface": "virtual", "channel": channel})
    try:
        assert bridge.exchange([(0x101, b"\x01\x02", False), (0x1ABCDE, b"", True)]) == []
        got = [board.recv(1.0), board.recv(1.0)]
        assert [(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in got] == [
            (0x101, b"\x01\x02", False), (0x1ABCDE, b"", True)]
        board.send(can.Message(arbitration_id=0x185, data=b"\xaa" * 8, is_extended_id=False))
        board.send(can.Message(arbitration_id=0x185, is_error_frame=True))
        board.send(can.Message(arbitration_id=0x186, is_remote_frame=True, is_extended_id=False))
        assert bridge.exchange([]) == [(0x185, b"\xaa" * 8, False)]
        assert bridge.counters == {"to_board": 2, "from_board": 1, "send_failed": 0, "error_frames": 1,
                                   "remote_frames": 1}
    finally:
        bridge.close()
        board.shutdown()


def test_can_bridge_names_a_missing_adapter(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match=r"can.device slcan:.*ttyACM9: cannot open the real board's bus"):
        CanBridge({"interface": "slcan", "channel": str(tmp_path / "ttyACM9"), "bitrate": 500000})


def board_config(cfg: Path, channel: str) -> None:
    """Two simulated robots and robot 2, whose LLC is the board behind the slcan adapter on ``channel``."""
    cfg.write_text(header(8) + swarm(2) + f"""
[[robots]]
behaviour = "random_walk"
can = {{ device = {{ interface = "slcan", channel = "{channel}", bitrate = 500000, sleep_after_open = 0 }} }}
motion = {{ kind = "fixed" }}
placement = {{ kind = "explicit", poses = [[4.5, 4.5, 0.0]] }}
""")


@pytest.mark.session
def test_a_robot_whose_llc_is_a_real_board_on_slcan(tmp_path: Path) -> None:
    """Robot 2's LLC is a board on the bench behind an slcan adapter: the session's logic drives it through the
    bridged bus (its wheels turn), hears its STATUS and ODOMETRY, and the body stays where the config puts it."""
    with LlcStand() as stand:
        cfg = tmp_path / "board.toml"
        board_config(cfg, stand.path)
        s = run(cfg, tmp_path / "run")
        turns, frames_in = stand.wheel_turns, stand.frames_in
        assert stand.error is None
    r2 = s["per_robot"][2]
    assert r2["alive"] and r2["motion"] == "fixed" and r2["distance_m"] == 0.0
    assert r2["final_pose"][:2] == [4.5, 4.5]
    bridge = r2["can_bridge"]
    assert bridge["from_board"] > 50 and bridge["to_board"] > 20 and bridge["send_failed"] == 0
    assert frames_in >= bridge["to_board"] - 5  # what the bridge sent reached the board (the last may be in flight)
    assert turns > 1.0  # the random walk drove the board's wheels
    names: dict[str, set[str]] = {}
    for topic, _t, payload in iter_messages(tmp_path / "run" / "session.mcap"):
        if topic == "/r002/can0":
            f = json.loads(payload)
            names.setdefault(f["src"], set()).add(f["name"])
    assert {"STATUS", "ODOMETRY"} <= names["r002/can_bridge"]  # the board's own reports
    assert "DRIVE_CMD" in names["r002/logic"] or "MOVE_CMD" in names["r002/logic"]
    assert all(r["alive"] for r in s["per_robot"])


# -- a MAVLink vehicle -----------------------------------------------------------------------------------------------


@pytest.mark.session
def test_a_mavlink_vehicle_in_the_swarm(tmp_path: Path) -> None:
    """Robot 2 is a vehicle that speaks only MAVLink on UDP: the session's random walk for it connects, sets
    GUIDED, arms and drives it; the vehicle moves, the session's body follows its stated script."""
    with RoverStand(sysid=1) as rover:
        cfg = tmp_path / "vehicle.toml"
        cfg.write_text(header(10) + swarm(2) + f"""
[[robots]]
behaviour = "random_walk"
vehicle = {{ url = "{rover.url}", target_system = 1 }}
motion = {{ kind = "scripted", waypoints = [[0, 4.5, 4.5, 0], [10, 5.0, 4.5, 0]] }}
""")
        s = run(cfg, tmp_path / "run")
        assert rover.error is None
        face = rover.face
        assert face.armed and face.mode == 15  # GUIDED, armed by the logic
        assert rover.travelled_m > 0.3  # driven by the session's random walk
        assert face.counters["bad_crc"] == 0
    r2 = s["per_robot"][2]
    assert r2["alive"] and r2["motion"] == "scripted"
    assert r2["final_pose"][:2] == pytest.approx([5.0, 4.5], abs=0.02)
    assert r2["distance_m"] == pytest.approx(0.5, abs=0.02)
    assert all(r["alive"] for r in s["per_robot"])


# -- an XBee gateway ------------------------------------------------------------------------------------------------


def gateway_config(tmp_path: Path, device: str, duration_s: float) -> Path:
    cfg = tmp_path / "gateway.toml"
    xbee = "xbee = { series = 2, baud = 115200 }\n"
    cfg.write_text(header(duration_s) + swarm(4, "rssi_keeper", xbee) + f"""
[[xbee_gateways]]
device = "{device}"
baud = 115200
series = 2
pose = [3.0, 3.0]
peer = "{DESK64:016X}"
""")
    return cfg


@pytest.mark.session
def test_a_desk_radio_and_the_swarm_hear_each_other_through_a_gateway(tmp_path: Path) -> None:
    """A program on the desk with its own XBee says hello as the swarm's robots do; the robots' modules receive it
    from the gateway's pose, and the desk program receives the robots' hellos."""
    with DeskRadios(series=2, baud=115200) as desk:
        cfg = gateway_config(tmp_path, desk.gateway_path, 10)
        proc = subprocess.Popen(cli("run", str(cfg), "--out", str(tmp_path / "run")), cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        port = serial.Serial(desk.desk_path, 115200, timeout=0)
        xb = XBee(port, WallClock(), api_mode=1, series=2)
        heard: list[tuple[int, bytes]] = []
        seq = 0
        try:
            next_hello = time.monotonic()
            while proc.poll() is None:
                if time.monotonic() >= next_hello:
                    next_hello += 0.5
                    seq += 1
                    xb.send_nowait(None, b"H" + struct.pack("<HH", 99, seq))
                while (pkt := xb.recv(timeout=0)) is not None:
                    heard.append((pkt.src64, pkt.data))
                time.sleep(0.01)
            err = proc.stderr.read()
        finally:
            port.close()
            if proc.poll() is None:
                proc.kill()
        assert desk.error is None and proc.returncode == 0, err[-3000:]
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    gw = s["per_robot"][4]
    assert gw["kind"] == "xbee_gateway" and gw["motion"] == "fixed" and gw["final_pose"][:2] == [3.0, 3.0]
    stats = gw["xbee_module"]["gateway"]
    assert stats["to_swarm"] >= 10 and stats["to_air"] >= 10
    assert stats["real_module"]["checksum_errors"] == 0 and stats["twin_module"]["malformed"] == 0
    # the desk heard the robots' hellos (from the gateway's module, the limitation stated in the docs)
    ids = {struct.unpack("<HH", d[1:5])[0] for src, d in heard if src == GATEWAY64 and d[:1] == b"H"}
    assert ids == {0, 1, 2, 3}
    # and the robots heard the desk's, from the gateway's simulated module
    rx_from_gw = {}
    for topic, _t, payload in iter_messages(tmp_path / "run" / "session.mcap"):
        if topic == "/radio/rx":
            m = json.loads(payload)
            if m["src"] == 4:
                rx_from_gw[m["dst"]] = rx_from_gw.get(m["dst"], 0) + 1
    assert set(rx_from_gw) == {0, 1, 2, 3} and min(rx_from_gw.values()) >= 5
    assert s["radio"]["connectivity"]["samples"] > 0  # the swarm's connectivity leaves the gateway out


def test_every_session_config_in_hil_configs_loads_and_plans() -> None:
    """The worked examples stay valid as the config grows (HAL configs for robot programs are another schema)."""
    import tomllib

    for path in sorted((ROOT / "hil_configs").rglob("*.toml")):
        if "robots" not in tomllib.loads(path.read_text()):
            continue
        cfg = load_config(path)
        assert make_plan(cfg, str(path)).robots, path.name


@pytest.mark.session
def test_a_real_board_that_disappears_fails_its_robot_only(tmp_path: Path) -> None:
    """The board's adapter is unplugged mid-session: robot 2 fails (its bridge's interface raises), the rest go on."""
    import threading

    stand = LlcStand().__enter__()

    def pull_the_plug() -> None:  # once the session drives the board (its start-up time varies with the load)
        deadline = time.monotonic() + 240  # (only bounds a hang: the test fails then)
        while stand.frames_in < 50 and time.monotonic() < deadline:
            time.sleep(0.05)
        stand.__exit__(None, None, None)

    unplug = threading.Thread(target=pull_the_plug)
    cfg = tmp_path / "board.toml"
    board_config(cfg, stand.path)
    unplug.start()
    try:
        s = run_until_failed(cfg, tmp_path / "run", 2)
    finally:
        unplug.join()
    alive = [r["alive"] for r in s["per_robot"]]
    assert alive == [True, True, False]
    (failure,) = s["failures"]
    assert failure["robot"] == 2 and failure["kind"] == "raised" and failure["t_s"] > 0.5
    assert "the real board's bus failed or disappeared" in failure["detail"]


@pytest.mark.session
def test_a_gateway_whose_xbee_disappears_fails_alone(tmp_path: Path) -> None:
    """The gateway's XBee is unplugged mid-session: the gateway fails (its relay's port raises), the robots go on."""
    import threading

    desk = DeskRadios(series=2, baud=115200).__enter__()

    def pull_the_plug() -> None:  # once the session's twin has joined and the relay carried something
        deadline = time.monotonic() + 240  # (only bounds a hang: the test fails then)
        while desk.frames[0] < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        desk.__exit__(None, None, None)

    unplug = threading.Thread(target=pull_the_plug)
    unplug.start()
    try:
        s = run_until_failed(gateway_config(tmp_path, desk.gateway_path, 8), tmp_path / "run", 4)
    finally:
        unplug.join()
    assert [r["alive"] for r in s["per_robot"]] == [True, True, True, True, False]
    (failure,) = s["failures"]
    assert failure["robot"] == 4 and failure["kind"] == "raised"
    assert "the gateway's XBee failed or disappeared" in failure["detail"]
