"""The robots' MAVLink 2 face and the MAVLink low level, on kinematic robots in simulated time: a pymavlink ground
station on the other end of an in-memory link commands them while the runner's supervisor services the face.

The robots here drive by wheel speeds (the GUIDED go-to does), which the numerical runner's point robots do not
(they move by rotate-then-go only), so the test has its own differential-drive robot in a walled arena.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
import uuid
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from swarm_logic.controller import Controller
from swarm_logic.drivers.llc_client import LlcState
from swarm_logic.families.demo.random_walk import RandomWalk
from swarm_logic.families.demo.rssi_keeper import RssiKeeper
from swarm_logic.families.rdpso.controller import Rdpso
from swarm_logic.mavlink.face import (
    AUTO,
    GUIDED,
    HOLD,
    RATES,
    MavlinkFace,
    MavutilLink,
    SerialLink,
    param_ids,
    sik_rssi,
)
from swarm_logic.mavlink.low_level import MavlinkLowLevel, open_low_level
from swarm_logic.mavlink.supervisor import Supervisor
from swarm_logic.robot import Robot
from swarm_logic.runner import run_controller

GCS_SYS, GCS_COMP = 255, mavlink.MAV_COMP_ID_MISSIONPLANNER
# SET_POSITION_TARGET_LOCAL_NED type_mask, bits set for what to ignore: 1 x, 2 y, 4 z, 8 vx, 16 vy, 32 vz,
# 64-256 accelerations, 1024 yaw, 2048 yaw rate
POS_ONLY = 0b1101_1111_1100  # x, y
VEL_YAW_RATE = 0b0101_1110_0111  # vx, vy, yaw rate
YAW_ONLY = 0b1001_1111_1111  # yaw


# -- simulated world -----------------------------------------------------------------------------------------------
class World:
    """The robots' clock: simulated time, kinematic robots integrated as it passes, actions scheduled ``at`` a time
    and hooks run whenever a robot program sleeps (before time moves on)."""

    DT = 0.01

    def __init__(self, size: tuple[float, float] = (4.0, 4.0)) -> None:
        self.t = 0.0
        self.size = size
        self.robots: list[DiffDrive] = []
        self.events: list[tuple[float, int, Callable[[], None]]] = []
        self.hooks: list[Callable[[], None]] = []
        self.wakes: list[float] = []
        self._seq = 0

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.sleep_until(self.t + dt)

    def sleep_until(self, t: float) -> None:
        self.wakes.append(t)
        for hook in self.hooks:
            hook()
        while self.events and self.events[0][0] <= t:
            te, _, fn = heapq.heappop(self.events)
            self._advance(te)
            fn()
        self._advance(t)

    def at(self, t: float, fn: Callable[[], None]) -> None:
        self._seq += 1
        heapq.heappush(self.events, (t, self._seq, fn))

    def _advance(self, t: float) -> None:
        while self.t < t - 1e-12:
            dt = min(self.DT, t - self.t)
            for r in self.robots:
                r.integrate(dt, self.t + dt)
            self.t = t if t - self.t <= self.DT else self.t + dt


class DiffDrive:
    """A kinematic differential-drive robot with the ``LowLevel`` protocol: ``drive`` with the eSwarBot LLC's 0.5 s
    watchdog, rotate-then-go ``move``, a 6 m sonar that sees the arena's walls, perfect odometry. ``calls`` records
    the commands by name."""

    ROT_RATE = 1.0
    SONAR_MAX = 6.0

    def __init__(self, world: World, x: float, y: float, theta: float) -> None:
        self.world = world
        self.state = LlcState(battery_v=8.1, battery_soc=90, heartbeat=0)
        self.state.x, self.state.y, self.state.theta = x, y, theta
        self.cmd = (0.0, 0.0)
        self.cmd_t = -math.inf
        self.plan: list[float] | None = None  # [rotation left, distance left, speed]
        self.calls: list[str] = []
        self.drives: list[tuple[float, float, float]] = []  # (t, v, w)
        world.robots.append(self)
        self._sense(0.0)

    def poll(self) -> int:
        return 0

    def drive(self, v: float, w: float) -> None:
        self.calls.append("drive")
        self.drives.append((self.world.t, v, w))
        self.cmd, self.cmd_t, self.plan = (v, w), self.world.t, None

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        self.calls.append("move")
        self.plan = [math.atan2(math.sin(rot_rad), math.cos(rot_rad)), dist_m, speed_mps]
        return 0

    def stop(self) -> None:
        self.calls.append("stop")
        self.cmd, self.cmd_t, self.plan = (0.0, 0.0), self.world.t, None

    def set_led(self, r: int, g: int, b: int) -> None:
        self.calls.append("set_led")

    def set_odometry(self, x: float, y: float, theta: float) -> None:
        self.calls.append("set_odometry")
        self.state.x, self.state.y, self.state.theta = x, y, theta

    def integrate(self, dt: float, t: float) -> None:
        s = self.state
        v = w = 0.0
        if self.plan is not None:
            rot, dist, speed = self.plan
            if abs(rot) > 1e-9:
                step = math.copysign(min(abs(rot), self.ROT_RATE * dt), rot)
                self.plan[0] -= step
                w = step / dt
            elif dist > 1e-9:
                step = min(dist, speed * dt)
                self.plan[1] -= step
                v = step / dt
            else:
                self.plan = None
        elif t - self.cmd_t <= 0.5:
            v, w = self.cmd
        w_size, h_size = self.world.size
        s.x = min(w_size, max(0.0, s.x + v * math.cos(s.theta) * dt))
        s.y = min(h_size, max(0.0, s.y + v * math.sin(s.theta) * dt))
        s.theta = math.atan2(math.sin(s.theta + w * dt), math.cos(s.theta + w * dt))
        s.v = v
        self._sense(t)

    def _sense(self, t: float) -> None:
        s = self.state
        c, n = math.cos(s.theta), math.sin(s.theta)
        w_size, h_size = self.world.size
        d = min((w_size - s.x) / c if c > 1e-12 else math.inf, -s.x / c if c < -1e-12 else math.inf,
                (h_size - s.y) / n if n > 1e-12 else math.inf, -s.y / n if n < -1e-12 else math.inf)
        s.sonar_valid = d <= self.SONAR_MAX
        s.sonar_m = d if s.sonar_valid else math.inf
        s.odom_t = s.sonar_t = s.status_t = t


class PipeEnd:
    """One end of an in-memory byte pipe: the ``Link`` protocol."""

    def __init__(self) -> None:
        self.inbox = bytearray()
        self.peer: PipeEnd | None = None
        self.closed = False

    def write(self, data: bytes) -> None:
        assert self.peer is not None
        self.peer.inbox += data

    def read(self) -> bytes:
        data = bytes(self.inbox)
        self.inbox.clear()
        return data

    def close(self) -> None:
        self.closed = True


def pipe() -> tuple[PipeEnd, PipeEnd]:
    a, b = PipeEnd(), PipeEnd()
    a.peer, b.peer = b, a
    return a, b


class Gcs:
    """A pymavlink ground station: what it receives, with the time and the robot's state then."""

    def __init__(self, link: PipeEnd, world: World, robot: DiffDrive) -> None:
        self.link = link
        self.world = world
        self.robot = robot
        self.mav = mavlink.MAVLink(link, GCS_SYS, GCS_COMP)
        self.mav.robust_parsing = True
        self.rx: list[tuple[float, Any, LlcState]] = []

    def pump(self) -> None:
        s = self.robot.state
        snap = LlcState(x=s.x, y=s.y, theta=s.theta, v=s.v, sonar_m=s.sonar_m, sonar_valid=s.sonar_valid)
        for m in self.mav.parse_buffer(self.link.read()) or ():
            self.rx.append((self.world.t, m, snap))

    def of(self, kind: str, since: float = -1.0) -> list[Any]:
        return [m for t, m, _ in self.rx if m.get_type() == kind and t >= since]

    def texts(self) -> list[str]:
        """STATUSTEXT, chunks joined again."""
        out: list[str] = []
        chunks: dict[int, str] = {}
        for m in self.of("STATUSTEXT"):
            if not m.id:
                out.append(m.text)
            elif len(m.text) < 50:
                out.append(chunks.pop(m.id, "") + m.text)
            else:
                chunks[m.id] = chunks.get(m.id, "") + m.text
        return out

    def command(self, cmd: int, *params: float, target: int = 1) -> None:
        p = [*params, 0, 0, 0, 0, 0, 0, 0][:7]
        self.mav.command_long_send(target, 1, cmd, 0, *p)

    def set_mode(self, mode: int, target: int = 1) -> None:
        self.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, target=target)

    def target(self, frame: int, mask: int, x: float = 0, y: float = 0, vx: float = 0, vy: float = 0,
               yaw: float = 0, yaw_rate: float = 0, target: int = 1) -> None:
        self.mav.set_position_target_local_ned_send(0, target, 1, frame, mask, x, y, 0, vx, vy, 0, 0, 0, 0, yaw,
                                                    yaw_rate)

    def acks(self, cmd: int) -> list[int]:
        return [m.result for m in self.of("COMMAND_ACK") if m.command == cmd]


class Radio:
    """A radio nobody hears: what rssi_keeper and rdpso need of an XBee."""

    def __init__(self, last_rssi_dbm: int | None = None) -> None:
        self.last_rssi_dbm = last_rssi_dbm

    def send_nowait(self, dest64: int | None, data: bytes, *, options: int = 0, radius: int = 0) -> int:
        return 0

    def recv(self, timeout: float | None = 0.0) -> None:
        return None

    def poll(self) -> None:
        pass


class Rig:
    """One robot with a face (system id 1) on a kinematic robot, and a ground station."""

    def __init__(self, boot: str = "auto", params: dict[str, Any] | None = None, pose=(1.0, 1.0, 0.0),
                 size=(4.0, 4.0), xbee: Any = None, rates: dict[str, float] | None = None) -> None:
        self.world = World(size)
        self.llc = DiffDrive(self.world, *pose)
        a, b = pipe()
        self.face = MavlinkFace(a, self.world, 1, boot=boot, rates=rates)
        self.robot = Robot(0, self.world, self.llc, np.random.Generator(np.random.PCG64(7)), dict(params or {}),
                           xbee=xbee, start_pose=pose, mavlink=self.face)
        self.gcs = Gcs(b, self.world, self.llc)
        self.world.hooks.append(self.gcs.pump)

    def at(self, t: float, fn: Callable[[], None]) -> None:
        self.world.at(t, fn)

    def run(self, controller: Controller, duration_s: float) -> None:
        run_controller(controller, self.robot, duration_s)
        self.gcs.pump()


class Spy(RandomWalk):
    """A random walk that records its life: instances, steps (times), destroy calls."""

    instances: ClassVar[list[Spy]] = []

    def init(self, robot: Robot) -> None:
        Spy.instances.append(self)
        self.steps: list[float] = []
        self.destroyed = False
        super().init(robot)

    def step(self) -> None:
        self.steps.append(self.robot.clock.now())
        super().step()

    def destroy(self) -> None:
        self.destroyed = True
        super().destroy()


# -- telemetry -----------------------------------------------------------------------------------------------------
def test_heartbeat_says_what_the_robot_is() -> None:
    rig = Rig()
    rig.run(RandomWalk(), 2.0)
    hb = rig.gcs.of("HEARTBEAT")[-1]
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == mavlink.MAV_COMP_ID_AUTOPILOT1
    assert hb.type == mavlink.MAV_TYPE_GROUND_ROVER and hb.autopilot == mavlink.MAV_AUTOPILOT_GENERIC
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert hb.custom_mode == AUTO and hb.system_status == mavlink.MAV_STATE_ACTIVE
    assert hb.get_msgbuf()[0] == 0xFD  # MAVLink 2 framing
    assert "RandomWalk started, armed, AUTO" in rig.gcs.texts()


def test_telemetry_rates_over_ten_seconds() -> None:
    rig = Rig()
    rig.run(RandomWalk(), 10.0)
    for name, hz in RATES.items():  # a random walk tells one float and one int
        assert abs(len(rig.gcs.of(name)) - hz * 10) <= 1, (name, len(rig.gcs.of(name)))


def test_rates_from_the_hal_and_the_face_wakes_at_least_every_tenth_of_a_second() -> None:
    quiet = dict.fromkeys(RATES, 0.0) | {"HEARTBEAT": 2.0}
    rig = Rig(params={"period_s": 2.0}, rates=quiet)
    rig.run(RandomWalk(), 5.0)
    assert abs(len(rig.gcs.of("HEARTBEAT")) - 10) <= 1 and not rig.gcs.of("LOCAL_POSITION_NED")
    gaps = np.diff(rig.world.wakes)
    assert gaps.max() <= 0.1 + 1e-9


def test_local_position_and_attitude_are_the_odometry_in_ned() -> None:
    rig = Rig(pose=(1.0, 1.5, 0.3))
    rig.run(RandomWalk(), 6.0)
    lpn = [(m, s) for _, m, s in rig.gcs.rx if m.get_type() == "LOCAL_POSITION_NED"]
    att = [(m, s) for _, m, s in rig.gcs.rx if m.get_type() == "ATTITUDE"]
    assert len(lpn) > 50 and len(att) > 50
    for m, s in lpn:
        assert m.x == pytest.approx(s.y, abs=1e-5) and m.y == pytest.approx(s.x, abs=1e-5) and m.z == 0
        assert m.vx == pytest.approx(s.v * math.sin(s.theta), abs=1e-5)
        assert m.vy == pytest.approx(s.v * math.cos(s.theta), abs=1e-5)
    for m, s in att:
        want = math.pi / 2 - s.theta
        assert math.cos(m.yaw - want) == pytest.approx(1.0, abs=1e-9) and -math.pi <= m.yaw <= math.pi
    moved = {round(m.x, 2) for m, _ in lpn}
    assert len(moved) > 10  # the robot did move


def test_distance_sensor_is_the_sonar() -> None:
    rig = Rig()  # 4 m arena: the wall ahead is 3 m away
    rig.run(RandomWalk(), 5.0)
    msgs = [(m, s) for _, m, s in rig.gcs.rx if m.get_type() == "DISTANCE_SENSOR"]
    assert msgs[0][0].current_distance == 300
    for m, s in msgs:
        assert m.type == mavlink.MAV_DISTANCE_SENSOR_ULTRASOUND and m.orientation == mavlink.MAV_SENSOR_ROTATION_NONE
        assert (m.min_distance, m.max_distance) == (15, 600)
        assert m.current_distance == round(s.sonar_m * 100)
    far = Rig(size=(10.0, 10.0), boot="hold")  # the wall ahead is 9 m away: no echo
    far.run(RandomWalk(), 0.5)
    m = far.gcs.of("DISTANCE_SENSOR")[-1]
    assert m.current_distance == 0xFFFF and m.signal_quality == 1


def test_battery_radio_and_named_values() -> None:
    rig = Rig(xbee=Radio(last_rssi_dbm=-60))
    rig.llc.state.rssi_dbm = -75.0
    rig.at(1.5, lambda: setattr(rig.llc.state, "rssi_dbm", None))
    rig.run(RssiKeeper(), 3.0)
    sys_status = rig.gcs.of("SYS_STATUS")[-1]
    assert sys_status.voltage_battery == 8100 and sys_status.battery_remaining == 90
    assert rig.gcs.of("BATTERY_STATUS")[-1].voltages[0] == 8100
    radio = rig.gcs.of("RADIO_STATUS")
    assert radio[0].rssi == sik_rssi(-75) == 99 and radio[-1].rssi == sik_rssi(-60) == 127
    assert sik_rssi(None) == 255
    ints = {m.name: m.value for m in rig.gcs.of("NAMED_VALUE_INT")}
    floats = {m.name for m in rig.gcs.of("NAMED_VALUE_FLOAT")}
    assert ints["neighbours"] == 0 and ints["good_links"] == 0 and "returning" in ints and "state" in ints
    assert floats == {"left_s"}


def mavproxy_sys_status_warnings(statuses: list[Any]) -> list[str]:
    """What MAVProxy makes of a run of SYS_STATUS: its fence module (it starts believing the fence healthy and says
    "fence breach" when the GEOFENCE health bit is clear) and its warning module (health of AS, MAG, INS, AHRS,
    TERR, LOG and FEN), as MAVProxy 1.8 checks them."""
    fence = mavlink.MAV_SYS_STATUS_GEOFENCE
    healthy, said = True, []
    for m in statuses:
        ok = m.onboard_control_sensors_health & fence == fence
        if healthy and not ok:
            said.append("fence breach")
        healthy = ok
        for bits in (mavlink.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE, mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG,
                     mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL | mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO,
                     mavlink.MAV_SYS_STATUS_AHRS, mavlink.MAV_SYS_STATUS_TERRAIN, mavlink.MAV_SYS_STATUS_LOGGING,
                     fence):
            if m.onboard_control_sensors_health & bits != bits:
                said.append(f"status {mavlink.enums['MAV_SYS_STATUS_SENSOR'][bits & -bits].name}")
    return said


def test_sys_status_reports_the_robots_sensors_and_no_bogus_failure() -> None:
    rig = Rig()
    rig.at(2.05, lambda: setattr(rig.llc.state, "faults", {"stall": True, "battery_low": True}))
    rig.run(RandomWalk(), 4.0)
    has = (mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
           | mavlink.MAV_SYS_STATUS_SENSOR_PROXIMITY)  # wheels, battery, sonar: nothing else
    statuses = rig.gcs.of("SYS_STATUS")
    assert len(statuses) == 5  # 1 Hz from t = 0
    for m in statuses:
        assert m.onboard_control_sensors_present == m.onboard_control_sensors_enabled == has
    assert mavproxy_sys_status_warnings(statuses) == []  # MAVProxy says nothing: no fence breach, no bad sensor
    healthy, faulty = statuses[0], rig.gcs.of("SYS_STATUS", since=2.05)[0]
    assert healthy.onboard_control_sensors_health & has == has  # its own sensors healthy ...
    assert faulty.onboard_control_sensors_health & has == mavlink.MAV_SYS_STATUS_SENSOR_PROXIMITY  # ... until faults
    assert faulty.onboard_control_sensors_health | has == healthy.onboard_control_sensors_health  # the rest unchanged


# -- arming and modes ----------------------------------------------------------------------------------------------
def test_arm_disarm_is_acknowledged_and_shown() -> None:
    rig = Rig(boot="disarmed")
    g = rig.gcs
    rig.at(1.03, lambda: g.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1))
    rig.at(2.53, lambda: g.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0))
    rig.at(2.73, lambda: g.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 7))
    rig.run(Spy(), 4.0)
    first = g.of("HEARTBEAT")[0]
    assert not first.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and first.custom_mode == HOLD
    assert first.system_status == mavlink.MAV_STATE_STANDBY
    acks = [(t, m) for t, m, _ in g.rx if m.get_type() == "COMMAND_ACK"]
    assert [m.result for _, m in acks] == [mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_ACCEPTED,
                                          mavlink.MAV_RESULT_DENIED]
    assert acks[0][0] <= 1.03 + 0.1 + 1e-9  # answered within the service period
    assert acks[0][1].target_system == GCS_SYS and acks[0][1].target_component == GCS_COMP
    armed = [m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED for m in g.of("HEARTBEAT", since=1.2)]
    assert armed[0] and not armed[-1]
    assert Spy.instances[-1].steps == []  # HOLD all along: the behaviour never stepped
    assert "stop" in rig.llc.calls and {"armed", "disarmed"} <= set(g.texts())


def test_modes_step_or_pause_the_behaviour() -> None:
    rig = Rig()
    g = rig.gcs
    rig.at(1.05, lambda: g.set_mode(HOLD))
    rig.at(2.05, lambda: g.set_mode(AUTO))
    rig.at(3.05, lambda: g.set_mode(GUIDED))
    rig.at(3.55, lambda: g.set_mode(99))
    rig.at(3.65, lambda: g.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, HOLD))
    spy = Spy()
    rig.run(spy, 4.0)
    steps = np.array(spy.steps)
    assert len(steps[steps < 1.05]) == 11  # at 0, 0.1, ... 1.0, the controller's own period
    assert not len(steps[(steps > 1.15) & (steps < 2.05)])
    assert len(steps[(steps >= 2.05) & (steps < 3.05)]) >= 9
    assert not len(steps[steps > 3.15])
    assert g.acks(mavlink.MAV_CMD_DO_SET_MODE) == [0, 0, 0, mavlink.MAV_RESULT_DENIED]
    assert g.acks(mavlink.MAVLINK_MSG_ID_SET_MODE) == [0]  # SET_MODE acknowledged as ArduPilot does
    assert [m.custom_mode for m in g.of("HEARTBEAT", since=3.7)] == [HOLD] * len(g.of("HEARTBEAT", since=3.7))
    assert {"mode HOLD", "mode AUTO", "mode GUIDED"} <= set(g.texts())
    hold = [t for t, v, w in rig.llc.drives if 1.15 < t < 2.05]
    assert not hold and rig.llc.calls.count("stop") >= 3


def test_commands_for_other_systems_are_ignored_and_unknown_ones_unsupported() -> None:
    rig = Rig(boot="disarmed")
    g = rig.gcs
    rig.at(0.5, lambda: g.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=99))
    rig.at(0.6, lambda: g.mav.command_long_send(1, 42, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
    rig.at(0.7, lambda: g.command(mavlink.MAV_CMD_NAV_TAKEOFF))
    rig.at(0.8, lambda: g.mav.command_int_send(0, 0, 0, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 1, 0, 0, 0,
                                                0, 0, 0))
    rig.run(Spy(), 1.0)
    assert rig.face.counters["other_target"] == 2
    assert g.acks(mavlink.MAV_CMD_NAV_TAKEOFF) == [mavlink.MAV_RESULT_UNSUPPORTED]
    assert g.acks(mavlink.MAV_CMD_COMPONENT_ARM_DISARM) == [0]  # the COMMAND_INT to every system
    assert rig.face.armed


def test_message_interval_request_message_and_capabilities() -> None:
    rig = Rig()
    g = rig.gcs
    rig.at(0.05, lambda: g.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HEARTBEAT, 250_000))
    rig.at(0.05, lambda: g.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, -1))
    rig.at(0.05, lambda: g.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GPS_RAW_INT, 1e6))
    rig.at(0.05, lambda: g.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
    rig.at(0.05, lambda: g.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_GPS_RAW_INT))
    rig.at(0.05, lambda: g.command(mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1))
    rig.run(RandomWalk(), 2.05)
    assert g.acks(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) == [0, 0, mavlink.MAV_RESULT_UNSUPPORTED]
    assert g.acks(mavlink.MAV_CMD_REQUEST_MESSAGE) == [0, mavlink.MAV_RESULT_UNSUPPORTED]
    assert g.acks(mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES) == [0]
    assert abs(len(g.of("HEARTBEAT", since=0.1)) - 8) <= 1
    assert not g.of("ATTITUDE", since=0.15)
    first, _ = g.of("AUTOPILOT_VERSION")  # asked for twice
    assert first.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 and first.uid == 1
    order = [(m.get_type(), getattr(m, "command", None)) for _, m, _ in g.rx]
    ack = order.index(("COMMAND_ACK", mavlink.MAV_CMD_REQUEST_MESSAGE))
    assert order[ack + 1] == ("AUTOPILOT_VERSION", None)  # acknowledged, then sent


def test_reboot_starts_a_fresh_controller_in_the_boot_state() -> None:
    Spy.instances.clear()
    rig = Rig(boot="hold", params={"speed_mps": 0.1})
    g = rig.gcs
    rig.at(0.5, lambda: g.set_mode(AUTO))
    rig.at(1.5, lambda: g.command(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1))
    rig.run(Spy(), 3.0)
    first, second = Spy.instances[-2:]
    assert first is not second and first.destroyed and second.destroyed  # the run's end destroys the second
    assert first.steps and not second.steps  # back in HOLD: the fresh one waits
    assert g.acks(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN) == [0]
    assert g.of("HEARTBEAT")[-1].custom_mode == HOLD
    assert sum("Spy started" in t for t in g.texts()) == 2
    assert rig.robot.start_pose == (rig.llc.state.x, rig.llc.state.y, rig.llc.state.theta)


# -- GUIDED --------------------------------------------------------------------------------------------------------


def test_a_position_target_is_reached_and_held() -> None:
    rig = Rig()
    g = rig.gcs
    rig.at(0.5, lambda: g.set_mode(GUIDED))
    rig.at(0.6, lambda: g.target(mavlink.MAV_FRAME_LOCAL_NED, POS_ONLY, x=2.5, y=3.0))
    poses: list[tuple[float, float, float]] = []
    rig.at(24.95, lambda: poses.append((rig.llc.state.x, rig.llc.state.y, rig.llc.state.theta)))
    rig.at(25.0, lambda: g.target(mavlink.MAV_FRAME_BODY_OFFSET_NED, POS_ONLY, x=-0.5, y=0.5))  # back, right
    spy = Spy()
    rig.run(spy, 45.0)
    x, y, theta = poses[0]
    assert math.hypot(x - 3.0, y - 2.5) <= 0.05 + 1e-9  # held where it stopped
    gx = x - 0.5 * math.cos(theta) + 0.5 * math.sin(theta)
    gy = y - 0.5 * math.sin(theta) - 0.5 * math.cos(theta)
    reached = [t for t in g.texts() if t.startswith("reached")]
    assert reached == ["reached N 2.50 E 3.00", f"reached N {gy:.2f} E {gx:.2f}"]
    s = rig.llc.state
    assert math.hypot(s.x - gx, s.y - gy) <= 0.05 + 1e-9
    assert not [t for t in spy.steps if t > 0.6]


def test_relative_targets_velocity_heading_and_their_timeout() -> None:
    rig = Rig(pose=(1.0, 1.0, 0.0))
    g = rig.gcs
    rig.at(0.2, lambda: g.set_mode(GUIDED))
    rig.at(0.3, lambda: g.target(mavlink.MAV_FRAME_LOCAL_OFFSET_NED, POS_ONLY, x=0.5, y=0.0))  # 0.5 m north
    rig.at(10.0, lambda: g.target(mavlink.MAV_FRAME_LOCAL_NED, YAW_ONLY, yaw=math.pi / 2))  # face east
    rig.at(15.0, lambda: g.target(mavlink.MAV_FRAME_BODY_NED, VEL_YAW_RATE, vx=0.1))
    states: dict[float, tuple[float, float, float]] = {}
    for t in (0.3, 9.9, 12.9, 16.0, 17.0, 25.0):
        rig.at(t, lambda t=t: states.__setitem__(t, (rig.llc.state.x, rig.llc.state.y, rig.llc.state.theta)))
    rig.run(RandomWalk(), 26.0)
    x0, y0, _ = states[0.3]  # where the robot was when the target came (it random-walked until 0.2 s)
    assert math.hypot(states[9.9][0] - x0, states[9.9][1] - (y0 + 0.5)) <= 0.05 + 1e-9
    assert abs(states[12.9][2]) <= 0.03  # heading east
    assert states[17.0][0] - states[16.0][0] == pytest.approx(0.1, abs=0.01)  # vx = 0.1 m/s
    assert states[25.0][0] - states[12.9][0] == pytest.approx(0.1 * 3, abs=0.015)  # 3 s, then it stopped
    assert "target not renewed for 3 s: stopped" in g.texts()


def test_targets_are_refused_unless_armed_and_guided_and_the_sonar_stops_the_robot() -> None:
    rig = Rig(pose=(1.0, 2.0, 0.0))
    g = rig.gcs
    rig.at(0.2, lambda: g.target(mavlink.MAV_FRAME_LOCAL_NED, POS_ONLY, x=2.0, y=3.0))  # in AUTO
    rig.at(0.3, lambda: g.set_mode(GUIDED))
    rig.at(0.4, lambda: g.target(mavlink.MAV_FRAME_GLOBAL, POS_ONLY, x=2.0, y=3.0))  # no global frame
    rig.at(0.5, lambda: g.target(mavlink.MAV_FRAME_LOCAL_NED, POS_ONLY, x=2.0, y=9.0))  # beyond the east wall
    rig.run(RandomWalk(), 20.0)
    assert rig.face.counters["refused_targets"] == 2
    texts = g.texts()
    assert "target ignored: arm and set GUIDED (15) first" in texts
    assert any(t.startswith("target ignored: frame 0") for t in texts)
    assert any(t.startswith("obstacle at") for t in texts)
    assert 4.0 - 0.25 - 0.03 <= rig.llc.state.x < 4.0 - 0.2


def test_repeated_velocity_targets_in_the_local_frame() -> None:
    rig = Rig(pose=(1.0, 2.0, 0.3))
    g = rig.gcs
    vel_only = VEL_YAW_RATE | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
    rig.at(0.05, lambda: g.set_mode(GUIDED))
    for i in range(1, 200):  # 0.2 m/s east, every 0.1 s, as a companion computer sends it: toward the east wall
        rig.at(0.1 * i + 0.01, lambda: g.target(mavlink.MAV_FRAME_LOCAL_NED, vel_only, vx=0.0, vy=0.2))
    for i in range(21):  # then turn in place at 0.5 rad/s clockwise (NED yaw rate > 0) for 2 s
        rig.at(21.0 + 0.1 * i, lambda: g.target(mavlink.MAV_FRAME_LOCAL_NED, VEL_YAW_RATE, yaw_rate=0.5))
    headings: list[float] = []
    rig.at(20.9, lambda: headings.append(rig.llc.state.theta))
    rig.at(23.0, lambda: headings.append(rig.llc.state.theta))
    rig.run(RandomWalk(), 24.0)
    assert 4.0 - 0.25 - 0.03 <= rig.llc.state.x < 4.0 - 0.2  # the sonar stopped it short of the wall
    assert abs(headings[0]) < 0.03  # it turned to the velocity's direction, east
    assert headings[1] - headings[0] == pytest.approx(-1.0, abs=0.06)
    assert sum(t.startswith("obstacle at") for t in g.texts()) == 1  # said once, not at every target


# -- parameters ----------------------------------------------------------------------------------------------------
def param_list(rig: Rig) -> dict[str, Any]:
    return {m.param_id: m for m in rig.gcs.of("PARAM_VALUE")}


@pytest.mark.parametrize("cls", [RandomWalk, RssiKeeper, Rdpso])
def test_param_list_has_every_numeric_parameter_with_a_unique_id(cls: type[Controller]) -> None:
    rig = Rig(xbee=Radio())
    rig.at(0.05, lambda: rig.gcs.mav.param_request_list_send(1, 0))
    rig.run(cls(), 0.3)
    got = param_list(rig)
    numeric = [n for n, v in cls.defaults.items() if not isinstance(v, str)]
    assert len(got) == len(numeric) and all(m.param_count == len(numeric) for m in got.values())
    assert sorted(m.param_index for m in got.values()) == list(range(len(numeric)))
    ids = param_ids(numeric)
    assert set(got) == set(ids.values()) and all(len(i) <= 16 and i == i.upper() for i in got)
    for name, pid in ids.items():
        v = cls.defaults[name]
        assert got[pid].param_value == pytest.approx(float(v), rel=1e-6)
        want = mavlink.MAV_PARAM_TYPE_REAL32 if isinstance(v, float) else mavlink.MAV_PARAM_TYPE_INT32
        assert got[pid].param_type == want


def test_long_parameter_names_get_unique_stable_ids() -> None:
    names = ["stagnation_on_improve", "stagnation_on_improvement", "stagnation_on_", "short", "exactly_sixteen_"]
    ids = param_ids(names)
    assert ids["short"] == "SHORT" and ids["exactly_sixteen_"] == "EXACTLY_SIXTEEN_"
    assert len(set(ids.values())) == len(names) and all(len(i) <= 16 and i == i.upper() for i in ids.values())
    assert ids["stagnation_on_improve"].startswith("STAGNATION_ON_") and ids == param_ids(names)
    crowd = [f"a_very_long_name_{i:04d}" for i in range(1296)]  # one 13-character prefix: every suffix is used
    assert len(set(param_ids(crowd).values())) == 1296
    cased = param_ids(["gain", "Gain", "GAIN"])  # unique ignoring case: the first keeps its name
    assert cased["gain"] == "GAIN" and len(set(cased.values())) == 3


class LongNames(Controller):
    defaults: ClassVar[dict[str, Any]] = {"a_rather_long_parameter": 1.5, "a_rather_long_parameter_too": 2,
                                          "enabled": True, "label": "text"}

    def init(self, robot: Robot) -> None:
        super().init(robot)
        self.p = {**self.defaults, **robot.params}

    def step(self) -> None:
        pass


def test_param_set_by_mapped_id_and_read_back() -> None:
    rig = Rig()
    ids = param_ids(["a_rather_long_parameter", "a_rather_long_parameter_too", "enabled"])
    long_id = ids["a_rather_long_parameter_too"]
    g = rig.gcs
    rig.at(0.1, lambda: g.mav.param_set_send(1, 1, long_id.encode(), 7, mavlink.MAV_PARAM_TYPE_INT32))
    rig.at(0.2, lambda: g.mav.param_set_send(1, 1, b"enabled", 0, mavlink.MAV_PARAM_TYPE_INT32))
    rig.at(0.3, lambda: g.mav.param_request_read_send(1, 1, b"", 0))
    rig.at(0.3, lambda: g.mav.param_request_read_send(1, 1, b"enabled", -1))
    rig.at(0.3, lambda: g.mav.param_request_read_send(1, 1, b"nothing", -1))
    ctl = LongNames()
    rig.run(ctl, 0.5)
    values = [(m.param_id, m.param_value) for m in g.of("PARAM_VALUE")]
    assert values == [(long_id, 7.0), ("ENABLED", 0.0), (ids["a_rather_long_parameter"], 1.5), ("ENABLED", 0.0)]
    assert ctl.p["a_rather_long_parameter_too"] == 7 and ctl.p["enabled"] is False
    assert rig.robot.params == {"a_rather_long_parameter_too": 7, "enabled": False}


def test_parameter_ids_are_upper_case_and_found_in_any_case_as_mavproxy_and_qgc_use_them() -> None:
    """MAVProxy lists what PARAM_VALUE names, matches ``param show speed_mps`` and ``param set speed_mps 0.2``
    upper-cased against it, sends PARAM_SET as REAL32 with the upper-case id and waits for the PARAM_VALUE echo;
    QGroundControl sends the id as listed and reads by param_index too."""
    rig = Rig()
    g = rig.gcs
    rig.at(0.1, lambda: g.mav.param_request_list_send(1, 1))
    rig.at(0.5, lambda: g.mav.param_set_send(1, 1, b"SPEED_MPS", 0.2, mavlink.MAV_PARAM_TYPE_REAL32))  # MAVProxy
    rig.at(0.6, lambda: g.mav.param_set_send(1, 1, b"Mean_Run_S", 3.0, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(0.7, lambda: g.mav.param_request_read_send(1, 1, b"speed_mps", -1))  # a script using the name
    rig.at(0.8, lambda: g.mav.param_request_read_send(1, 1, b"ignored", 3))  # by index: the id is ignored
    ctl = Spy()
    rig.run(ctl, 1.0)
    names = list(RandomWalk.defaults)
    values = g.of("PARAM_VALUE")
    listed = [m.param_id for m in values[:len(names)]]
    assert listed == [n.upper() for n in names]  # what MAVProxy's `param show SPEED_MPS` finds
    after = [(m.param_id, round(m.param_value, 6), m.param_type, m.param_index, m.param_count)
             for m in values[len(names):]]
    real, n = mavlink.MAV_PARAM_TYPE_REAL32, len(names)
    assert after == [("SPEED_MPS", 0.2, real, names.index("speed_mps"), n),  # the echo MAVProxy waits for
                     ("MEAN_RUN_S", 3.0, real, names.index("mean_run_s"), n),
                     ("SPEED_MPS", 0.2, real, names.index("speed_mps"), n),
                     (names[3].upper(), RandomWalk.defaults[names[3]], real, 3, n)]
    assert ctl.p["speed_mps"] == 0.2 and ctl.p["mean_run_s"] == 3.0  # the controller's names are unchanged
    assert rig.robot.params == {"speed_mps": 0.2, "mean_run_s": 3.0}


def test_param_set_is_applied_or_refused_with_a_reason() -> None:
    rig = Rig()
    g = rig.gcs
    rig.at(1.0, lambda: g.mav.param_set_send(1, 1, b"speed_mps", 0.1, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(1.0, lambda: g.mav.param_set_send(1, 1, b"period_s", -1, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(1.0, lambda: g.mav.param_set_send(1, 1, b"avoid_m", math.nan, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(1.0, lambda: g.mav.param_set_send(1, 1, b"no_such", 1, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(1.0, lambda: g.mav.param_set_send(1, 1, b"period_s", 0.2, mavlink.MAV_PARAM_TYPE_REAL32))
    ctl = Spy()
    rig.run(ctl, 3.0)
    values = [(m.param_id, m.param_value) for m in g.of("PARAM_VALUE")]
    assert values == [("SPEED_MPS", pytest.approx(0.1)), ("PERIOD_S", pytest.approx(0.1)),
                      ("AVOID_M", pytest.approx(0.45)), ("PERIOD_S", pytest.approx(0.2))]
    assert ctl.p["speed_mps"] == 0.1 and rig.robot.params["speed_mps"] == 0.1  # the decimal sent, not float32's
    assert ctl.period_s == 0.2 and np.diff(ctl.steps)[-5:] == pytest.approx([0.2] * 5)
    assert {v for t, v, w in rig.llc.drives if t > 1.2 and w == 0} == {0.1}
    texts = g.texts()
    assert "PERIOD_S refused: period_s: must be > 0, got -1.0" in texts
    assert "AVOID_M refused: not a finite number" in texts and "no parameter no_such" in texts


def test_a_value_outside_its_declared_range_is_refused_answered_unchanged_counted_and_logged() -> None:
    """As ArduPilot answers a PARAM_SET it refuses: the PARAM_VALUE echo carries the unchanged value (MAVProxy then
    reports the set as failed); the range is the one a session config is checked against."""
    rig = Rig()
    logs: list[tuple[str, dict[str, Any]]] = []
    rig.robot.log_sink = lambda topic, values: logs.append((topic, values))
    g = rig.gcs
    rig.at(0.5, lambda: g.mav.param_set_send(1, 1, b"SPEED_MPS", 50, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(0.6, lambda: g.mav.param_set_send(1, 1, b"TURN_RATE_RPS", 0, mavlink.MAV_PARAM_TYPE_REAL32))
    rig.at(0.7, lambda: g.mav.param_set_send(1, 1, b"SPEED_MPS", 0.3, mavlink.MAV_PARAM_TYPE_REAL32))
    ctl = Spy()
    rig.run(ctl, 1.5)
    values = [(m.param_id, round(m.param_value, 6)) for m in g.of("PARAM_VALUE")]
    assert values == [("SPEED_MPS", 0.15), ("TURN_RATE_RPS", 1.5), ("SPEED_MPS", 0.3)]
    assert ctl.p["speed_mps"] == 0.3 and ctl.p["turn_rate_rps"] == 1.5 and rig.robot.params == {"speed_mps": 0.3}
    assert {v for t, v, w in rig.llc.drives if 0.5 < t < 0.7 and w == 0} <= {0.15}  # never 50 m/s
    texts = g.texts()
    assert "SPEED_MPS refused: speed_mps: must lie in [0, 2], got 50.0" in texts
    assert "TURN_RATE_RPS refused: turn_rate_rps: must lie in (0, 20], got 0.0" in texts
    assert rig.face.counters["refused_params"] == 2
    assert logs == [("mavlink_param_refused", {"param": "speed_mps", "value": 50.0,
                                               "reason": "speed_mps: must lie in [0, 2], got 50.0"}),
                    ("mavlink_param_refused", {"param": "turn_rate_rps", "value": 0.0,
                                               "reason": "turn_rate_rps: must lie in (0, 20], got 0.0"})]
    with pytest.raises(ValueError, match=r"speed_mps: must lie in \[0, 2\], got 50"):  # the same range, directly
        ctl.set_param("speed_mps", 50)


def test_rdpso_parameters_resolve_and_static_ones_wait_for_a_reboot() -> None:
    rig = Rig(xbee=Radio(), params={"n_total": 4, "subgroups_init": 1})
    g = rig.gcs
    for name, value in (("alpha", 5.0), ("alpha", 0.6), ("n_total", 6), ("fuzzy", 2), ("sc_max", 2.5),
                        ("comm_window_s", 1.5)):
        rig.at(0.5, lambda name=name, value=value: g.mav.param_set_send(1, 1, name.encode(), value, 0))
    ctl = Rdpso()
    rig.run(ctl, 2.0)
    texts = g.texts()
    assert "ALPHA refused: alpha: must lie in (0, 1], got 5.0" in texts  # its declared range
    assert ("COMM_WINDOW_S refused: comm_window_s: must lie in (0, iteration_s = 1.0), got 1.5" in texts  # resolve;
            and ctl.p["comm_window_s"] == 0.25)  # two chunks
    assert ctl.alpha == 0.6 and ctl.p["alpha"] == 0.6
    assert "N_TOTAL stored: a reboot applies it" in texts
    assert rig.robot.params["n_total"] == 6 and ctl.p["n_total"] == 4
    assert "FUZZY refused: 0 or 1 expected" in texts and "SC_MAX refused: an integer expected" in texts
    tele = {m.name for m in g.of("NAMED_VALUE_INT")} | {m.name for m in g.of("NAMED_VALUE_FLOAT")}
    assert {"k", "sid", "excluded", "group_n", "hbest"} <= tele


# -- robustness ----------------------------------------------------------------------------------------------------
def packet(build: Callable[[mavlink.MAVLink], None], src: int = GCS_SYS) -> bytes:
    out = PipeEnd()
    out.peer = PipeEnd()
    build(mavlink.MAVLink(out, src, GCS_COMP))
    return bytes(out.peer.inbox)


def bound_face(boot: str = "auto") -> tuple[MavlinkFace, PipeEnd, Supervisor]:
    world = World()
    llc = DiffDrive(world, 1.0, 1.0, 0.0)
    a, b = pipe()
    face = MavlinkFace(a, world, 1, boot=boot)
    robot = Robot(0, world, llc, np.random.Generator(np.random.PCG64(1)), {}, xbee=Radio(), mavlink=face)
    sup = Supervisor(RandomWalk(), robot)
    sup.start()
    return face, b, sup


def test_bad_crc_is_counted_and_dropped() -> None:
    face, gcs_end, sup = bound_face("disarmed")
    arm = packet(lambda m: m.command_long_send(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
    bad = bytearray(arm)
    bad[-1] ^= 0xFF
    gcs_end.write(bytes(bad) + b"\x00garbage" + arm)
    sup.tick()
    assert face.counters["bad_crc"] == 1 and face.counters["bad_data"] >= 1
    assert face.armed  # the good packet after them was handled
    gcs = mavlink.MAVLink(None)
    gcs.robust_parsing = True
    acks = [m for m in gcs.parse_buffer(gcs_end.read()) or () if m.get_type() == "COMMAND_ACK"]
    assert len(acks) == 1


def test_a_loopback_link_echo_is_ignored() -> None:
    port = serial.serial_for_url("loop://", timeout=0)
    link = SerialLink(port)
    link.write(b"abc")
    assert link.read() == b"abc" and link.read() == b""
    world = World()
    face = MavlinkFace(link, world, 3)
    robot = Robot(0, world, DiffDrive(world, 1, 1, 0), np.random.Generator(np.random.PCG64(1)), {}, mavlink=face)
    ctl = RandomWalk()
    ctl.init(robot)
    face.bind(robot, ctl)
    face.service()
    face.service()
    assert face.counters["echo"] > 5 and face.counters["rx_packets"] == 0
    face.close()
    assert not port.is_open


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.binary(max_size=300), max_size=8))
def test_random_bytes_never_raise(chunks: list[bytes]) -> None:
    _, gcs_end, sup = bound_face()
    for c in chunks:
        gcs_end.write(c)
        sup.tick()


floats = st.floats(width=32, allow_nan=True, allow_infinity=True)


@st.composite
def messages(draw: st.DrawFn) -> bytes:
    kind = draw(st.sampled_from(["long", "int", "target", "param", "mode"]))
    cmd = draw(st.sampled_from([400, 176, 178, 246, 511, 512, 520, 22, 0, 65535]))
    p = [draw(floats) for _ in range(7)]
    if kind == "long":
        return packet(lambda m: m.command_long_send(draw(st.sampled_from([0, 1])), 0, cmd, 0, *p))
    if kind == "int":
        return packet(lambda m: m.command_int_send(1, 1, 0, cmd, 0, 0, *p[:4], 0, 0, p[4]))
    if kind == "target":
        frame = draw(st.sampled_from([0, 1, 7, 8, 9, 12]))
        mask = draw(st.integers(0, 0xFFFF))
        return packet(lambda m: m.set_position_target_local_ned_send(0, 1, 1, frame, mask, *p, *p[:4]))
    if kind == "param":
        pid = draw(st.sampled_from([b"speed_mps", b"period_s", b"mean_run_s", b"\xff\xfe", b"x" * 16]))
        return packet(lambda m: m.param_set_send(1, 1, pid, p[0], draw(st.integers(0, 255))))
    return packet(lambda m: m.set_mode_send(1, draw(st.integers(0, 255)), draw(st.integers(0, 2**32 - 1))))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(messages(), min_size=1, max_size=6), st.sampled_from(["auto", "hold"]))
def test_well_formed_packets_with_any_values_never_raise(msgs: list[bytes], boot: str) -> None:
    _, gcs_end, sup = bound_face(boot)
    gcs_end.write(packet(lambda m: m.command_long_send(1, 1, 176, 0, 1, GUIDED, 0, 0, 0, 0, 0)))
    sup.tick()
    world = sup.robot.clock
    for data in msgs:
        gcs_end.write(data)
        world.sleep_until(sup.tick())
    for _ in range(3):
        world.sleep_until(sup.tick())


# -- a LowLevel over MAVLink ---------------------------------------------------------------------------------------
def driven_pair(pose=(2.0, 2.0, 0.0)) -> tuple[World, DiffDrive, MavlinkLowLevel, Supervisor]:
    """Robot A (system 1, a point robot with a face, supervised by world events) and the low level of robot B,
    connected to A's face."""
    world = World()
    llc_a = DiffDrive(world, *pose)
    a, b = pipe()
    face = MavlinkFace(a, world, 1)
    robot_a = Robot(0, world, llc_a, np.random.Generator(np.random.PCG64(3)), {}, mavlink=face)
    sup = Supervisor(RandomWalk(), robot_a)
    sup.start()

    def tick() -> None:
        world.at(sup.tick(), tick)

    world.at(0.0, tick)
    llc_b = MavlinkLowLevel(b, world, 1, name="pipe")
    llc_b.connect(5.0)
    return world, llc_a, llc_b, sup


def test_a_behaviour_drives_another_robot_through_its_face() -> None:
    world, llc_a, llc_b, sup = driven_pair()
    assert sup.face.armed and sup.face.mode == GUIDED  # connect set GUIDED and armed
    robot_b = Robot(1, world, llc_b, np.random.Generator(np.random.PCG64(5)), {})
    errors: list[float] = []

    def compare() -> None:
        errors.append(math.hypot(llc_b.state.x - llc_a.state.x, llc_b.state.y - llc_a.state.y))
        world.at(world.t + 0.5, compare)

    world.at(world.t + 0.5, compare)
    start = (llc_a.state.x, llc_a.state.y)
    path = [start]
    world.hooks.append(lambda: path.append((llc_a.state.x, llc_a.state.y)))
    run_controller(RandomWalk(), robot_b, 15.0)
    travelled = sum(math.dist(p, q) for p, q in itertools.pairwise(path))
    assert travelled > 1.0  # A moved as B's random walk commanded
    assert max(errors) < 0.06  # B's state follows A's pose (10 Hz telemetry, 0.15 m/s)
    world.sleep(1.0)
    llc_b.poll()
    s, a = llc_b.state, llc_a.state
    assert (s.x, s.y, s.theta) == pytest.approx((a.x, a.y, a.theta), abs=1e-4)
    assert llc_b.vehicle_mode == GUIDED and llc_b.vehicle_armed and not any(s.faults.values())
    assert s.battery_v == pytest.approx(8.1) and s.battery_soc == 90 and s.sonar_valid
    assert s.sonar_m == pytest.approx(a.sonar_m, abs=0.011)
    assert llc_b.counters["bad"] == 0 and sup.face.counters["bad_crc"] == 0


def test_move_rotates_then_goes_and_set_odometry_rebases() -> None:
    world, llc_a, llc_b, _ = driven_pair()
    seen: list[str] = []

    def run_move(rot: float, dist: float) -> None:
        seq = llc_b.move(rot, dist, 0.2)
        assert llc_b.state.move_seq == seq
        for _ in range(400):
            world.sleep(0.1)
            llc_b.poll()
            if not seen or seen[-1] != llc_b.state.move_state:
                seen.append(llc_b.state.move_state)
            if llc_b.state.move_state in ("done", "aborted"):
                return

    run_move(math.pi / 2, 0.5)
    assert seen == ["rotating", "forward", "done"]
    assert (llc_a.state.x, llc_a.state.y) == pytest.approx((2.0, 2.5), abs=0.09)
    assert llc_a.state.theta == pytest.approx(math.pi / 2, abs=0.06)
    llc_b.set_odometry(0.0, 0.0, 0.0)
    assert (llc_b.state.x, llc_b.state.y, llc_b.state.theta) == pytest.approx((0, 0, 0), abs=1e-6)
    seen.clear()
    run_move(0.0, 0.4)
    assert seen == ["forward", "done"]
    assert (llc_b.state.x, llc_b.state.y) == pytest.approx((0.4, 0.0), abs=0.09)
    llc_b.move(1.0, 0.3, 0.2)
    llc_b.drive(0.1, 0.0)  # a drive command interrupts a move, as on the LLC
    assert llc_b.state.move_state == "aborted"
    llc_b.set_led(1, 2, 3)
    assert llc_b.led == (1, 2, 3)


def test_connect_timeout_names_the_link() -> None:
    world = World()
    with pytest.raises(TimeoutError, match=r"loop://: no HEARTBEAT from MAVLink system 7 within 0\.5 s"):
        open_low_level({"port": "loop://", "target_system": 7, "timeout_s": 0.5}, world)


def test_face_and_ground_station_over_udp() -> None:
    from pymavlink import mavutil

    world = World()
    link = MavutilLink("udpin:127.0.0.1:0")
    face = MavlinkFace(link, world, 5)
    robot = Robot(4, world, DiffDrive(world, 1, 1, 0), np.random.Generator(np.random.PCG64(1)), {}, mavlink=face)
    ctl = RandomWalk()
    ctl.init(robot)
    face.bind(robot, ctl)
    port = link.conn.port.getsockname()[1]
    gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS_SYS)
    try:
        gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        gcs.mav.command_long_send(5, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
        got: dict[str, Any] = {}
        deadline = time.monotonic() + 60.0  # only bounds a hang: the loop ends on both answers
        while {"HEARTBEAT", "COMMAND_ACK"} - set(got) and time.monotonic() < deadline:
            world.t += 1.0
            face.service()
            while (m := gcs.recv_msg()) is not None:
                got.setdefault(m.get_type(), m)
            time.sleep(0.01)
        assert got["HEARTBEAT"].get_srcSystem() == 5 and got["COMMAND_ACK"].result == 0 and not face.armed
    finally:
        gcs.close()
        face.close()


# -- the HAL ---------------------------------------------------------------------------------------------------
def can_hal(**extra: Any) -> dict[str, Any]:
    return {"llc_can": {"interface": "virtual", "channel": f"m-{uuid.uuid4().hex}"}, **extra}


def test_robot_open_builds_and_closes_the_face() -> None:
    world = World()
    robot = Robot.open(2, can_hal(mavlink={"port": "loop://", "boot": "hold", "rates": {"ATTITUDE": 4}}), world, 1)
    try:
        assert robot.mavlink is not None and robot.mavlink.system_id == 3 and robot.mavlink.mode == HOLD
        assert robot.mavlink.rates["ATTITUDE"] == 4.0
    finally:
        robot.close()
    assert not robot.mavlink.link.port.is_open


@pytest.mark.parametrize(("cfg", "match"), [
    ({"port": "loop://", "boot": "fly"}, r"HAL config mavlink\.boot: 'fly' is not one of auto, hold, disarmed"),
    ({"port": "loop://", "url": "udpout:127.0.0.1:9"}, r"HAL config mavlink: give port .* or url"),
    ({}, r"HAL config mavlink: give port"),
    ({"port": "loop://", "system_id": 300}, r"HAL config mavlink\.system_id: an integer in 1\.\.255"),
    ({"port": "loop://", "rates": {"GPS_RAW_INT": 1}}, r"HAL config mavlink\.rates\.GPS_RAW_INT: not a telemetry"),
    ({"port": "loop://", "rates": {"HEARTBEAT": -1}}, r"HAL config mavlink\.rates\.HEARTBEAT: a rate in"),
    ({"port": "loop://", "speed": 1}, r"HAL config mavlink\.speed: unknown key"),
])
def test_hal_errors_name_the_mavlink_field(cfg: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Robot.open(0, can_hal(mavlink=cfg), World(), 1)


def test_llc_mavlink_hal_errors() -> None:
    with pytest.raises(ValueError, match=r"HAL config llc_mavlink: the robot has one low-level controller"):
        Robot.open(0, can_hal(llc_mavlink={"port": "loop://"}), World(), 1)
    with pytest.raises(ValueError, match=r"HAL config llc_mavlink\.target_system: an integer in 1\.\.255"):
        Robot.open(0, {"llc_mavlink": {"port": "loop://", "target_system": 0}}, World(), 1)


# -- without MAVLink nothing changes ------------------------------------------------------------------------------
class RecordingClock:
    def __init__(self) -> None:
        self.t = 0.0
        self.calls: list[tuple] = []

    def now(self) -> float:
        self.calls.append(("now",))
        return self.t

    def sleep(self, dt: float) -> None:
        raise AssertionError("the runner sleeps until a time")

    def sleep_until(self, t: float) -> None:
        self.calls.append(("sleep_until", t))
        self.t = max(self.t, t)


class Idle(Controller):
    period_s = 0.25

    def step(self) -> None:
        self.robot.llc.poll()


def test_without_mavlink_the_runner_calls_the_clock_exactly_as_before() -> None:
    clock = RecordingClock()
    world = World()
    llc = DiffDrive(world, 1, 1, 0)
    robot = Robot(0, clock, llc, np.random.Generator(np.random.PCG64(1)), {}, start_pose=(1.0, 1.0, 0.0))
    run_controller(Idle(), robot, 1.0)
    assert clock.calls == [("now",), ("now",), ("sleep_until", 0.25), ("now",), ("sleep_until", 0.5), ("now",),
                           ("sleep_until", 0.75), ("now",), ("sleep_until", 1.0), ("now",)]
    assert llc.calls == []  # no odometry set, no stop: only what the controller does

    clock = RecordingClock()
    robot = Robot(0, clock, DiffDrive(world, 1, 1, 0), np.random.Generator(np.random.PCG64(1)), {})
    rw = RandomWalk()
    run_controller(rw, robot, 0.5)
    wakes = [c[1] for c in clock.calls if c[0] == "sleep_until"]
    t, want = 0.0, []
    for _ in range(5):
        t += 0.1
        want.append(t)
    assert wakes == want  # the same float sums as the loop always made
