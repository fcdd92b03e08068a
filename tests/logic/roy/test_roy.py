"""Roy ch.3 family: the law's analytic targets (A1 pair spacing, A2 obstacle trigger; digest 001 §6), each
optimiser improving its objective on a toy problem, determinism and parameter validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_logic.families.roy import potential
from swarm_logic.families.roy.bat import bat
from swarm_logic.families.roy.bfo import bfo
from swarm_logic.families.roy.controller import RoyApf
from swarm_logic.families.roy.objective import AgentState, observe, theta
from swarm_logic.families.roy.pso import pso

LO, HI = np.full(4, 0.1), np.full(4, 10.0)
OPTIMUM = np.array([4.4, 0.31, 6.64, 2.5])


def sphere(k: np.ndarray) -> np.ndarray:
    return np.sum((np.atleast_2d(k) - OPTIMUM) ** 2, axis=1)


@pytest.mark.parametrize(("k_a", "k_r", "d"), [(4.4, 6.64, 2.10), (8.8, 8.97, 1.69), (3.03, 4.95, 2.18)])
def test_a1_pair_spacing_formula(k_a: float, k_r: float, d: float) -> None:
    assert potential.pair_spacing(k_a, k_r) == pytest.approx(d, rel=0.01)


def test_a1_the_law_balances_at_the_spacing() -> None:
    """At d*, attraction to the pair's mean and the repulsion cancel (eq. 3.5, no velocity error)."""
    k_a, k_r = 4.4, 6.64
    d = potential.pair_spacing(k_a, k_r)
    x1, x2 = np.array([0.0, 0.0]), np.array([d, 0.0])
    basis = potential.law_basis(x1, np.zeros(2), (x1 + x2) / 2, np.zeros(2), x2[None, :], np.zeros(2), 1.0, 4.0)
    assert np.allclose(potential.control(np.array([k_a, 0.31, k_r, 2.5]), basis), 0.0, atol=1e-12)


def test_a2_obstacle_term_is_zero_beyond_r_s_and_points_away_within() -> None:
    x = np.array([3.0, 4.0])
    angles = np.radians([-90.0, -45.0, 0.0, 45.0, 90.0])
    far = np.array([1.01, 2.0, math.inf, 4.9, 1.5])
    pts = potential.obstacle_points(x, 0.3, far, angles)
    assert np.all(potential.obstacle_avoidance(x, pts, far, 1.0) == 0.0)
    assert np.all(np.isinf(pts[2]))  # no echo: no point
    near = np.array([math.inf, math.inf, 0.6, math.inf, math.inf])
    pts = potential.obstacle_points(x, 0.3, near, angles)
    assert np.allclose(pts[2], x + 0.6 * np.array([math.cos(0.3), math.sin(0.3)]))  # eq. 3.20
    k_oa = 2.5
    u = k_oa * potential.obstacle_avoidance(x, pts, near, 1.0)
    away = (x - pts[2]) / np.linalg.norm(x - pts[2])
    assert np.allclose(u / np.linalg.norm(u), away)
    assert np.linalg.norm(u) == pytest.approx(k_oa * math.exp(-0.36) * 0.6, rel=1e-12)
    bounded = k_oa * potential.obstacle_avoidance(x, pts, near, 1.0, law="bounded")
    assert np.allclose(bounded / np.linalg.norm(bounded), away)
    assert np.linalg.norm(bounded) == pytest.approx(k_oa * math.exp(-0.36), rel=1e-12)


def test_the_bounded_obstacle_term_grows_to_contact_where_the_literal_one_vanishes() -> None:
    """Erratum-style resolution of eq. 3.21: the printed term's size d e^(-d^2/r_s^2) is 0 at contact; the bounded
    reading's e^(-d^2/r_s^2) r_s grows monotonically to r_s, and both agree at the trigger d = r_s."""
    x = np.zeros(2)
    angles = np.array([0.0])
    sizes = {}
    for law in potential.OA_LAWS:
        out = []
        for d in (1.0, 0.5, 0.1, 1e-4):
            r = np.array([d])
            out.append(np.linalg.norm(potential.obstacle_avoidance(x, potential.obstacle_points(x, 0.0, r, angles),
                                                                     r, 1.0, law=law)))
        sizes[law] = out
    assert sizes["literal"][0] == pytest.approx(sizes["bounded"][0])
    assert sizes["literal"][-1] < 1e-3 and sizes["bounded"][-1] == pytest.approx(1.0, abs=1e-6)
    assert np.all(np.diff(sizes["bounded"]) > 0)
    with pytest.raises(ValueError, match="oa_law"):
        potential.obstacle_avoidance(x, np.zeros((1, 2)), np.array([0.5]), 1.0, law="soft")


@pytest.mark.parametrize("name", ["pso", "bfo", "bat_literal", "bat_standard"])
def test_each_optimiser_improves_on_a_toy_problem(name: str) -> None:
    rng = np.random.default_rng(3)
    x0 = np.array([9.0, 9.0, 0.5, 9.0])
    if name == "pso":
        best, val = pso(sphere, LO, HI, rng, x0=x0)
    elif name == "bfo":
        best, val, pop = bfo(sphere, LO, HI, rng, bacteria=30, x0=x0)
        assert pop.shape == (30, 4)
    else:
        best, val = bat(sphere, LO, HI, rng, mode=name.split("_")[1], x0=x0)
    assert val == pytest.approx(float(sphere(best)[0]))
    assert np.all((best >= LO) & (best <= HI))
    assert val < 0.05 * float(sphere(x0)[0])


def state() -> AgentState:
    """One agent with three others and a wall point 0.7 below it (its right-hand sonar, heading +x)."""
    p = RoyApf.resolve({"oa_law": "literal"})
    x_i, v_i = np.array([[5.0, 5.0]]), np.array([[0.1, 0.0]])
    xs = np.array([[[6.0, 5.0], [5.0, 6.5], [4.0, 4.0]]])
    vs = np.array([[[0.0, 0.1], [0.1, 0.1], [0.0, 0.0]]])
    ranges = np.array([[0.7, math.inf, math.inf, math.inf, math.inf]])
    return observe(x_i, v_i, xs, vs, np.zeros(1), ranges, np.radians([-90.0, -45.0, 0.0, 45.0, 90.0]), p)


def test_observe_gathers_the_means_the_obstacle_point_and_the_basis() -> None:
    s = state()
    assert s.n == 4 and np.allclose(s.x_bar, [[5.0, 5.125]]) and np.allclose(s.v_bar, [[0.05, 0.05]])
    assert np.allclose(s.points[0, 0], [5.0, 4.3]) and np.all(np.isinf(s.points[0, 1:]))
    assert s.d_near[0] == pytest.approx(0.7)
    assert np.allclose(s.basis[0, 3], math.exp(-0.49) * np.array([0.0, 0.7]))


@pytest.mark.parametrize("mode", ["literal", "lookahead", "weighted", "spacing"])
def test_optimisers_improve_theta_in_every_mode(mode: str) -> None:
    s = state()
    x0 = np.array([4.4, 0.31, 6.64, 2.5])
    start = float(theta(x0[None, None], s, mode)[0, 0])

    def f(k: np.ndarray) -> np.ndarray:
        return theta(k[None], s, mode)[0]

    for run in (lambda r: pso(f, LO, HI, r, 20, 20, x0=x0)[1], lambda r: bat(f, LO, HI, r, 15, 20, x0=x0)[1],
                lambda r: bfo(f, LO, HI, r, bacteria=20, x0=x0)[1]):
        assert run(np.random.default_rng(1)) < start


def still_state() -> AgentState:
    """Agent i at rest at the origin with two others at 1 and 3 units on the x axis, a law of zero output (so the
    predicted state is the present one), nothing sensed, T 4 units north of the centroid."""
    x_bar = np.array([[4.0 / 3.0, 0.0]])
    z = np.zeros((1, 2))
    return AgentState(z, z, x_bar, z, 3, np.array([[[1.0, 0.0], [3.0, 0.0]]]), np.full((1, 1, 2), np.inf),
                      np.array([5.0]), np.zeros((1, 4, 2)), z, x_bar[0] + [0.0, 4.0], 1.0, 0.05, 5.0, 1.0,
                      progress="centroid")


def test_the_readings_of_theta_at_a_known_state() -> None:
    """Pairs at 1 and 3 units (x_ij / 2r_s - 1 = -0.5 and 0.5), centroid 4 units from T, d = d_max = 5:
    lookahead 4 + 0.25 + 0.25 + 1/25; spacing counts only the pair closer than 2 r_s; weighted weighs the
    unsquared terms by the gains and divides the obstacle term by k_OA."""
    s = still_state()
    k = np.array([[[2.0, 3.0, 5.0, 0.5], [4.0, 3.0, 5.0, 0.5]]])
    assert theta(k, s, "lookahead")[0] == pytest.approx([4.54, 4.54])
    assert theta(k, s, "spacing")[0] == pytest.approx([4.29, 4.29])
    assert theta(k, s, "weighted")[0] == pytest.approx([2 * 4 + 5 * 0.0 + 1 / (0.5 * 25), 4 * 4 + 1 / (0.5 * 25)])
    crowded = AgentState(**{**s.__dict__, "others": np.array([[[1.0, 0.0], [0.0, 1.5]]])})
    assert theta(k, crowded, "weighted")[0, 0] == pytest.approx(2 * 4 + 5 * (-0.5 - 0.25) + 1 / 12.5)


def test_literal_theta_is_linear_in_the_gains() -> None:
    """The degeneracy the digest notes (§2.1.7): Theta's first three terms are linear in k_a, k_v, k_r."""
    s = state()
    k = np.array([[[1.0, 1.0, 1.0, 1.0], [2.0, 1.0, 1.0, 1.0], [3.0, 1.0, 1.0, 1.0]]])
    t = theta(k, s, "literal")[0]
    assert t[2] - t[1] == pytest.approx(t[1] - t[0])
    with pytest.raises(ValueError, match="objective"):
        theta(k, s, "quadratic")


def test_optimisers_are_deterministic_for_a_seed() -> None:
    for opt in (lambda r: pso(sphere, LO, HI, r, 10, 10), lambda r: bat(sphere, LO, HI, r, 10, 10),
                lambda r: bfo(sphere, LO, HI, r, bacteria=10)[:2]):
        a, b = opt(np.random.default_rng(7)), opt(np.random.default_rng(7))
        assert np.array_equal(a[0], b[0]) and a[1] == b[1]


@pytest.mark.parametrize(("params", "name"), [
    ({"bat_alpha": 2.0}, "bat_alpha"), ({"optimiser": "ga"}, "optimiser"), ({"objective": "x"}, "objective"),
    ({"r_s": 0.0}, "r_s"), ({"pso_particles": 2.5}, "pso_particles"), ({"gain_min": 5.0, "gain_max": 1.0}, "gain_min"),
    ({"k_a": 20.0}, "k_a"), ({"bat_f_min": 2.0}, "bat_f_min"), ({"bfo_ped": 1.5}, "bfo_ped"),
])
def test_parameter_errors_name_the_parameter(params: dict[str, object], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        RoyApf.resolve(params)


def test_bat_mode_and_pair_spacing_errors_name_their_argument() -> None:
    with pytest.raises(ValueError, match="bat mode"):
        bat(sphere, LO, HI, np.random.default_rng(0), mode="yang")
    with pytest.raises(ValueError, match="k_a, k_r"):
        potential.pair_spacing(10.0, 4.0)


def test_the_behaviour_is_registered() -> None:
    from importlib.metadata import entry_points

    assert entry_points(group="swarm_sitl.behaviours")["roy_apf"].load() is RoyApf
