"""Acceptance: digi-xbee's own ``ZigBeeDevice`` on the pseudo-terminals of a session's emulated Series 2 modules,
as a user's host program or XCTU would open them: ``open()`` learns each module's role from its ZDO, explicit data
goes out and comes in with its endpoints, a remote AT command reads another module's NI over the air, and node
discovery finds every other module in range. The session is paced (speed 1), so digi-xbee's wall-clock waits match
simulated time; each wait below returns on its answer, the timeouts only bound a hang."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
import serial
from digi.xbee.devices import RemoteZigBeeDevice, ZigBeeDevice
from digi.xbee.models.mode import APIOutputModeBit
from digi.xbee.models.protocol import Role

from bridge.core.entities import xbee_serial64
from swarm_logic.clock import WallClock
from swarm_logic.drivers.xbee import XBee
from tests.conftest import ROOT
from tests.core.test_session import cli, wait_started
from tests.firmware.test_xbee_digi import discover

pytestmark = pytest.mark.session

CFG = """
[session]
name = "xbee-digi"
duration_s = 3600
seed = 5
speed = 1
[arena]
width_m = 10
length_m = 10
[[robots]]
count = 4
behaviour = "tests.support.xbee_probe:Idle"
xbee = { series = 2, api_mode = 1, baud = 115200, pty = "xbee{id}" }
[robots.placement]
kind = "explicit"
poses = [[2.0, 2.0, 0.0], [5.0, 2.0, 0.0], [2.0, 6.0, 0.0], [7.0, 7.0, 0.0]]
"""


def wait_joined(link: Path) -> None:
    """Until the module says it has joined (AI 0): a host opening it at power-up would wait the same way."""
    with serial.Serial(str(link), 115200, timeout=0) as port:
        x = XBee(port, WallClock(), api_mode=1)
        while x.at("AI", timeout=30)[0] != 0:
            WallClock().sleep(0.2)


def test_digi_xbee_s_zigbee_device_on_the_session_s_ptys(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cfg = tmp_path / "digi.toml"
    cfg.write_text(CFG)
    out = tmp_path / "run"
    p = subprocess.Popen(cli("run", str(cfg), "--out", str(out)), cwd=ROOT, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True)
    devs: list[ZigBeeDevice] = []
    try:
        wait_started(p)
        for i in range(4):
            wait_joined(out / f"xbee{i}")
        opened_s = []
        for i in range(4):
            d = ZigBeeDevice(str(out / f"xbee{i}"), 115200)
            d.set_sync_ops_timeout(30)
            t0 = time.monotonic()
            d.open()
            opened_s.append(time.monotonic() - t0)
            devs.append(d)
        with capsys.disabled():  # the figure, for the record (not a check: this machine's load varies)
            print(f"\nZigBeeDevice.open() on a session pty: {', '.join(f'{s:.2f}' for s in opened_s)} s")
        for i, d in enumerate(devs):
            assert d.get_role() == Role.ROUTER and d.get_node_id() == f"r{i:03d}"
            assert d.get_64bit_addr().address == bytearray(xbee_serial64(i).to_bytes(8, "big"))
        a, b = devs[0], devs[1]
        b.set_api_output_mode_value(APIOutputModeBit.EXPLICIT.code)
        b.flush_queues()
        rb = RemoteZigBeeDevice(a, x64bit_addr=b.get_64bit_addr())
        a.send_expl_data(rb, b"over the air", 0xE8, 0xE8, 0x0011, 0xC105)
        msg = b.read_expl_data(timeout=30)
        assert msg is not None and bytes(msg.data) == b"over the air" and msg.cluster_id == 0x11
        rc = RemoteZigBeeDevice(a, x64bit_addr=devs[2].get_64bit_addr())
        assert bytes(rc.get_parameter("NI")) == b"r002"
        a.set_parameter("NT", bytearray((0x20,)))
        assert sorted(discover(a, {"r001", "r002", "r003"})) == ["r001", "r002", "r003"]
    finally:
        for d in devs:
            if d.is_open():
                d.close()
        p.send_signal(signal.SIGINT)
        try:
            p.wait(timeout=240)
        except subprocess.TimeoutExpired:
            p.kill()
