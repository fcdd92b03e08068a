"""Driver for the eSwarBot low-level controller over any python-can bus (SITL or a real adapter).

``poll()`` drains received frames without blocking and decodes them with the robot's DBC (the eSwarBot's unless
the client is given another); commands are encoded with the same database. Frames with an unknown ID or a wrong
length are counted and dropped.

Two ways to move: ``drive(v, w)`` sets wheel speeds (repeat it, the LLC stops 0.5 s after the last), and
``move(rot, dist, speed)`` hands the LLC a rotate-then-go displacement, which it executes on its own and
reports in ``state.move_*``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import can

from swarm_logic.robots.eswarbot import eswarbot_llc_db

if TYPE_CHECKING:
    from cantools.database.can import Database

MOVE_STATES = ("idle", "rotating", "forward", "done", "aborted")  # MOVE_STATUS.state, by value


@dataclass
class LlcState:
    """The latest telemetry from the LLC, in SI units; ``*_t`` is the bus timestamp of each update."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    v: float = 0.0
    odom_t: float | None = None
    encoders: tuple[int, int] = (0, 0)
    sonar_m: float = math.inf
    sonar_valid: bool = False
    sonar_t: float | None = None
    light_raw: int = 0
    battery_v: float = 0.0
    battery_soc: int = 0
    heartbeat: int = -1
    status_t: float | None = None
    faults: dict[str, bool] = field(default_factory=dict)
    rssi_dbm: float | None = None  # the XBee's last-packet RSSI read from its PWM pin; None when the output is off
    rssi_t: float | None = None
    pose_ideal: bool = False  # the LLC reports an external (motion-capture) pose, not its dead reckoning
    move_seq: int | None = None  # the MOVE that MOVE_STATUS last reported on
    move_state: str = "idle"  # "idle", "rotating", "forward", "done" or "aborted"
    move_rot_pulses: int = 0  # executed rotation, encoder pulses (positive counter-clockwise)
    move_fwd_pulses: int = 0  # executed forward run, encoder pulses
    move_t: float | None = None
    sonar_left_m: float = math.inf  # a robot with three sonars (TraxBot): the side ones (SONAR_SIDES)
    sonar_right_m: float = math.inf
    conveyor_position: int = 0  # a carrier: slots its belt has advanced (CONVEYOR_STATUS) ...
    conveyor_pending: int = 0  # ... still to advance ...
    conveyor_moving: bool = False  # ... and whether it is moving
    conveyor_seq: int | None = None
    conveyor_t: float | None = None


class LlcClient:
    """The LLC's client on ``bus``, speaking the robot's CAN database ``db`` (default: the eSwarBot's)."""

    def __init__(self, bus: can.BusABC, db: Database | None = None) -> None:
        self.bus = bus
        self.db = db if db is not None else eswarbot_llc_db()
        self.state = LlcState()
        self.rx_frames = 0
        self.rx_unknown = 0
        self.rx_bad_length = 0
        self.tx_failed = 0
        self._seq = 0
        self._move_seq = 0
        self._conveyor_seq = 0

    def poll(self) -> int:
        """Decode every frame waiting on the bus; returns how many were accepted."""
        n = 0
        while (msg := self.bus.recv(timeout=0)) is not None:
            if self._handle(msg):
                n += 1
        return n

    def _handle(self, msg: can.Message) -> bool:
        if msg.is_error_frame or msg.is_remote_frame:
            return False
        if msg.is_extended_id:  # the LLC's interface uses standard (11-bit) IDs only
            self.rx_unknown += 1
            return False
        try:
            spec = self.db.get_message_by_frame_id(msg.arbitration_id)
        except KeyError:
            self.rx_unknown += 1
            return False
        if len(msg.data) != spec.length or spec.senders != ["LLC"]:
            self.rx_bad_length += 1
            return False
        s = spec.decode(bytes(msg.data), decode_choices=False)
        st, ts = self.state, msg.timestamp
        name = spec.name
        if name == "ODOMETRY":
            st.x, st.y = s["x_mm"] / 1000.0, s["y_mm"] / 1000.0
            st.theta, st.v = s["theta_mrad"] / 1000.0, s["v_mm_s"] / 1000.0
            st.odom_t = ts
        elif name == "ENCODERS":
            st.encoders = (int(s["left"]), int(s["right"]))
        elif name == "SONAR":
            st.sonar_valid = bool(s["valid"])
            st.sonar_m = s["range_mm"] / 1000.0 if st.sonar_valid else math.inf
            st.sonar_t = ts
        elif name == "LIGHT":
            st.light_raw = int(s["ldr_raw"])
        elif name == "BATTERY":
            st.battery_v = s["voltage_mv"] / 1000.0
            st.battery_soc = int(s["soc_pct"])
        elif name == "RADIO_RSSI":
            st.rssi_dbm = float(s["rssi_dbm"]) if s["valid"] else None
            st.rssi_t = ts
        elif name == "STATUS":
            st.heartbeat = int(s["heartbeat"])
            st.status_t = ts
            st.faults = {k[6:]: bool(v) for k, v in s.items() if k.startswith("fault_")}
            st.pose_ideal = bool(s["pose_ideal"])
        elif name == "MOVE_STATUS":
            state = int(s["state"])
            st.move_seq = int(s["seq"])
            st.move_state = MOVE_STATES[state] if state < len(MOVE_STATES) else f"unknown({state})"
            st.move_rot_pulses, st.move_fwd_pulses = int(s["rot_pulses"]), int(s["fwd_pulses"])
            st.move_t = ts
        elif name == "SONAR_SIDES":
            st.sonar_left_m = s["left_mm"] / 1000.0 if s["left_valid"] else math.inf
            st.sonar_right_m = s["right_mm"] / 1000.0 if s["right_valid"] else math.inf
        elif name == "CONVEYOR_STATUS":
            st.conveyor_seq, st.conveyor_moving = int(s["seq"]), bool(s["moving"])
            st.conveyor_position, st.conveyor_pending = int(s["position_slots"]), int(s["pending_slots"])
            st.conveyor_t = ts
        self.rx_frames += 1
        return True

    def _send(self, name: str, **signals: float) -> None:
        """Encode and send a command. A frame the adapter cannot send (bus-off, a full queue) is counted in
        ``tx_failed`` and lost: the LLC's watchdog stops the motors when commands stop arriving, which is the
        safe outcome, so the robot program goes on rather than crash."""
        spec = self.db.get_message_by_name(name)
        try:
            self.bus.send(can.Message(arbitration_id=spec.frame_id, data=spec.encode(signals), is_extended_id=False))
        except can.CanOperationError:
            self.tx_failed += 1

    def drive(self, v: float, w: float) -> None:
        """Forward speed ``v`` (m/s) and turn rate ``w`` (rad/s); repeat within 0.5 s or the LLC stops."""
        self._seq = (self._seq + 1) & 0xFF
        self._send(
            "DRIVE_CMD",
            v_mm_s=max(-2000, min(2000, round(v * 1000))),
            w_mrad_s=max(-20000, min(20000, round(w * 1000))),
            seq=self._seq,
        )

    def move(self, rot_rad: float, dist_m: float, speed_mps: float) -> int:
        """Rotate in place by ``rot_rad`` (counter-clockwise positive; taken the shorter way round), then drive
        ``dist_m`` (>= 0) straight, at wheel rim speed ``speed_mps`` (> 0; the LLC caps it at the wheels' top
        speed). Aborts a running move. Returns the move's ``seq``, which ``state.move_seq`` echoes."""
        if not (math.isfinite(rot_rad) and math.isfinite(dist_m) and math.isfinite(speed_mps)):
            raise ValueError("move: arguments must be finite")
        if dist_m < 0 or speed_mps <= 0:
            raise ValueError("move: the distance must be >= 0 (turn by pi to go back) and the speed > 0")
        self._move_seq = (self._move_seq + 1) & 0xFF
        self._send(
            "MOVE_CMD",
            rot_mrad=max(-3142, min(3142, round(math.atan2(math.sin(rot_rad), math.cos(rot_rad)) * 1000))),
            dist_mm=min(32767, round(dist_m * 1000)),
            speed_mm_s=max(1, min(65535, round(speed_mps * 1000))),
            seq=self._move_seq,
        )
        return self._move_seq

    def stop(self) -> None:
        self.drive(0.0, 0.0)

    def set_led(self, r: int, g: int, b: int) -> None:
        self._send("LED_CMD", red=r, green=g, blue=b)

    def set_odometry(self, x: float, y: float, theta: float) -> None:
        self._send("ODOM_SET", x_mm=round(x * 1000), y_mm=round(y * 1000), theta_mrad=round(theta * 1000))

    def release(self, slots: int = 1) -> int:
        """A carrier (TraxBot): advance the conveyor by ``slots`` pitches, dropping that many scouts behind the
        robot, one after the other. Returns the command's ``seq``, which ``state.conveyor_seq`` echoes."""
        if not 1 <= slots <= 255:
            raise ValueError(f"release: slots must be 1..255, got {slots!r}")
        self._conveyor_seq = (self._conveyor_seq + 1) & 0xFF
        self._send("CONVEYOR_CMD", slots=slots, seq=self._conveyor_seq)
        return self._conveyor_seq
