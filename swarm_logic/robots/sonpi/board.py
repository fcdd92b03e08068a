"""The Pi's driver of the SonPI's Arduino board (``board_protocol``): one I2C device serving three of the robot's
faces (``interfaces``):

- ``sonpi_sonar``: the five sonars from the board's last complete 250 ms window: a sensor that had echoes gives the
  nearest one, one whose pings all went unanswered gives ``inf``, one that had no ping in the window (sequential
  firing pings each sensor every 300 ms) keeps its last result;
- ``sonpi_velocity``: a world-frame velocity, followed through the tracking layer (``tracking``), which the driver
  re-runs at every poll with the latest heading and sends to the board as wheel speed set-points (again at least
  every ``keepalive_s``, as the board's watchdog stops the motors after 0.5 s without one);
- ``sonpi_odometry``: the pose dead-reckoned from the encoders (from the robot's start pose when its HAL gives one).

The heading for the tracking layer is the robot's ``sonpi_pose`` (the overhead camera's) when it has that device,
looked up at first use, else the odometry's. While the camera has lost the robot, that device carries its last pose
on by odometry (``fresh`` False), which steers as well; while it has never had one (``NoPose``, a robot the camera
has not seen), the odometry's heading steers (``counters["heading_from_odometry"]``).

Each poll is one I2C transaction (the odometry block, and the window block when a new window is due: 54 bytes read
after repeated STARTs) and, when the set-points change or the keep-alive is due, one write. A bus error is counted
(``counters``) and the call retried at the next poll; it never reaches the algorithm. The bus is anything with
smbus2's calls: ``smbus2.SMBus(1)`` on the robot (HAL ``sonpi_board = {bus = 1}``), the simulated bus in a session
(``{bus = "sitl://i2c"}``), a USB-ISS adapter (``{bus = "usb-iss:///dev/ttyACM0"}``).
"""

from __future__ import annotations

import contextlib
import math
from typing import Any

from smbus2 import i2c_msg

from swarm_logic.clock import Clock
from swarm_logic.drivers.i2c import open_smbus
from swarm_logic.robots.sonpi import board_protocol as P
from swarm_logic.robots.sonpi.interfaces import (
    ODOMETRY,
    POSE,
    SONAR,
    SONAR_ANGLES_RAD,
    VELOCITY,
    NoPose,
    OdometryReading,
    SonarReading,
)
from swarm_logic.robots.sonpi.tracking import TrackingParams, clip_speed, wheel_speeds

MAX_RANGE_M = 4.0  # the HC-SR04's rated range


class SonpiBoard:
    """The board on ``bus`` (see the module docstring). ``robot`` (optional) gives the heading source and the start
    pose; ``wheel_radius_m``, ``half_track_m`` and ``encoder_cpr`` are the robot's, ``max_speed_mps`` what the
    tracking layer follows at most."""

    def __init__(
        self,
        bus: Any,
        clock: Clock,
        *,
        wheel_radius_m: float,
        half_track_m: float,
        encoder_cpr: int,
        max_speed_mps: float = 0.2,
        max_wheel_mps: float | None = None,
        lookahead_m: float = 0.1,
        keepalive_s: float = 0.2,
        robot: Any = None,
    ) -> None:
        if not (wheel_radius_m > 0 and encoder_cpr > 0):
            raise ValueError("sonpi_board: wheel_radius_m and encoder_cpr must be > 0")
        self.bus = bus
        self.clock = clock
        self.robot = robot
        self.m_per_count = 2 * math.pi * wheel_radius_m / encoder_cpr
        self.track = TrackingParams(half_track_m, max_speed_mps, max_wheel_mps or 1.25 * max_speed_mps, lookahead_m)
        self.keepalive_s = keepalive_s
        self.max_speed_mps = max_speed_mps
        start = getattr(robot, "start_pose", None)
        self.x, self.y, self.yaw = (float(v) for v in start) if start else (0.0, 0.0, 0.0)
        self.v = self.w = 0.0
        self.counts: tuple[int, int] | None = None
        self.odo_t = clock.now()
        self.window: P.Window | None = None
        self.readings_: list[SonarReading] = [SonarReading(math.inf, a) for a in SONAR_ANGLES_RAD]
        self.next_window = clock.now()
        self.command = (0.0, 0.0)  # world-frame velocity
        self.sent: tuple[int, int] | None = None
        self.sent_at = -math.inf
        self.identified = False
        self._pose: Any = None  # the heading source: False once looked up and absent
        self.counters = {
            "polls": 0,
            "reads": 0,
            "writes": 0,
            "bus_errors": 0,
            "windows": 0,
            "windows_missed": 0,
            "not_identified": 0,
            "heading_from_odometry": 0,  # polls that steered by the encoders: the pose device had no pose yet
        }
        self.last_error: str | None = None
        self._faces = {SONAR: SonarFace(self), VELOCITY: VelocityFace(self), ODOMETRY: OdometryFace(self)}

    def faces(self) -> dict[str, Any]:
        return self._faces

    # -- the robot's poll -------------------------------------------------------------------------------------------
    def poll(self) -> None:
        """Read the board (odometry, and the window when one is due), then send the tracking layer's set-points."""
        self.counters["polls"] += 1
        if not self.identified and not self._identify():
            return
        self._read()
        self._send()

    def _identify(self) -> bool:
        try:
            who, version = self.bus.read_i2c_block_data(P.ADDRESS, P.WHO_AM_I, 2)
        except OSError as e:
            return self._error(e)
        if who != P.WHO_AM_I_VALUE:
            self.counters["not_identified"] += 1
            self.last_error = f"who-am-I 0x{who:02X}, expected 0x{P.WHO_AM_I_VALUE:02X}"
            return False
        self.identified = True
        self.version = version
        return True

    def _read(self) -> None:
        now = self.clock.now()
        want_window = now >= self.next_window
        msgs = [i2c_msg.write(P.ADDRESS, [P.ODOMETRY]), i2c_msg.read(P.ADDRESS, P.ODOMETRY_BYTES)]
        if want_window:
            msgs += [i2c_msg.write(P.ADDRESS, [P.WINDOW]), i2c_msg.read(P.ADDRESS, P.WINDOW_BYTES)]
        try:
            self.bus.i2c_rdwr(*msgs)
        except OSError as e:
            self._error(e)
            return
        self.counters["reads"] += 1
        self._odometry(P.decode_odometry(bytes(msgs[1])), self.clock.now())
        if want_window:
            self._window(P.decode_window(bytes(msgs[3])))
            self.next_window = now + 0.125  # twice a window: a new one is seen within 125 ms of its end

    def _odometry(self, b: P.OdometryBlock, t: float) -> None:
        if self.counts is not None:
            dl = (b.left - self.counts[0]) * self.m_per_count
            dr = (b.right - self.counts[1]) * self.m_per_count
            ds, dth = 0.5 * (dl + dr), (dr - dl) / (2 * self.track.half_track_m)
            mid = self.yaw + 0.5 * dth
            self.x += ds * math.cos(mid)
            self.y += ds * math.sin(mid)
            self.yaw = math.remainder(self.yaw + dth, 2 * math.pi)
        self.counts = (b.left, b.right)
        self.v = 0.5 * (b.left_mm_s + b.right_mm_s) / 1000
        self.w = (b.right_mm_s - b.left_mm_s) / 1000 / (2 * self.track.half_track_m)
        self.odo_t = t

    def _window(self, w: P.Window) -> None:
        if w.seq == 0 or (self.window is not None and w.seq == self.window.seq):  # none complete yet, or seen
            return
        if self.window is not None and (w.seq - self.window.seq) & 0xFFFF > 1:
            self.counters["windows_missed"] += ((w.seq - self.window.seq) & 0xFFFF) - 1
        self.counters["windows"] += 1
        self.window = w
        out = []
        for s, angle in zip(w.sensors, SONAR_ANGLES_RAD, strict=True):
            if s.echoes and s.min_mm is not None:
                r = s.min_mm / 1000
            elif s.pings:
                r = math.inf
            else:  # no ping ended in this window: its last result stands
                r = math.inf if s.last_mm is None else s.last_mm / 1000
            out.append(SonarReading(r, angle))
        self.readings_ = out

    def _heading(self) -> float:
        if self._pose is None:
            try:
                self._pose = self.robot.device(POSE) if self.robot is not None else False
            except KeyError:
                self._pose = False
        if not self._pose:
            return self.yaw
        try:
            return self._pose.read().yaw_rad  # the camera's, or its last one carried on by odometry (not fresh)
        except NoPose:  # the camera has never seen this robot: steer by the encoders meanwhile
            self.counters["heading_from_odometry"] += 1
            return self.yaw

    def _send(self) -> None:
        vx, vy = self.command
        left, right = wheel_speeds(vx, vy, self._heading(), self.track) if (vx or vy) else (0.0, 0.0)
        sp = (round(left * 1000), round(right * 1000))
        now = self.clock.now()
        if sp == self.sent and (sp == (0, 0) or now - self.sent_at < self.keepalive_s):
            return
        try:
            self.bus.write_i2c_block_data(P.ADDRESS, P.SPEED_SP, list(P.pack_pair(*sp)))
        except OSError as e:
            self._error(e)
            return
        self.counters["writes"] += 1
        self.sent, self.sent_at = sp, now

    def _error(self, e: OSError) -> bool:
        self.counters["bus_errors"] += 1
        self.last_error = str(e)
        return False

    # -- what the faces ask ---------------------------------------------------------------------------------------
    def set_velocity(self, vx: float, vy: float) -> None:
        self.command = clip_speed(float(vx), float(vy), self.max_speed_mps)
        if self.identified:
            self._send()

    def odometry(self) -> OdometryReading:
        c = self.counts or (0, 0)
        return OdometryReading(self.odo_t, self.x, self.y, self.yaw, self.v, self.w, c[0], c[1])

    def close(self) -> None:
        if self.identified and self.sent not in (None, (0, 0)):
            with contextlib.suppress(OSError):  # leave the motors stopped (the watchdog would, 0.5 s later)
                self.bus.write_i2c_block_data(P.ADDRESS, P.SPEED_SP, list(P.pack_pair(0, 0)))
        close = getattr(self.bus, "close", None)
        if close is not None:
            close()


class SonarFace:
    """``sonpi_sonar``: the latest window's readings, right to left."""

    max_range_m = MAX_RANGE_M

    def __init__(self, board: SonpiBoard) -> None:
        self.board = board

    def readings(self) -> list[SonarReading]:
        return list(self.board.readings_)


class VelocityFace:
    """``sonpi_velocity``: the world-frame velocity the tracking layer follows."""

    def __init__(self, board: SonpiBoard) -> None:
        self.board = board
        self.max_speed_mps = board.max_speed_mps

    def set_velocity(self, vx_mps: float, vy_mps: float) -> None:
        self.board.set_velocity(vx_mps, vy_mps)


class OdometryFace:
    """``sonpi_odometry``: the encoders' dead reckoning."""

    def __init__(self, board: SonpiBoard) -> None:
        self.board = board

    def read(self) -> OdometryReading:
        return self.board.odometry()


def open_sonpi_board(cfg: dict[str, Any], robot: Any) -> SonpiBoard:
    """The HAL ``sonpi_board`` table's device: ``bus`` (1: the Pi's /dev/i2c-1; ``"sitl://i2c"``: a session's
    simulated bus; ``"usb-iss://PATH"``: a USB-ISS adapter; at ``scl_hz``), the robot's ``wheel_radius_m``,
    ``half_track_m``, ``encoder_cpr``, and optionally ``max_speed_mps``, ``lookahead_m``, ``keepalive_s``."""
    bus = cfg.get("bus", 1)
    options = {"scl_hz": int(cfg.get("scl_hz", 100_000))} if isinstance(bus, str) and "://" in bus else {}
    missing = [k for k in ("wheel_radius_m", "half_track_m", "encoder_cpr") if k not in cfg]
    if missing:
        raise ValueError(f"HAL config sonpi_board: {', '.join(missing)} needed (the robot's wheels and encoders)")
    return SonpiBoard(
        open_smbus(bus, **options),
        robot.clock,
        wheel_radius_m=float(cfg["wheel_radius_m"]),
        half_track_m=float(cfg["half_track_m"]),
        encoder_cpr=int(cfg["encoder_cpr"]),
        max_speed_mps=float(cfg.get("max_speed_mps", 0.2)),
        lookahead_m=float(cfg.get("lookahead_m", 0.1)),
        keepalive_s=float(cfg.get("keepalive_s", 0.2)),
        robot=robot,
    )
