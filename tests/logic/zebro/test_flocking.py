"""Algorithm 2 (flocking) and the readings of A-1 and A-2: heading changes only, each bounded per tick."""

from __future__ import annotations

import math

import pytest

from swarm_logic.families.zebro.flocking import (
    FlockRules,
    align,
    arithmetic_mean,
    circular_mean,
    cohere,
    flock,
    separate,
    turn_away,
    turn_towards,
)
from swarm_logic.robots.decizebro.interfaces import Neighbour

D = math.radians


def rules(**kw: object) -> FlockRules:
    base = {"d_min": 1.0, "d_max": 3.0, "align_turn": D(5), "cohere_turn": D(3), "separate_turn": D(1.5)}
    return FlockRules(**{**base, **kw})  # type: ignore[arg-type]


def test_turns_are_bounded_and_take_the_short_way() -> None:
    assert turn_towards(0.0, D(90), D(5)) == pytest.approx(D(5))
    assert turn_towards(D(170), D(-170), D(5)) == pytest.approx(D(175))  # across +-180
    assert turn_towards(0.0, D(2), D(5)) == pytest.approx(D(2))
    assert turn_away(0.0, D(10), D(5)) == pytest.approx(D(-5))
    assert turn_away(0.0, 0.0, D(5)) == 0.0  # NetLogo turn-away: nothing to turn from


def test_circular_mean_repairs_the_arithmetic_mean_across_north() -> None:
    """A-1: 350 and 10 degrees average to 0 (circular), 180 (the literal arithmetic mean in [0, 360))."""
    a = [D(-10), D(10)]
    assert circular_mean(a) == pytest.approx(0.0, abs=1e-12)
    assert abs(arithmetic_mean(a)) == pytest.approx(math.pi)
    assert circular_mean([0.0, math.pi]) is None  # opposite headings cancel
    assert circular_mean([]) is None and arithmetic_mean([]) is None


def test_align_turns_towards_the_neighbours_heading() -> None:
    nbrs = [Neighbour(1, 2.0, 0.5, D(-10)), Neighbour(2, 2.0, -0.5, D(10))]
    assert align(D(20), nbrs, rules()) == pytest.approx(D(15))
    assert align(D(20), nbrs, rules(align_mean="arithmetic")) == pytest.approx(D(25))  # towards 180, the long way


def test_cohere_only_beyond_d_max_towards_their_bearing() -> None:
    near = Neighbour(1, 2.0, D(90), 0.0)
    far = Neighbour(2, 4.0, D(90), D(-90))
    assert cohere(0.0, [near], rules()) == 0.0
    assert cohere(0.0, [near, far], rules()) == pytest.approx(D(3))  # repaired: towards it
    assert cohere(0.0, [near, far], rules(cohere_mode="heading")) == pytest.approx(D(-3))  # literal: its heading


def test_separation_wins_below_d_min() -> None:
    close = Neighbour(1, 0.5, D(90), D(10))
    other = Neighbour(2, 2.0, 0.0, D(90))
    assert flock(0.0, [close, other], rules()) == pytest.approx(D(-1.5))  # away from its heading, not aligning
    assert separate(0.0, close, rules(separate_mode="plus90")) == pytest.approx(D(1.5))  # literal: towards 100


def test_no_neighbours_no_turn() -> None:
    assert flock(1.0, [], rules()) == 1.0
    assert align(1.0, [Neighbour(1, 2.0, 0.0, None)], rules()) == 1.0  # a heading it has not heard
