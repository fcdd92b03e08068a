"""The point foot-bot model: P_STA as eq. 2 (K-U4), RETURN -> TIMEOUT on entering the base (K-U1), the
Lennard-Jones lattice (K-U2), the range-and-bearing board (range, occlusion, payload size), deployment errors and
determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.studies.pfsm.experiments import PfsmSearch, search_trial
from bridge.studies.pfsm.numerical import Arena, Deployment, RabModel, Swarm, deploy, p_sta
from swarm_logic.families.pfsm import messages as msg


def test_p_sta_is_eq_2() -> None:
    # digest K-U4: 1000 / (9e6) x 10 x 2.5 = 2.78e-3
    assert p_sta(30_000, 300.0, 10, 10, 25.0, 10) == pytest.approx(2.7778e-3, rel=1e-4)
    assert p_sta(30_000, 300.0, 5, 10, 25.0, 10) == pytest.approx(2.7778e-3 / 4, rel=1e-4)  # N_found^2 / N_total
    assert math.isnan(p_sta(0, 300.0, 10, 10, 25.0, 10))


def fixed(searchers: list[tuple[float, float]], headings: list[float],
          targets: list[tuple[float, float]] | None = None) -> Deployment:
    return Deployment(np.array(searchers, float), np.array(headings, float),
                      np.array(targets or [], float).reshape(-1, 2))


def test_return_becomes_timeout_exactly_on_entering_the_base() -> None:
    arena = Arena(5.0)
    sw = Swarm(arena, fixed([(2.0, 2.5)], [math.pi]), seed=1, params={"social": "none"})
    c = sw.ctls[0]
    c.p_sr, c.p_rs, c.p_ts = 0.9, 0.1, 0.5  # the literal guard sends it home at once
    seen = []  # (the base as the step's sensors read it, the state the step left)
    for _ in range(300):
        grey = c.in_base()
        sw.tick()
        seen.append((grey, c.state))
        if c.state == msg.TIMEOUT:
            break
    assert seen[-1] == (True, msg.TIMEOUT)
    assert all(state == msg.RETURN and not grey for grey, state in seen[1:-1])  # returning until the floor is grey
    assert len(seen) > 100  # it drove 1 m and more at 0.1 m/s


def test_free_searchers_settle_at_the_lj_spacing() -> None:
    """K-U2: no target, the literal zero search vector, SEARCH held (sampled guards, an unreachable bound): the
    group spreads from 0.45 m to about delta = 0.75 m and stops there."""
    pts = [(5.0 + 0.45 * math.cos(a), 5.0 + 0.45 * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 7)[:-1]]
    pts.append((5.0, 5.0))
    sw = Swarm(Arena(10.0), fixed(pts, [0.0] * len(pts)), seed=2,
               params={"pfsm_mode": "sampled", "max_search_s": 1e6, "social": "none"})
    for _ in range(1200):
        sw.tick()
    p = sw.world.pos
    d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
    np.fill_diagonal(d, np.inf)
    nearest = d.min(axis=1)
    assert np.median(nearest) == pytest.approx(0.75, rel=0.2)
    before = p.copy()
    for _ in range(50):
        sw.tick()
    assert np.abs(sw.world.pos - before).max() < 0.05  # a static formation (K-S5's sub-optimum)


def test_the_board_hears_within_range_and_line_of_sight_only() -> None:
    arena = Arena(10.0)
    dep = fixed([(2.0, 5.0), (3.0, 5.0), (4.0, 5.0), (2.0, 7.9)], [0.0] * 4)
    sw = Swarm(arena, dep, seed=3)
    sw.tick()
    w = sw.world
    assert w.hear[0, 1] and w.hear[1, 2] and w.hear[0, 3]
    assert not w.hear[0, 2]  # robot 1 stands on the line of sight
    assert not w.hear[3, 2]  # 3.52 m apart: beyond the 3 m range
    assert sorted(round(r.range_m, 3) for r in w.rab_readings(0)) == [1.0, 2.9]
    sw2 = Swarm(arena, dep, seed=3, rab=RabModel(occlusion=False))
    sw2.tick()
    assert sw2.world.hear[0, 2]


def test_the_point_board_refuses_a_payload_of_eleven_bytes() -> None:
    sw = Swarm(Arena(5.0), fixed([(2.0, 2.0)], [0.0]), seed=1)
    rab = sw.rabs[0]
    rab.send(bytes(10))
    with pytest.raises(ValueError, match="11 bytes: at most 10"):
        rab.send(bytes(11))


def test_a_cell_whose_searchers_cannot_fit_in_the_base_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match=r"base region \(0.3 x 2.0 m\) cannot hold 30 searchers"):
        deploy(Arena(2.0, base_depth_m=0.3), 30, 5, seed=1)
    with pytest.raises(ValueError, match="leaves no arena"):
        deploy(Arena(2.0, base_depth_m=2.0), 3, 1, seed=1)


def test_deployment_is_in_the_base_and_deterministic() -> None:
    arena = Arena(7.5)
    a, b = deploy(arena, 30, 30, seed=9), deploy(arena, 30, 30, seed=9)
    assert np.array_equal(a.searchers, b.searchers) and np.array_equal(a.targets, b.targets)
    assert (a.searchers[:, 0] < arena.base_depth_m).all() and (a.targets[:, 0] > arena.base_depth_m).all()


def test_a_run_is_deterministic_and_finds_every_target_in_the_small_arena() -> None:
    params = {"search_vector": "diffusion", "max_search_s": 150.0}
    r1 = search_trial(5.0, 10, 10, 11, params, max_s=300.0)
    r2 = search_trial(5.0, 10, 10, 11, params, max_s=300.0)
    assert r1.metrics == r2.metrics
    m = r1.metrics
    assert m["all_found"] and m["found"] == 10
    assert m["p_sta"] == pytest.approx(p_sta(m["e_total"], m["t_total_s"], 10, 10, 25.0, 10))


def test_the_grid_is_27_scenarios_of_10_seeds() -> None:
    e = PfsmSearch()
    grid = [c for c in e.cells(False) if c["variant"] == "grid"]
    assert len(grid) == 27 and e.trials == 10
    assert {(c["side"], c["searchers"], c["targets"]) for c in grid} == {
        (s, n, t) for s in (5.0, 7.5, 10.0) for n in (10, 20, 30) for t in (10, 20, 30)}


def test_a_wall_dead_ahead_lights_a_fan_of_sensors_and_turns_the_searcher() -> None:
    """Head-on, one lit sensor would leave ARGoS's diffusion vector pointing ahead and short (go straight, into the
    wall); the ray model lights several, and the searcher avoids."""
    sw = Swarm(Arena(5.0), fixed([(4.9, 2.5)], [0.0]), seed=1)
    lit = [r.value for r in sw.world.proximity(0) if r.value > 0]
    assert len(lit) >= 5
    assert sw.ctls[0].avoidance() is not None


def test_a_slower_board_holds_its_readings_between_updates() -> None:
    dep = fixed([(2.0, 2.0), (2.5, 2.0)], [0.0, 0.0])
    sw = Swarm(Arena(5.0), dep, seed=1, rab=RabModel(period_ticks=5),
               params={"search_vector": "diffusion", "pfsm_mode": "sampled", "max_search_s": 1e6})
    heard = []
    for _ in range(6):
        sw.tick()
        heard.append(len(sw.world.rab_readings(0)))
    # the first payloads are sent in tick 1's steps; the board carries them from its next update, tick 5
    assert heard == [0, 0, 0, 0, 1, 1]
    with pytest.raises(ValueError, match="period_ticks"):
        RabModel(period_ticks=0)
