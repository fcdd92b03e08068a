"""The circle-gathering baseline (Sharma et al. 2017, our reading): the smallest enclosing circle, the ring slots,
and the rigid rounds (the circle waits for its last robot)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_logic.families.roy.gathering import CircleGathering, enclosing_circle, ring_slots


def test_the_enclosing_circle_is_the_smallest() -> None:
    c, r = enclosing_circle(np.array([[0.0, 0.0], [4.0, 0.0], [2.0, 1.0]]))
    assert np.allclose(c, [2.0, 0.0]) and r == pytest.approx(2.0)  # the widest pair's circle
    tri = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, math.sqrt(3)]])
    c, r = enclosing_circle(tri)
    assert np.allclose(c, [1.0, math.sqrt(3) / 3]) and r == pytest.approx(2 / math.sqrt(3))
    pts = np.random.default_rng(1).uniform(0, 10, (30, 2))
    c, r = enclosing_circle(pts)
    assert np.all(np.hypot(*(pts - c).T) <= r + 1e-9)
    assert np.sum(np.hypot(*(pts - c).T) >= r - 1e-9) >= 2  # it touches at least two points


@pytest.mark.parametrize("n", [6, 7, 12, 30])
def test_ring_slots_fill_circles_two_r_s_apart_from_the_inside(n: int) -> None:
    s = ring_slots(n, 1.0)
    radii = np.round(np.hypot(*s.T), 9)
    assert s.shape == (n, 2) and radii.max() <= 2.0 * math.ceil(max(1, n) / 6) + 1e-9
    assert np.sum(radii == 2.0) == min(n, 6)
    if n > 1:
        d = np.hypot(s[:, None, 0] - s[None, :, 0], s[:, None, 1] - s[None, :, 1]) + np.eye(n) * 99
        assert d.min() >= 1.9  # neighbours about 2 r_s apart


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_with_a_spacing_a_small_swarm_sits_on_one_circle_its_neighbours_that_far_apart(n: int) -> None:
    s = ring_slots(n, 1.5, spacing=2.0)
    assert s.shape == (n, 2)
    if n == 1:
        assert np.allclose(s, 0.0)
        return
    radii = np.hypot(*s.T)
    assert np.allclose(radii, radii[0]) and np.allclose(s.mean(0), 0.0, atol=1e-12)
    d = np.hypot(s[:, None, 0] - s[None, :, 0], s[:, None, 1] - s[None, :, 1]) + np.eye(n) * 99
    assert d.min() == pytest.approx(3.0)  # 2 r_s
    assert np.allclose(ring_slots(6, 1.5, spacing=2.0), ring_slots(6, 1.5))  # six: the inner circle of the default
    assert np.allclose(np.hypot(*ring_slots(3, 1.0, spacing=2.5).T), 2.5 / math.sqrt(3))


def test_the_gathering_circle_reaches_the_target_in_open_space_and_waits_for_its_robots() -> None:
    from dataclasses import replace

    from bridge.studies.roy.numerical import Ch3Scenario, Swarm, deploy

    sc = replace(Ch3Scenario(), lines=(), movers=(), target=(12.0, 12.0), timeout_s=300.0)
    sw = Swarm(sc, deploy(sc, 3), 3, {"v_max": 1.0}, controller=CircleGathering)
    run = sw.run()
    assert run.success and run.collisions == 0
    rounds = [c.rounds for c in sw.ctls]  # type: ignore[attr-defined]
    assert len(set(rounds)) == 1 and rounds[0] > 0  # all robots advanced the same circle, round by round
    assert run.mission_s is not None and run.mission_s > math.dist((5.0, 5.0), (12.0, 12.0)) / 1.0
