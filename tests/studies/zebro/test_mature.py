"""The mature election (thesis Algorithms 7-10; digest 2.5.7) on static graphs: Z-U1 uniqueness, Z-U2 the line
topology, Z-U3 latency scaling; and every literal reading still runs."""

from __future__ import annotations

import numpy as np
import pytest

from bridge.studies.zebro.numerical import Model, Swarm, make_scenario
from swarm_logic.families.zebro.mature import FOLLOW, LEAD, ZebroMature
from swarm_logic.graph import components

from .helpers import UP, line, ring, star, swarm


def elect(s: Swarm, limit: int = 400) -> int:
    """Tick until every robot has left the election; the tick of the election's end."""
    for _ in range(limit):
        s.tick()
        if all(c.state in (FOLLOW, LEAD) for c in s.ctls):
            return s.world.tick
    raise AssertionError(f"no end of election in {limit} ticks: {[c.state for c in s.ctls]}")


def check_unique(s: Swarm) -> int:
    """Z-U1: one EOE, from the best (utility, id) contender; every robot heard it."""
    contenders = {(r["utility"], r["robot"]) for r in s.topic("zebro_contender")}
    elected = s.topic("zebro_elected")
    assert len(elected) == 1, elected
    leader = elected[0]["robot"]
    assert (elected[0]["utility"], leader) == max(contenders)
    assert [c.state for c in s.ctls].count(LEAD) == 1 and s.ctls[leader].state == LEAD
    assert all(c.the_leader == leader for c in s.ctls)
    return leader


@pytest.mark.parametrize("n", [5, 20, 50])
@pytest.mark.parametrize("contenders", [{0: 40}, {0: 95, 3: 15}, {1: 15, 3: 95, 4: 60}])
def test_line_elects_one_leader(n: int, contenders: dict[int, int]) -> None:
    s = swarm(ZebroMature, line(n, {(i * (n - 1)) // 4: u for i, u in contenders.items()}), frozen=True)
    elect(s)
    check_unique(s)


def test_cousins_leave_the_highest_id_to_contest() -> None:
    """Two robots see one particle (95): the higher id contests, the other withdraws (A-5)."""
    sc = line(6, {5: 15})
    sc.particles.append((1.5, 1.5, 95))  # in the cones of robots 1 and 2
    sc.heading[[1, 2]] = UP
    s = swarm(ZebroMature, sc, frozen=True)
    elect(s)
    assert check_unique(s) == 2
    assert {r["robot"] for r in s.topic("zebro_withdraw")} >= {1, 5}


@pytest.mark.parametrize(("make", "best"), [(lambda: ring(8, {0: 30, 4: 90}), 4), (lambda: ring(8, {2: 90}), 2),
                                             (lambda: star(5, {1: 20, 3: 70, 4: 50}), 3),
                                             (lambda: star(5, {0: 60, 2: 50}), 0)])
def test_ring_and_star(make, best: int) -> None:
    s = swarm(ZebroMature, make(), frozen=True)
    elect(s)
    assert check_unique(s) == best


@pytest.mark.parametrize(("n", "seed"), [(5, 1), (5, 2), (20, 3), (20, 4)])
def test_random_geometric_graphs_at_the_short_range(n: int, seed: int) -> None:
    sc = make_scenario(n, 2, False, np.random.default_rng(seed))
    s = swarm(ZebroMature, sc, seed, frozen=True)
    elect(s)
    check_unique(s)


@pytest.mark.parametrize("delivery", ["at_once", "next_tick"])
def test_line_with_contenders_at_both_ends_stays_connected(delivery: str) -> None:
    """Z-U2: the line's far ends both contend; the best wins and the halted swarm stays one piece."""
    n = 10
    sc = line(n, {0: 15, n - 1: 95})
    sc.heading[:] = UP  # a flock walking up: parallel steps keep the line until STOP halts it
    s = swarm(ZebroMature, sc, delivery=delivery)
    for _ in range(300):
        s.tick()
        if any(c.state == LEAD for c in s.ctls):
            break
        assert components(s.world.adjacency()) == 1  # through the whole election
    assert s.topic("zebro_elected")[0]["robot"] == n - 1


def test_election_ticks_grow_linearly_with_eccentricity_and_are_constant_on_a_complete_graph() -> None:
    """Z-U3 with one hop per tick: the line's election time grows by a fixed number of ticks per hop (STOP, n2,
    acks and EOE each cross it); on a complete graph it does not depend on N."""
    ticks = {}
    for n in (4, 8, 16):
        s = swarm(ZebroMature, line(n, {0: 50}), frozen=True, delivery="next_tick")
        ticks[n] = elect(s)
    per_hop = (ticks[8] - ticks[4]) / 4
    assert per_hop >= 2
    assert ticks[16] - ticks[8] == pytest.approx(8 * per_hop, abs=1)
    complete = []
    for n in (5, 10, 20):
        s = swarm(ZebroMature, line(n, {0: 50}, spacing=0.2, r=100.0), frozen=True, delivery="next_tick")
        complete.append(elect(s))
    assert len(set(complete)) == 1


def test_the_leader_walks_three_times_as_fast_eats_and_erases() -> None:
    s = swarm(ZebroMature, line(5, {2: 60}, r=10.0))
    leader = s.ctls[2]
    while leader.state != LEAD:
        s.tick()
    x0, y0 = s.world.x[2], s.world.y[2]
    s.tick()  # the particle is 1.5 u ahead, eaten within 0.5 u: this step is still a leader's
    step = np.hypot(s.world.x[2] - x0, s.world.y[2] - y0)
    assert step == pytest.approx(3 * 0.2 * 0.268, rel=1e-6)
    for _ in range(20):
        s.tick()
    assert s.world.eat_count == 1 and s.world.particles[0].eaten_by == 2
    assert leader.state not in (LEAD,) and all(c.state != FOLLOW for c in s.ctls)
    assert s.world.tx[0x16] >= 1  # ERASE


@pytest.mark.parametrize("option", [{"ack_symbols": "as_defined"}, {"election_tags": "utility"},
                                    {"leader_rule": "count"}, {"leader_pace": "duty"}, {"new_contenders": "join"},
                                    {"follow_mode": "heading"}, {"graph": False, "beacon": False}])
def test_every_reading_runs(option: dict) -> None:
    sc = make_scenario(5, 2, False, np.random.default_rng(7))
    s = Swarm(ZebroMature, option, sc, 7, Model())
    for _ in range(60):
        s.tick()


def test_the_literal_ack_symbols_deadlock_on_a_line() -> None:
    """A-4 as defined (ack when acks were received): a leaf never acks, so a line never ends its election."""
    s = swarm(ZebroMature, line(4, {0: 50}), params={"ack_symbols": "as_defined"}, frozen=True)
    for _ in range(50):
        s.tick()
    assert not s.topic("zebro_elected")


@pytest.mark.parametrize("seed", [0, 1])
def test_the_link_gossip_builds_the_adjacency_matrix(seed: int) -> None:
    """Z-U4 in the running swarm: after more ticks than the diameter (one hop per tick) every robot's matrix is the
    communication graph's, and symmetric."""
    sc = make_scenario(20, 1, False, np.random.default_rng(seed))
    sc.particles.clear()
    s = swarm(ZebroMature, sc, seed, frozen=True, delivery="next_tick")
    for _ in range(22):
        s.tick()
    truth = s.world.adjacency() & ~np.eye(20, dtype=bool)
    for c in s.ctls:
        assert np.array_equal(c.graph.matrix(20), truth)
        assert c.graph.complete()


def test_elections_follow_one_another_past_the_sequence_byte() -> None:
    """Election numbers are one byte: a swarm that has held 256 elections still floods and elects."""
    s = swarm(ZebroMature, line(5, {0: 60}), frozen=True)
    for c in s.ctls:
        c.seq = c.erased = 255
        c.flooded = {(0x10, 255), (0x15, 255), (0x16, 255)}
    elect(s)
    assert all(c.seq == 256 for c in s.ctls) and len(s.topic("zebro_elected")) == 1
    assert all((0x10, 256) in c.flooded and (0x10, 255) in c.flooded for c in s.ctls)


def lose_first(s: Swarm, kind: int, count: int = 1) -> list[int]:
    """Make the swarm's radio lose the first ``count`` frames of type ``kind`` (to every receiver); the senders."""
    lost: list[int] = []
    send = s.world.broadcast

    def lossy(i: int, data: bytes) -> bool:
        if data and data[0] == kind and len(lost) < count:
            lost.append(i)
            return True  # the module took it; the air lost it
        return send(i, data)

    s.world.broadcast = lossy  # type: ignore[method-assign]
    return lost


@pytest.mark.parametrize("kind", [0x14, 0x12, 0x10])  # n4, n2, STOP
def test_a_lost_frame_stalls_the_thesis_election_and_resending_repairs_it(kind: int) -> None:
    """The thesis' election has no timeout: one lost n4 (or n2, or STOP) halts the swarm for good. With
    ``resend_ticks`` the same loss only delays it, and the election still ends with the one right leader."""
    sc = line(8, {1: 15, 6: 95})
    s = swarm(ZebroMature, sc, frozen=True)
    lost = lose_first(s, kind)
    with pytest.raises(AssertionError, match="no end of election"):
        elect(s, limit=60)
    assert lost

    clean = swarm(ZebroMature, line(8, {1: 15, 6: 95}), frozen=True, params={"resend_ticks": 3})
    t_clean = elect(clean)
    r = swarm(ZebroMature, line(8, {1: 15, 6: 95}), frozen=True, params={"resend_ticks": 3})
    lost = lose_first(r, kind)
    t = elect(r, limit=60)
    assert lost
    assert check_unique(r) == 6 == check_unique(clean)
    assert t >= t_clean
