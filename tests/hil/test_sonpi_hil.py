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
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bridge.core.config import load_config
from bridge.core.plan import make_plan
from bridge.robots.sonpi import firmware
from swarm_logic.__main__ import load_hal, main
from swarm_logic.clock import WallClock
from swarm_logic.drivers.i2c import open_smbus
from swarm_logic.families.demo.sonar_wander import SonarWander
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi.board import SonpiBoard
from swarm_logic.robots.sonpi.interfaces import ODOMETRY, SONAR, VELOCITY
from tests.conftest import ROOT
from tests.core.test_session import check_stopped_cleanly, start, wait_started
from tests.support.sonpi_bench import robot_with

GUARD_S = 120.0  # a failure guard on loops that wait for an event: never what passes them
START = (0.5, 1.0, 0.0)

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
            assert bus.read_byte_data(P.ADDRESS, 0x07) == 0xFF  # a missing register: the pull-ups, counted
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
        hal = (ROOT / "hil_configs" / "robots" / "sonpi_sitl_ports.toml").read_text()
        hal = hal.replace("runs/sonpi_outside/r2-", f"{out}/r0-").replace("robot_id = 2", "robot_id = 0")
        (tmp_path / "hal.toml").write_text(hal)
        r = subprocess.run(
            [sys.executable, "-m", "swarm_logic", "--hal", str(tmp_path / "hal.toml"), "--duration", "3"],
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
    assert r0["i2c"]["nacks"] == adapter["nacks"] == 1 and r0["i2c"]["transactions"] == adapter["transactions"]
    assert arduino["bad_reads"] == 1 and arduino["refused_writes"] == 0 and arduino["malformed"] == 0
    assert r0["distance_m"] > 0.5 and r0["final_pose"][0] > START[0] + 0.5  # it drove east


def test_the_real_sonpi_hal_config_is_valid_and_a_missing_bus_is_named() -> None:
    p = ROOT / "hil_configs" / "robots" / "sonpi_real.toml"
    hal = load_hal(str(p))
    assert hal["sonpi_board"]["bus"] == 1 and "llc_can" not in hal
    SonarWander.with_defaults(hal["params"])
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
    assert hal["start_pose"] == list(ext[0].placement.poses[0]) and hal["behaviour"] == ext[0].behaviour
    plan = make_plan(cfg, str(outside))
    session_table = firmware.hal(plan.robots[0], cfg)["sonpi_board"]
    assert session_table["bus"] == "sitl://i2c" and firmware.hal(plan.robots[rid], cfg) == {}
    for key in ("wheel_radius_m", "half_track_m", "encoder_cpr", "max_speed_mps"):
        assert hal["sonpi_board"][key] == session_table[key], key
    real = load_hal(str(ROOT / "hil_configs" / "robots" / "sonpi_real.toml"))["sonpi_board"]
    assert {k: real[k] for k in ("wheel_radius_m", "half_track_m", "encoder_cpr")} == {
        k: session_table[k] for k in ("wheel_radius_m", "half_track_m", "encoder_cpr")
    }
