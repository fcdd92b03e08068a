"""Series 2 modules as digi-xbee's own classes meet them: ``ZigBeeDevice.open()`` learns the role from the module's
own ZDO, explicit addressing both ways, remote AT commands over the air, node discovery of every module in range.

Several emulated modules share an ideal medium (``tests.support.xbee_loop.World``); each ``ZigBeeDevice`` talks to
its module through a communication interface on that world. Simulated time moves when a device's packet listener
polls (1 ms a poll), so digi-xbee's wall-clock waits are only bounds: every answer comes in simulated time first.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from digi.xbee.devices import RemoteZigBeeDevice, ZigBeeDevice
from digi.xbee.exception import XBeeException
from digi.xbee.models.address import XBee64BitAddress
from digi.xbee.models.mode import APIOutputModeBit
from digi.xbee.models.protocol import Role

from firmware_sim.modules.xbee import XBeeModule
from tests.firmware.test_xbee_module import LoopIface
from tests.support.xbee_loop import NS, World

BASE = 0x0013A20040A1B200
NAMES = ("alpha", "bravo", "charlie", "delta")


class WorldIface(LoopIface):
    """digi-xbee's view of one module of a ``World``: whole API frames in, frames out; a poll with nothing to read
    moves the shared world 1 ms (``LoopIface``'s open/close/timeout, another source of frames)."""

    lock = threading.Lock()

    def __init__(self, world: World, index: int) -> None:
        self.world, self.port = world, world.ports[index]
        self._open = False

    def _frame(self) -> bytes | None:
        rx = self.port.rx
        while rx and rx[0] != 0x7E:
            del rx[0]
        if len(rx) < 3 or len(rx) < int.from_bytes(rx[1:3], "big") + 4:
            return None
        n = int.from_bytes(rx[1:3], "big") + 4
        frame = bytes(rx[:n])
        del rx[:n]
        return frame

    def wait_for_frame(self, operating_mode):
        with self.lock:
            frame = self._frame()
            if frame is None:
                self.world.advance(self.world.t_ns + 1_000_000)
                frame = self._frame()
        if frame is None:
            time.sleep(0.0005)  # let the other threads in (this harness's own pacing, not a simulated component)
            return None
        return bytearray(frame)

    def quit_reading(self):
        pass

    def write_frame(self, frame):
        with self.lock:
            self.port.write(bytes(frame))


def modules(n: int, *, hear=None) -> tuple[World, list[ZigBeeDevice]]:
    mods = [XBeeModule(series=2, serial64=BASE + i, node_id=NAMES[i], rng=np.random.default_rng(10 + i),
                       baud=115200, my16=0x1000 + i, routing="mesh") for i in range(n)]
    world = World(mods, baud=115200, link=hear, limit_s=1e6)
    world.run_until(2 * NS)  # every module has joined (scan time: about 1.5 s)
    devs = []
    for i in range(n):
        d = ZigBeeDevice(comm_iface=WorldIface(world, i))
        d.set_sync_ops_timeout(30)  # a bound on a hang only: each operation returns on its answer
        devs.append(d)
    return world, devs


def discover(dev: ZigBeeDevice, want: set[str], passes: int = 5) -> dict:
    """digi-xbee's network discovery, again until it has found ``want`` (``passes`` at most): digi-xbee waits out
    NT on the wall clock, and a module's answer comes within NT of simulated time, so on a loaded machine (the
    simulation slower than the wall clock) one pass may end before the last answers; those found are kept."""
    net = dev.get_network()
    for _ in range(passes):
        net.start_discovery_process()
        while net.is_discovery_running():
            time.sleep(0.05)  # digi-xbee's own thread runs the pass
        found = {d.get_node_id(): d for d in net.get_devices()}
        if want <= set(found):
            break
    return found


def close(devs: list[ZigBeeDevice]) -> None:
    for d in devs:
        if d.is_open():
            d.close()


def test_open_learns_the_router_role_from_the_module_s_own_zdo_in_a_fraction_of_a_second() -> None:
    world, (dev,) = modules(1)
    t0 = world.t_ns
    dev.open()
    try:
        opened_in_s = (world.t_ns - t0) / NS
        assert dev.get_role() == Role.ROUTER
        assert dev.get_node_id() == "alpha" and dev.get_64bit_addr() == XBee64BitAddress.from_hex_string(
            f"{BASE:016X}")
        assert opened_in_s < 1.0, opened_in_s  # simulated: the frames at 115200 baud and the module's answers
        # the ZDO read restored AO to what it was (0): received data is 0x90 again
        assert dev.get_api_output_mode_value()[0] == 0
    finally:
        close([dev])


def test_explicit_data_goes_out_with_its_endpoints_cluster_and_profile_and_comes_in_as_0x91() -> None:
    _, devs = modules(2)
    a, b = devs
    for d in devs:
        d.open()
    try:
        b.set_api_output_mode_value(APIOutputModeBit.EXPLICIT.code)
        b.flush_queues()  # digi-xbee queued the answer of open()'s node descriptor read too (a 0x91)
        rb = RemoteZigBeeDevice(a, x64bit_addr=b.get_64bit_addr())
        a.send_expl_data(rb, b"hello", 0xE8, 0xE9, 0x0042, 0xC105)
        msg = b.read_expl_data(timeout=30)
        assert msg is not None and bytes(msg.data) == b"hello"
        assert (msg.source_endpoint, msg.dest_endpoint, msg.cluster_id, msg.profile_id) == (0xE8, 0xE9, 0x42, 0xC105)
        assert msg.remote_device.get_64bit_addr() == a.get_64bit_addr()
        # with AO back to 0, the same data arrives as a plain receive packet
        b.set_api_output_mode_value(0)
        a.send_expl_data(rb, b"plain", 0xE8, 0xE8, 0x0011, 0xC105)
        msg = b.read_data(timeout=30)
        assert msg is not None and bytes(msg.data) == b"plain"
    finally:
        close(devs)


def test_remote_at_reads_and_sets_a_parameter_over_the_air_and_an_absent_node_fails() -> None:
    _, devs = modules(2)
    a, b = devs
    for d in devs:
        d.open()
    try:
        rb = RemoteZigBeeDevice(a, x64bit_addr=b.get_64bit_addr())
        assert bytes(rb.get_parameter("NI")) == b"bravo"
        rb.set_parameter("NI", bytearray(b"renamed"), apply=True)
        assert b.get_parameter("NI") == bytearray(b"renamed")  # the module itself says so
        assert rb.get_parameter("HV")[0] == 0x19
        with pytest.raises(XBeeException):  # an unknown command: the remote answers "invalid command"
            rb.get_parameter("TP")
        ghost = RemoteZigBeeDevice(a, x64bit_addr=XBee64BitAddress.from_hex_string("0013A200DEADBEEF"))
        with pytest.raises(XBeeException):  # nobody acknowledges: status 4, "transmission failed"
            ghost.get_parameter("NI")
    finally:
        close(devs)


def test_discovery_finds_every_module_in_range_and_only_those() -> None:
    # delta hears nobody and nobody hears it
    _, devs = modules(4, hear=lambda i, j: None if 3 in (i, j) else -55)
    for d in devs:
        d.open()
    try:
        a = devs[0]
        a.set_parameter("NT", bytearray((0x20,)))  # the shortest window: 3.2 s
        found = discover(a, {"bravo", "charlie"})
        assert set(found) == {"bravo", "charlie"}
        assert found["bravo"].get_64bit_addr() == devs[1].get_64bit_addr()
        assert found["charlie"].get_role() == Role.ROUTER
    finally:
        close(devs)
