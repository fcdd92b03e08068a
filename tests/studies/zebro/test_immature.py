"""The immature gossip (thesis Algorithms 4-6): Z-U5 (a robot h hops from the best contender adopts it after h
communication cycles, never earlier, with one hop per tick), the better value winning, STOP as a one-tick pause
(A-8) and the timeout reset (A-9) that lets a rumour die."""

from __future__ import annotations

import pytest

from swarm_logic.families.zebro.immature import ZebroImmature

from .helpers import line, swarm


def adoption_ticks(s, leader: int) -> dict[int, int]:
    out: dict[int, int] = {}
    for r in s.topic("zebro_leader"):
        if r["leader"] == leader:
            out.setdefault(r["robot"], r["tick"])
    return out


def test_a_robot_h_hops_away_adopts_the_leader_after_h_cycles() -> None:
    """Z-U5, one hop per tick: the contender (robot 0) leads itself in tick 1; robot h adopts it in tick h + 1."""
    n = 7
    s = swarm(ZebroImmature, line(n, {0: 95}), frozen=True, delivery="next_tick")
    for _ in range(n + 2):
        s.tick()
    got = adoption_ticks(s, 0)
    assert got == {h: h + 1 for h in range(n)}
    assert all(c.my_leader == 0 and c.max_utility == 95 for c in s.ctls)


def test_delivery_within_the_tick_can_be_faster_but_never_beats_the_hops() -> None:
    n = 7
    s = swarm(ZebroImmature, line(n, {0: 95}), frozen=True)
    for _ in range(n + 2):
        s.tick()
    got = adoption_ticks(s, 0)
    assert set(got) == set(range(n)) and all(got[h] >= 1 for h in got)
    assert all(got[h] <= h + 1 for h in got)


def test_the_better_utility_wins_everywhere() -> None:
    s = swarm(ZebroImmature, line(8, {0: 95, 7: 15}), frozen=True, delivery="next_tick")
    for _ in range(15):
        s.tick()
    assert all(c.my_leader == 0 for c in s.ctls)


@pytest.mark.parametrize(("mode", "halted"), [("pause", True), ("ignore", False)])
def test_stop_pauses_one_tick(mode: str, halted: bool) -> None:
    """A-8: STOP (m0) halts a neighbour for its next step only (pause), or not at all (ignore)."""
    sc = line(2, {0: 60}, r=5.0)
    s = swarm(ZebroImmature, sc, params={"stop_mode": mode}, delivery="next_tick")
    s.tick()
    y = s.world.y[1]
    s.tick()  # robot 1 reads STOP in this step
    assert (s.world.y[1] == y) is halted
    y = s.world.y[1]
    s.tick()
    assert s.world.y[1] != y


def test_a_latched_stop_never_resumes() -> None:
    s = swarm(ZebroImmature, line(2, {0: 60}, r=5.0), params={"stop_mode": "latched"}, delivery="next_tick")
    s.tick()
    s.tick()
    y = s.world.y[1]
    for _ in range(5):
        s.tick()
    assert s.world.y[1] == y


@pytest.mark.parametrize(("mode", "dies"), [("timeout", True), ("never", False)])
def test_a_rumour_dies_when_its_particle_is_gone(mode: str, dies: bool) -> None:
    """A-9: when the leader's particle vanishes, everyone forgets it within a few timeouts (no rumour keeps itself
    alive around the line); literally, nothing resets."""
    n = 6
    s = swarm(ZebroImmature, line(n, {0: 95}), params={"reset_mode": mode}, frozen=True, delivery="next_tick")
    for _ in range(10):
        s.tick()
    assert all(c.my_leader == 0 for c in s.ctls)
    s.world.particles[0].eaten_by = 0  # gone
    for _ in range(6 * n):
        s.tick()
    assert all(c.my_leader is None for c in s.ctls) is dies
