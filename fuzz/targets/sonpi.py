"""The SonPI: its sonar-and-motor board's sketch as a master's I2C transactions reach it, the Pi's board driver as the
board's bytes reach it, and the Wi-Fi packets (``pose_packet``) as a datagram from the network reaches a robot, the
region controller's plans followed through to the law a robot applies."""

from __future__ import annotations

import contextlib
import errno
import math
import os

import numpy as np

from firmware_sim.robots.sonpi.hcsr04 import RangerParams, Rangers
from firmware_sim.robots.sonpi.sonar_board import MotorParams, SonarBoard
from fuzz.harness import Cursor, FakeClock, Target, lp
from swarm_logic.drivers.i2c import Message, PlainI2cSMBus
from swarm_logic.families.roy.regions.agent import RegionAgent
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi import pose_packet as pp
from swarm_logic.robots.sonpi.board import SonpiBoard
from swarm_logic.robots.sonpi.interfaces import (
    LOCALISATION,
    POSE,
    SONAR,
    SONAR_ANGLES_RAD,
    VELOCITY,
    AgentPose,
    SonarReading,
)
from swarm_logic.robots.sonpi.wifi import PLAN, PlanOrder

MS = 1_000_000
MOTORS = MotorParams(wheel_radius_m=0.0325, encoder_cpr=2048, max_wheel_rad_s=0.30 / 0.0325, deadband_pwm=15,
                     motor_time_constant_s=0.06)


# -- the board's sketch ------------------------------------------------------------------------------------------------
def _board(data: bytes) -> None:
    """Transactions as the I2C medium delivers them to the sketch: per transaction a header (bits 0-5 the time
    before it in 4 ms, bit 6 new ranges in the sonars' beams), a message count, then per message a selector (bit 0
    read, bits 2-7 its length - 1) and a write's data. A refused read ends the transaction, as it does on the bus."""
    c = Cursor(data)
    rangers = Rangers(RangerParams(SONAR_ANGLES_RAD, 0.09, 0.01, 0.0, 0.1))
    board = SonarBoard(rangers, MOTORS, np.random.default_rng(1))
    t, txn = 0, 0
    ranges = [1.0, 2.0, math.inf, 0.5, 3.0]
    counts = [0, 0]
    while c.more():
        head = c.u8()
        t += (head & 0x3F) * 4 * MS
        if head & 0x40:
            ranges = [c.u8() / 50.0 if c.u8() & 1 else math.inf for _ in range(5)]
        segs = []
        for _ in range(1 + c.u8() % 4):
            sel = c.u8()
            segs.append([P.ADDRESS, True, 1 + (sel >> 2)] if sel & 1 else [P.ADDRESS, False, c.chunk()])
        txn += 1
        counts = [counts[0] + 7, counts[1] + 9]
        sens = {"ranges_m": ranges, "encoders": counts, "battery_v": 7.4}
        board.run(t, {"in": [["i2c", txn, segs]] if segs else [], "sens": sens})
    board.run(t + 300 * MS, {"in": [], "sens": {"ranges_m": ranges, "encoders": counts, "battery_v": 7.4}})
    _ = board.counters


def _board_seeds() -> list[bytes]:
    def write(reg: int, *values: int) -> bytes:
        return b"\x00" + lp(bytes((reg, *values)))

    def read(reg: int, n: int) -> bytes:
        return write(reg) + bytes((1 | (n - 1) << 2,))

    return [
        bytes((1, 0)) + write(P.SPEED_SP, *P.pack_pair(100, -100)) + bytes((5, 1)) + read(P.ODOMETRY, P.ODOMETRY_BYTES)
        + bytes((30, 1)) + read(P.WINDOW, P.WINDOW_BYTES) + bytes((1, 0)) + write(P.PWM_SP, *P.pack_pair(300, 0))
        + bytes((1, 0)) + write(P.FIRING, 2) + bytes((1, 0)) + write(P.FIRING, 7) + bytes((1, 1)) + read(0x07, 2)
        + bytes((1, 1)) + read(P.WHO_AM_I, 40) + bytes((1, 0)) + write(P.SPEED_SP, 1, 2)
        + bytes((1, 0)) + write(P.ERROR_COUNT, 0) + bytes((1, 0)) + write(P.WATCHDOG, 0) + bytes((1, 0))
        + write(P.WHO_AM_I, 1) + bytes((1, 0)) + write(0x40, *range(40)),
        bytes((0x41,)) + bytes((1, 100, 0, 0, 1, 25, 1, 250, 1, 10)) + bytes((1,)) + read(P.WINDOW, P.WINDOW_BYTES),
    ]


# -- the Pi's board driver ---------------------------------------------------------------------------------------------
class _Bus(PlainI2cSMBus):
    """An smbus2 bus whose board answers each transaction from the script: a status byte (bit 0 NACK, bit 1 a bus
    time-out), then the bytes every read gets."""

    def __init__(self, c: Cursor) -> None:
        super().__init__(None)
        self.c = c
        self.fd = -1

    def _transfer(self, msgs: list[Message]) -> list[bytes]:
        status = self.c.u8()
        if status & 1:
            raise OSError(errno.EREMOTEIO, os.strerror(errno.EREMOTEIO))
        if status & 2:
            raise OSError(errno.ETIMEDOUT, os.strerror(errno.ETIMEDOUT))
        return [self.c.take(int(n)).ljust(int(n), b"\xff") for _, read, n in msgs if read]

    def close(self) -> None:
        pass


def _board_driver(data: bytes) -> None:
    """The driver's polls (the odometry block, the window block when due, the set-points) against the script's
    answers; a velocity command now and then (the byte before each poll)."""
    c = Cursor(data)
    clock = FakeClock()
    drv = SonpiBoard(_Bus(c), clock, wheel_radius_m=0.0325, half_track_m=0.075, encoder_cpr=2048)
    while c.more():
        k = c.u8()
        if k & 1:
            drv.set_velocity((k >> 1 & 7) / 40.0, (k >> 4) / 80.0)
        clock.sleep(0.05 * (1 + (k >> 6)))
        drv.poll()
        drv.faces()
        drv.odometry()
    drv.close()


def _board_driver_seeds() -> list[bytes]:
    ident = b"\x00" + bytes((P.WHO_AM_I_VALUE, 1))
    odo = P.encode_odometry(P.OdometryBlock(100, 120, 30, 40, 50, 60, 1000, 7400))
    win = P.encode_window(3, [(500, 400, 2, 1), (P.NO_ECHO, P.NO_ECHO, 3, 0), (100, 90, 0, 0), (20, 20, 1, 1),
                              (4000, 3999, 2, 2)])
    return [b"\x00" + ident + b"\x00" + odo + win + b"\x00" + b"\x03" + b"\x00" + b"\x00" + odo
            + b"\xc0" + b"\x00" + odo + P.encode_window(9, [(1, 1, 1, 1)] * 5) + b"\x00" + b"\x00\x01\x02",
            b"\x00\x00\x00\x01", b"\x00\x00\x52\x01"]


# -- the Wi-Fi packets -------------------------------------------------------------------------------------------------
def _packets(data: bytes) -> None:
    """One datagram, decoded as every receiver decodes it (``decode``, and ``accept`` for each kind a robot or the
    localisation service waits for)."""
    with contextlib.suppress(pp.PacketError):  # not a packet: the receiver counts it and drops it
        pp.decode(data)
    for kind in (pp.Odometry, pp.Status, (pp.Odometry, pp.Status), pp.SonarWindow):
        pp.accept(data, kind, 3)


class _Device:
    """A SonPI device as a region agent reads it: its answers set by the harness."""

    def __init__(self, **answers: object) -> None:
        self.__dict__.update(answers)


class _Robot:
    """What a ``RegionAgent`` needs of its robot: id, clock, parameters, a log, its devices by name."""

    def __init__(self, rid: int, clock: FakeClock, params: dict[str, object], devices: dict[str, object]) -> None:
        self.id, self.clock, self.params, self._devices = rid, clock, params, devices
        self.devices: dict[str, object] = {}
        self.faces: dict[str, object] = {}

    def device(self, name: str) -> object:
        return self._devices[name]

    def log(self, topic: str, **values: object) -> None:
        pass


def _plan(data: bytes) -> None:
    """A datagram as a SonPI following a region controller takes it (``SonpiWifi``: decoded; a plan becomes the plan
    device's order) and applies it (``RegionAgent.step``, three steps): the robot is the plan's first agent, in the
    plan's unit, with the camera seeing the other agents at their goals (but every one the datagram's last byte
    masks), its sonars echoing at 0.4 m ahead."""
    try:
        head, packet = pp.decode(data)
    except pp.PacketError:  # counted and dropped by the robot's Wi-Fi device
        return
    if not isinstance(packet, pp.PlanPacket) or not packet.agents:
        return
    clock = FakeClock()
    unit = packet.unit_m
    me = packet.agents[0]
    poses = [AgentPose(a.id, a.goal_x * unit + 0.05 * k, a.goal_y * unit - 0.03 * k, 0.1 * k, 0.0, 0.0)
             for k, a in enumerate(packet.agents) if k == 0 or not (data[-1] >> (k % 8)) & 1]
    order = PlanOrder(packet, head.t_s)
    devices = {
        POSE: _Device(read=lambda: poses[0], fresh=True),
        LOCALISATION: _Device(poses=lambda: poses[1:]),
        SONAR: _Device(readings=lambda: [SonarReading(0.4 if k % 2 else math.inf, a) for k, a in
                                         enumerate(SONAR_ANGLES_RAD)]),
        VELOCITY: _Device(set_velocity=lambda vx, vy: None),
        PLAN: _Device(read=lambda: order, send_sonar=lambda t, ranges: None),
    }
    params: dict[str, object] = {"unit_m": unit, "face_tol_deg": 30.0}
    try:
        RegionAgent.with_defaults(params)
    except ValueError:
        params = {}
    agent = RegionAgent()
    agent.init(_Robot(me.id, clock, params, devices))  # type: ignore[arg-type]
    for _ in range(3):
        agent.step()
        clock.sleep(0.05)


def _packet_seeds() -> list[bytes]:
    poses = [pp.PoseEntry(1, True, 1.0, 2.0, 0.5, 0.1, 0.0), pp.PoseEntry(3, False)]
    return [
        pp.encode_poses(1, 1.5, poses),
        pp.encode_odometry(2, 2.0, pp.Odometry(3, 1.0, 1.0, 0.1, 0.2, 0.0, 100, 120)),
        pp.encode_mission(3, 3.0, pp.Mission(True, 2.0, -1.0)),
        pp.encode_status(4, 4.0, pp.Status(3, "running", True, 1.0, 1.0, 0.0)),
        pp.encode_sonar(5, 5.0, pp.SonarWindow(3, (0.5, math.inf, None, 1.25, 4.0))),
        *_plan_seeds(),
    ]


def _plan_seeds() -> list[bytes]:
    agents = tuple(pp.PlanAgent(i, i % 2, i == 0, float(i), 1.0 - i) for i in range(4))
    desired = [[0.0 if i == j else 1.0 + (i + j) % 2 for j in range(4)] for i in range(4)]
    laws = (("formation", {"desired": desired, "k_c": 3.0, "k_f": 5.0, "safety": {"r_robot": 0.9}}),
            ("formation", {"desired": desired, "k_c": 1.0, "k_f": 1.0, "safety": None}),
            ("scalable", {"k_c": 1.0, "k_f": 2.0, "r_s": 1.5}), ("packing", {}), ("split_merge", {"k_c": 3.0}),
            ("formation", {"desired": desired, "k_c": "x", "k_f": [1.0, 2.0]}))
    return [pp.encode_plan(9, 9.0, pp.PlanPacket(agents, law, params, 0.1, False, 0.5)) for law, params in laws]


TARGETS = [
    Target("sonpi_board", "SonPI sonar-and-motor board sketch (I2C slave 0x20): a master's transactions", _board,
           _board_seeds),
    Target("sonpi_board_driver", "the SonPI Pi's board driver: the board's I2C answers", _board_driver,
           _board_driver_seeds),
    Target("sonpi_packets", "SonPI Wi-Fi packets (pose_packet): a datagram from the network, every kind", _packets,
           _packet_seeds),
    Target("sonpi_plan", "a region controller's plan datagram as a SonPI applies it (decode, restrict, its law)",
           _plan, _plan_seeds),
]
