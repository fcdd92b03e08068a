"""The region controller's packets (version 2 of the SonPI's wire format): a robot's sonar window and the plan, their
round trips, their sizes against one datagram, and malformed ones refused naming why; version 1's packets unchanged."""

from __future__ import annotations

import math
import struct
from dataclasses import replace

import numpy as np
import pytest

from swarm_logic.families.roy.regions.formation import DELTA_TRI, desired_distances
from swarm_logic.families.roy.regions.planner import LAWS
from swarm_logic.robots.sonpi import pose_packet as pp

HEADER = struct.Struct("<2sBBIQ")


def test_the_wire_names_the_planner_contracts_laws_in_order() -> None:
    assert tuple(LAWS) == pp.LAWS


def test_a_sonar_window_round_trips_with_no_echo_and_no_reading_explicit() -> None:
    w = pp.SonarWindow(4, (0.25, math.inf, 1.5, None, 3.999))
    data = pp.encode_sonar(7, 12.25, w)
    assert len(data) == 16 + 3 + 5 * 2
    head, got = pp.decode(data)
    assert (head.type, head.seq, head.t_s) == (pp.SONAR, 7, 12.25)
    assert data[2] == 2  # a version 2 packet
    assert got == w
    assert struct.unpack_from("<5H", data, 19) == (250, 0xFFFF, 1500, 0xFFFE, 3999)
    assert pp.decode(pp.encode_sonar(0, 0.0, pp.SonarWindow(1, (math.nan,))))[1] == pp.SonarWindow(1, (None,))


@pytest.mark.parametrize("r", [-0.01, 70.0])
def test_a_range_that_cannot_be_sent_is_refused(r: float) -> None:
    with pytest.raises(ValueError, match="outside"):
        pp.encode_sonar(0, 0.0, pp.SonarWindow(1, (r,)))


def _plan(n: int, done: bool = False) -> pp.PlanPacket:
    agents = tuple(pp.PlanAgent(10 + i, i % 2 if i else None, i == 1, 1.5 * i, -0.25 * i) for i in range(n))
    desired = (np.ones((n, n)) - np.eye(n)) * 2.0
    params = {"desired": desired.tolist(), "k_c": 3.68, "k_f": 5.0, "safety": {"r_robot": 0.9, "k": 5.0}}
    return pp.PlanPacket(agents, "formation", params, 0.1, done)


def test_a_plan_round_trips_with_its_matrix_as_edges() -> None:
    plan = _plan(3, done=True)
    head, got = pp.decode(pp.encode_plan(3, 4.5, plan))
    assert (head.type, head.seq, head.t_s) == (pp.PLAN, 3, 4.5)
    assert isinstance(got, pp.PlanPacket)
    assert got.agents == plan.agents and got.law == "formation" and got.done
    assert got.unit_m == pytest.approx(0.1) and got.params["k_c"] == 3.68
    assert got.params["desired"] == plan.params["desired"]
    assert got.params["safety"] == {"r_robot": 0.9, "k": 5.0}
    # the triangle graph's 9 edges at rho = 2, symmetric: 9 entries of 6 bytes
    tri = desired_distances(DELTA_TRI, 2.0)
    six = pp.PlanPacket(
        _plan(6).agents,
        "formation",
        {"desired": tri.tolist(), "safety": None, "flag": True, "mode": "nearest", "w": [1.0, 2.5]},
        0.1,
    )
    data = pp.encode_plan(0, 0.0, six)
    got6 = pp.decode(data)[1]
    assert np.array_equal(np.array(got6.params["desired"]), tri)
    assert got6.params["safety"] is None and got6.params["flag"] is True and got6.params["w"] == [1.0, 2.5]
    assert got6.params["mode"] == "nearest"
    assert data.count(struct.pack("<f", 2.0)) >= 9
    # an asymmetric matrix keeps every non-zero entry
    asym = [[0, 1, 0], [0, 0, 2], [3, 0, 0]]
    got3 = pp.decode(pp.encode_plan(0, 0.0, pp.PlanPacket(_plan(3).agents, "formation", {"desired": asym}, 0.1)))[1]
    assert got3.params["desired"] == asym
    assert got3.face_rad is None and got.face_rad is None


def test_a_plan_carries_the_heading_to_face_exactly_and_refuses_one_that_is_not() -> None:
    plan = pp.PlanPacket(_plan(3).agents, "split_merge", {"k_c": 3.0}, 0.5, face_rad=-2.0943951023931953)
    data = pp.encode_plan(1, 2.0, plan)
    got = pp.decode(data)[1]
    assert got == plan and len(data) == len(pp.encode_plan(1, 2.0, replace(plan, face_rad=None))) + 8
    with pytest.raises(ValueError, match="face_rad: a heading must be finite"):
        pp.encode_plan(0, 0.0, replace(plan, face_rad=math.nan))


def test_fourteen_agents_fully_linked_fit_one_datagram_and_more_are_refused_naming_the_size() -> None:
    data = pp.encode_plan(0, 0.0, _plan(14))
    # header, flags/law/unit/count, 14 rows, the 4 parameters (name, type, value): 91 edges of 6 bytes
    assert len(data) == 16 + 7 + 14 * 12 + 1 + (1 + 7 + 1 + 3 + 91 * 6) + (1 + 3 + 9) * 2 + (1 + 6 + 1 + 1 + 17 + 11)
    assert len(data) < pp.MAX_DATAGRAM
    with pytest.raises(
        pp.PacketTooLarge,
        match=r"a plan of 24 agents \(276 matrix entries\): \d+ bytes, more than "
        r"one datagram \(1472 bytes\)",
    ):
        pp.encode_plan(0, 0.0, _plan(24))
    with pytest.raises(pp.PacketTooLarge, match="more than one datagram"):
        pp.encode_sonar(0, 0.0, pp.SonarWindow(1, (1.0,) * 200), limit=100)


@pytest.mark.parametrize(
    "params, why",
    [
        ({"x": math.inf}, "not finite"),
        ({"bad name": 1.0}, "ASCII identifier"),
        ({"x": object()}, "no wire encoding"),
        ({"x": [[1.0, 2.0]]}, "no wire encoding"),
    ],
)
def test_parameters_without_an_encoding_are_refused_naming_them(params: dict, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        pp.encode_plan(0, 0.0, pp.PlanPacket(_plan(3).agents, "formation", params, 0.1))


def test_a_law_or_group_the_wire_cannot_carry_is_refused() -> None:
    with pytest.raises(ValueError, match="law"):
        pp.encode_plan(0, 0.0, pp.PlanPacket((), "teleport", {}, 0.1))
    with pytest.raises(ValueError, match="group 300"):
        pp.encode_plan(0, 0.0, pp.PlanPacket((pp.PlanAgent(1, 300, False, 0, 0),), "formation", {}, 0.1))


def _v2(kind: int, body: bytes) -> bytes:
    return HEADER.pack(b"SP", 2, kind, 0, 0) + body


GOOD = pp.encode_plan(0, 0.0, _plan(3))


@pytest.mark.parametrize(
    "data, why",
    [
        (HEADER.pack(b"SP", 1, pp.SONAR, 0, 0) + b"\x01\x00\x00", "version 2 packet, got version 1"),
        (HEADER.pack(b"SP", 3, pp.SONAR, 0, 0), "speaks 1 to 2"),
        (HEADER.pack(b"SP", 2, pp.POSES, 0, 0) + b"\x00\x00", "version 1 packet"),
        (_v2(pp.SONAR, b"\x01\x00\x02" + b"\x00\x00"), "for 2 sonar ranges"),
        (_v2(pp.SONAR, b"\x01"), "without its id"),
        (GOOD[:-3], "cut short"),
        (GOOD + b"\x00", "after the plan's parameters"),
        (_v2(pp.PLAN, struct.pack("<BBfB", 4, 0, 0.1, 0) + b"\x00"), "flags"),
        (_v2(pp.PLAN, struct.pack("<BBfBd", 2, 0, 0.1, 0, math.inf) + b"\x00"), "not finite"),
        (_v2(pp.PLAN, struct.pack("<BBfB", 2, 0, 0.1, 0) + b"\x00"), "cut short"),
        (_v2(pp.PLAN, struct.pack("<BBfB", 0, 9, 0.1, 0) + b"\x00"), "unknown law"),
        (_v2(pp.PLAN, struct.pack("<BBfB", 0, 0, -1.0, 0) + b"\x00"), "not a length"),
        (
            _v2(pp.PLAN, struct.pack("<BBfB", 0, 0, 0.1, 1) + struct.pack("<HBB2f", 1, 0, 0, math.nan, 0) + b"\x00"),
            "not finite",
        ),
        (_v2(pp.PLAN, struct.pack("<BBfB", 0, 0, 0.1, 0) + b"\x01\x01x\x09"), "unknown parameter type"),
        (_v2(pp.PLAN, struct.pack("<BBfB", 0, 0, 0.1, 0) + b"\x01\x011\x00"), "not an identifier"),
        (
            _v2(
                pp.PLAN,
                struct.pack("<BBfB", 0, 0, 0.1, 1)
                + struct.pack("<HBB2f", 1, 0, 0, 0, 0)
                + b"\x01\x01d\x06"
                + struct.pack("<BH", 1, 1)
                + struct.pack("<BBf", 0, 3, 1.0),
            ),
            "outside the plan's 1 agents",
        ),
    ],
)
def test_malformed_region_packets_are_refused_naming_why(data: bytes, why: str) -> None:
    with pytest.raises(pp.PacketError, match=why):
        pp.decode(data)


def test_a_robots_window_naming_another_robot_is_malformed() -> None:
    data = pp.encode_sonar(0, 0.0, pp.SonarWindow(2, (1.0,)))
    assert pp.accept(data, pp.SonarWindow, 2)[0] == "ok"
    assert pp.accept(data, pp.SonarWindow, 3)[0] == "malformed"
    assert pp.accept(data, pp.Status, 2)[0] == "ignored"
