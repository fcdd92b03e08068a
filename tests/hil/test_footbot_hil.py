"""A foot-bot outside a session: a real one's HAL config (its CAN interface) runs the controller a session runs, and
a session foot-bot whose logic is outside (``logic = "external"``) is driven through its CAN bus exposed as an slcan
pseudo-terminal, by the same driver (``FootbotBoards``) over python-can's own slcan interface."""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import uuid
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import can
import pytest

from bridge.core.config import load_config
from bridge.core.recorder import iter_messages
from swarm_logic.__main__ import load_hal, main
from swarm_logic.behaviours import load_behaviour
from swarm_logic.clock import WallClock
from swarm_logic.families.pfsm import messages as msg
from swarm_logic.families.pfsm.searcher import PfsmSearcher
from swarm_logic.robots.footbot import footbot_db
from swarm_logic.robots.footbot.can_boards import open_footbot_can
from swarm_logic.robots.footbot.interfaces import PROXIMITY, RANGE_AND_BEARING, WHEELS
from tests.conftest import ROOT
from tests.core.test_session import check_stopped_cleanly, start, wait_started

REAL = ROOT / "hil_configs" / "robots" / "footbot_real.toml"
PORTS = ROOT / "hil_configs" / "robots" / "footbot_sitl_ports.toml"
OUTSIDE = ROOT / "hil_configs" / "hil" / "footbot_outside.toml"
DB = footbot_db()


class InstantClock:
    """The program's clock: a sleep ends at once, time jumps to its end."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += max(0.0, dt)

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


def test_a_real_footbots_hal_config_runs_the_sessions_controller(tmp_path: Path) -> None:
    hal = load_hal(str(REAL))
    assert hal["footbot_can"]["interface"] == "socketcan" and hal["footbot_can"]["channel"] == "can0"
    assert "llc_can" not in hal
    cls = load_behaviour(hal["behaviour"])
    demo = load_config(ROOT / "hil_configs" / "pfsm" / "demo.toml")
    assert cls is PfsmSearcher and cls is load_behaviour(demo.robots[0].behaviour)  # the session's searcher
    cls.resolve(hal["params"])  # its parameters mean something to it
    # the same file with python-can's virtual bus for the robot's socketcan one: it opens and the controller drives
    ch = f"footbot-{uuid.uuid4().hex}"
    text = re.sub(r'^interface = "socketcan"', 'interface = "virtual"', REAL.read_text(), flags=re.M)
    text = re.sub(r'^channel = "can0"', f'channel = "{ch}"', text, flags=re.M)
    (tmp_path / "hal.toml").write_text(text)
    assert load_hal(str(tmp_path / "hal.toml"))["footbot_can"] == {**hal["footbot_can"], "interface": "virtual",
                                                                    "channel": ch}
    boards = can.Bus(interface="virtual", channel=ch)
    try:
        assert main(["--hal", str(tmp_path / "hal.toml"), "--duration", "2"], clock=InstantClock()) == 0
        names = []
        while (m := boards.recv(0.0)) is not None:
            names.append(DB.get_message_by_frame_id(m.arbitration_id).name)
    finally:
        boards.shutdown()
    assert "WHEELS_CMD" in names and "RAB_DATA_0" in names  # it drove, and told the others about itself


def test_the_outside_session_and_its_ports_config_agree() -> None:
    cfg = load_config(OUTSIDE)
    ext = [g for g in cfg.robots if g.logic == "external"]
    assert len(ext) == 1 and ext[0].profile == "footbot" and ext[0].can.slcan_pty == "r{id}-can"
    hal = load_hal(str(PORTS))
    rid = sum(g.count for g in cfg.robots[:cfg.robots.index(ext[0])])
    assert hal["robot_id"] == rid and hal["footbot_can"]["channel"] == f"runs/{cfg.session.name}/r{rid}-can"
    assert hal["footbot_can"]["interface"] == "slcan" and hal["footbot_can"]["bitrate"] == cfg.can.bitrate
    assert hal["behaviour"] == ext[0].behaviour and hal["params"] == dict(cfg.robots[0].params)
    PfsmSearcher.resolve(hal["params"])


GUARD_S = 120.0  # a failure guard on loops that wait for an event: never what passes them

SESSION = """
[session]
name = "footbot-outside"
duration_s = 3600
seed = 4
speed = 1
[can]
bitrate = 1000000
[arena]
width_m = 4
length_m = 4
[[arena.floor]]
x_min = 0.5
y_min = 0.5
x_max = 2.5
y_max = 1.1
grey = 0.5
[[robots]]
profile = "footbot"
logic = "external"
can = { slcan_pty = "r{id}-can" }
placement = { kind = "explicit", poses = [[1.0, 0.8, 0.0]] }
[[robots]]
profile = "footbot"
behaviour = "pfsm_target"
placement = { kind = "explicit", poses = [[1.0, 1.0, 0.0]] }
"""


@pytest.mark.session
def test_a_footbot_is_driven_from_outside_through_its_can_port(tmp_path: Path) -> None:
    """Robot 0's CAN bus on an slcan pseudo-terminal, robot 1 (a waiting target) beside it on its left. The test process
    runs the robot's own driver over python-can's slcan interface: the base board's sensor frames arrive and decode,
    a WHEELS_CMD moves the robot in the world, robot 1's range-and-bearing payload is read, and a payload set from
    outside is heard by robot 1. Every wait is for something the session sent (frames of its simulated boards)."""
    cfg = tmp_path / "outside.toml"
    cfg.write_text(SESSION)
    out = tmp_path / "run"
    p = start(cfg, out)
    clock = WallClock()
    try:
        wait_started(p)
        drv = open_footbot_can({"interface": "slcan", "channel": str(out / "r0-can"), "bitrate": 1_000_000,
                                "sleep_after_open": 0}, SimpleNamespace(clock=clock))
        faces = drv.faces()
        try:
            def until(done: Callable[[], bool]) -> None:
                t0 = clock.now()
                while not done() and clock.now() - t0 < GUARD_S:
                    clock.sleep(0.02)
                    drv.poll()
                assert done()

            # the base board's sensor frames: the grey patch under it, robot 1 on its left in the proximity ring
            until(lambda: drv.ground != [1.0] * 4 and max(drv.proximity) > 0 and bool(drv.status))
            assert drv.ground == [pytest.approx(0.5, abs=0.05)] * 4, drv.ground
            ring = faces[PROXIMITY].readings()
            nearest = max(ring, key=lambda r: r.value)
            assert nearest.value > 0.1 and abs(math.degrees(nearest.angle_rad) - 90) <= 30, nearest
            assert drv.status["battery_mv"] > 0 and drv.counters["bad_frames"] == 0

            # WHEELS_CMD: forward at 0.1 m/s until the encoders say 0.15 m (the driver repeats it for the watchdog)
            wheels = faces[WHEELS]
            start_left = drv.encoders[0]
            pulses = 0.15 * 1024 / (2 * math.pi * 0.0291)

            def moved() -> bool:
                wheels.set_speeds(0.1, 0.1)
                return drv.encoders[0] - start_left >= pulses

            until(moved)
            wheels.set_speeds(0.0, 0.0)

            # robot 1's payload: the waiting target names itself
            rab = faces[RANGE_AND_BEARING]
            until(lambda: any((m := msg.decode(r.data)) is not None and m.kind == msg.TARGET and m.target_id == 1
                              for r in rab.readings()))
            heard = rab.readings()[0]
            assert 0.1 < heard.range_m < 1.0 and abs(heard.bearing_rad) <= math.pi

            # a payload set from outside (8 bytes: RAB_DATA_0 and RAB_DATA_1), then five of the board's periods
            rab.send(PAYLOAD)
            scans = drv.counters["scans"]
            until(lambda: drv.counters["scans"] >= scans + 5)
            assert drv.counters["bad_frames"] == 0 and drv.counters["send_errors"] == 0
        finally:
            drv.close()
    finally:
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    s = check_stopped_cleanly(p, out)
    r0 = s["per_robot"][0]
    assert r0["final_pose"][0] > 1.0 + 0.1 and r0["distance_m"] > 0.1, r0  # it drove east
    assert r0["rab"]["emitted"] >= 3 and s["per_robot"][1]["rab"]["received"] >= 3
    tx = [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/r000/rab/tx"]
    ours = [e for e in tx if e["data"] == PAYLOAD.hex()]
    assert tx and ours == tx  # silent until given a payload, then the outside one
    assert len(ours) >= 3 and all(e["heard"] == [1] for e in ours)


PAYLOAD = b"outside!"


@pytest.mark.session
def test_the_outside_program_runs_on_the_shipped_session(tmp_path: Path) -> None:
    """The README's two terminals: ``swarm-sitl run hil_configs/hil/footbot_outside.toml`` and ``python -m swarm_logic
    --hal hil_configs/robots/footbot_sitl_ports.toml`` (its paths moved to this test's output directory)."""
    out = tmp_path / "run"
    hal = PORTS.read_text().replace("runs/footbot_outside/", f"{out}/")
    assert hal.count(str(out)) == 2
    (tmp_path / "hal.toml").write_text(hal)
    p = start(OUTSIDE, out, "--duration", "3600")
    try:
        wait_started(p)
        r = subprocess.run([sys.executable, "-m", "swarm_logic", "--hal", str(tmp_path / "hal.toml"), "--duration",
                            "3"], cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
    finally:
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    s = check_stopped_cleanly(p, out)
    r3 = s["per_robot"][3]
    assert r3["rab"]["emitted"] >= 10 and r3["rab"]["received"] >= 10  # it announced itself and heard the others
    assert r3["distance_m"] > 0.05, r3  # the searcher drove
