"""A ground station's MAV_CMD_INJECT_FAILURE, handled by the world (bridge.hil.mavlink_failures): each mapped unit and
type becomes the fault it stands for, from the next quantum; FAILURE_TYPE_OK ends the unit's faults started this
way and a new type replaces the old; unmapped units and types answer UNSUPPORTED, a fault the robot cannot carry
DENIED (each refusal with a STATUSTEXT saying why), always by one COMMAND_ACK from the robot's system id. In a
session, through the swarm's MAVLink endpoint: the face never sees the command, the fault and its event appear,
and FAILURE_TYPE_OK ends it."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from bridge.core.config import FaultCfg
from bridge.hil.mavlink_failures import GARBAGE_SIGMA_M, WRONG_BIAS_M, FailureInjector, Refused, failure_fault

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mav

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "hil_configs" / "demo.toml"
Q = 10_000_000
DIST, GPS, MOTOR = mav.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR, mav.FAILURE_UNIT_SENSOR_GPS, mav.FAILURE_UNIT_SYSTEM_MOTOR
OK, OFF, STUCK, GARBAGE, WRONG = (mav.FAILURE_TYPE_OK, mav.FAILURE_TYPE_OFF, mav.FAILURE_TYPE_STUCK,
                                  mav.FAILURE_TYPE_GARBAGE, mav.FAILURE_TYPE_WRONG)


@pytest.mark.parametrize(("unit", "ftype", "instance", "fields"), [
    (DIST, OFF, 0, {"kind": "sensor", "sensor": "sonar", "mode": "dead"}),
    (DIST, STUCK, 1, {"kind": "sensor", "sensor": "sonar", "mode": "stuck"}),
    (DIST, GARBAGE, 0, {"kind": "sensor", "sensor": "sonar", "mode": "noisy", "sigma": GARBAGE_SIGMA_M["sonar"]}),
    (GPS, WRONG, 0, {"kind": "sensor", "sensor": "uwb", "mode": "bias", "bias": WRONG_BIAS_M["uwb"]}),
    (GPS, OFF, 0, {"kind": "sensor", "sensor": "uwb", "mode": "dead"}),
    (MOTOR, OFF, 0, {"kind": "motor_stall", "wheel": "both"}),
    (MOTOR, OFF, 1, {"kind": "motor_stall", "wheel": "left"}),
    (MOTOR, STUCK, 2, {"kind": "motor_stall", "wheel": "right"}),
])
def test_each_mapped_failure_is_its_fault(unit: int, ftype: int, instance: int, fields: dict[str, Any]) -> None:
    f = failure_fault(float(unit), float(ftype), float(instance), 3, 1.25)
    assert f == FaultCfg(robot=3, at_s=1.25, **fields)
    assert failure_fault(float(unit), float(OK), 0.0, 3, 1.25) is None


@pytest.mark.parametrize(("unit", "ftype", "instance", "result"), [
    (mav.FAILURE_UNIT_SENSOR_GYRO, OFF, 0, mav.MAV_RESULT_UNSUPPORTED),
    (mav.FAILURE_UNIT_SYSTEM_BATTERY, OK, 0, mav.MAV_RESULT_UNSUPPORTED),
    (DIST, mav.FAILURE_TYPE_SLOW, 0, mav.MAV_RESULT_UNSUPPORTED),
    (MOTOR, GARBAGE, 1, mav.MAV_RESULT_UNSUPPORTED),
    (MOTOR, OFF, 3, mav.MAV_RESULT_DENIED),  # no third motor
    (DIST, 1.5, 0, mav.MAV_RESULT_DENIED),
    (float("nan"), OFF, 0, mav.MAV_RESULT_DENIED),
])
def test_unmapped_failures_are_refused(unit: float, ftype: float, instance: float, result: int) -> None:
    with pytest.raises(Refused) as e:
        failure_fault(unit, ftype, instance, 0, 1.0)
    assert e.value.result == result


class FakeHub:
    """What the injector asks of the world: inject (ValueError for a robot without UWB), end, events."""

    q_ns = Q

    def __init__(self) -> None:
        self.injected: list[tuple[FaultCfg, int]] = []
        self.ended: list[tuple[FaultCfg, int]] = []
        self.events: list[dict[str, Any]] = []

    def inject_fault(self, f: FaultCfg, t: int) -> None:
        if f.sensor == "uwb" and f.robot == 1:
            raise ValueError("sensor: robot 1 has no UWB module")
        self.injected.append((f, t))

    def end_fault(self, f: FaultCfg, t: int) -> None:
        if f.kind == "motor_stall":
            raise ValueError("a motor_stall fault cannot be ended early")
        self.ended.append((f, t))

    def event(self, t: int, payload: dict[str, Any]) -> None:
        self.events.append(payload)


def command(unit: int, ftype: float, instance: int = 0, target: int = 1, component: int = 1) -> Any:
    """A ground station's COMMAND_LONG, as the world decodes it."""
    gcs = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    msg = gcs.command_long_encode(target, component, mav.MAV_CMD_INJECT_FAILURE, 0, unit, ftype, instance, 0, 0, 0, 0)
    return msg.pack(gcs), msg


def answers(sent: list[tuple[int, bytes]]) -> list[tuple[int, int, str, Any]]:
    """What the world sent each robot's ground station: (robot, source system, type, message)."""
    out = []
    for r, data in sent:
        parser = mav.MAVLink(None)
        for m in parser.parse_buffer(data) or ():
            out.append((r, m.get_srcSystem(), m.get_type(), m))
    return out


def test_the_injector_injects_answers_replaces_and_ends() -> None:
    hub, sent = FakeHub(), []
    inj = FailureInjector(hub, lambda r, data: sent.append((r, data)), {0: 1, 1: 2})  # type: ignore[arg-type]
    raw, _ = command(DIST, OFF)
    assert inj.take(5 * Q, 0, raw, "COMMAND_LONG") and not inj.take(5 * Q, 0, raw, "HEARTBEAT")
    other = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    arm = other.command_long_encode(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(other)
    assert not inj.take(5 * Q, 0, arm, "COMMAND_LONG")  # the face's
    assert not inj.take(5 * Q, 0, command(DIST, OFF, component=2)[0], "COMMAND_LONG")  # another component's
    (f, t), = hub.injected
    assert (f.kind, f.sensor, f.mode, f.robot, f.at_s, t) == ("sensor", "sonar", "dead", 0, 0.06, 5 * Q)
    assert hub.events[0]["kind"] == "fault_injected" and hub.events[0]["source"] == "mavlink"
    assert json.loads(hub.events[0]["detail"])["mode"] == "dead"
    inj.handle(6 * Q, 0, command(DIST, GARBAGE)[1])  # a new type for the unit replaces the old
    assert hub.ended == [(f, 7 * Q)] and hub.injected[-1][0].mode == "noisy"
    inj.handle(8 * Q, 0, command(DIST, OK)[1])
    assert hub.ended[-1] == (hub.injected[-1][0], 9 * Q) and hub.events[-1]["kind"] == "fault_cleared"
    inj.handle(8 * Q, 0, command(DIST, OK)[1])  # nothing left to end: accepted all the same
    inj.handle(8 * Q, 1, command(GPS, OFF, target=2)[1])  # robot 1 has no UWB module
    inj.handle(8 * Q, 1, command(mav.FAILURE_UNIT_SENSOR_MAG, OFF, target=2)[1])
    inj.handle(8 * Q, 1, command(MOTOR, OFF, target=2)[1])
    inj.handle(9 * Q, 1, command(MOTOR, OK, target=2)[1])  # the world could not end it
    got = [(r, src, kind, getattr(m, "result", None)) for r, src, kind, m in answers(sent)]
    accepted, denied, unsupported = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED, mav.MAV_RESULT_UNSUPPORTED
    assert got == [(0, 1, "COMMAND_ACK", accepted)] * 4 + [
        (1, 2, "STATUSTEXT", None), (1, 2, "COMMAND_ACK", denied), (1, 2, "STATUSTEXT", None),
        (1, 2, "COMMAND_ACK", unsupported), (1, 2, "COMMAND_ACK", accepted), (1, 2, "STATUSTEXT", None),
        (1, 2, "COMMAND_ACK", mav.MAV_RESULT_FAILED)]
    ack = answers(sent)[0][3]
    assert (ack.command, ack.target_system, ack.target_component) == (mav.MAV_CMD_INJECT_FAILURE, 255, 190)
    assert "no UWB module" in answers(sent)[4][3].text and len(hub.ended) == 2
    assert inj.stats() == {"accepted": 5, "denied": 1, "failed": 1, "unsupported": 1}


@pytest.mark.session
def test_a_ground_station_injects_failures_into_a_session(tmp_path: Path) -> None:
    from bridge.testing import SwarmSession

    over = {"robots.count": 2, "session.robots_per_process": 2, "robots.0.uwb": True}
    with SwarmSession(DEMO, over, tmp_path, mavlink=True) as s:
        s.run_for(0.5)
        g = s.mavlink
        for unit, ftype in ((DIST, OFF), (mav.FAILURE_UNIT_SENSOR_GYRO, OFF), (GPS, WRONG), (DIST, OK), (GPS, OK)):
            g.mav.command_long_send(g.system_id(0), 1, mav.MAV_CMD_INJECT_FAILURE, 0, unit, ftype, 0, 0, 0, 0, 0)
            n = len(g.messages("COMMAND_ACK", 0))
            s.run_until(lambda s, n=n: len(g.messages("COMMAND_ACK", 0)) > n, timeout_s=1.0)
        s.run_for(0.5)
        acks = [(m.command, m.result) for m in g.messages("COMMAND_ACK", 0)]
        events = [e.values for e in s.events()]
        summary = s.stop()
    inject = mav.MAV_CMD_INJECT_FAILURE
    # one answer each, from the world (the face, which knows no such command, never saw it)
    assert acks == [(inject, mav.MAV_RESULT_ACCEPTED), (inject, mav.MAV_RESULT_UNSUPPORTED)] + [
        (inject, mav.MAV_RESULT_ACCEPTED)] * 3
    injected = [json.loads(e["detail"]) for e in events if e["kind"] == "fault_injected"]
    assert all(e["source"] == "mavlink" for e in events if e["kind"] == "fault_injected")
    assert [(x["sensor"], x["mode"]) for x in injected] == [("sonar", "dead"), ("uwb", "bias")]
    started = [e["detail"] for e in events if e["kind"] == "sensor" and e["robot"] == 0]
    assert started == ["its sonar goes dead", f"its uwb goes bias (bias {WRONG_BIAS_M['uwb']:+g})"]
    # FAILURE_TYPE_OK ended both, each with its end event
    assert [e["kind"] for e in events if e["kind"] in ("fault_cleared", "sensor_end")] == [
        "fault_cleared", "sensor_end", "fault_cleared", "sensor_end"]
    assert summary["mavlink"]["inject_failure"] == {"accepted": 4, "unsupported": 1}
    uwb, = summary["radio"]["uwb_faults"]["sensors"]
    sonar, = (x for x in summary["faults"]["list"] if x["kind"] == "sensor")
    assert uwb["robot"] == 0 and uwb["until_s"] is not None and sonar["until_s"] is not None
