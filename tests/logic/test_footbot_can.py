"""The foot-bot's robot-side CAN driver: ``FastDecoder`` agrees with cantools on the whole DBC, and ``FootbotBoards``
over python-can's ``virtual`` interface, against the base and range-and-bearing boards' firmware in the world, serves
the PFSM controllers' faces what the robot senses and carries their commands to the boards."""

from __future__ import annotations

import itertools
import math
from typing import Any

import can
import numpy as np
import pytest

from bridge.core.config import Config
from bridge.core.plan import make_plan
from bridge.core.world import World
from bridge.robots.footbot.base import BASE_PINS, BaseBoard
from firmware_sim.robots.footbot.rab_board import RabBoard
from swarm_logic.clock import SteppedClock
from swarm_logic.families.pfsm import messages as msg
from swarm_logic.families.pfsm.searcher import PfsmSearcher
from swarm_logic.robot import Robot
from swarm_logic.robots.footbot import footbot_db
from swarm_logic.robots.footbot.can_boards import FastDecoder, FootbotBoards
from swarm_logic.robots.footbot.interfaces import (
    LIGHT,
    MOTOR_GROUND,
    PROXIMITY,
    RANGE_AND_BEARING,
    RabPacket,
    ring_angles,
)

DB = footbot_db()
_channels = itertools.count()


# -- FastDecoder ------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", [m.name for m in DB.messages])
def test_fast_decoder_agrees_with_cantools_on_random_frames(name: str) -> None:
    m = DB.get_message_by_name(name)
    dec = FastDecoder(DB)
    rng = np.random.default_rng(m.frame_id)
    frames = [bytes(m.length), b"\xff" * m.length, *(rng.bytes(m.length) for _ in range(300))]
    for data in frames:
        got = dec.decode(m.frame_id, data)
        assert got is not None and got[0] == name
        want = m.decode(data, decode_choices=False, scaling=True)
        assert got[1].keys() == want.keys()
        for k, v in want.items():
            assert got[1][k] == pytest.approx(float(v), abs=1e-9), (k, data.hex())


def test_fast_decoder_refuses_wrong_lengths_and_unknown_ids() -> None:
    dec = FastDecoder(DB)
    wheels = DB.get_message_by_name("WHEELS_CMD")
    assert dec.decode(wheels.frame_id, bytes(wheels.length + 1)) is None
    assert dec.decode(wheels.frame_id, bytes(wheels.length - 1)) is None
    assert dec.decode(0x7FF, bytes(8)) is None


# -- the driver against the boards -----------------------------------------------------------------------------------


class Robots:
    """Foot-bots in the world: robot 0 with its base board and range-and-bearing board on a python-can ``virtual``
    bus whose other end is ``host`` (a ``FootbotBoards``); the others only a range-and-bearing board emitting
    ``payloads``. The air between the boards is the world's ``range_and_bearing`` model, delivered at the next
    quantum as the ``rab`` medium does."""

    def __init__(self, poses: list[list[float]], payloads: dict[int, bytes], **cfg: Any) -> None:
        c = Config.model_validate({"session": {"seed": 2}, **cfg, "robots": [
            {"profile": "footbot", "count": len(poses), "placement": {"kind": "explicit", "poses": poses}}]})
        plan = make_plan(c)
        self.world = World(c, plan.robots)
        self.links = self.world.model("range_and_bearing")
        self.base = BaseBoard(self.world.profiles[0], plan.robots[0])
        self.rab = {r: RabBoard(period_ms=100, phase_ms=17 * r) for r in range(len(poses))}
        self.q, self.t, self.wake = c.session.quantum_ns, 0, 0
        self.pins: dict | None = None
        self.air: dict[int, list[dict]] = {r: [] for r in self.rab}
        self.emitted: dict[int, list[bytes]] = {r: [] for r in self.rab}
        self.heard: dict[int, list[dict]] = {r: [] for r in self.rab}
        for r, data in payloads.items():
            ids = {m.name: m.frame_id for m in DB.messages}
            self.rab[r].step(0, [(ids["RAB_DATA_0"], bytes([len(data)]) + data[:7] + bytes(max(0, 7 - len(data))))],
                             [])
        channel = f"footbot-test-{next(_channels)}"
        self.fw_bus = can.Bus(interface="virtual", channel=channel)
        self.clock = SteppedClock()
        self.host = FootbotBoards(can.Bus(interface="virtual", channel=channel), self.clock)

    def close(self) -> None:
        self.host.close()
        self.fw_bus.shutdown()
        self.world.close()

    def step(self) -> None:
        frames = []
        while (m := self.fw_bus.recv(0.0)) is not None:
            frames.append((m.arbitration_id, bytes(m.data)))
        out: list[tuple[int, bytes]] = []
        air, self.air = self.air, {r: [] for r in self.rab}
        for r, board in self.rab.items():
            res = board.step(self.t, frames if r == 0 else [], air[r])
            self.heard[r] += air[r]
            if r == 0:
                out += res.can
            for a in res.air:
                self.emitted[r].append(a["data"])
                for d, rng, b in self.links.receivers(r)[0]:
                    self.air[d].append({"src": r, "range_m": rng, "bearing_rad": b, "data": a["data"]})
        if self.pins is not None:
            BASE_PINS.actuate(self.world, 0, self.pins)
            self.pins = None
        if self.wake <= self.t:
            sens, _ = BASE_PINS.sense(self.world, 0, {}, False)
            res = self.base.run(self.t, {"in": [["can0", i, d, False, self.t] for i, d in frames], "sens": sens})
            out += [(f[1], f[2]) for f in res["out"]]
            self.wake, self.pins = res["wake"], res.get("pins")
        for arb_id, data in out:
            self.fw_bus.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        self.world.step_quantum(self.t, self.q)
        self.t += self.q
        self.clock.t = self.t / 1e9

    def run_for(self, seconds: float, every_s: float = 0.1, control: Any = None) -> None:
        """Steps the world; every ``every_s`` the host polls its bus and runs ``control`` (a control step)."""
        end, k = self.t + round(seconds * 1e9), round(every_s * 1e9)
        while self.t < end:
            self.step()
            if self.t % k == 0:
                self.host.poll()
                if control is not None:
                    control()


TARGET = msg.encode(msg.Payload(msg.TARGET, 0, False, 1))
# robot 0 faces the west wall (its inner face at x = 0) 3 cm off, on the grey base, the light east of it; robot 1 a
# target out on the floor, behind it to its right
POSES = [[0.085 + 0.03, 2.0, 180.0], [1.0, 1.2, 0.0]]
ARENA = {"arena": {"width_m": 4, "length_m": 4, "floor": [{"x_min": 0, "y_min": 0, "x_max": 0.5, "y_max": 4,
                                                           "grey": 0.5}]},
         "light": {"ambient_lux": 0.0, "sources": [{"x": 3.0, "y": 2.0, "peak_lux": 1000.0, "sigma_m": 5.0}]}}


@pytest.fixture
def robots() -> Any:
    r = Robots(POSES, {1: TARGET}, **ARENA)
    yield r
    r.close()


def test_the_faces_read_what_the_boards_sense(robots: Robots) -> None:
    robots.run_for(0.5)
    faces = robots.host.faces()
    sensed = robots.world.model("footbot_sensors")
    prox = [r.value for r in faces[PROXIMITY].readings()]
    assert [r.angle_rad for r in faces[PROXIMITY].readings()] == list(ring_angles(24))
    assert prox == pytest.approx(sensed.proximity[0], abs=1 / 255 + 1e-9)  # 8 bits on the bus
    assert prox[0] > 0.3 and prox[12] == 0.0  # the wall ahead, nothing behind
    light = [r.value for r in faces[LIGHT].readings()]
    assert light == pytest.approx(sensed.light[0], abs=1 / 255 + 1e-9)
    assert int(np.argmax(light)) == 12  # the light is behind it
    assert [g.value for g in faces[MOTOR_GROUND].readings()] == pytest.approx([0.5] * 4, abs=1 / 255)
    (p,) = faces[RANGE_AND_BEARING].readings()
    assert isinstance(p, RabPacket) and p.data == TARGET
    true = math.hypot(1.0 - POSES[0][0], 1.2 - 2.0)
    bearing = math.remainder(math.atan2(1.2 - 2.0, 1.0 - POSES[0][0]) - math.pi, math.tau)
    assert p.range_m == pytest.approx(true, abs=0.006)
    assert math.remainder(p.bearing_rad - bearing, math.tau) == pytest.approx(0.0, abs=math.radians(0.36))
    assert robots.host.counters["bad_frames"] == 0 and robots.host.counters["scans"] >= 4


def test_the_wheels_face_drives_the_robot_and_the_rab_face_sets_the_payload(robots: Robots) -> None:
    faces = robots.host.faces()
    faces["differential_steering"].set_speeds(-0.1, -0.1)  # back off the wall (east)
    faces[RANGE_AND_BEARING].send(b"0123456789")
    x0 = float(robots.world.pos[0, 0])
    robots.run_for(2.0, control=lambda: faces["differential_steering"].set_speeds(-0.1, -0.1))
    assert float(robots.world.pos[0, 0]) - x0 == pytest.approx(0.2, rel=0.1)
    assert robots.emitted[0][-1] == b"0123456789"
    assert robots.heard[1][-1]["data"] == b"0123456789"


def test_the_watchdog_holds_while_the_driver_repeats_the_same_speeds(robots: Robots) -> None:
    faces = robots.host.faces()
    faces["differential_steering"].set_speeds(-0.1, -0.1)
    robots.run_for(2.0, control=lambda: faces["differential_steering"].set_speeds(-0.1, -0.1))
    assert not robots.base.fw.watchdog_tripped and robots.base.fw.target_pps[0] < 0


def test_the_pfsm_searchers_faces_get_readings(robots: Robots) -> None:
    faces = robots.host.faces()
    robot = Robot(0, robots.clock, None, np.random.Generator(np.random.PCG64(1)), {}, devices=faces)
    c = PfsmSearcher()
    c.init(robot)
    assert c.rab is faces[RANGE_AND_BEARING] and c.proximity is faces[PROXIMITY]
    seen: list[Any] = []

    def control() -> None:
        c.step()
        seen.append((c.rab.readings(), c.in_base(), c.avoidance(), c.to_light()))

    robots.run_for(1.0, every_s=c.period_s, control=control)
    assert seen
    heard = [r for readings, *_ in seen for r in readings]
    assert heard and all(msg.decode(r.data) == msg.decode(TARGET) for r in heard)  # the target's payload
    assert seen[-1][1]  # on the grey base
    assert any(a is not None for _, _, a, _ in seen)  # the wall ahead makes it avoid
    lx, _ly = next(v for *_, v in seen if v != (0.0, 0.0))  # the first step with a light sample on the bus
    assert lx < 0  # the light is behind it
    assert robots.heard[1] and msg.decode(robots.heard[1][-1]["data"]).kind == msg.SEARCHER  # the target hears it
