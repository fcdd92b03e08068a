"""Every robot's MAVLink 2 face: a ground station (MAVProxy, QGroundControl, a pymavlink script) sees and commands
the robot as a ground rover.

The face speaks over a byte ``Link``: any pyserial port (``SerialLink``: ``sitl://mavlink`` in a session, a
telemetry radio on ``/dev/ttyUSB1``) or a pymavlink connection string (``MavutilLink``: ``udpout:gcs:14550``,
``udpin:0.0.0.0:14551``, ``tcp:host:5760``). It is system ``system_id`` (HAL ``mavlink.system_id``, default robot id
+ 1), component 1 (MAV_COMP_ID_AUTOPILOT1), HEARTBEAT type MAV_TYPE_GROUND_ROVER, autopilot MAV_AUTOPILOT_GENERIC.
``swarm_logic.runner`` services it: ``service()`` reads what arrived, handles it and sends the telemetry that is
due, ``next_due()`` says when to call again (never more than 0.1 s later); the runner acts on what the face holds
(``armed``, ``mode``, ``target``, ``reboot_requested``).

Modes, numbered as ArduPilot Rover numbers them (HEARTBEAT custom_mode, MAV_CMD_DO_SET_MODE param2, SET_MODE):
HOLD 4 (stopped, the behaviour paused), AUTO 10 (the swarm behaviour steps), GUIDED 15 (the runner drives to the
last position target, or follows the velocity target). Disarmed, the motors are stopped in any mode. The boot state
(HAL ``mavlink.boot``): "auto" (armed, AUTO: a robot without a ground station runs as before), "hold" (armed, HOLD)
or "disarmed" (disarmed, HOLD).

Frames: the LLC's odometry is ENU-like (x, y in metres, theta counter-clockwise from x); MAVLink's local frame is
NED, so north = y, east = x, down = 0 and yaw = pi/2 - theta (wrapped); velocities likewise. When the robot knows
where it was put down (``robot.start_pose``) the runner sets the odometry to it, so the local frame is the arena's.

Telemetry, default rates in Hz (HAL ``mavlink.rates`` and MAV_CMD_SET_MESSAGE_INTERVAL change them, up to 50 Hz;
0 stops one): HEARTBEAT, SYS_STATUS, BATTERY_STATUS, RADIO_STATUS and NAMED_VALUE_FLOAT / NAMED_VALUE_INT (the
controller's ``telemetry()``, names cut to 10 characters) at 1; LOCAL_POSITION_NED, ATTITUDE and DISTANCE_SENSOR
(the sonar: ultrasound, forward, 15-600 cm; no echo: current_distance UINT16_MAX and signal_quality 1) at 10.
SYS_STATUS reports the robot's sensors (motor outputs, battery, proximity: present and enabled), each healthy unless
the LLC flags a fault (a stall or the watchdog: motors; battery_low: battery), and every other health bit set, as
MAVLink means it (1: no error) and ArduPilot sends it, so a ground station sees no fence breach or failed sensor the
robot does not have. It counts the XBee driver's lost frames as comm errors and the face's dropped packets in
errors_count1. ATTITUDE's yaw rate comes from successive odometry updates (the LLC reports no turn rate).
RADIO_STATUS carries the XBee RSSI (the LLC's reading of the module's RSSI PWM output, else the driver's last packet
RSSI) scaled as SiK radios scale theirs, rssi = 1.9 * (dBm + 127) (255: unknown), so MAVProxy and QGroundControl
show it as they show a SiK radio's.

Commands (COMMAND_LONG or COMMAND_INT to this system or to all, each answered by COMMAND_ACK): ARM_DISARM (400),
DO_SET_MODE (176, param1 with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), DO_CHANGE_SPEED (178: the GUIDED cruise speed,
until the next mode change), PREFLIGHT_REBOOT_SHUTDOWN (246, param1 = 1: the runner starts a fresh controller),
SET_MESSAGE_INTERVAL (511), REQUEST_MESSAGE (512), REQUEST_AUTOPILOT_CAPABILITIES (520); anything else is
MAV_RESULT_UNSUPPORTED. SET_MODE is acknowledged as ArduPilot does (COMMAND_ACK with command 11).
SET_POSITION_TARGET_LOCAL_NED is obeyed only armed and in GUIDED, as ArduPilot obeys it; otherwise it is ignored
and a STATUSTEXT says why. A position (x and y given) is a go-to: MAV_FRAME_LOCAL_NED absolute, LOCAL_OFFSET_NED
relative in NED axes, BODY_NED / BODY_OFFSET_NED relative to the robot (x forward, y right). Without a position, a
velocity in a body frame is a forward speed vx (vy is ignored: the robot cannot move sideways) with the yaw rate
(NED: positive turns clockwise); a velocity in a local frame with a yaw rate is the velocity's component along the
robot's heading with that yaw rate, without one a heading (the velocity's direction) and a speed (its length); a
yaw alone is a heading to turn to (absolute in local frames, relative in body frames); a yaw rate alone turns in
place. Velocity, heading and turn targets lapse 3 s after the last one, as ArduPilot Rover's do; a go-to holds its
point. The LLC limits the speeds.

Parameters: the controller's numeric parameters (its class ``defaults``, as configured in ``robot.params``;
strings are not shown), REAL32 for floats and INT32 for ints and bools, values C-cast into the float field.
MAVLink ids are upper case, as ArduPilot's and PX4's are (MAVProxy upper-cases the names it is given, and matches
what it received against them): a name of up to 16 characters is its id in upper case (``speed_mps`` is
SPEED_MPS); a longer one becomes its first 13 characters, "_" and two base-36 characters of its CRC-32 (the next
free value on a clash), so ids are unique, even ignoring case, and stable. PARAM_SET and PARAM_REQUEST_READ find a
parameter by its id in any case (or PARAM_REQUEST_READ by param_index), and every PARAM_SET is answered by the
PARAM_VALUE a ground station waits for (id, value, type, index and count). PARAM_SET is checked
(a finite number, an integer for INT32, 0 or 1 for a bool, the range the controller declares for the parameter
(``Controller.ranges``, the one a session config is checked against), the class's ``resolve`` if it has one) and
applied by ``Controller.set_param``; a refused value is answered, as ArduPilot answers it, with the unchanged
PARAM_VALUE, and a STATUSTEXT says why; it is counted (``counters["refused_params"]``) and logged
(``robot.log("mavlink_param_refused", ...)``: in a session, the recording). A parameter in ``static_params`` is
stored for the next reboot, which a STATUSTEXT says.

Robustness: pymavlink's parser runs in robust mode; packets with a bad CRC or bad data are counted in ``counters``
and dropped, and no input raises. Messages for other systems or components are counted and ignored, and so are
the face's own packets echoed back by a loop-back or half-duplex link.
"""

from __future__ import annotations

import math
import os
import zlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np
import serial
from pymavlink.dialects.v20 import common as mavlink

from swarm_logic.clock import Clock
from swarm_logic.geometry import wrap

if TYPE_CHECKING:
    from swarm_logic.hal import LowLevel

os.environ.setdefault("MAVLINK20", "1")  # pymavlink's mavutil frames MAVLink 2 as the face does (MavutilLink)

HOLD, AUTO, GUIDED = 4, 10, 15  # ArduPilot Rover's custom mode numbers
MODE_NAMES = {HOLD: "HOLD", AUTO: "AUTO", GUIDED: "GUIDED"}
BOOT_STATES = {"auto": (True, AUTO), "hold": (True, HOLD), "disarmed": (False, HOLD)}  # -> (armed, mode)
COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1
SERVICE_S = 0.1  # the face is serviced at least this often: the latency of a command
EPS = 1e-6  # s: deadlines closer than this count as reached (clock times are floats)
RATES = {  # telemetry streams and their default rates (Hz)
    "HEARTBEAT": 1.0,
    "SYS_STATUS": 1.0,
    "BATTERY_STATUS": 1.0,
    "LOCAL_POSITION_NED": 10.0,
    "ATTITUDE": 10.0,
    "DISTANCE_SENSOR": 10.0,
    "RADIO_STATUS": 1.0,
    "NAMED_VALUE_FLOAT": 1.0,
    "NAMED_VALUE_INT": 1.0,
}
MAX_RATE_HZ = 50.0  # no stream faster: the supervisor would wake for nothing else
SONAR_MIN_CM, SONAR_MAX_CM = 15, 600  # the eSwarBot's sonar
# SYS_STATUS: the robot's sensors and controllers (present and enabled): wheels, battery, sonar. Its health bits
# are 1 for "no error" (MAVLink: 0 error, 1 healthy), so what the robot lacks is not failing, as ArduPilot reports
# it: a clear GEOFENCE bit is a "fence breach" to MAVProxy, a clear AHRS or LOGGING bit a sensor alarm
SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
           | mavlink.MAV_SYS_STATUS_SENSOR_PROXIMITY)
NO_ERRORS = sum(b for b in mavlink.enums["MAV_SYS_STATUS_SENSOR"] if b < mavlink.MAV_SYS_STATUS_EXTENSION_USED)
UINT16_MAX = 0xFFFF
RSSI_UNKNOWN = 255
TARGET_TIMEOUT_S = 3.0  # velocity, heading and turn targets lapse this long after the last one (ArduPilot Rover)
GUIDED_SPEED_MPS = 0.2  # cruise speed of a go-to until DO_CHANGE_SPEED sets another
WARN_EVERY_S = 5.0  # a repeated refusal is reported at most this often
XBEE_DROPS = ("checksum_errors", "bad_length", "truncated", "stalled", "malformed")  # XBee counters: lost frames
COUNTER_NAMES = (
    "rx_bytes",  # bytes read from the link
    "rx_packets",  # good packets from others
    "bad_crc",  # packets dropped for a bad CRC
    "bad_data",  # other garbage dropped: bytes before a start marker, bad lengths or flags
    "unknown",  # good packets of a message the common dialect does not define
    "echo",  # the face's own packets read back
    "other_target",  # packets for another system or component
    "ignored",  # messages the face does not act on (a ground station's HEARTBEAT, ...)
    "refused_targets",  # SET_POSITION_TARGET_LOCAL_NED not obeyed (disarmed, not GUIDED, bad frame or values)
    "refused_params",  # PARAM_SET refused: a value not of the parameter's kind or outside its declared range
)
IGNORE_POS = mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
IGNORE_VEL = mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
IGNORE_YAW = mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
IGNORE_YAW_RATE = mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
LOCAL_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_OFFSET_NED)
BODY_FRAMES = (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED)


# -- frames and scales ---------------------------------------------------------------------------------------
def yaw_ned(theta: float) -> float:
    """NED yaw (clockwise from north) of an ENU heading ``theta`` (counter-clockwise from east); its own inverse."""
    return wrap(math.pi / 2 - theta)


def sik_rssi(dbm: float | None) -> int:
    """RADIO_STATUS rssi of ``dbm`` on the SiK radios' scale (1.9 per dB above -127 dBm); 255 when unknown."""
    if dbm is None or not math.isfinite(dbm):
        return RSSI_UNKNOWN
    return max(0, min(254, round((dbm + 127.0) * 1.9)))


def sik_dbm(rssi: int) -> float | None:
    """The inverse of ``sik_rssi``."""
    return None if rssi == RSSI_UNKNOWN else rssi / 1.9 - 127.0


# -- links ---------------------------------------------------------------------------------------------------
class Link(Protocol):
    """A byte stream to a ground station: ``read`` returns what has arrived without blocking."""

    def write(self, data: bytes) -> None: ...

    def read(self) -> bytes: ...

    def close(self) -> None: ...


class SerialLink:
    """A ``Link`` over an open pyserial port (``serial.serial_for_url(url, timeout=0)``)."""

    def __init__(self, port: serial.SerialBase) -> None:
        self.port = port

    def write(self, data: bytes) -> None:
        self.port.write(data)

    def read(self) -> bytes:
        n = self.port.in_waiting
        return self.port.read(n) if n else b""

    def close(self) -> None:
        self.port.close()


class MavutilLink:
    """A ``Link`` over a pymavlink connection string (UDP, TCP, a serial device): the connection's raw bytes, not
    its parser. Socket errors on reading are counted in ``errors`` (a ground station that went away is no reason
    for the robot to stop)."""

    READ_MAX = 4096

    def __init__(self, url: str, baudrate: int = 57600) -> None:
        from pymavlink import mavutil  # imported here, after MAVLINK20 is set

        self.url = url
        self.conn = mavutil.mavlink_connection(url, baud=baudrate)
        self.errors = 0

    def write(self, data: bytes) -> None:
        self.conn.write(bytes(data))

    def read(self) -> bytes:
        try:
            data = self.conn.recv(self.READ_MAX)
        except OSError:
            self.errors += 1
            return b""
        return bytes(data) if data else b""  # mavutil's UDP answers "" (a str) when nothing has arrived

    def close(self) -> None:
        self.conn.close()


def open_link(cfg: Mapping[str, Any], what: str) -> Link:
    """The link a HAL table names: ``port`` (a pyserial URL or device, ``baudrate``) or ``url`` (pymavlink)."""
    port, url = cfg.get("port"), cfg.get("url")
    if bool(port) == bool(url):
        raise ValueError(f"HAL config {what}: give port (a serial device or pyserial URL, e.g. sitl://mavlink) or "
                         "url (a pymavlink connection, e.g. udpout:127.0.0.1:14550), one of them")
    baud = cfg.get("baudrate", 57600)
    if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
        raise ValueError(f"HAL config {what}.baudrate: a positive integer expected, got {baud!r}")
    if port:
        return SerialLink(serial.serial_for_url(str(port), baudrate=baud, timeout=0))
    return MavutilLink(str(url), baud)


# -- what the runner acts on ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class PositionTarget:
    """Go to (x, y) of the odometry frame and hold there."""

    x: float
    y: float


@dataclass(frozen=True)
class VelocityTarget:
    """Drive at forward speed ``v`` (m/s) turning at ``w`` (rad/s, counter-clockwise) until ``until``."""

    v: float
    w: float
    until: float


@dataclass(frozen=True)
class HeadingTarget:
    """Turn to heading ``theta`` (odometry frame) and drive along it at ``v`` (m/s) until ``until``."""

    theta: float
    v: float
    until: float


Target = PositionTarget | VelocityTarget | HeadingTarget


@dataclass(frozen=True)
class Param:
    name: str  # the controller's
    id: str  # MAVLink's, at most 16 characters
    kind: type  # bool, int or float, as the class's default


def param_ids(names: Iterable[str]) -> dict[str, str]:
    """Parameter name -> MAVLink param_id: upper case, at most 16 characters, unique even ignoring case; see the
    module's docstring."""
    names = list(names)
    ids: dict[str, str] = {}
    taken: set[str] = set()
    for n in names:
        if len(n) <= 16 and n.upper() not in taken:
            ids[n] = n.upper()
            taken.add(ids[n])
    for n in names:
        if n in ids:
            continue
        h = zlib.crc32(n.encode())
        while True:
            h %= 36 * 36
            pid = f"{n[:13].upper()}_{np.base_repr(h, 36):0>2}"
            if pid not in taken:
                break
            h += 1
        ids[n] = pid
        taken.add(pid)
    return ids


# -- what the face serves ------------------------------------------------------------------------------------
class FaceRobot(Protocol):
    """The robot as its face sees it (a ``swarm_logic.robot.Robot``; the face does not import it): its low level
    and radio for telemetry, its configured parameters and its log."""

    llc: LowLevel
    xbee: Any  # None, or a radio with ``counters`` and ``last_rssi_dbm``
    params: dict[str, Any]

    def log(self, topic: str, **values: Any) -> None: ...


class FaceController(Protocol):
    """The controller as its face sees it (a ``swarm_logic.controller.Controller``): its class's parameters, how
    they are checked and set, its telemetry."""

    defaults: ClassVar[dict[str, Any]]
    static_params: ClassVar[frozenset[str]]

    @classmethod
    def param_error(cls, name: str, value: Any) -> str | None: ...

    def set_param(self, name: str, value: Any) -> None: ...

    def telemetry(self) -> dict[str, float | int]: ...


# -- the face ------------------------------------------------------------------------------------------------
class MavlinkFace:
    """The robot's MAVLink 2 endpoint: vehicle state (``armed``, ``mode``, ``target``), telemetry, commands and
    parameters. ``bind`` it to the robot and its controller before servicing it."""

    def __init__(self, link: Link, clock: Clock, system_id: int, *, boot: str = "auto",
                 rates: Mapping[str, float] | None = None) -> None:
        """ValueError names the HAL field (``mavlink.system_id``, ``mavlink.boot``, ``mavlink.rates.X``)."""
        if isinstance(system_id, bool) or not isinstance(system_id, int) or not 1 <= system_id <= 255:
            raise ValueError(f"mavlink.system_id: an integer in 1..255 expected, got {system_id!r}")
        if boot not in BOOT_STATES:
            raise ValueError(f"mavlink.boot: {boot!r} is not one of {', '.join(BOOT_STATES)}")
        for name, hz in (rates or {}).items():
            if name not in RATES:
                raise ValueError(f"mavlink.rates.{name}: not a telemetry stream; known: {', '.join(RATES)}")
            if isinstance(hz, bool) or not isinstance(hz, int | float) or not 0 <= hz <= MAX_RATE_HZ:
                raise ValueError(f"mavlink.rates.{name}: a rate in [0, {MAX_RATE_HZ:g}] Hz expected, got {hz!r}")
        self.link = link
        self.clock = clock
        self.system_id = system_id
        self.boot = boot
        self.mav = mavlink.MAVLink(link, system_id, COMPONENT)
        self.mav.robust_parsing = True
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.rates = {**RATES, **{k: float(v) for k, v in (rates or {}).items()}}
        self.t0 = clock.now()
        self._next = {name: self.t0 if hz > 0 else math.inf for name, hz in self.rates.items()}
        self._next_service = self.t0
        self._warned: dict[str, float] = {}
        self._statustext_id = 0
        self._pose_prev: tuple[float, float] | None = None  # (theta, odom_t) at the last ATTITUDE
        self._yaw_rate = 0.0
        self.robot: FaceRobot | None = None
        self.controller: FaceController | None = None
        self.params: list[Param] = []
        self._param_index: dict[str, int] = {}
        self._senders: dict[str, Callable[[], None]] = {
            "HEARTBEAT": self._heartbeat, "SYS_STATUS": self._sys_status, "BATTERY_STATUS": self._battery_status,
            "LOCAL_POSITION_NED": self._local_position, "ATTITUDE": self._attitude,
            "DISTANCE_SENSOR": self._distance_sensor, "RADIO_STATUS": self._radio_status,
            "NAMED_VALUE_FLOAT": self._named_floats, "NAMED_VALUE_INT": self._named_ints,
            "AUTOPILOT_VERSION": self._autopilot_version}
        self._handlers: dict[str, Callable[[Any], None]] = {
            "COMMAND_LONG": self._command_long, "COMMAND_INT": self._command_int, "SET_MODE": self._set_mode_msg,
            "PARAM_REQUEST_LIST": self._param_request_list, "PARAM_REQUEST_READ": self._param_request_read,
            "PARAM_SET": self._param_set, "SET_POSITION_TARGET_LOCAL_NED": self._position_target}
        self.reset()

    def reset(self) -> None:
        """Back to the boot state: its arming and mode, no target, the default cruise speed."""
        self.armed, self.mode = BOOT_STATES[self.boot]
        self.target: Target | None = None
        self.speed_mps = GUIDED_SPEED_MPS
        self.reboot_requested = False

    def bind(self, robot: FaceRobot, controller: FaceController) -> None:
        """Serve ``robot`` and ``controller`` (again after a reboot): telemetry sources and the parameter table."""
        self.robot = robot
        self.controller = controller
        defaults = type(controller).defaults
        names = [n for n, v in defaults.items() if isinstance(v, bool | int | float)]
        ids = param_ids(names)
        self.params = [Param(n, ids[n], type(defaults[n])) for n in names]
        self._param_index = {p.id: i for i, p in enumerate(self.params)}
        self.statustext(f"{type(controller).__name__} started, {'armed' if self.armed else 'disarmed'}, "
                        f"{MODE_NAMES[self.mode]}")

    def close(self) -> None:
        self.link.close()

    # -- servicing ---------------------------------------------------------------------------------------------
    def service(self) -> None:
        """Handle what has arrived and send the telemetry that is due."""
        now = self.clock.now()
        data = self.link.read()
        if data:
            self.counters["rx_bytes"] += len(data)
            for m in self.mav.parse_buffer(data) or ():
                self._receive(m)
        for name, t in self._next.items():
            if now >= t - EPS:
                self._senders[name]()
                period = 1.0 / self.rates[name]
                self._next[name] = t + period if t + period > now else now + period
        self._next_service = now + SERVICE_S

    def next_due(self) -> float:
        """When ``service`` must run next: the next telemetry, and never more than ``SERVICE_S`` after the last."""
        return min(self._next_service, *self._next.values())

    def statustext(self, text: str, severity: int = mavlink.MAV_SEVERITY_INFO) -> None:
        """Send ``text`` (ASCII); longer than 50 characters, in chunks a ground station joins again."""
        raw = text.encode("ascii", "replace")
        if len(raw) <= 50:
            self.mav.statustext_send(severity, raw)
            return
        self._statustext_id = self._statustext_id % UINT16_MAX + 1
        chunks = [raw[i:i + 50] for i in range(0, len(raw), 50)]
        if len(chunks[-1]) == 50:
            chunks.append(b"")  # the last chunk must be shorter than 50 characters
        for seq, chunk in enumerate(chunks):
            self.mav.statustext_send(severity, chunk, self._statustext_id, seq)

    def _warn(self, key: str, text: str) -> None:
        """A warning that may repeat at every packet (refused targets): at most once per ``WARN_EVERY_S``."""
        now = self.clock.now()
        if now >= self._warned.get(key, -math.inf) + WARN_EVERY_S:
            self._warned[key] = now
            self.statustext(text, mavlink.MAV_SEVERITY_WARNING)

    def _receive(self, m: Any) -> None:
        kind = m.get_type()
        if kind == "BAD_DATA":
            self.counters["bad_crc" if "CRC" in m.reason else "bad_data"] += 1
            return
        if kind.startswith("UNKNOWN_"):
            self.counters["unknown"] += 1
            return
        if m.get_srcSystem() == self.system_id and m.get_srcComponent() == COMPONENT:
            self.counters["echo"] += 1
            return
        self.counters["rx_packets"] += 1
        handler = self._handlers.get(kind)
        if handler is None:
            self.counters["ignored"] += 1
        elif self._for_me(m):
            handler(m)

    def _for_me(self, m: Any) -> bool:
        if m.target_system in (0, self.system_id) and getattr(m, "target_component", 0) in (0, COMPONENT):
            return True
        self.counters["other_target"] += 1
        return False

    def _time_boot_ms(self) -> int:
        return round((self.clock.now() - self.t0) * 1000) & 0xFFFFFFFF

    # -- telemetry ---------------------------------------------------------------------------------------------
    def _state(self) -> Any:
        assert self.robot is not None, "bind the face to a robot before servicing it"
        return self.robot.llc.state

    def _faults(self) -> dict[str, bool]:
        return getattr(self._state(), "faults", None) or {}

    def _heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        if self.mode in (AUTO, GUIDED):
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.mode == AUTO:
            base |= mavlink.MAV_MODE_FLAG_AUTO_ENABLED  # the behaviour finds its own goals
        if any(self._faults().values()):
            status = mavlink.MAV_STATE_CRITICAL
        else:
            status = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self.mav.heartbeat_send(mavlink.MAV_TYPE_GROUND_ROVER, mavlink.MAV_AUTOPILOT_GENERIC, base, self.mode, status)

    def _xbee_errors(self) -> tuple[int, int]:
        """(frames the XBee driver lost, frames it read) so far; (0, 0) without its counters."""
        c = getattr(self.robot.xbee, "counters", None) if self.robot is not None else None
        if not c:
            return 0, 0
        return sum(c.get(k, 0) for k in XBEE_DROPS), c.get("frames", 0)

    def _battery(self) -> tuple[int, int]:
        """(mV or UINT16_MAX, remaining % or -1): unknown until the LLC has reported a voltage."""
        st = self._state()
        if not st.battery_v > 0:
            return UINT16_MAX, -1
        return min(UINT16_MAX - 1, round(st.battery_v * 1000)), max(0, min(100, int(st.battery_soc)))

    def _sys_status(self) -> None:
        motors, battery = mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS, mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
        faults = self._faults()
        health = NO_ERRORS
        if faults.get("stall") or faults.get("watchdog"):
            health &= ~motors
        if faults.get("battery_low"):
            health &= ~battery
        mv, remaining = self._battery()
        dropped, frames = self._xbee_errors()
        drop_rate = round(10000 * dropped / (dropped + frames)) if dropped else 0
        bad = self.counters["bad_crc"] + self.counters["bad_data"]
        self.mav.sys_status_send(SENSORS, SENSORS, health, 0, mv, -1, remaining, drop_rate, min(dropped, UINT16_MAX),
                                 min(bad, UINT16_MAX), 0, 0, 0)

    def _battery_status(self) -> None:
        mv, remaining = self._battery()
        cells = [mv] + [UINT16_MAX] * 9  # the pack's voltage in cell 0: the LLC does not measure cells
        self.mav.battery_status_send(0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_UNKNOWN,
                                     0x7FFF, cells, -1, -1, -1, remaining)

    def _local_position(self) -> None:
        st = self._state()
        vn, ve = st.v * math.sin(st.theta), st.v * math.cos(st.theta)
        self.mav.local_position_ned_send(self._time_boot_ms(), st.y, st.x, 0.0, vn, ve, 0.0)

    def _attitude(self) -> None:
        st = self._state()
        if st.odom_t is not None:  # the NED yaw rate between odometry updates: the LLC reports no turn rate
            if self._pose_prev is not None and st.odom_t > self._pose_prev[1]:
                self._yaw_rate = -wrap(st.theta - self._pose_prev[0]) / (st.odom_t - self._pose_prev[1])
            self._pose_prev = (st.theta, st.odom_t)
        self.mav.attitude_send(self._time_boot_ms(), 0.0, 0.0, yaw_ned(st.theta), 0.0, 0.0, self._yaw_rate)

    def _distance_sensor(self) -> None:
        st = self._state()
        if st.sonar_valid and math.isfinite(st.sonar_m):
            cm, quality = max(0, min(UINT16_MAX - 1, round(st.sonar_m * 100))), 0  # 0: quality unknown
        else:
            cm, quality = UINT16_MAX, 1  # no echo: 1 = invalid signal
        self.mav.distance_sensor_send(self._time_boot_ms(), SONAR_MIN_CM, SONAR_MAX_CM, cm,
                                      mavlink.MAV_DISTANCE_SENSOR_ULTRASOUND, 0, mavlink.MAV_SENSOR_ROTATION_NONE,
                                      255, signal_quality=quality)

    def _radio_status(self) -> None:
        rssi = self._state().rssi_dbm
        if rssi is None and self.robot is not None:
            rssi = getattr(self.robot.xbee, "last_rssi_dbm", None)
        dropped, _ = self._xbee_errors()
        self.mav.radio_status_send(sik_rssi(rssi), RSSI_UNKNOWN, 100, RSSI_UNKNOWN, RSSI_UNKNOWN,
                                   min(dropped, UINT16_MAX), 0)

    def _telemetry(self) -> dict[bytes, float | int]:
        values = self.controller.telemetry() if self.controller is not None else {}
        return {k.encode("ascii", "replace")[:10]: v for k, v in values.items()}

    def _named_floats(self) -> None:
        t = self._time_boot_ms()
        for name, v in self._telemetry().items():
            if isinstance(v, float | np.floating):
                self.mav.named_value_float_send(t, name, float(v))

    def _named_ints(self) -> None:
        t = self._time_boot_ms()
        for name, v in self._telemetry().items():
            if isinstance(v, bool | int | np.integer):
                self.mav.named_value_int_send(t, name, max(-(2**31), min(2**31 - 1, int(v))))

    def _autopilot_version(self) -> None:
        caps = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED)
        self.mav.autopilot_version_send(caps, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, self.system_id)

    # -- commands ----------------------------------------------------------------------------------------------
    def _ack(self, m: Any, command: int, result: int) -> None:
        self.mav.command_ack_send(command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent())

    def _command_long(self, m: Any) -> None:
        self._command(m, m.command, (m.param1, m.param2, m.param3, m.param4))

    def _command_int(self, m: Any) -> None:
        self._command(m, m.command, (m.param1, m.param2, m.param3, m.param4))

    def _command(self, m: Any, cmd: int, p: tuple[float, float, float, float]) -> None:
        ok, denied = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] in (0.0, 1.0):
                self._set_armed(p[0] == 1.0)
            self._ack(m, cmd, ok if p[0] in (0.0, 1.0) else denied)
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            self._ack(m, cmd, self._set_mode(p[0], p[1]))
        elif cmd == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            speed = p[1]  # m/s; -1: no change, -2: the default
            if 0 < speed < math.inf:
                self.speed_mps = speed
            elif speed == -2:
                self.speed_mps = GUIDED_SPEED_MPS
            self._ack(m, cmd, ok if 0 < speed < math.inf or speed in (-1, -2) else denied)
        elif cmd == mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
            if p[0] == 1:
                self.reboot_requested = True
                self.statustext("rebooting the robot program")
            self._ack(m, cmd, ok if p[0] in (0, 1) else mavlink.MAV_RESULT_UNSUPPORTED)
        elif cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self._ack(m, cmd, self._set_interval(p[0], p[1]))
        elif cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            name = self._stream_of(p[0])
            self._ack(m, cmd, ok if name is not None else mavlink.MAV_RESULT_UNSUPPORTED)
            if name is not None:
                self._senders[name]()
        elif cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._ack(m, cmd, ok)
            if p[0] == 1:
                self._autopilot_version()
        else:
            self._ack(m, cmd, mavlink.MAV_RESULT_UNSUPPORTED)

    def _stream_of(self, msg_id: float) -> str | None:
        """The sender's name for a MAVLink message id, if the face sends that message."""
        if not (math.isfinite(msg_id) and msg_id.is_integer()):
            return None
        cls = mavlink.mavlink_map.get(int(msg_id))
        name = cls.msgname if cls is not None else None
        return name if name in self._senders else None

    def _set_interval(self, msg_id: float, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 stops the stream, 0 restores its default rate."""
        name = self._stream_of(msg_id)
        if name is None or name not in self.rates:
            return mavlink.MAV_RESULT_UNSUPPORTED
        if interval_us == -1:
            self.rates[name] = 0.0
        elif interval_us == 0:
            self.rates[name] = RATES[name]
        elif 0 < interval_us < math.inf:
            self.rates[name] = min(MAX_RATE_HZ, 1e6 / interval_us)
        else:
            return mavlink.MAV_RESULT_DENIED
        self._next[name] = self.clock.now() if self.rates[name] > 0 else math.inf
        return mavlink.MAV_RESULT_ACCEPTED

    def _set_mode_msg(self, m: Any) -> None:
        self._ack(m, mavlink.MAVLINK_MSG_ID_SET_MODE, self._set_mode(m.base_mode, m.custom_mode))

    def _set_mode(self, base_mode: float, custom_mode: float) -> int:
        if not (math.isfinite(base_mode) and math.isfinite(custom_mode)):
            return mavlink.MAV_RESULT_DENIED
        if not int(base_mode) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self.statustext("set a custom mode: HOLD 4, AUTO 10, GUIDED 15", mavlink.MAV_SEVERITY_WARNING)
            return mavlink.MAV_RESULT_DENIED
        mode = int(custom_mode)
        if mode != custom_mode or mode not in MODE_NAMES:
            self.statustext(f"no mode {custom_mode:g}: HOLD 4, AUTO 10, GUIDED 15", mavlink.MAV_SEVERITY_WARNING)
            return mavlink.MAV_RESULT_DENIED
        if mode != self.mode:
            self.mode = mode
            self.target = None
            self.speed_mps = GUIDED_SPEED_MPS
            self.statustext(f"mode {MODE_NAMES[mode]}")
        return mavlink.MAV_RESULT_ACCEPTED

    def _set_armed(self, armed: bool) -> None:
        if armed != self.armed:
            self.armed = armed
            self.target = None
            self.statustext("armed" if armed else "disarmed")

    # -- targets -----------------------------------------------------------------------------------------------
    def _position_target(self, m: Any) -> None:
        if not (self.armed and self.mode == GUIDED):
            self.counters["refused_targets"] += 1
            self._warn("target", "target ignored: arm and set GUIDED (15) first")
            return
        frame, mask = m.coordinate_frame, m.type_mask
        target = self._target(frame, mask, m)
        if target is None:
            self.counters["refused_targets"] += 1
            self._warn("frame", f"target ignored: frame {frame}, type_mask {mask:#06x} not supported")
            return
        self.target = target

    def _target(self, frame: int, mask: int, m: Any) -> Target | None:
        """The target a SET_POSITION_TARGET_LOCAL_NED asks for, in the odometry frame; None if it is not one."""
        if frame not in LOCAL_FRAMES + BODY_FRAMES:
            return None
        st = self._state()
        until = self.clock.now() + TARGET_TIMEOUT_S
        yaw_rate = 0.0 if mask & IGNORE_YAW_RATE else m.yaw_rate
        if not mask & IGNORE_POS:
            if not (math.isfinite(m.x) and math.isfinite(m.y)):
                return None
            if frame == mavlink.MAV_FRAME_LOCAL_NED:
                return PositionTarget(m.y, m.x)
            if frame == mavlink.MAV_FRAME_LOCAL_OFFSET_NED:
                return PositionTarget(st.x + m.y, st.y + m.x)
            c, s = math.cos(st.theta), math.sin(st.theta)  # body: x forward, y to the right
            return PositionTarget(st.x + m.x * c + m.y * s, st.y + m.x * s - m.y * c)
        if (mask & IGNORE_VEL) != IGNORE_VEL:
            vx = 0.0 if mask & mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE else m.vx
            vy = 0.0 if mask & mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE else m.vy
            if not (math.isfinite(vx) and math.isfinite(vy) and math.isfinite(yaw_rate)):
                return None
            if frame in BODY_FRAMES:
                return VelocityTarget(vx, -yaw_rate, until)
            if not mask & IGNORE_YAW_RATE or vx == vy == 0.0:  # the speed along the heading, and the turn rate
                return VelocityTarget(vy * math.cos(st.theta) + vx * math.sin(st.theta), -yaw_rate, until)
            return HeadingTarget(math.atan2(vx, vy), math.hypot(vx, vy), until)
        if not mask & IGNORE_YAW:
            if not math.isfinite(m.yaw):
                return None
            yaw = m.yaw + (yaw_ned(st.theta) if frame in BODY_FRAMES else 0.0)
            return HeadingTarget(yaw_ned(yaw), 0.0, until)
        if not mask & IGNORE_YAW_RATE and math.isfinite(yaw_rate):
            return VelocityTarget(0.0, -yaw_rate, until)
        return None

    # -- parameters --------------------------------------------------------------------------------------------
    def _value(self, p: Param) -> bool | int | float:
        """The configured value: the robot's params over the class's defaults (what a reboot starts from)."""
        assert self.controller is not None and self.robot is not None
        return self.robot.params.get(p.name, type(self.controller).defaults[p.name])

    def _send_param(self, i: int) -> None:
        p = self.params[i]
        kind = mavlink.MAV_PARAM_TYPE_REAL32 if p.kind is float else mavlink.MAV_PARAM_TYPE_INT32
        self.mav.param_value_send(p.id.encode(), float(self._value(p)), kind, len(self.params), i)

    def _param_request_list(self, m: Any) -> None:
        for i in range(len(self.params)):
            self._send_param(i)

    def _find_param(self, param_id: Any) -> int | None:
        """The index of the parameter a ground station names, in any case (MAVProxy upper-cases what it is given,
        a script may send the controller's own name)."""
        return self._param_index.get(param_id.upper()) if isinstance(param_id, str) else None

    def _param_request_read(self, m: Any) -> None:
        i = self._find_param(m.param_id) if m.param_index == -1 else m.param_index
        if i is not None and 0 <= i < len(self.params):
            self._send_param(i)

    def _param_set(self, m: Any) -> None:
        i = self._find_param(m.param_id)
        if i is None:
            self.statustext(f"no parameter {m.param_id}", mavlink.MAV_SEVERITY_WARNING)
            return
        p = self.params[i]
        error = self._apply(p, m.param_value)
        if error is not None:  # the value stays as it was, and the PARAM_VALUE below says so (as ArduPilot answers)
            self.counters["refused_params"] += 1
            assert self.robot is not None
            self.robot.log("mavlink_param_refused", param=p.name, value=m.param_value, reason=error)
            self.statustext(f"{p.id} refused: {error}", mavlink.MAV_SEVERITY_WARNING)
        elif p.name in type(self.controller).static_params:
            self.statustext(f"{p.id} stored: a reboot applies it", mavlink.MAV_SEVERITY_NOTICE)
        self._send_param(i)

    def _apply(self, p: Param, raw: float) -> str | None:
        """Check and set ``p`` to ``raw``; the reason it was refused, or None."""
        assert self.controller is not None and self.robot is not None
        if not math.isfinite(raw):
            return "not a finite number"
        value: bool | int | float
        if p.kind is bool:
            if raw not in (0.0, 1.0):
                return "0 or 1 expected"
            value = raw == 1.0
        elif p.kind is int:
            if not raw.is_integer():
                return "an integer expected"
            value = int(raw)
        else:
            value = float(str(np.float32(raw)))  # the decimal the sender meant, not float32's binary neighbour
        cls = type(self.controller)
        error = cls.param_error(p.name, value)  # its declared range: the one a session config is checked against
        if error is not None:
            return f"{p.name}: {error}"
        resolve = getattr(cls, "resolve", None)
        try:
            if resolve is not None:
                resolve({**self.robot.params, p.name: value})
            self.controller.set_param(p.name, value)
        except ValueError as e:
            return str(e)
        return None


def open_face(cfg: Mapping[str, Any], robot_id: int, clock: Clock) -> MavlinkFace:
    """The face a HAL ``mavlink`` table describes (``port`` or ``url``, ``baudrate``, ``system_id``, ``boot``,
    ``rates``); ValueError names the HAL field."""
    if not isinstance(cfg, Mapping):
        raise ValueError(f"HAL config mavlink: a table expected, got {cfg!r}")
    known = ("port", "url", "baudrate", "system_id", "boot", "rates")
    for key in cfg:
        if key not in known:
            raise ValueError(f"HAL config mavlink.{key}: unknown key; known: {', '.join(known)}")
    rates = cfg.get("rates") or {}
    if not isinstance(rates, Mapping):
        raise ValueError(f"HAL config mavlink.rates: a table of message name = rate in Hz expected, got {rates!r}")
    link = open_link(cfg, "mavlink")
    try:
        return MavlinkFace(link, clock, cfg.get("system_id", robot_id + 1), boot=str(cfg.get("boot", "auto")),
                           rates=rates)
    except ValueError as e:
        link.close()
        raise ValueError(f"HAL config {e}") from None
