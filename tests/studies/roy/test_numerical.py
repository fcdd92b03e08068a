"""Roy ch.3 point-agent model: A1 (two agents settle at d*), A2 (the obstacle term through the SonPI protocols),
the metrics, the scenario's checks, determinism and the study's registration (digest 001 §4.1, §5.5, §6)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.studies.roy.numerical import (
    Ch3Scenario,
    Mover,
    PointWorld,
    Swarm,
    ch3_trial,
    cohesion_index,
    deploy,
    lambda_min,
)

OPEN = Ch3Scenario(lines=(), movers=())
LITERAL_LAW = {"optimiser": "fixed", "target_term": "none", "v_max": 100.0, "oa_law": "literal"}


@pytest.mark.parametrize(("k_a", "k_v", "k_r", "d"),
                         [(4.4, 0.31, 6.64, 2.10), (8.8, 0.36, 8.97, 1.69), (3.03, 1.05, 4.95, 2.18)])
def test_a1_two_agents_settle_at_the_pair_spacing(k_a: float, k_v: float, k_r: float, d: float) -> None:
    """Eq. 3.5 with delta = 4, r_s = 1, no obstacle, k_v > 0, the unsaturated double integrator: the pair settles
    at sqrt(4 ln(2 k_r / k_a)) within 1 % (digest A1)."""
    sw = Swarm(OPEN, np.array([[19.5, 20.0], [20.5, 20.0]]), seed=1,
               params={**LITERAL_LAW, "k_a": k_a, "k_v": k_v, "k_r": k_r})
    run = sw.run(max_s=120.0, until_arrived=False)
    p = sw.world.pos
    assert float(np.hypot(*(p[0] - p[1]))) == pytest.approx(d, rel=0.01)
    assert np.allclose(p.mean(axis=0), [20.0, 20.0], atol=1e-9)  # symmetric forces: the centroid stays put
    assert run.collisions == 0 and np.all(np.isfinite(run.trace))


def test_a2_the_obstacle_term_reaches_the_controller_through_the_sonar() -> None:
    """One agent, at rest, 0.5 units below a line it faces: its u is k_OA e^(-d^2/r_s^2) (x - O), pointing away
    (attraction and repulsion vanish for a lone agent): the nearest reading alone (``nearest``), or that and the two
    45-degree sonars' (0.707 away, 0.5 below the line too; ``per_sensor``); 2 units away it is zero (digest A2)."""
    g = 0.5
    one = math.exp(-g * g) * g
    diag = math.exp(-2 * g * g) * g  # each 45-degree reading: d = g sqrt(2), (x - O) has y component -g
    for gap, mode, expect in ((g, "nearest", one), (g, "per_sensor", one + 2 * diag), (2.0, "per_sensor", 0.0)):
        sc = Ch3Scenario(lines=(((10.0, 20.0), (30.0, 20.0)),), movers=(), target=(20.0, 35.0), n=1)
        sw = Swarm(sc, np.array([[20.0, 20.0 - gap]]), seed=2, params={**LITERAL_LAW, "oa_mode": mode})
        assert sw.world.heading[0] == pytest.approx(math.pi / 2)  # it faces the target, across the line
        sw.tick()
        assert sw.ctls[0].u == pytest.approx([0.0, -2.5 * expect], abs=1e-9)


def test_a_move_into_a_line_is_refused_and_counted() -> None:
    sc = Ch3Scenario(lines=(((10.0, 20.0), (30.0, 20.0)),), movers=())
    w = PointWorld(sc, np.array([[20.0, 19.99]]))
    w.cmd[0] = [0.0, 1.0]
    w.move(0.05)
    assert w.collisions == 1 and w.pos[0] == pytest.approx([20.0, 19.99]) and np.all(w.vel[0] == 0)


def test_the_mover_goes_back_and_forth_and_the_sonar_sees_it() -> None:
    m = Mover((0.0, 0.0), (10.0, 0.0), 1.0, 1.0)
    assert m.centre(5.0) == pytest.approx([5.0, 0.0]) and m.centre(15.0) == pytest.approx([5.0, 0.0])
    assert m.centre(20.0) == pytest.approx([0.0, 0.0])
    sc = Ch3Scenario(lines=(), movers=(Mover((23.0, 20.0), (23.0, 20.0), 1.0, 0.0),), target=(35.0, 20.0))
    w = PointWorld(sc, np.array([[20.0, 20.0]]))
    assert w.ranges[0, 2] == pytest.approx(2.0)  # straight ahead: the circle's near side
    assert math.isinf(w.ranges[0, 0])  # to the right: the wall at y = 0 is 20 units away, beyond the 5 of a sonar


def test_cohesion_index_and_lambda_min() -> None:
    tight = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    assert cohesion_index(tight, 1.0) == 1.0
    loose = np.vstack([tight, [[30.0, 30.0]]])
    assert cohesion_index(loose, 1.0) == pytest.approx(0.0)  # the straggler drags the centroid away from all
    assert lambda_min(np.array([[0.0, 0.0], [5.0, 0.0]]), 1.0) == 0.0  # no pair within 2 r_s: F = 0
    assert lambda_min(np.array([[0.0, 0.0], [1.5, 0.0]]), 1.0) == pytest.approx(-1.5)


def test_scenario_and_deployment_errors_name_the_field() -> None:
    with pytest.raises(ValueError, match="n:"):
        Ch3Scenario(n=0)
    with pytest.raises(ValueError, match="start box"):
        deploy(Ch3Scenario(n=40, start_lo=(2.0, 2.0), start_hi=(4.0, 4.0)), seed=1)
    with pytest.raises(ValueError, match="bat_mode"):
        Swarm(OPEN, np.array([[5.0, 5.0]]), seed=1, params={"bat_mode": "yang"})


def test_the_default_scenario_starts_apart_and_away_from_obstacles() -> None:
    sc = Ch3Scenario()
    p = deploy(sc, seed=5)
    d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1]) + np.eye(len(p)) * 99
    assert p.shape == (6, 2) and d.min() >= sc.min_sep


@pytest.mark.parametrize("optimiser", ["bat", "pso", "bfo", "bgpso", "psoabg"])
def test_a_run_is_the_same_for_the_same_seed(optimiser: str) -> None:
    small = {"optimiser": optimiser, "bat_pop": 6, "bat_iters": 5, "pso_particles": 6, "pso_iters": 5,
             "bfo_bacteria": 6, "bfo_nre": 1, "bfo_ned": 1, "deadlock_window_s": 0.25}
    sc = Ch3Scenario()
    a, b = Swarm(sc, deploy(sc, 3), 3, small), Swarm(sc, deploy(sc, 3), 3, small)
    ra, rb = a.run(max_s=1.0), b.run(max_s=1.0)
    assert np.array_equal(ra.final, rb.final) and np.array_equal(a.gains, b.gains)
    c = ch3_trial(4, small, max_s=1.0)
    assert not np.array_equal(ra.final, c.final)
    g = np.array(a.gains)
    assert ra.ticks == 20 and g.shape == (20, 6, 4)
    assert np.all((g >= 0.1) & (g <= 10.0))


def test_fixed_gains_with_the_target_term_reach_the_target_in_open_space() -> None:
    """The target term (erratum #2) brings the swarm to T; success, mission time and path length are scored."""
    sc = Ch3Scenario(lines=(), movers=(), target=(12.0, 12.0), timeout_s=300.0)
    run = Swarm(sc, deploy(sc, 1), seed=1, params={"optimiser": "fixed", "v_max": 1.0}).run()
    assert run.success and run.mission_s is not None and run.mission_s < 300.0
    assert run.path_length >= math.dist((5.0, 5.0), (12.0, 12.0)) - 4.0
    assert 0.0 < run.ci_mean <= 1.0


def test_the_study_is_registered() -> None:
    from importlib.metadata import entry_points

    study = entry_points(group="swarm_sitl.studies")["roy"].load()
    assert study.name == "roy"


@pytest.mark.parametrize("optimiser", ["bat", "pso", "bfo", "bgpso", "psoabg", "psoabg_stuck"])
def test_each_optimiser_improves_theta_on_an_agent_of_the_scenario(optimiser: str) -> None:
    """One re-tuning from the warm start never makes Theta worse, in both modes; PSOABG runs PSO when stuck."""
    from swarm_logic.families.roy.objective import theta

    sc = Ch3Scenario()
    for mode in ("lookahead", "literal"):
        sw = Swarm(sc, deploy(sc, 2), seed=2, params={"optimiser": optimiser.split("_")[0], "objective": mode,
                                                      "bat_pop": 10, "bat_iters": 10, "pso_particles": 10,
                                                      "pso_iters": 10, "bfo_bacteria": 10})
        c = sw.ctls[0]
        me = c.read_pose()
        assert me is not None
        s = c.state(me)
        if optimiser == "psoabg_stuck":
            c.centroids.extend([s.x_bar[0]] * (c.centroids.maxlen - 1))  # type: ignore[operator]
        before = float(theta(c.gains[None, None], s, mode)[0, 0])
        c.step()
        after = float(theta(c.gains[None, None], s, mode)[0, 0])
        assert after <= before
        assert c.using_pso == (optimiser == "psoabg_stuck")


SMALL = {"bat_pop": 6, "bat_iters": 5, "pso_particles": 6, "pso_iters": 5, "bfo_bacteria": 6, "bfo_nre": 1,
         "bfo_ned": 1, "deadlock_window_s": 0.25}


def same_run(a: object, b: object) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True)
               for k in ("final", "trace", "gain_sum", "gain_sq", "path_length", "ci_mean", "collisions", "ticks"))


@pytest.mark.parametrize("optimiser", ["bat", "pso", "bfo", "bgpso", "psoabg", "fixed"])
def test_a_batched_run_is_the_run_alone_and_the_controllers_run(optimiser: str) -> None:
    """``BatchSwarm`` steps runs together through the controller's own functions: each run's numbers are those it has
    alone in a batch of one, and those ``RoyApf`` gives through the SonPI protocols (``Swarm``), to the bit."""
    from bridge.studies.roy.numerical import ch3_batch

    params = {**SMALL, "optimiser": optimiser, "oa_law": "bounded"}
    together = ch3_batch([5, 3, 4], params, max_s=1.5)
    alone = ch3_batch([3], params, max_s=1.5)[0]
    through = ch3_trial(3, params, max_s=1.5)
    assert same_run(together[1], alone) and same_run(alone, through)
    assert not np.array_equal(together[0].final, together[1].final)


@pytest.mark.parametrize("objective", ["weighted", "spacing"])
def test_the_batched_run_and_the_controllers_agree_on_each_reading_of_theta(objective: str) -> None:
    """The readings of Theta beside the default one: the batched runner and ``RoyApf`` give the same run."""
    from bridge.studies.roy.numerical import ch3_batch

    params = {**SMALL, "optimiser": "bat", "objective": objective}
    together = ch3_batch([5, 3], params, max_s=1.5)
    through = ch3_trial(3, params, max_s=1.5)
    assert same_run(together[1], through)
    default = ch3_trial(3, {**params, "objective": "lookahead"}, max_s=1.5)
    assert not np.array_equal(default.gain_sum, through.gain_sum)


def test_a_batch_stops_each_run_where_it_arrives() -> None:
    """Runs that arrive stop (their figures end there) while the others go on."""
    from bridge.studies.roy.numerical import ch3_batch

    sc = Ch3Scenario(lines=(), movers=(), target=(12.0, 12.0), timeout_s=300.0)
    params = {"optimiser": "fixed", "v_max": 1.0}
    runs = ch3_batch([1, 2], params, sc)
    for seed, r in zip([1, 2], runs, strict=True):
        alone = Swarm(sc, deploy(sc, seed), seed, params).run()
        assert r.success and r.mission_s == alone.mission_s and same_run(r, alone)


def test_the_bounded_obstacle_term_takes_fixed_gains_round_the_baffle_where_the_printed_one_jams() -> None:
    """roy-ch3-v2 with the fixed gains: eq. 3.21 as printed fades at contact and the agents press into the baffle
    (refused moves pile up); the bounded reading keeps them off it and they round its end, without a collision."""
    from bridge.studies.roy.numerical import ch3_batch

    bounded, literal = (ch3_batch([7], {"optimiser": "fixed", "oa_law": law}, max_s=70.0)[0]
                        for law in ("bounded", "literal"))
    assert bounded.collisions == 0 and bounded.trace[-1, 2] > 12.0  # the centroid is past the baffle (y = 11)
    assert literal.collisions > 100 and literal.path_length < bounded.path_length


def test_the_v2_layout_closes_the_way_but_for_the_gap() -> None:
    """The wall along x + y = 40 runs from wall to wall with one 3-unit opening centred on (20, 20)."""
    from bridge.studies.roy.numerical import SCENARIOS

    sc = SCENARIOS["roy-ch3-v2"]
    assert sc.version == "roy-ch3-v2" and SCENARIOS["roy-ch3-v1"].version == "roy-ch3-v1"
    (_, a), (b, _) = sc.lines[1], sc.lines[2]
    assert math.dist(a, b) == pytest.approx(3.0, abs=1e-3) and np.allclose(np.add(a, b) / 2, [20.0, 20.0], atol=1e-3)
    assert sc.lines[1][0] == (0.0, 40.0) and sc.lines[2][1] == (40.0, 0.0)
