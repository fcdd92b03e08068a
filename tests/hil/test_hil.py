"""Hardware in the loop without hardware: a "real" robot is one whose swarm logic runs outside the session, on the
wall clock, and reaches its devices only through the ports a real robot's would: its XBee through a pseudo-terminal
carrying XBee API frames, its LLC through a pseudo-terminal speaking slcan (python-can's own slcan interface). It
must behave like its simulated twins."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import Config, ConfigError, load_config
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from tests.conftest import ROOT
from tests.core.test_session import cli, wait_line, wait_started

MIXED = ROOT / "hil_configs" / "hil" / "mixed_real_robot.toml"
HAL = ROOT / "hil_configs" / "robots" / "eswarbot_sitl_ports.toml"
BUS_OFF_CFG = ROOT / "hil_configs" / "demos" / "can_bus_off.toml"


def test_external_logic_needs_ports_and_real_time(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text('[session]\nspeed = 1\n[[robots]]\nlogic = "external"\n')
    with pytest.raises(ConfigError, match=r"robots\[0\]: can.slcan_pty: an external logic reaches the robot's LLC"):
        load_config(p)
    p.write_text('[session]\nspeed = 1\n[[robots]]\nprofile = "traxbot"\nlogic = "external"\n')
    with pytest.raises(ConfigError, match=r"robots\[0\]: can.slcan_pty: an external logic reaches the robot's LLC"):
        load_config(p)
    p.write_text('[session]\nspeed = 1\n[[robots]]\nlogic = "external"\ncan = { slcan_pty = "c" }\nxbee = {}\n')
    with pytest.raises(ConfigError, match=r"xbee.pty: an external logic reaches the robot's XBee"):
        load_config(p)
    p.write_text('[session]\nspeed = "max"\n[[robots]]\ncan = { slcan_pty = "c" }\n')
    with pytest.raises(ConfigError, match=r"session.speed = 'max': a session with ports to the outside world "
                                          r"\(robots\[0\].can.slcan_pty\) runs paced to wall time"):
        load_config(p)
    with pytest.raises(ConfigError, match=r"session.speed = 4.0"):
        load_config(MIXED, {"session.speed": 4.0})
    p.write_text('[session]\nspeed = 1\n[[robots]]\ncount = 2\ncan = { slcan_pty = "c" }\n')
    with pytest.raises(ConfigError, match=r"can.slcan_pty: a group of several robots needs '\{id\}'"):
        load_config(p)


def test_plan_of_a_mixed_session() -> None:
    plan = make_plan(load_config(MIXED), str(MIXED))
    ext = plan.robots[5]
    assert ext.logic == "external" and ext.modules() == ("llc", "xbee", "slcan")
    assert ext.can_nodes() == ("llc", "slcan") and ext.host_node == "slcan"
    logic_robots = [r for p in plan.procs if p.kind == "logic" for r in p.robots]
    firmware_robots = [r for p in plan.procs if p.kind == "firmware" for r in p.robots]
    assert logic_robots == [0, 1, 2, 3, 4] and firmware_robots == [0, 1, 2, 3, 4, 5]
    assert Config.model_validate(plan.config).robots[1].logic == "external"


def _neighbour_logs_from_recording(path: Path) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = {}
    for topic, _t, payload in iter_messages(path):
        if topic.endswith("/log/neighbours"):
            out.setdefault(int(topic[2:5]), []).append(json.loads(payload))
    return out


@pytest.mark.long
@pytest.mark.session
def test_mixed_swarm_with_a_real_robot_on_ptys(tmp_path: Path) -> None:
    """Acceptance: 5 simulated eSwarBots and 1 whose XBee and CAN are reached only through pseudo-terminals run the
    RSSI-keeping behaviour, and the real one stays in the swarm."""
    out = tmp_path / "run"
    hal = tomllib.loads(HAL.read_text())
    logic_s = 25.0
    hal_path = tmp_path / "hal.toml"
    hal_path.write_text(f"""robot_id = {hal["robot_id"]}
behaviour = "{hal["behaviour"]}"
[llc_can]
interface = "slcan"
channel = "{out / "r5-can"}"
bitrate = {hal["llc_can"]["bitrate"]}
sleep_after_open = 0
[xbee]
port = "{out / "r5-xbee"}"
baudrate = {hal["xbee"]["baudrate"]}
api_mode = {hal["xbee"]["api_mode"]}
rssi_from_db = true
[log]
path = "{tmp_path / "real.jsonl"}"
[params]
speed_mps = {hal["params"]["speed_mps"]}
q_min_dbm = {hal["params"]["q_min_dbm"]}
""")
    # a session far longer than the robot's program, however late that starts: stopped once the program ended and the
    # session went on (it took the program's last frames)
    launched = time.monotonic()
    session = subprocess.Popen(cli("run", str(MIXED), "--out", str(out), "--duration", "3600"), cwd=ROOT,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_started(session)
        # the robot's companion computer: the same program a real eSwarBot runs, on the wall clock
        robot = subprocess.run([sys.executable, "-m", "swarm_logic", "--hal", str(hal_path), "--duration",
                                str(logic_s)], cwd=ROOT, capture_output=True, text=True, timeout=logic_s + 120)
        assert robot.returncode == 0, robot.stderr[-3000:]
        # paced to wall time (speed 1), the session shows a simulated time beyond the wall time since its launch only
        # once that much wall time passed: after the program ended
        beyond = time.monotonic() - launched + 1
        while float(re.search(r" sim +([0-9.]+) /", wait_line(session, "rtf"))[1]) < beyond:
            pass
    finally:
        if session.poll() is None:
            session.send_signal(signal.SIGINT)
        session.wait(timeout=240)
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] and not s["failures"] and s["error"] is None, s.get("error")
    session_s = s["sim_time_s"]
    per = {r["id"]: r for r in s["per_robot"]}
    real, twins = per[5], [per[i] for i in range(5)]

    # it moved: its MOVE/DRIVE commands crossed the slcan adapter onto its simulated bus
    assert real["distance_m"] > 1.0, real
    stats = real["xbee_module"]
    # it said hello as often as its twins (1 Hz, for the time it ran) and heard them
    twin_rate = np.median([t["xbee_module"]["tx_requests"] for t in twins]) / session_s
    assert abs(stats["tx_requests"] / logic_s - twin_rate) <= 0.2 * twin_rate, (stats, twin_rate)
    assert stats["rx_delivered"] >= 0.5 * np.median([t["xbee_module"]["rx_delivered"] for t in twins])
    # it stays in the swarm: the radio graph (with it) is connected throughout, and its own neighbour table, as its
    # logic logged it, keeps good neighbours as its twins' do
    assert s["radio"]["connectivity"]["connected_share"] == 1.0
    mine = [json.loads(line) for line in (tmp_path / "real.jsonl").read_text().splitlines()]
    mine = [m for m in mine if m["topic"] == "neighbours"]
    assert len(mine) >= logic_s - 3
    share_mine = np.mean([m["good"] >= 1 for m in mine])
    theirs = _neighbour_logs_from_recording(out / "session.mcap")
    share_twins = np.mean([m["good"] >= 1 for r in range(5) for m in theirs[r]])
    assert share_mine >= 0.8 and share_mine >= share_twins - 0.2, (share_mine, share_twins)
    rssi = [v for m in mine for v in m["rssi"]]
    assert rssi and min(rssi) >= -94 and max(rssi) <= -30
    # the session was paced to wall time and says how far it lagged
    assert s["wall_lag"]["quanta"] == s["quanta"]


def real_xbee_config(tmp_path: Path, device: str, duration_s: float, others: int = 0) -> Path:
    """Robot 0 with a real Series 1 XBee on ``device`` (probing it); ``others`` simulated random walkers."""
    cfg = tmp_path / "real_xbee.toml"
    text = f"""
[session]
name = "real-xbee"
duration_s = {duration_s}
speed = 1
[arena]
width_m = 4
length_m = 4
[[robots]]
count = 1
behaviour = "tests.support.xbee_probe:RealRadio"
xbee = {{ series = 1, api_mode = 1, baud = 115200, device = "{device}" }}
[robots.placement]
kind = "explicit"
poses = [[1.0, 1.0, 0.0]]
"""
    if others:
        text += f'[[robots]]\ncount = {others}\nbehaviour = "random_walk"\n[robots.placement]\nkind = "explicit"\n'
        text += f"poses = {[[3.0, 3.0 - 0.5 * i, 0.0] for i in range(others)]}\n"
    cfg.write_text(text)
    return cfg


@pytest.mark.session
def test_a_robot_with_a_real_xbee_on_a_serial_device(tmp_path: Path) -> None:
    """A simulated robot whose XBee is a real module on a serial port (here a pseudo-terminal whose far side runs the
    XBee firmware in wall time, with a neighbour heard over its air): its logic identifies the module, hears the
    neighbour with RSSI and transmits through it; the simulated radio channel does not include it."""
    from tests.support.standins import NEIGHBOUR64, SERIAL64, EmulatedXBee

    # (the neighbour talks every 0.25 s of wall time, the session lasts at least 6 s of it: 8 heard is a wide margin)
    with EmulatedXBee(series=1, api_mode=1, baud=115200, neighbour_every_s=0.25) as radio:
        cfg = real_xbee_config(tmp_path, radio.path, 6)
        plan = make_plan(load_config(cfg), str(cfg))
        assert plan.robots[0].modules() == ("llc",)  # no simulated module
        out = tmp_path / "run"
        r = subprocess.run(cli("run", str(cfg), "--out", str(out)), cwd=ROOT, capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0, r.stderr[-3000:]
        c = radio.module.counters  # the stand-in has no air to send on: its transmit buffer fills, then overflows
        tx = c["tx_requests"] + c["serial_rx_overflow"]
    logs: dict[str, list[dict]] = {}
    for topic, _t, payload in iter_messages(out / "session.mcap"):
        if topic.startswith("/r000/log/"):
            logs.setdefault(topic.rsplit("/", 1)[1], []).append(json.loads(payload))
    assert logs["identity"] == [{"serial64": SERIAL64, "series": 1}]
    heard = logs["heard"]
    assert len(heard) >= 8 and all(h["src64"] == NEIGHBOUR64 and h["rssi_dbm"] == -60 for h in heard)
    assert tx >= 10  # the logic's hellos went to the real module
    s = json.loads((out / "summary.json").read_text())
    assert "xbee_module" not in s["per_robot"][0] and s["wall_lag"] is not None


def test_devices_lists_ports_and_refuses_a_missing_device(tmp_path: Path) -> None:
    r = subprocess.run(cli("devices", str(MIXED), "--out", "runs/x"), cwd=ROOT, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0
    assert "robots[1].xbee.pty (r005): runs/x/r5-xbee" in r.stdout and "robots[1].can.slcan_pty (r005)" in r.stdout
    cfg = tmp_path / "gone.toml"
    cfg.write_text(f'[session]\nspeed = 1\n[[robots]]\nxbee = {{ device = "{tmp_path / "ttyUSB9"}" }}\n')
    r = subprocess.run(cli("devices", str(cfg)), cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "FAILED" in r.stdout and "no such device" in r.stdout
    r = subprocess.run(cli("run", str(cfg), "--out", str(tmp_path / "run")), cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert f"robots[0].xbee.device (r000): {tmp_path / 'ttyUSB9'}" in r.stderr and "no such device" in r.stderr
    assert not (tmp_path / "run").exists()  # nothing started


@pytest.mark.session
def test_a_real_xbee_that_disappears_fails_its_robot_only(tmp_path: Path) -> None:
    """Unplugged mid-session: the robot with the real XBee fails (its logic's port raises), the others go on."""
    import threading

    from tests.support.standins import EmulatedXBee

    radio = EmulatedXBee(series=1, api_mode=1, baud=115200, neighbour_every_s=0.5).__enter__()

    def pull_the_plug() -> None:  # once the logic used the module (its hellos), whatever the load
        while radio.module.counters["tx_requests"] < 3 and p.poll() is None:
            time.sleep(0.05)
        radio.__exit__(None, None, None)

    unplug = threading.Thread(target=pull_the_plug)
    cfg = real_xbee_config(tmp_path, radio.path, 3600, others=1)  # far longer than the test: stopped after the failure
    out = tmp_path / "run"
    p = subprocess.Popen(cli("run", str(cfg), "--out", str(out)), cwd=ROOT, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True)
    unplug.start()
    try:
        wait_line(p, "robot 0 failed at sim t=")
        wait_line(p, "rtf")  # the session went on
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    finally:
        if p.poll() is None:
            p.kill()
        unplug.join()
    s = json.loads((out / "summary.json").read_text())
    assert s["exit_code"] == 130 and s["interrupted"]
    (fail,) = s["failures"]
    assert fail["robot"] == 0 and fail["kind"] == "raised", fail
    assert "the device failed or disappeared" in fail["detail"]
    assert s["per_robot"][1]["alive"] and not s["per_robot"][0]["alive"] and s["sim_time_s"] > fail["t_s"]


def test_fault_fields_fit_their_kind(tmp_path: Path) -> None:
    p = tmp_path / "f.toml"
    p.write_text('[[robots]]\n[[faults]]\nrobot = 0\nat_s = 1\nkind = "can_bus_off"\nprobability = 0.5\n')
    with pytest.raises(ConfigError, match=r"faults\[0\]: probability do\(es\) not apply to kind = 'can_bus_off'"):
        load_config(p)
    p.write_text('[[robots]]\n[[faults]]\nrobot = 0\nat_s = 1\nkind = "can_bus_off"\nnode = "slcan"\n')
    with pytest.raises(ConfigError, match=r"faults\[0\].node: robot 0 has no slcan adapter"):
        load_config(p)
    assert load_config(BUS_OFF_CFG).faults[0].node == "host"
