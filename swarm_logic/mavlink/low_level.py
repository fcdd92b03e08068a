"""A ``swarm_logic.hal.LowLevel`` over MAVLink: the swarm logic drives a vehicle that speaks only MAVLink, an
ArduPilot Rover or another swarm-sitl robot's face (``swarm_logic.mavlink.face``), as it drives the eSwarBot's LLC.

The HAL names it instead of ``llc_can``: ``llc_mavlink = {url = "udpin:0.0.0.0:14551", target_system = 1}`` (or
``port`` for a pyserial URL; ``target_component`` 1, ``system_id`` that of the vehicle, as a companion computer's,
``timeout_s`` 10, ``baudrate``). The program speaks as component MAV_COMP_ID_ONBOARD_COMPUTER (191) and sends a
HEARTBEAT every second. ``connect`` waits for the vehicle's HEARTBEAT (a timeout names the URL), asks for the
telemetry it reads (MAV_CMD_SET_MESSAGE_INTERVAL), sets GUIDED (custom mode 15) and arms, checking each
COMMAND_ACK. A vehicle that a ground station takes out of GUIDED ignores the commands: the operator has the last
word.

Commands, all SET_POSITION_TARGET_LOCAL_NED: ``drive(v, w)`` a velocity and yaw rate in MAV_FRAME_BODY_NED (vx =
v, yaw_rate = -w; ArduPilot Rover's GUIDED takes it and stops 3 s after the last one, where the eSwarBot's LLC
stops after 0.5 s; ArduPilot drives at the vector's length, so it does not reverse); ``stop()`` a zero velocity;
``move(rot, dist, speed)`` rotate-then-go as the LLC's MOVE: a yaw-only target in MAV_FRAME_LOCAL_NED (the heading
reached at the current yaw + rot), then, once the reported heading is within 0.05 rad, MAV_CMD_DO_CHANGE_SPEED and
a position target in MAV_FRAME_LOCAL_NED ``dist`` ahead along that heading. Absolute targets, so the poll resends
the active one every second without changing it (ArduPilot drops a heading target after 3 s). ``state.move_state``
follows the vehicle's position feedback: "rotating", "forward", then "done" within 0.08 m of the point (ArduPilot's
WP_RADIUS must be smaller), or "aborted" when a drive command or a new move interrupts it or it takes longer than
three times its nominal duration + 2 s. The moves' pulse counts stay 0.

``state`` (``llc_client.LlcState``) comes from LOCAL_POSITION_NED and ATTITUDE (NED back to the ENU-like odometry
frame: x = east, y = north, theta = pi/2 - yaw), DISTANCE_SENSOR (forward; out of range, UINT16_MAX or signal
quality 1: no echo), BATTERY_STATUS / SYS_STATUS, RADIO_STATUS (SiK scale back to dBm) and HEARTBEAT (``heartbeat``
counts them, ``faults`` says critical / disarmed / not in GUIDED). ``set_odometry`` re-bases the reported pose by
an offset transform held here, since no common message resets a vehicle's frame; commands are computed in the
vehicle's own frame. ``set_led`` keeps the colour in ``led`` and sends nothing: MAVLink has no common LED message.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from swarm_logic.clock import Clock
from swarm_logic.drivers.llc_client import LlcState
from swarm_logic.geometry import wrap
from swarm_logic.mavlink.face import (
    GUIDED,
    IGNORE_POS,
    IGNORE_YAW,
    IGNORE_YAW_RATE,
    UINT16_MAX,
    Link,
    open_link,
    sik_dbm,
    yaw_ned,
)

POLL_S = 0.01  # s between reads while ``connect`` waits
ACK_TIMEOUT_S = 1.0  # per try of a command; three tries
HEARTBEAT_S = 1.0
RESEND_S = 1.0  # an active move's target is sent again this often
ROT_TOL_RAD = 0.05  # a move's rotation is done this close (smaller rotations are skipped, as the LLC skips them)
DONE_M = 0.08  # a move's run is done this close to its point
ROT_NOMINAL_RPS = 0.5  # rotation rate a move's time limit assumes
STREAMS = {  # telemetry asked of the vehicle: message id -> interval (us)
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100_000,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 100_000,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: 100_000,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 1_000_000,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 1_000_000,
}
ALL_BUT_VEL_YAW_RATE = (IGNORE_POS | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE
                        | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
                        | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
                        | IGNORE_YAW)
IGNORE_VEL_ACC = (mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
                  | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
                  | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE)
YAW_ONLY = IGNORE_POS | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE | IGNORE_VEL_ACC | IGNORE_YAW_RATE
POSITION_ONLY = mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE | IGNORE_VEL_ACC | IGNORE_YAW | IGNORE_YAW_RATE


@dataclass
class _Move:
    heading: float  # vehicle frame, ENU-like
    dist: float
    speed: float
    deadline: float
    goal: tuple[float, float] | None = None  # vehicle frame, once the run starts
    sent: float = -math.inf  # when the active target was last sent


class MavlinkLowLevel:
    """The ``LowLevel`` protocol for a MAVLink vehicle; ``connect()`` before use."""

    def __init__(self, link: Link, clock: Clock, target_system: int, *, target_component: int = 1,
                 system_id: int | None = None, name: str = "the MAVLink link") -> None:
        self.link = link
        self.clock = clock
        self.target_system = target_system
        self.target_component = target_component
        self.name = name
        self.mav = mavlink.MAVLink(link, system_id or target_system, mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
        self.mav.robust_parsing = True
        self.state = LlcState()
        self.led = (0, 0, 0)
        self.vehicle_armed = False
        self.vehicle_mode: int | None = None
        self.counters = {"rx_packets": 0, "bad": 0, "other_source": 0}
        self._acks: dict[int, int] = {}
        self._raw: tuple[float, float] | None = None  # vehicle frame x, y
        self._raw_theta: float | None = None
        self._raw_vel = (0.0, 0.0)  # east, north
        self._offset = (0.0, 0.0, 0.0)  # rotation, then translation: vehicle frame -> odometry frame
        self._odom_request: tuple[float, float, float] | None = None
        self._move: _Move | None = None
        self._move_seq = 0
        self._t0 = clock.now()
        self._next_heartbeat = self._t0

    # -- connection ----------------------------------------------------------------------------------------------
    def connect(self, timeout_s: float = 10.0) -> None:
        """Wait for the vehicle's HEARTBEAT, ask for telemetry, set GUIDED and arm; TimeoutError or RuntimeError
        naming the link when it does not answer or refuses."""
        deadline = self.clock.now() + timeout_s
        self.poll()
        while self.state.status_t is None:
            if self.clock.now() >= deadline:
                raise TimeoutError(f"{self.name}: no HEARTBEAT from MAVLink system {self.target_system} within "
                                   f"{timeout_s:g} s")
            self.clock.sleep(POLL_S)
            self.poll()
        for msg_id, interval in STREAMS.items():
            self._command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval)
        self._command(mavlink.MAV_CMD_DO_SET_MODE, "GUIDED", mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)
        self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, "arming", 1)

    def close(self) -> None:
        self.link.close()

    def _command_long(self, cmd: int, *params: float, confirmation: int = 0) -> None:
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        self.mav.command_long_send(self.target_system, self.target_component, cmd, confirmation, *p)

    def _command(self, cmd: int, what: str, *params: float) -> None:
        """Send a COMMAND_LONG and wait for its ACCEPTED acknowledgement (three tries)."""
        for attempt in range(3):
            self._acks.pop(cmd, None)
            self._command_long(cmd, *params, confirmation=attempt)
            deadline = self.clock.now() + ACK_TIMEOUT_S
            while cmd not in self._acks and self.clock.now() < deadline:
                self.clock.sleep(POLL_S)
                self.poll()
            result = self._acks.get(cmd)
            if result == mavlink.MAV_RESULT_ACCEPTED:
                return
            if result is not None:
                name = mavlink.enums["MAV_RESULT"][result].name if result in mavlink.enums["MAV_RESULT"] else result
                raise RuntimeError(f"{self.name}: MAVLink system {self.target_system} refused {what}: {name}")
        raise TimeoutError(f"{self.name}: MAVLink system {self.target_system} did not acknowledge {what}")

    # -- telemetry -------------------------------------------------------------------------------------------------
    def poll(self) -> int:
        """Read what has arrived and update ``state``; send the heartbeat and move targets that are due. Returns the
        number of packets from the vehicle."""
        now = self.clock.now()
        n = 0
        data = self.link.read()
        if data:
            for m in self.mav.parse_buffer(data) or ():
                n += self._handle(m, now)
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + HEARTBEAT_S
            self.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                    mavlink.MAV_STATE_ACTIVE)
        if self._move is not None:
            self._advance_move(now)
        return n

    def _handle(self, m: Any, now: float) -> int:
        kind = m.get_type()
        if kind == "BAD_DATA" or kind.startswith("UNKNOWN_"):
            self.counters["bad"] += 1
            return 0
        st = self.state
        if kind == "RADIO_STATUS":  # from the vehicle, or injected by a telemetry radio on the way
            st.rssi_dbm = sik_dbm(m.rssi)
            st.rssi_t = now
            self.counters["rx_packets"] += 1
            return 1
        if m.get_srcSystem() != self.target_system or m.get_srcComponent() != self.target_component:
            self.counters["other_source"] += 1
            return 0
        self.counters["rx_packets"] += 1
        if kind == "HEARTBEAT":
            st.heartbeat = (st.heartbeat + 1) & 0xFF
            st.status_t = now
            self.vehicle_armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self.vehicle_mode = m.custom_mode
            st.faults = {"critical": m.system_status >= mavlink.MAV_STATE_CRITICAL, "disarmed": not self.vehicle_armed,
                         "not_guided": m.custom_mode != GUIDED}
        elif kind == "LOCAL_POSITION_NED":
            self._raw = (m.y, m.x)
            self._raw_vel = (m.vy, m.vx)
            self._update_pose(now)
        elif kind == "ATTITUDE":
            self._raw_theta = yaw_ned(m.yaw)
            self._update_pose(now)
        elif kind == "DISTANCE_SENSOR":
            if m.orientation == mavlink.MAV_SENSOR_ROTATION_NONE:
                cm = m.current_distance
                st.sonar_valid = cm != UINT16_MAX and cm <= m.max_distance and m.signal_quality != 1  # no echo
                st.sonar_m = cm / 100.0 if st.sonar_valid else math.inf
                st.sonar_t = now
        elif kind == "BATTERY_STATUS":
            if m.id == 0:
                cells = [v for v in m.voltages if v != UINT16_MAX]
                if cells:
                    st.battery_v = sum(cells) / 1000.0
                if m.battery_remaining >= 0:
                    st.battery_soc = m.battery_remaining
        elif kind == "SYS_STATUS":
            if m.voltage_battery != UINT16_MAX:
                st.battery_v = m.voltage_battery / 1000.0
            if m.battery_remaining >= 0:
                st.battery_soc = m.battery_remaining
        elif kind == "COMMAND_ACK" and m.target_system in (0, self.mav.srcSystem):
            self._acks[m.command] = m.result
        return 1

    def _update_pose(self, now: float) -> None:
        if self._raw is None or self._raw_theta is None:
            return
        if self._odom_request is not None:
            self._rebase(*self._odom_request)
        (xr, yr), th = self._raw, self._raw_theta
        dth, tx, ty = self._offset
        c, s = math.cos(dth), math.sin(dth)
        st = self.state
        st.x, st.y, st.theta = c * xr - s * yr + tx, s * xr + c * yr + ty, wrap(th + dth)
        ve, vn = self._raw_vel
        st.v = ve * math.cos(th) + vn * math.sin(th)  # along the heading
        st.odom_t = now

    def _rebase(self, x: float, y: float, theta: float) -> None:
        assert self._raw is not None and self._raw_theta is not None
        (xr, yr), th = self._raw, self._raw_theta
        dth = wrap(theta - th)
        c, s = math.cos(dth), math.sin(dth)
        self._offset = (dth, x - (c * xr - s * yr), y - (s * xr + c * yr))
        self._odom_request = None

    # -- commands ----------------------------------------------------------------------------------------------
    def _time_boot_ms(self) -> int:
        return round((self.clock.now() - self._t0) * 1000) & 0xFFFFFFFF

    def _target(self, frame: int, mask: int, *, x: float = 0.0, y: float = 0.0, vx: float = 0.0,
                yaw: float = 0.0, yaw_rate: float = 0.0) -> None:
        self.mav.set_position_target_local_ned_send(self._time_boot_ms(), self.target_system, self.target_component,
                                                    frame, mask, x, y, 0.0, vx, 0.0, 0.0, 0.0, 0.0, 0.0, yaw,
                                                    yaw_rate)

    def drive(self, v: float, w: float) -> None:
        """Forward speed ``v`` (m/s) and turn rate ``w`` (rad/s, counter-clockwise); aborts a running move."""
        self._abort_move()
        self._target(mavlink.MAV_FRAME_BODY_NED, ALL_BUT_VEL_YAW_RATE, vx=v, yaw_rate=-w)

    def stop(self) -> None:
        self.drive(0.0, 0.0)

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        """Rotate by ``rot_rad`` (counter-clockwise), then drive ``dist_m`` straight at ``speed_mps``; returns the
        move's ``seq`` (``state.move_seq``). Arguments as ``LlcClient.move`` takes them."""
        if not (math.isfinite(rot_rad) and math.isfinite(dist_m) and math.isfinite(speed_mps)):
            raise ValueError("move: arguments must be finite")
        if dist_m < 0 or speed_mps <= 0:
            raise ValueError("move: the distance must be >= 0 (turn by pi to go back) and the speed > 0")
        self._abort_move()
        now = self.clock.now()
        self._move_seq = (self._move_seq + 1) & 0xFF
        st = self.state
        st.move_seq, st.move_t = self._move_seq, now
        theta = self._raw_theta if self._raw_theta is not None else 0.0
        nominal = abs(wrap(rot_rad)) / ROT_NOMINAL_RPS + dist_m / speed_mps
        self._move = _Move(wrap(theta + rot_rad), dist_m, speed_mps, now + 3 * nominal + 2.0)
        if abs(wrap(rot_rad)) > ROT_TOL_RAD:
            st.move_state = "rotating"
        else:
            self._run(now)
        if self._move is not None:
            self._advance_move(now)
        return self._move_seq

    def _abort_move(self) -> None:
        if self._move is not None:
            self._move = None
            self.state.move_state = "aborted"
            self.state.move_t = self.clock.now()

    def _run(self, now: float) -> None:
        """Start a move's straight run (or finish a move without one)."""
        mv, st = self._move, self.state
        assert mv is not None
        if mv.dist <= 0 or self._raw is None:
            self._move = None
            st.move_state = "done" if mv.dist <= 0 else "aborted"  # no position yet: nowhere to go from
            st.move_t = now
            return
        xr, yr = self._raw
        mv.goal = (xr + mv.dist * math.cos(mv.heading), yr + mv.dist * math.sin(mv.heading))
        mv.sent = -math.inf
        st.move_state, st.move_t = "forward", now
        self._command_long(mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.SPEED_TYPE_GROUNDSPEED, mv.speed, -1)

    def _advance_move(self, now: float) -> None:
        mv, st = self._move, self.state
        assert mv is not None
        if now > mv.deadline:
            self.drive(0.0, 0.0)  # records the abort
            return
        if st.move_state == "rotating":
            if self._raw_theta is not None and abs(wrap(mv.heading - self._raw_theta)) <= ROT_TOL_RAD:
                self._run(now)
                if self._move is None:
                    return
            elif now >= mv.sent + RESEND_S:
                mv.sent = now
                self._target(mavlink.MAV_FRAME_LOCAL_NED, YAW_ONLY, yaw=yaw_ned(mv.heading))
                return
        if mv.goal is None or self._raw is None:
            return
        if math.hypot(mv.goal[0] - self._raw[0], mv.goal[1] - self._raw[1]) <= DONE_M:
            self._move = None
            st.move_state, st.move_t = "done", now
        elif now >= mv.sent + RESEND_S:
            mv.sent = now
            self._target(mavlink.MAV_FRAME_LOCAL_NED, POSITION_ONLY, x=mv.goal[1], y=mv.goal[0])

    def set_led(self, r: int, g: int, b: int) -> None:
        self.led = (r, g, b)

    def set_odometry(self, x: float, y: float, theta: float) -> None:
        """Report the pose as (x, y, theta) from now on (at the first pose when none has come yet)."""
        self._odom_request = (x, y, theta)
        self._update_pose(self.clock.now())


def open_low_level(cfg: Mapping[str, Any], clock: Clock) -> MavlinkLowLevel:
    """The connected low level a HAL ``llc_mavlink`` table describes; ValueError names the HAL field."""
    if not isinstance(cfg, Mapping):
        raise ValueError(f"HAL config llc_mavlink: a table expected, got {cfg!r}")
    known = ("url", "port", "baudrate", "target_system", "target_component", "system_id", "timeout_s")
    for key in cfg:
        if key not in known:
            raise ValueError(f"HAL config llc_mavlink.{key}: unknown key; known: {', '.join(known)}")
    ids = {}
    for key, default in (("target_system", 1), ("target_component", 1), ("system_id", None)):
        v = cfg.get(key, default)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 255):
            raise ValueError(f"HAL config llc_mavlink.{key}: an integer in 1..255 expected, got {v!r}")
        ids[key] = v
    timeout = cfg.get("timeout_s", 10.0)
    if isinstance(timeout, bool) or not isinstance(timeout, int | float) or not 0 < timeout < math.inf:
        raise ValueError(f"HAL config llc_mavlink.timeout_s: a time > 0 in seconds expected, got {timeout!r}")
    link = open_link(cfg, "llc_mavlink")
    llc = MavlinkLowLevel(link, clock, ids["target_system"], target_component=ids["target_component"],
                          system_id=ids["system_id"], name=str(cfg.get("url") or cfg.get("port")))
    try:
        llc.connect(float(timeout))
    except BaseException:
        llc.close()
        raise
    return llc
