"""A ground station's failure injection, handled by the world as PX4 SITL's simulator handles it.

``MAV_CMD_INJECT_FAILURE`` (420: param1 FAILURE_UNIT, param2 FAILURE_TYPE, param3 instance), in a COMMAND_LONG or
COMMAND_INT to a robot's system id (or to all, target 0; component 0 or 1), never reaches the robot's MAVLink face:
the world turns it into a ``[[faults]]`` entry (``FaultCfg``) from the next quantum on, as ``Hub.inject_fault``
takes any injected fault, and answers COMMAND_ACK from the robot's system id, component 1: MAV_RESULT_ACCEPTED,
UNSUPPORTED for a unit or type not mapped, DENIED when the robot cannot carry it (it has no UWB module, no such
motor) or a parameter is not an integer. Each is an event (``fault_injected`` with ``"source": "mavlink"``).

============================== =============================================================================
FAILURE_UNIT                   fault
============================== =============================================================================
SENSOR_DISTANCE_SENSOR (7)     ``sensor``, ``sensor = "sonar"`` (every sonar of the robot; instance ignored)
SENSOR_GPS (4)                 ``sensor``, ``sensor = "uwb"`` (its positioning: the UWB module's ranges)
SYSTEM_MOTOR (101)             ``motor_stall``, instance 1 the left wheel, 2 the right, 0 both
============================== =============================================================================

FAILURE_TYPE for a sensor: OFF (1) ``mode = "dead"``, STUCK (2) ``stuck``, GARBAGE (3) ``noisy`` with
``GARBAGE_SIGMA_M``, WRONG (4) ``bias`` with ``WRONG_BIAS_M``; for a motor OFF (1) and STUCK (2) stall it. OK (0)
ends the faults of that unit and robot started this way (``Hub.end_fault``; an event ``fault_cleared``; FAILED if the
world cannot end one); a new type for a unit replaces the one before, as PX4 keeps one state per unit. SLOW, DELAYED
and INTERMITTENT are unsupported.
"""

from __future__ import annotations

import json
import math
import os
import struct
from collections import Counter
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2

from bridge.core.config import FaultCfg

if TYPE_CHECKING:
    from bridge.core.hub import Hub

M = mavlink2
COMPONENT = 1  # MAV_COMP_ID_AUTOPILOT1: the robot's face, and the world answering for it
#: GARBAGE: the noise a sensor's readings get, 1-sigma (m): ten times the DW1000's ranging noise, a sixth of the
#: eSwarBot sonar's 6 m range
GARBAGE_SIGMA_M = {"sonar": 1.0, "uwb": 1.0}
#: WRONG: the offset of its readings (m): an obstacle half a metre farther than it is, a range half a metre long
WRONG_BIAS_M = {"sonar": 0.5, "uwb": 0.5}
SENSORS = {M.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR: "sonar", M.FAILURE_UNIT_SENSOR_GPS: "uwb"}
SENSOR_MODES = {M.FAILURE_TYPE_OFF: "dead", M.FAILURE_TYPE_STUCK: "stuck", M.FAILURE_TYPE_GARBAGE: "noisy",
                M.FAILURE_TYPE_WRONG: "bias"}
MOTOR_TYPES = (M.FAILURE_TYPE_OFF, M.FAILURE_TYPE_STUCK)
WHEELS = {0: "both", 1: "left", 2: "right"}


class Refused(Exception):
    """A failure injection the world does not carry out: ``result`` is the MAV_RESULT to answer with."""

    def __init__(self, result: int, why: str) -> None:
        super().__init__(why)
        self.result = result


def failure_fault(unit: float, ftype: float, instance: float, robot: int, at_s: float) -> FaultCfg | None:
    """The fault a MAV_CMD_INJECT_FAILURE asks for on ``robot`` from ``at_s`` (None: FAILURE_TYPE_OK, the end of the
    unit's faults); ``Refused`` if it is not carried out."""
    params = (unit, ftype, instance)
    if not all(math.isfinite(p) and p == int(p) for p in params):
        raise Refused(M.MAV_RESULT_DENIED, "unit, type and instance are integers")
    unit, ftype, instance = (int(p) for p in params)
    if unit not in SENSORS and unit != M.FAILURE_UNIT_SYSTEM_MOTOR:
        raise Refused(M.MAV_RESULT_UNSUPPORTED, f"failure unit {unit} is not simulated")
    if ftype == M.FAILURE_TYPE_OK:
        return None
    if unit in SENSORS:
        sensor = SENSORS[unit]
        mode = SENSOR_MODES.get(ftype)
        if mode is None:
            raise Refused(M.MAV_RESULT_UNSUPPORTED, f"failure type {ftype} is not simulated for a {sensor}")
        extra = ({"sigma": GARBAGE_SIGMA_M[sensor]} if mode == "noisy" else
                 {"bias": WRONG_BIAS_M[sensor]} if mode == "bias" else {})
        return FaultCfg(kind="sensor", robot=robot, at_s=at_s, sensor=sensor, mode=mode, **extra)
    if ftype not in MOTOR_TYPES:
        raise Refused(M.MAV_RESULT_UNSUPPORTED, f"failure type {ftype} is not simulated for a motor")
    if instance not in WHEELS:
        raise Refused(M.MAV_RESULT_DENIED, f"motor {instance}: the robot's motors are 1 (left) and 2 (right)")
    return FaultCfg(kind="motor_stall", robot=robot, at_s=at_s, wheel=WHEELS[instance])


class _Out:
    """pymavlink's file interface: the encoded packet, kept."""

    def __init__(self) -> None:
        self.data = b""

    def write(self, buf: bytes) -> None:
        self.data += bytes(buf)


class FailureInjector:
    """The world's side of MAV_CMD_INJECT_FAILURE: faults injected into ``hub``, answers sent with ``send(robot,
    bytes)`` (to the robot's ground station, from its system id ``system_ids[robot]``)."""

    def __init__(self, hub: Hub, send: Callable[[int, bytes], None], system_ids: dict[int, int]) -> None:
        self.hub, self.send = hub, send
        self.system_ids = system_ids
        self._decoder = mavlink2.MAVLink(None)
        self._encoders: dict[int, Any] = {}  # robot -> its answering encoder (its own packet sequence)
        self.started: dict[tuple[int, int], list[FaultCfg]] = {}  # (robot, unit) -> its faults started this way
        self.counts: Counter[str] = Counter()

    def take(self, t: int, r: int, data: bytes, kind: str) -> bool:
        """Whether the packet ``data`` for robot ``r`` (``kind``: its message type) is a failure injection, then
        handled here at quantum ``t``; any other packet is the face's."""
        if kind not in ("COMMAND_LONG", "COMMAND_INT"):
            return False
        try:
            m = self._decoder.decode(bytearray(data))
        except (mavlink2.MAVError, struct.error):  # (the face counts it as a bad packet)
            return False
        if m.command != M.MAV_CMD_INJECT_FAILURE or m.target_component not in (0, COMPONENT):
            return False
        self.handle(t, r, m)
        return True

    def handle(self, t: int, r: int, m: Any) -> None:
        """Carry out the failure injection ``m`` (COMMAND_LONG or COMMAND_INT) on robot ``r`` at quantum ``t``."""
        hub = self.hub
        at = t + hub.q_ns
        unit = m.param1
        try:
            f = failure_fault(m.param1, m.param2, m.param3, r, at / 1e9)
        except Refused as e:
            self._ack(r, m, e.result, e)
            return
        key = (r, int(unit))
        what = f"FAILURE_UNIT {int(unit)} FAILURE_TYPE {int(m.param2)} instance {int(m.param3)}"
        if f is not None:
            try:
                hub.inject_fault(f, t)
            except ValueError as e:
                self._ack(r, m, M.MAV_RESULT_DENIED, e)
                return
        ended = self.started.pop(key, [])
        refused: ValueError | None = None
        for g in ended:  # OK, or a new type for the unit: the faults it started before end now
            try:
                hub.end_fault(g, at)
            except ValueError as e:  # (a fault the world cannot end early)
                refused = e
        if f is None:
            if refused is not None:
                self._ack(r, m, M.MAV_RESULT_FAILED, refused)
                return
            hub.event(t, {"kind": "fault_cleared", "robot": r, "source": "mavlink",
                          "detail": f"{what}: {len(ended)} fault(s) end"})
        else:
            self.started[key] = [f]
            detail = json.dumps({**f.model_dump(exclude_defaults=True), "kind": f.kind, "mavlink": what})
            hub.event(t, {"kind": "fault_injected", "robot": r, "source": "mavlink", "detail": detail})
        self._ack(r, m, M.MAV_RESULT_ACCEPTED)

    def _ack(self, r: int, m: Any, result: int, why: Exception | None = None) -> None:
        """COMMAND_ACK from robot ``r``'s system id to the sender of ``m`` (a refusal's reason in a STATUSTEXT
        first, as a ground station shows it)."""
        enc = self._encoders.get(r)
        if enc is None:
            enc = self._encoders[r] = mavlink2.MAVLink(_Out(), srcSystem=self.system_ids[r], srcComponent=COMPONENT)
        if why is not None:
            enc.statustext_send(M.MAV_SEVERITY_WARNING, str(why)[:50].encode())
            self._flush(r, enc)
        enc.command_ack_send(M.MAV_CMD_INJECT_FAILURE, result, 0, 0, m.get_srcSystem(), m.get_srcComponent())
        self._flush(r, enc)
        self.counts[M.enums["MAV_RESULT"][result].name.removeprefix("MAV_RESULT_").lower()] += 1

    def _flush(self, r: int, enc: Any) -> None:
        """The packet ``enc`` just encoded, to robot ``r``'s ground station (one datagram, as the face sends)."""
        data, enc.file.data = enc.file.data, b""
        self.send(r, data)

    def stats(self) -> dict[str, int]:
        """The failure injections answered, by result (``accepted``, ``unsupported``, ``denied``)."""
        return dict(sorted(self.counts.items()))
