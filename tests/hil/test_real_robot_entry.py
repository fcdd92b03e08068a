"""The companion-computer entry point runs the same behaviour against any python-can bus: here
python-can's ``virtual`` bus wired to the emulated LLC, with the wall clock (no session involved)."""

from __future__ import annotations

import select
import signal
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import pytest

from swarm_logic.__main__ import load_hal, main
from tests.logic.test_llc_client import VirtualWiredLlc

ROOT = Path(__file__).resolve().parents[2]
DRIVE_CMD = 0x100


class LockStepClock:
    """The robot program's clock, moved by the test: a sleep of the program ends once the test has run the LLC board
    up to its end, and the board runs only while the program sleeps. The program and the board take turns, so what
    they exchange does not depend on how fast either thread gets the CPU."""

    def __init__(self) -> None:
        self.t_ms = 0
        self.until_ms: int | None = None  # the program sleeps until then (None: it runs)
        self.cond = threading.Condition()

    def now(self) -> float:
        with self.cond:
            return self.t_ms / 1000

    def sleep(self, dt: float) -> None:
        self.sleep_until(self.now() + dt)

    def sleep_until(self, t: float) -> None:
        with self.cond:
            self.until_ms = max(self.t_ms, round(t * 1000))
            self.cond.notify_all()
            self.cond.wait_for(lambda: self.until_ms is None)

    def run_board(self, llc: VirtualWiredLlc, program: threading.Thread) -> None:
        """Until the program ends: each time it sleeps, run the board 20 ms at a time to the end of its sleep."""
        while program.is_alive():
            with self.cond:
                if self.until_ms is None:
                    self.cond.wait(0.01)  # the program runs (or ends: checked again)
                    continue
                until = self.until_ms
            while self.t_ms < until:
                llc.loop_ms(20)
                self.t_ms += 20
            with self.cond:
                self.until_ms = None
                self.cond.notify_all()


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
    clock = LockStepClock()
    t = threading.Thread(target=main, args=(["--hal", str(hal), "--duration", "0.5"],), kwargs={"clock": clock})
    t.start()
    try:
        clock.run_board(llc, t)
    finally:
        t.join(timeout=60)
        llc.loop_ms(20)
        llc.bus.shutdown()
    assert not t.is_alive()
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


def test_shipped_zebro_robot_config_is_valid_and_a_missing_bus_is_named() -> None:
    """A real DeciZebro's HAL: its legs on I2C bus 1 and its modules on serial ports; where they are missing (as on
    this machine) the program says which and exits, no traceback."""
    from swarm_logic.families.zebro.mature import ZebroMature
    from swarm_logic.robots.decizebro.interfaces import DEVICE_NAMES

    p = Path(__file__).resolve().parents[2] / "hil_configs" / "robots" / "decizebro_real.toml"
    hal = load_hal(str(p))
    assert set(DEVICE_NAMES) <= set(hal) and hal["legs"]["bus"] == 1 and "llc_can" not in hal
    assert list(hal).index("imu") < list(hal).index("uwb_radio")  # the radio's driver sends the IMU's heading
    ZebroMature.with_defaults(hal["params"])
    if Path("/dev/i2c-1").exists():
        pytest.skip("this machine has an I2C bus 1")
    with pytest.raises(SystemExit, match=r"decizebro_real\.toml: cannot open the robot's devices: .*i2c-1"):
        main(["--hal", str(p), "--duration", "1"])


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_the_program_stops_cleanly_on_sigint_and_sigterm_even_with_sigint_ignored(tmp_path: Path, sig: int) -> None:
    """A program started in the background (or by a test runner) may inherit SIGINT ignored, and a service manager
    stops it with SIGTERM: either must end the loop and close the robot (its motors stopped), exit 0, no traceback."""
    log = tmp_path / "log.jsonl"
    hal = tmp_path / "hal.toml"
    hal.write_text(f'robot_id = 1\nbehaviour = "random_walk"\n[llc_can]\ninterface = "virtual"\n'
                   f'channel = "{uuid.uuid4().hex}"\n[log]\npath = "{log}"\n')
    p = subprocess.Popen([sys.executable, "-X", "faulthandler", "-m", "swarm_logic", "--hal", str(hal)], cwd=ROOT,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        while not log.exists():  # the robot's devices are open (its log with them)
            assert p.poll() is None, p.stderr.read() if p.stderr else ""
            select.select([], [], [], 0.05)
        p.send_signal(sig)
        try:
            p.wait(timeout=120)  # a guard against a hang, not a wait: it exits at once
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGABRT)  # its stacks (faulthandler) in the failure
            p.wait()
        err = p.stderr.read() if p.stderr else ""
        assert p.returncode == 0, err
        assert "Traceback" not in err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
