"""A DeciZebro driven from outside its session: its I2C bus as a Devantech USB-ISS and its radio, IMU and utility board
on pseudo-terminals (``i2c_pty``, ``uwb_radio_pty``, ``imu_pty``, ``utility_pty``). The test process walks it through
its leg modules over the adapter, reads their registers back, meets a NACK, talks to a session Zebro over the radio,
reads its IMU and utility board; then ``python -m swarm_logic`` runs the robot's program on those ports. And the
config: ``logic = "external"`` on a Zebro needs all four ports, and names the first one missing."""

from __future__ import annotations

import errno
import json
import math
import signal
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import serial

from bridge.core.config import ConfigError, load_config
from bridge.core.recorder import iter_messages
from firmware_sim.robots.decizebro import zebrobus as zb
from swarm_logic.clock import WallClock
from swarm_logic.drivers.i2c import open_smbus
from swarm_logic.robots.decizebro.imu import Bno055Imu
from swarm_logic.robots.decizebro.locomotion import ZebroLegs
from swarm_logic.robots.decizebro.utility import UtilityBoardDriver
from swarm_logic.robots.decizebro.uwb_radio import ZebroUwbRadio
from tests.conftest import ROOT
from tests.core.test_session import check_stopped_cleanly, start, wait_started

pytestmark = pytest.mark.session

PORTS = ('i2c_pty = "r{id}-i2c"\nuwb_radio_pty = "r{id}-uwb"\nimu_pty = "r{id}-imu"\n'
         'utility_pty = "r{id}-utility"\n')
GUARD_S = 120.0  # a failure guard on loops that wait for an event: never what passes them

CONFIG = f"""
[session]
name = "zebro-outside"
duration_s = 3600
seed = 2
speed = 1
[arena]
width_m = 8
length_m = 8
[[robots]]
profile = "decizebro"
logic = "external"
{PORTS}placement = {{ kind = "explicit", poses = [[1.5, 2.0, 0.0]] }}
[[robots]]
profile = "decizebro"
behaviour = "tests.support.zebro_radio_probe:Chatter"
placement = {{ kind = "explicit", poses = [[1.5, 4.0, 0.0]] }}
"""

EXTERNAL = '[session]\nspeed = 1\n[[robots]]\nprofile = "decizebro"\nlogic = "external"\n'


def test_an_external_zebro_logic_needs_its_four_ports(tmp_path: Path) -> None:
    p = tmp_path / "external.toml"
    p.write_text(EXTERNAL + PORTS)
    assert load_config(p).robots[0].logic == "external"
    lines = PORTS.splitlines()
    for i, line in enumerate(lines):
        name = line.split(" = ")[0]
        p.write_text(EXTERNAL + "\n".join(lines[:i] + lines[i + 1:]) + "\n")
        with pytest.raises(ConfigError, match=rf"robots\[0\]: {name}: an external logic .* expose it, e\.g\. {name} ="):
            load_config(p)
    demo = load_config(ROOT / "hil_configs" / "hil" / "zebro_outside.toml")  # the README's example session
    assert [g.logic for g in demo.robots] == ["session", "external"]


def leg_angle_cdeg(bus: Any, leg: int) -> int:
    """Leg ``leg``'s angle register (centidegrees, big-endian)."""
    return int.from_bytes(bytes(bus.read_i2c_block_data(zb.LEG_ADDRESS_BASE + leg, zb.LEG_ANGLE, 2)), "big")


def test_a_zebro_is_driven_from_outside_through_its_bus_and_radio(tmp_path: Path) -> None:
    cfg = tmp_path / "outside.toml"
    cfg.write_text(CONFIG)
    out = tmp_path / "run"
    p = start(cfg, out)
    clock = WallClock()
    try:
        wait_started(p)
        bus: Any = open_smbus(f"usb-iss://{out / 'r0-i2c'}", scl_hz=100_000, timeout_s=20)  # 20 s: a guard
        try:
            # registers read back: leg 2's ZebroBus header, a write to the test field; nobody at 0x30: a NACK
            assert bus.read_i2c_block_data(0x12, zb.ZEBROBUS_VERSION, 7) == [1, 1, 1, 1, 3, 1, 0x12]  # serial 3
            bus.write_i2c_block_data(0x10, zb.TEST_FIELD, [0xC3])
            assert bus.read_byte_data(0x10, zb.TEST_FIELD) == 0xC3
            with pytest.raises(OSError) as e:
                bus.write_byte_data(0x30, 0x00, 1)
            assert e.value.errno == errno.EREMOTEIO
            bus.port.write(b"\x99")  # a byte that starts no command: counted and dropped
            # walk it with the robot's own locomotion layer (sync once a second, motion blocks) until leg 0 has
            # turned twice (about 0.6 m of walking)
            legs = ZebroLegs(bus, clock)
            legs.walk(0.0)
            turned, last, t0 = 0.0, leg_angle_cdeg(bus, 0), clock.now()
            while turned < 72000 and clock.now() - t0 < GUARD_S:
                legs.poll()
                clock.sleep(0.05)
                now = leg_angle_cdeg(bus, 0)
                turned += (now - last) % 36000  # forward only: the legs never turn back
                last = now
            assert turned >= 72000, turned
            # leg 3 turns forward too (0.1 rpm: 60 rpm, as its PI tracks its phase); read until it is seen at speed
            # (a poll late by over 2 s on a starved machine would let the legs' emergency stop halt it for a while)
            speed, t0 = 0, clock.now()
            while not 300 < speed < 1700 and clock.now() - t0 < GUARD_S:
                legs.poll()
                speed = int.from_bytes(bytes(bus.read_i2c_block_data(0x13, zb.LEG_SPEED, 2)), "big", signed=True)
                clock.sleep(0.05)
            assert 300 < speed < 1700, speed
            legs.halt()
            assert legs.counters["bus_errors"] == 0 and legs.counters["motion_writes"] >= 6
        finally:
            bus.close()

        # the radio: a frame sent through its UART reaches robot 1's program; robot 1's beacon comes back
        with serial.Serial(str(out / "r0-uwb"), 115200, timeout=0) as port:
            radio = ZebroUwbRadio(port, clock, timeout=30)
            assert radio.info["id"] == 0
            t0, got, nbs = clock.now(), [], []
            while clock.now() - t0 < GUARD_S and not (got and nbs):
                radio.broadcast(struct.pack("<HI", 0, 7))
                got += radio.receive()
                nbs = radio.neighbours()
                clock.sleep(0.2)
            assert {m.src for m in got} == {1} and nbs[0].id == 1 and 1.0 < nbs[0].range_m < 4.0
        with serial.Serial(str(out / "r0-imu"), 115200, timeout=0) as port:
            imu = Bno055Imu(port, clock, timeout=20)
            assert math.isfinite(imu.heading()) and imu.counters["reads"] == 1
        with serial.Serial(str(out / "r0-utility"), 115200, timeout=0) as port:
            board = UtilityBoardDriver(port, clock)
            t0 = clock.now()
            while board.reports == 0 and clock.now() - t0 < GUARD_S:
                clock.sleep(0.05)
                board.poll()
            assert board.reports >= 1 and board.read() == 0 and board.bad_frames == 0  # no food in this arena

        # the robot's program, as it runs on the Pi, on the same ports (a HAL config like decizebro_sitl_ports.toml)
        hal = (ROOT / "hil_configs" / "robots" / "decizebro_sitl_ports.toml").read_text()
        hal = hal.replace("runs/zebro_outside/r2-", f"{out}/r0-").replace("robot_id = 2", "robot_id = 0")
        (tmp_path / "hal.toml").write_text(hal)
        r = subprocess.run([sys.executable, "-m", "swarm_logic", "--hal", str(tmp_path / "hal.toml"), "--behaviour",
                            "tests.support.zebro_walkers:Walker", "--duration", "3"], cwd=ROOT, capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        logged = [json.loads(line) for line in (out / "r0-logic.jsonl").read_text().splitlines()]
        walked = [rec for rec in logged if rec["topic"] == "legs"]
        assert walked and walked[-1]["motion_writes"] >= 6 and walked[-1]["bus_errors"] == 0
    finally:
        p.send_signal(signal.SIGINT)
        p.wait(timeout=240)
    s = check_stopped_cleanly(p, out)
    assert not (out / "r0-i2c").exists()  # the links go with the session
    r0 = s["per_robot"][0]
    adapter = r0["firmware"]["i2c_adapter"]
    assert r0["i2c"]["nacks"] == adapter["nacks"] == 1 and r0["i2c"]["transactions"] == adapter["transactions"]
    assert adapter["unknown_command"] == 1 and adapter["pty_dropped_bytes"] == 0
    assert r0["distance_m"] > 0.4 and r0["final_pose"][0] > 1.5 + 0.4  # it walked east
    heard = {src for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/r001/log/chatter"
             for src, _k in json.loads(d).get("got", [])}
    assert heard == {0}  # robot 1's program got what the outside program broadcast
