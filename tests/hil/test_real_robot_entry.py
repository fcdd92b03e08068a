"""The companion-computer entry point runs the same behaviour against any python-can bus: here
python-can's ``virtual`` bus wired to the emulated LLC, with the wall clock (no session involved)."""

from __future__ import annotations

import threading
import uuid
from pathlib import Path

import pytest

from swarm_logic.__main__ import load_hal, main
from tests.logic.test_llc_client import VirtualWiredLlc

DRIVE_CMD = 0x100


def test_runs_behaviour_over_a_real_python_can_interface(tmp_path: Path) -> None:
    ch = f"robot-{uuid.uuid4().hex}"
    hal = tmp_path / "hal.toml"
    hal.write_text(f'robot_id = 2\n[llc_can]\ninterface = "virtual"\nchannel = "{ch}"\n[params]\nspeed_mps = 0.1\n')
    llc = VirtualWiredLlc(ch)
    seen: list[int] = []
    orig = llc.board.can.on_bus_frame

    def spy(frame):
        seen.append(frame.arbitration_id)
        orig(frame)

    llc.board.can.on_bus_frame = spy
    t = threading.Thread(target=main, args=(["--hal", str(hal), "--duration", "0.5"],))
    t.start()
    try:
        while t.is_alive():
            llc.loop_ms(20)
            t.join(timeout=0.02)
    finally:
        t.join(timeout=5)
        llc.loop_ms(20)
        llc.bus.shutdown()
    assert seen.count(DRIVE_CMD) >= 2  # it drove the LLC...
    assert llc.llc.v_cmd == 0.0  # ...and stopped the motors when it ended (Controller.destroy)


def test_hal_errors_name_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "hal.toml"
    bad.write_text("[llc_can]\nchannel = 'can0'\n")
    with pytest.raises(SystemExit, match=r"llc_can\.interface: missing"):
        load_hal(str(bad))


def test_shipped_real_robot_config_is_valid() -> None:
    hal = load_hal(str(Path(__file__).resolve().parents[2] / "hil_configs" / "robots" / "eswarbot_real.toml"))
    assert hal["llc_can"]["interface"] == "slcan"


def test_shipped_rdpso_robot_config_is_valid() -> None:
    from swarm_logic.families.rdpso.controller import Rdpso

    hal = load_hal(str(Path(__file__).resolve().parents[2] / "hil_configs" / "robots" / "eswarbot_rdpso_real.toml"))
    assert hal["clock"] == "realtime" and hal["xbee"]["port"] and len(hal["start_pose"]) == 3
    Rdpso.resolve(hal["params"])  # the parameters mean something


def test_an_unknown_clock_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "hal.toml"
    bad.write_text("clock = 'sundial'\n[llc_can]\ninterface = 'virtual'\n")
    with pytest.raises(SystemExit, match=r"clock: 'sundial' is not one of monotonic, realtime"):
        load_hal(str(bad))
