"""Hardware stand-ins for sessions with real devices: the real byte protocols on pseudo-terminals, driven in wall
time by a thread, with the project's own firmware emulations on the far side.

- ``EmulatedXBee``: an XBee module on a pty, with a neighbour heard over its air now and then.
- ``LlcStand``: an eSwarBot's LLC board on the bench, wheels off the ground, its CAN bus reached through a USB-CAN
  adapter that speaks slcan (LAWICEL), as a CANable does. The session opens it with python-can's ``slcan``.
- ``DeskRadios``: two XBees on a desk: the gateway's (the session opens it) and a desk radio (the test's program
  opens it), sharing the desk's air.

Each is a context manager that stops its thread and closes its descriptors.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import select
import termios
import threading
import time
import tty
from typing import Any

import numpy as np

from bridge.core.registry import robot_profile
from bridge.models.differential_drive import DriveParams
from bridge.models.sonar import SonarParams
from bridge.robots.eswarbot.board import llc_params
from firmware_sim.board import sensors
from firmware_sim.board.arduino import Board
from firmware_sim.board.can_controller import Frame
from firmware_sim.modules.slcan import SlcanAdapter
from firmware_sim.modules.xbee import BAUD_CODES, XBeeModule
from firmware_sim.robots.eswarbot.llc import PIN_BATTERY, PIN_DIR, PIN_LDR, PIN_PWM, PIN_SONAR, LowLevelController

SERIAL64 = 0x0013A20040B0C0D1
NEIGHBOUR64 = 0x0013A20040B0C0D2
SPEEDS = {getattr(termios, f"B{b}"): b for b in (*BAUD_CODES, 38400)}


def uart_resample(data: bytes, tx_baud: int, rx_baud: int) -> bytes:
    """What a UART at ``rx_baud`` reads from ``data`` sent back to back at ``tx_baud`` (8N1, LSB first): when
    the line is low it takes that as a start bit and samples the middle of each of its own bit times; bytes
    with a framing error are delivered as read. Time in units of 1 / (2 tx rx) s, so every edge is exact."""
    bits = [bit for b in data for bit in (0, *((b >> k) & 1 for k in range(8)), 1)]
    tx_bit, rx_bit = 2 * rx_baud, 2 * tx_baud  # one bit time of each side, in those units

    def level(u: int) -> int:
        i = u // tx_bit
        return bits[i] if i < len(bits) else 1

    out = bytearray()
    u = 0
    while True:
        if level(u):
            nxt = next((i for i in range(u // tx_bit + 1, len(bits)) if bits[i] == 0), None)
            if nxt is None:
                return bytes(out)
            u = nxt * tx_bit
        out.append(sum(level(u + (2 * k + 3) * rx_bit // 2) << k for k in range(8)))
        u += 19 * rx_bit // 2  # to the middle of the stop bit


class _Pty:
    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)

    def read(self) -> bytes:
        try:
            return os.read(self.master, 4096)
        except (BlockingIOError, OSError):
            return b""

    def write(self, data: bytes) -> None:
        with contextlib.suppress(BlockingIOError, OSError):  # nobody reads: lost, as on a serial line
            os.write(self.master, data)

    def close(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class _Stand:
    """A thread stepping ``_step(t_ns)`` every ``period_s`` of wall time until the context ends."""

    period_s = 0.002

    def __init__(self, name: str) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.error: BaseException | None = None

    def __enter__(self) -> Any:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=60)  # it stops at its next step; the bound only catches a hang
        assert not self._thread.is_alive()
        self.close()

    def _run(self) -> None:
        t0 = time.monotonic_ns()
        try:
            while not self._stop.is_set():
                self._wait(self.period_s)
                self._step(time.monotonic_ns() - t0)
        except BaseException as e:  # reported by the test, never lost in a thread
            self.error = e

    def _wait(self, s: float) -> None:
        time.sleep(s)

    def _step(self, t_ns: int) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


class LlcStand(_Stand):
    """An eSwarBot LLC board on the bench behind an slcan adapter on a pty: ``path`` is what the session opens.
    Its wheels turn freely (first-order motors at the profile's time constant), the sonar sees nothing, the
    battery is full. ``wheel_turns`` says how far the wheels turned, ``frames_in`` how many frames it received."""

    def __init__(self) -> None:
        super().__init__("llc-stand")
        self.pty = _Pty()
        self.path = self.pty.path
        prof = robot_profile("eswarbot")
        self.prof = prof
        self.adapter = SlcanAdapter(500_000, serial_number="BNCH")
        self.board = Board()
        self.llc = LowLevelController(self.board, llc_params(prof))
        self.omega = np.zeros(2)
        self.angle = np.zeros(2)
        self.next_loop_ns = 0
        self.last_ns = 0
        self.frames_in = 0
        self.booted = False

    @property
    def wheel_turns(self) -> float:
        return float(np.abs(self.angle).sum() / (2 * math.pi))

    def _step(self, t_ns: int) -> None:
        self.adapter.feed(self.pty.read())
        b = self.board
        for f in self.adapter.take_tx():  # frames the session put on the bus, through the adapter
            b.can.on_bus_frame(Frame(f.arbitration_id, f.data, t_ns // 1000, f.extended))
            self.frames_in += 1
        dt = (t_ns - self.last_ns) / 1e9
        self.last_ns = t_ns
        p = self.prof.part(DriveParams)
        for i in (0, 1):  # the motors spin the free wheels
            pwm = b.pwm.get(PIN_PWM[i], 0) * (1 if b.digital_read(PIN_DIR[i]) else -1)
            w_ss = np.sign(pwm) * max(0.0, (abs(pwm) - p.motor_deadband_pwm) / (255 - p.motor_deadband_pwm)) \
                * p.motor_max_wheel_rad_s
            decay = math.exp(-dt / p.motor_time_constant_s)
            self.omega[i] = w_ss + (self.omega[i] - w_ss) * decay
            self.angle[i] += self.omega[i] * dt
        if t_ns >= self.next_loop_ns:
            b.time_us = t_ns // 1000
            b.encoder_counts = [math.floor(a * p.encoder_cpr / (2 * math.pi)) for a in self.angle]
            b.analog_volts[PIN_SONAR] = sensors.sonar_volts(self.prof.part(SonarParams).max_range_m)
            b.analog_volts[PIN_LDR] = sensors.ldr_volts(50.0)
            b.analog_volts[PIN_BATTERY] = sensors.battery_volts_at_pin(8.2)
            if not self.booted:
                self.booted = True
                self.llc.setup()
            self.llc.loop()
            self.next_loop_ns = t_ns + self.llc.loop_period_us * 1000
            for f in b.can.take_tx():  # the board's frames, to the session through the adapter
                self.adapter.on_bus_frame(t_ns, f.arbitration_id, f.data, f.is_extended_id)
        if out := self.adapter.take_output():
            self.pty.write(out)

    def close(self) -> None:
        self.pty.close()


class EmulatedXBee(_Stand):
    """An XBee on a pseudo-terminal: ``path`` is the side a host opens; a thread pumps the other side through
    the firmware emulation in wall time. Both ends have a line speed (the module's BD, the host's as pyserial set it
    on the terminal); when they differ, bytes cross as a UART at one rate samples a line driven at the other.
    ``neighbour_every_s``: a neighbour's broadcast arrives over the air that often (Series 1), so the module talks
    on its own."""

    def __init__(self, *, series: int = 1, api_mode: int = 1, baud: int = 9600,
                 neighbour_every_s: float | None = None) -> None:
        super().__init__("xbee-pty")
        self.pty = _Pty()
        self.master, self.slave, self.path = self.pty.master, self.pty.slave, self.pty.path
        self.module = XBeeModule(series=series, serial64=SERIAL64, node_id="probe-me",
                                 rng=np.random.default_rng(7), api_mode=api_mode, baud=baud)
        self.neighbour_every_ns = None if neighbour_every_s is None else int(neighbour_every_s * 1e9)
        self.next_air, self.seq = 0, 0
        self.writes = 0  # times the module wrote to the line
        self.steps = 0
        self.quiet_step = 0  # the last step that read nothing, wrote nothing and had nothing left to send

    def host_baud(self) -> int | None:
        """The line speed the host set on its side of the terminal (the settings belong to the device)."""
        return SPEEDS.get(termios.tcgetattr(self.slave)[5])

    def _neighbour(self, t_ns: int, seq: int) -> dict:
        payload = b"hello from a neighbour"
        return {"ev": "rx", "t_ns": t_ns, "rssi_dbm": -60, "frame": {
            "handle": seq, "src64": NEIGHBOUR64, "src16": 0xFFFE, "dst": "bcast", "dst_addr": 0xFFFF,
            "pan_id": 0x3332, "channel": 0x0C, "seq": seq % 256, "psdu_len": 11 + len(payload) + 2,
            "mac_retries": 0, "payload": payload, "ack": False}}

    def _wait(self, s: float) -> None:
        select.select([self.master], [], [], s)

    def _step(self, t_ns: int) -> None:
        data = self.pty.read()
        host, own = self.host_baud(), self.module.baud
        if data and host != own:
            data = uart_resample(data, host or 38400, own)
        air = []
        if self.neighbour_every_ns is not None and t_ns >= self.next_air:
            air.append(self._neighbour(t_ns, self.seq))
            self.seq += 1
            self.next_air = t_ns + self.neighbour_every_ns
        tx = self.module.step(t_ns, data, air).uart_tx
        if tx and host != own:
            tx = uart_resample(tx, own, host or 38400)
        if tx:
            self.pty.write(tx)
            self.writes += 1
        self.steps += 1
        if not data and not tx and not self.module._uart:
            self.quiet_step = self.steps

    def wait_writes(self, n: int) -> None:
        """Until the module wrote to the line ``n`` times more than it had when called (the writes of a step that
        was under way at the call are not counted)."""
        first = self.writes + 1 + n
        while self.writes < first and self._thread.is_alive():
            time.sleep(0.001)

    def settle(self) -> None:
        """Until the module took what the host wrote before the call and answered it in full: a quiet step (nothing
        read, written or left to send) that began after the call."""
        after = self.steps + 1
        while self.quiet_step <= after and self._thread.is_alive():
            time.sleep(0.001)

    def close(self) -> None:
        self.pty.close()


GATEWAY64 = 0x0013A200_41B00001
DESK64 = 0x0013A200_41B00002


class DeskRadios(_Stand):
    """Two XBees on a desk, each on a pty: ``gateway_path`` (the session's gateway opens it) and ``desk_path``
    (the desk program opens it). What one puts on the air the other receives at ``rssi_dbm``; a unicast is
    acknowledged when it is for the other one."""

    period_s = 0.001

    def __init__(self, *, series: int = 2, baud: int = 115200, api_mode: int = 1, rssi_dbm: int = -42) -> None:
        super().__init__("desk-radios")
        self.rssi_dbm = rssi_dbm
        self.ptys = [_Pty(), _Pty()]
        self.gateway_path, self.desk_path = (p.path for p in self.ptys)
        self.modules = [XBeeModule(series=series, serial64=a, node_id=n, rng=np.random.default_rng(i),
                                   api_mode=api_mode, baud=baud)
                        for i, (a, n) in enumerate(((GATEWAY64, "gateway"), (DESK64, "desk")))]
        self.air: list[list[dict]] = [[], []]  # events for each module's next step
        self.frames = [0, 0]  # frames each put on the air

    def _wait(self, s: float) -> None:
        select.select([p.master for p in self.ptys], [], [], s)

    def _step(self, t_ns: int) -> None:
        for i, (m, p) in enumerate(zip(self.modules, self.ptys, strict=True)):
            events, self.air[i] = self.air[i], []
            res = m.step(t_ns, p.read(), events)
            if res.uart_tx:
                p.write(res.uart_tx)
            other = self.modules[1 - i]
            for f in res.air_tx:
                self.frames[i] += 1
                self.air[1 - i].append({"ev": "rx", "t_ns": t_ns, "rssi_dbm": self.rssi_dbm, "frame": f})
                acked = f["dst"] == "bcast" or (f["dst"] == "64" and f["dst_addr"] == other.serial64)
                self.air[i].append({"ev": "done", "t_ns": t_ns, "handle": f["handle"], "attempts": 1,
                                    "status": "ok" if acked or not f["ack"] else "no_ack"})

    def close(self) -> None:
        for p in self.ptys:
            p.close()


class RoverStand(_Stand):
    """A vehicle that speaks only MAVLink, on UDP: another robot's MAVLink face (system ``sysid``, booted in HOLD)
    on a kinematic differential-drive body, in wall time, as an ArduPilot Rover's SITL would answer. ``url`` is
    where a companion computer reaches it (``udpout:127.0.0.1:PORT``); ``body`` is its ``DiffDrive``."""

    period_s = 0.005

    def __init__(self, sysid: int = 1, pose: tuple[float, float, float] = (2.0, 2.0, 0.0)) -> None:
        from swarm_logic.families.demo.random_walk import RandomWalk
        from swarm_logic.mavlink.face import MavlinkFace, MavutilLink
        from swarm_logic.mavlink.supervisor import Supervisor
        from swarm_logic.robot import Robot
        from tests.logic.test_mavlink import DiffDrive, World

        super().__init__("rover-stand")
        self.world = World((6.0, 6.0))
        self.body = DiffDrive(self.world, *pose)
        self.link = MavutilLink("udpin:127.0.0.1:0")
        self.url = f"udpout:127.0.0.1:{self.link.conn.port.getsockname()[1]}"
        self.face = MavlinkFace(self.link, self.world, sysid, boot="hold")
        robot = Robot(sysid - 1, self.world, self.body, np.random.Generator(np.random.PCG64(sysid)), {},
                      mavlink=self.face)
        self.sup = Supervisor(RandomWalk(), robot)
        self.sup.start()
        self.next_tick = 0.0
        self.path: list[tuple[float, float]] = [(pose[0], pose[1])]

    @property
    def travelled_m(self) -> float:
        return sum(math.dist(p, q) for p, q in itertools.pairwise(self.path))

    def _step(self, t_ns: int) -> None:
        self.world.sleep_until(t_ns / 1e9)
        if self.world.t >= self.next_tick:
            self.next_tick = self.sup.tick()
        s = self.body.state
        self.path.append((s.x, s.y))

    def close(self) -> None:
        self.face.close()
