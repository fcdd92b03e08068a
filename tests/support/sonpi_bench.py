"""A one-robot bench for the SonPI's Arduino sketch, without processes or physics: the sketch stepped every 10 ms with
the ranges its sonars' beams meet, on a first-order motor per wheel (as the world's differential drive has it) that
moves a unicycle body; ``WiredBus`` is an ``smbus2.SMBus`` whose transactions reach the sketch at once (no bus
timing), and ``BenchClock`` the robot's clock on the bench's time (sleeping steps it)."""

from __future__ import annotations

import errno
import math
import os
from typing import Any

import numpy as np

from firmware_sim.robots.sonpi.hcsr04 import RangerParams, Rangers
from firmware_sim.robots.sonpi.sonar_board import MotorParams, SonarBoard
from swarm_logic.drivers.i2c import Message, PlainI2cSMBus
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi.interfaces import SONAR_ANGLES_RAD

MS = 1_000_000
Q = 10 * MS
HALF_TRACK_M = 0.075
MOTORS = MotorParams(
    wheel_radius_m=0.0325, encoder_cpr=2048, max_wheel_rad_s=0.30 / 0.0325, deadband_pwm=15, motor_time_constant_s=0.06
)


class Board:
    """The sketch and its robot (see the module docstring); ``pose`` is the body's true pose."""

    def __init__(
        self,
        ranges: list[float],
        *,
        firing: int = P.FIRING_SEQUENTIAL,
        seed: int = 1,
        noise_m: float = 0.0,
        crosstalk: float = 0.0,
        watchdog_ms: int = 500,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        rangers = Rangers(RangerParams(SONAR_ANGLES_RAD, 0.09, noise_m, 0.0, crosstalk))
        self.b = SonarBoard(rangers, MOTORS, np.random.default_rng(seed), firing=firing, watchdog_ms=watchdog_ms)
        self.ranges = list(ranges)
        self.t = 0
        self.txn = 0
        self.out: list[list] = []
        self.pwm = [0, 0]
        self.omega = [0.0, 0.0]
        self.angle = [0.0, 0.0]
        self.pose = list(pose)
        self.trig: list[list[int]] | None = None  # the last firing times the sketch told (pins "trig")
        self.tick([])

    def tick(self, items: list) -> dict:
        counts = [math.floor(a * MOTORS.encoder_cpr / (2 * math.pi)) for a in self.angle]
        sens = {"ranges_m": self.ranges, "encoders": counts, "battery_v": 7.4}
        res = self.b.run(self.t, {"in": items, "sens": sens})
        self.out += res["out"]
        if "pins" in res:
            self.pwm = res["pins"]["pwm"]
            self.trig = res["pins"].get("trig", self.trig)
        return res

    def advance(self, dt_ns: int) -> None:
        """Let time pass in 10 ms quanta: the motors respond, the body moves, the sketch runs."""
        end = self.t + dt_ns
        while self.t < end:
            before = list(self.angle)
            for i in range(2):
                frac = max(0.0, (abs(self.pwm[i]) - MOTORS.deadband_pwm) / (255 - MOTORS.deadband_pwm))
                w_ss = math.copysign(frac * MOTORS.max_wheel_rad_s, self.pwm[i])
                decay = math.exp(-0.01 / 0.06)
                self.angle[i] += w_ss * 0.01 + (self.omega[i] - w_ss) * 0.06 * (1 - decay)
                self.omega[i] = w_ss + (self.omega[i] - w_ss) * decay
            dl, dr = ((a - b) * MOTORS.wheel_radius_m for a, b in zip(self.angle, before, strict=True))
            ds, dth = 0.5 * (dl + dr), (dr - dl) / (2 * HALF_TRACK_M)
            mid = self.pose[2] + 0.5 * dth
            self.pose = [self.pose[0] + ds * math.cos(mid), self.pose[1] + ds * math.sin(mid), self.pose[2] + dth]
            self.t += Q
            self.tick([])

    def transfer(self, msgs: list[list]) -> list[bytes | None]:
        """One transaction's messages to the sketch, as the bus delivers them; the read messages' bytes (None: the
        sketch refused that read, and the transaction ended there)."""
        self.txn += 1
        self.out.clear()
        self.tick([["i2c", self.txn, msgs]])
        replies = [o for o in self.out if o[0] == "i2c"]
        return replies[0][2] if replies else []

    def write(self, reg: int, *data: int) -> None:
        self.transfer([[P.ADDRESS, False, bytes([reg, *data])]])

    def read(self, reg: int, n: int = 1) -> bytes | None:
        return self.transfer([[P.ADDRESS, False, bytes([reg])], [P.ADDRESS, True, n]])[0]

    def window(self) -> P.Window:
        return P.decode_window(self.read(P.WINDOW, P.WINDOW_BYTES))


class WiredBus(PlainI2cSMBus):
    """An ``smbus2.SMBus`` wired straight to the bench's sketch: another address, ``unplugged``, or a read the sketch
    refuses, is not ACKed."""

    def __init__(self, board: Board) -> None:
        super().__init__()
        self.board = board
        self.unplugged = False

    def _transfer(self, msgs: list[Message]) -> list[bytes]:
        if self.unplugged or any(addr != P.ADDRESS for addr, _, _ in msgs):
            raise OSError(errno.EREMOTEIO, os.strerror(errno.EREMOTEIO))
        got = self.board.transfer([[a, rd, d] for a, rd, d in msgs])
        if any(b is None for b in got):
            raise OSError(errno.EREMOTEIO, os.strerror(errno.EREMOTEIO))
        return got  # type: ignore[return-value]


class BenchClock:
    """The robot's clock on the bench's time: sleeping lets the bench run."""

    def __init__(self, board: Board) -> None:
        self.board = board

    def now(self) -> float:
        return self.board.t / 1e9

    def sleep(self, dt: float) -> None:
        self.board.advance(max(Q, round(dt * 1e9 / Q) * Q))

    def sleep_until(self, t: float) -> None:
        self.sleep(t - self.now())


def robot_with(**devices: Any) -> Any:
    """A stand-in for the robot the driver is opened for: its start pose and the devices it has."""

    class _Robot:
        start_pose = devices.pop("start_pose", None)

        def device(self, name: str) -> Any:
            if name not in devices:
                raise KeyError(name)
            return devices[name]

    return _Robot()
