"""The world (``bridge.core.hub.Hub``) decoding what reaches it from outside, in a session with two robots of every
kind, a service and a MAVLink endpoint, so every medium is reached:

- ``hub_reply``: a participant's zenoh message: a process's reply to its tick (``done/<proc>``: msgpack, each
  entity's outputs routed to the media that carry them: CAN frames, the 2.4 GHz radio, serial lines, UWB ranging
  and data, I2C (a master's transactions, a slave's answers), the foot-bots' range and bearing, Wi-Fi, MAVLink from a
  service, logs, a service's faults and stop) or a launcher's control message. An input is a selector byte (which
  process replied; 0xF0 and above: the launcher's ``control`` key) then the payload, exactly as the bytes arrive.
- ``mavlink_world``: a ground station's datagrams at the world's MAVLink endpoint (``bridge.hil.mavlink_link``):
  routed by system id to the robots' faces, a MAV_CMD_INJECT_FAILURE taken by the world (``mavlink_failures``) and
  carried out as an injected fault. An input is records as ``fuzz.targets.mavlink`` reads them.

The world is built once per fuzzing process (building one takes 0.1 s) and rebuilt every ``REBUILD`` inputs, so what
a session accumulates (its recording, the media's queues) stays bounded; between inputs the robots and services a
malformed input failed are revived, so every input meets a live session. (An input's effect may therefore depend on
the inputs before it since the last rebuild; ``tests/fuzz`` replays each target's corpus in one process, in order.)
"""

from __future__ import annotations

import atexit
import math
import queue
import shutil
import tempfile
from typing import Any

from bridge.core import transport
from bridge.core.config import Config
from bridge.core.entities import entity
from bridge.core.hub import Hub
from bridge.core.plan import make_plan
from fuzz.harness import Cursor, Target
from fuzz.targets.mavlink import datagrams, mavlink, packet, record, seed_messages

REBUILD = 500
QUANTA_AFTER = 4  # quanta run after each reply, so what it scheduled is delivered

CONFIG = {
    "robots": [
        {"count": 2, "xbee": {"series": 2}, "uwb": True},
        {"count": 2, "profile": "footbot", "behaviour": "pfsm_searcher"},
        {"count": 2, "profile": "decizebro"},
        {"count": 2, "profile": "sonpi"},
    ],
    "services": [{"kind": "global_controller", "name": "ctl"}],
    "mavlink": {"endpoint": "udpin:127.0.0.1:0"},  # one UDP socket on the loopback, any port
    "session": {"hang_timeout_s": 5.0},
}


class _World:
    """The hub the inputs meet, how many it met, and its clock."""

    def __init__(self) -> None:
        self.dir = tempfile.mkdtemp(prefix="swarm-sitl-fuzz-hub-")
        cfg = Config.model_validate(CONFIG)
        self.hub = Hub(make_plan(cfg), self.dir, self.dir, "fuzz")
        self.inputs = 0
        self.t = 0

    def close(self) -> None:
        try:
            self.hub.close()
        finally:
            shutil.rmtree(self.dir, ignore_errors=True)


_WORLD: _World | None = None


@atexit.register
def _close_world() -> None:
    """The last world's recording and temporary directory go with the process (a test run replaying the corpus)."""
    global _WORLD
    if _WORLD is not None:
        _WORLD.close()
        _WORLD = None


def _world() -> _World:
    global _WORLD
    if _WORLD is not None and _WORLD.inputs >= REBUILD:
        _WORLD.close()
        _WORLD = None
    if _WORLD is None:
        _WORLD = _World()
    return _WORLD


def _revive(h: Hub) -> None:
    """Undo what failing a robot or a service did to the hub's books, so the next input meets them alive."""
    h.dead.clear()
    h.dead_services.clear()
    h.world.alive[:] = True
    h.failures.clear()
    h.stop_reason = None
    h.failed_stop = False
    h.live_procs = set(h.procs)
    h._dead_detail.clear()
    for e in h.ents:
        h.inbox[e].clear()
    while True:
        try:
            h.q.get_nowait()
        except queue.Empty:
            break


def _quantum(h: Hub, t: int) -> None:
    h._deliver(t)
    for m in h._media:
        m.start_quantum(t)


def _begin() -> tuple[Hub, int]:
    """The hub for the next input, revived, at the start of its quantum: (hub, t)."""
    w = _world()
    w.inputs += 1
    h = w.hub
    _revive(h)
    t = w.t
    w.t += (QUANTA_AFTER + 1) * h.q_ns
    _quantum(h, t)
    return h, t


def _end(h: Hub, t: int) -> None:
    """The rest of the input's quantum, and the quanta that deliver what it scheduled."""
    h._apply_deaths(t)
    for m in h._media:
        m.advance(t)
    for k in range(1, QUANTA_AFTER + 1):
        _quantum(h, t + k * h.q_ns)
        for m in h._media:
            m.advance(t + k * h.q_ns)


def _run(data: bytes) -> None:
    h, t = _begin()
    sel, payload = (data[0], data[1:]) if data else (0, b"")
    if sel >= 0xF0:
        h._control(payload, t)
    else:
        procs = sorted(h.procs)
        p = procs[sel % len(procs)]
        h.q.put((f"done/{p}", payload))
        h.q.put((f"done/{p}", transport.pack({"k": h.k, "ents": {}})))  # ends the wait if the reply was unusable
        results = h._collect({p}, t)
        due = {p: list(h.procs[p].entities(h.plan.robots))}
        h._outputs(t, results, {}, due)
    _end(h, t)


def _mavlink(data: bytes) -> None:
    h, t = _begin()
    link = h.medium("mavlink")
    for datagram in datagrams(Cursor(data)):
        link._to_faces(t, link.gateway.route(link.gateway.parser(), datagram))
    _end(h, t)


# -- seeds: one good reply per process, every item its entities send ---------------------------------------------------
Q = 10_000_000


def _items(e: str) -> list[list[Any]]:
    """What entity ``e`` sends, by role."""
    r = int(e[1:4]) if e.startswith("r") else -1
    role = e.split("/", 1)[1]
    frame = {"handle": 1, "src64": 100 + r, "src16": 0xFFFE, "dst": "bcast", "dst_addr": 0xFFFF, "pan_id": 0x3332,
             "channel": 12, "ack": False, "mac_retries": 0, "psdu_len": 40, "seq": 1, "payload": b"hello", "opts": 0}
    node = {"channel": 12, "pan_id": 0x3332, "addr64": 100 + r, "addr16": 0xFFFE, "tx_power_dbm": 3.0,
            "sensitivity_dbm": -96.0, "series": 2}
    by_role: dict[str, list[list[Any]]] = {
        "llc": [["can0", 0x181, bytes(8), False], ["can0", 0x100, b"\x01\x02\x03\x04\x05", False, True]],
        "xbee": [["node", node], ["air", frame], ["rssi_pwm", 0.5], ["uart", b"\x7e\x00\x02\x8a\x00\x75"]],
        "uwb": [["uwb", {"op": "range", "peer": 1 - r % 2, "t_ns": 2 * Q}], ["uart", b"\x40\x01\x00"]],
        "logic": [["uart", "xbee", b"\x7e\x00\x04\x08\x01NI\x5f", 9600], ["baud", "xbee", 115200],
                  ["uart", "uwb", b"\x0c\x00", 115200], ["log", "fuzz", {"a": 1, "b": [1.5, "x"]}],
                  ["i2c", 1, [[0x10, False, b"\x12\x00"], [0x10, True, 4]], 100_000],
                  ["wifi", "ctl", b"SP\x01\x02" + bytes(12)], ["can0", 0x100, bytes(5), False]],
        "rab": [["rab", {"op": "tx", "data": b"hi"}], ["can0", 0x1C2, bytes(4), False]],
        "uwb_radio": [["uwb_radio", {"op": "tx", "t_ns": 2 * Q, "kind": "beacon", "heading_cdeg": 9000}],
                      ["uwb_radio", {"op": "tx", "t_ns": 2 * Q, "kind": "data", "seq": 1, "data": b"x"}],
                      ["uart", b"\xa5\x01\x81\x00\x00"]],
        "imu": [["uart", b"\xbb\x01\xa0"]],
        "utility": [["uart", b"\xa5\x01\x90\x00\x00"]],
        "arduino": [["i2c_attach", 0x20, False, True], ["i2c", 1, [b"\x53\x01"]]],
        "service": [["log", "plain", {"a": 1}], ["wifi", None, b"SP\x01\x01" + bytes(12)],
                    ["mavlink", packet(mavlink.MAVLINK_MSG_ID_COMMAND_LONG, bytes(33), 255, 190)],
                    ["fault", {"kind": "battery_depleted", "robot": 1, "at_s": 10.0}], ["stop", "enough"]],
    }
    if role.startswith("leg"):
        return [["i2c_attach", 0x10 + int(role[3:]), True], ["i2c", 1, [b"\x00\x01"]]]
    return by_role.get(role, [["log", "x", {}]])


def _seeds() -> list[bytes]:
    cfg = Config.model_validate(CONFIG)
    plan = make_plan(cfg)
    procs = sorted(p.name for p in plan.procs)
    out = []
    for i, name in enumerate(procs):
        proc = next(p for p in plan.procs if p.name == name)
        ents = {}
        for e in proc.entities(plan.robots):
            role = "service" if e.startswith("svc/") else e.split("/", 1)[1]
            ents[e] = {"out": _items(e if role != "service" else "r000/service"), "wake": 5 * Q, "wom": ["uart"],
                       "err": None}
            if role == "llc":
                ents[e]["pins"] = {"pwm": [100, -100], "led": [1, 2, 3]}
        out.append(bytes((i,)) + transport.pack({"k": 0, "ents": ents}))
    bad = {entity(0, "llc"): {"out": None}, entity(1, "llc"): {"out": [], "wake": 1.5}}
    out.append(bytes((procs.index("fw0"),)) + transport.pack({"k": 0, "ents": bad}))
    out.append(bytes((0xF0,)) + transport.pack({"op": "dead", "proc": "fw1", "detail": "exit code -9"}))
    out.append(bytes((0xF1,)) + transport.pack({"op": "stop", "reason": "fuzz"}))
    return out


def _mavlink_seeds() -> list[bytes]:
    m = mavlink
    inject = m.MAVLink_command_long_message
    units = ((m.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR, m.FAILURE_TYPE_OFF, 0), (m.FAILURE_UNIT_SENSOR_GPS, 3, 0),
             (m.FAILURE_UNIT_SYSTEM_MOTOR, m.FAILURE_TYPE_STUCK, 1), (m.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR, 4, 0),
             (m.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR, m.FAILURE_TYPE_OK, 0), (m.FAILURE_UNIT_SYSTEM_MOTOR, 1, 3),
             (m.FAILURE_UNIT_SENSOR_GYRO, 1, 0), (m.FAILURE_UNIT_SENSOR_GPS, m.FAILURE_TYPE_SLOW, 0))
    out = []
    for target in (1, 0, 6):
        msgs = [inject(target, 1, m.MAV_CMD_INJECT_FAILURE, 0, u, ft, i, 0, 0, 0, 0) for u, ft, i in units]
        msgs.append(m.MAVLink_command_int_message(target, 0, 0, m.MAV_CMD_INJECT_FAILURE, 0, 0, 101, 1, 2, 0, 0, 0, 0))
        msgs.append(inject(target, 1, m.MAV_CMD_INJECT_FAILURE, 0, 7.5, math.nan, math.inf, 0, 0, 0, 0))
        out.append(b"".join(record(x) for x in msgs))
    out.append(b"".join(record(x) for x in seed_messages()))
    return out


TARGETS = [
    Target("hub_reply", "the world's hub: a participant's zenoh reply (msgpack) or control message, routed to every "
                        "medium", _run, _seeds),
    Target("mavlink_world", "the world's MAVLink endpoint: a ground station's datagrams to the faces, and "
                            "MAV_CMD_INJECT_FAILURE carried out as a fault", _mavlink, _mavlink_seeds),
]
