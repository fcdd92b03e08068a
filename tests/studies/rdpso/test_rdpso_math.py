"""RDPSO math (Couceiro 2013): the deterministic reproduction targets U1-U7, U9, U10, U12, U13, and unit behaviour.

Expected numbers are written out independently (from the thesis's equations and printed values), never taken
from the implementation's own output.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from swarm_logic.families.rdpso.fuzzy import (
    FuzzyAdapter,
    bell,
    obstacle_proximity,
    proximity_distance,
    proximity_rssi,
    socialization,
    swarm_activity,
)
from swarm_logic.families.rdpso.graph import (
    adjacency,
    choose_neighbours,
    connectivity_metric,
    connectivity_vector,
    fiedler,
    multihop_matrix,
)
from swarm_logic.families.rdpso.motion import (
    attraction_domain,
    characteristic_roots,
    check_parameters,
    clamp,
    deceleration_alpha_max,
    gl_increments,
    memory_term,
    memory_weights,
    numeric_stable_range,
    truncation_order,
    validate_parameters,
)
from swarm_logic.families.rdpso.spiral import (
    est_next,
    k_first_distance_ratio,
    k_first_threshold_dbm,
    theodorus_angles,
    theodorus_spiral,
)

S1 = (0.632, (0.1, 0.3, 0.79, 0.79))
S2 = (0.632, (0.4, 0.69, 0.2, 0.69))


# --- motion -------------------------------------------------------------------------------------------------------

def test_U1_truncation_order_eswarbot() -> None:
    delta = 2 * math.pi * 0.02109 / 48
    assert round(delta * 1000, 4) == 2.7607
    inc_mm = [round(v * 1000, 3) for v in gl_increments(0.5, 0.1, 5)]
    assert inc_mm == [50.0, 12.5, 6.25, 3.906, 2.734]
    assert truncation_order(0.5, 0.1, delta) == 4
    # A coarser encoder stops the series earlier: 6.25 mm is the first increment below 7 mm -> tau = 3, r = 2.
    assert truncation_order(0.5, 0.1, 0.007) == 2


@pytest.mark.parametrize(("alpha", "expected"), [
    (0.5, (0.5, 0.25, 0.041667, 0.015625)),
    (0.632, (0.632, 0.316, 0.03876, 0.01326)),
])
def test_U2_thesis_memory_weights(alpha: float, expected: tuple[float, ...]) -> None:
    w = memory_weights(alpha)
    assert len(w) == 4
    for got, want in zip(w, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-4)
    if alpha == 0.632:
        assert sum(w) == pytest.approx(1.0, abs=1e-4)


def test_U2_exact_gl_weights_and_forms() -> None:
    for got, want in zip(memory_weights(0.5, "exact_gl"), (0.5, 0.125, 0.0625, 0.0391), strict=True):
        assert got == pytest.approx(want, abs=1e-4)
    for got, want in zip(memory_weights(0.632, "exact_gl"), (0.632, 0.1163, 0.0530, 0.0314), strict=True):
        assert got == pytest.approx(want, abs=1e-4)
    # alpha(1-alpha)(2-alpha)(3-alpha)(4-alpha)/120 at 0.5
    assert memory_weights(0.5, "exact_gl", r=5)[4] == pytest.approx(0.5 * 0.5 * 1.5 * 2.5 * 3.5 / 120, abs=1e-12)
    assert memory_weights(1.0, "exact_gl", r=3) == pytest.approx((1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="r = 4"):
        memory_weights(0.5, "thesis", r=3)
    with pytest.raises(ValueError, match="exact_gl"):
        memory_weights(0.5, "gl")


def test_U3_deceleration_bound() -> None:
    a = deceleration_alpha_max()
    assert a == pytest.approx(0.632, abs=1e-3)
    assert a == pytest.approx(0.63199, abs=1e-5)
    assert a + a / 2 + a * (1 - a) / 6 + a * (1 - a) * (2 - a) / 24 == pytest.approx(1.0, abs=1e-12)


def test_U4_acceleration_bound_flags_thesis_set() -> None:
    warnings = check_parameters(0.5, (0.2, 0.4, 0.8, 0.8))
    assert len(warnings) == 1
    assert "A_p" in warnings[0] and "7.17" in warnings[0]
    assert "1.1" in warnings[0] and "inside" in warnings[0]  # E[sum rho r] = 2.2/2
    assert check_parameters(*S1) == []
    assert check_parameters(*S2) == []


def test_check_parameters_other_bounds() -> None:
    dec = check_parameters(0.7, (0.1, 0.3, 0.79, 0.79))
    assert any("deceleration" in w and "7.10" in w for w in dec)
    # alpha = 0.1: eq. 7.4 upper bound 2.1 < 2.2 = sum(rho)
    up = check_parameters(0.1, (0.2, 0.4, 0.8, 0.8))
    assert any("7.4" in w and "2.1" in w for w in up)
    both = check_parameters(0.5, (1.0, 1.0, 1.0, 1.0))
    assert any("also outside" in w for w in both)
    # exact GL memory sums to < 1 for alpha < 1: no deceleration warning at alpha = 0.7
    assert not any("deceleration" in w for w in check_parameters(0.7, (0.1, 0.3, 0.79, 0.79), form="exact_gl"))
    with pytest.raises(ValueError, match="exact_gl"):
        check_parameters(0.5, (0.1, 0.1, 0.1, 0.1), form="nope")


@pytest.mark.parametrize(("alpha", "numeric", "eq74"), [
    (0.1, (0.0, 2.116), (0.0, 2.1)),
    (0.5, (0.0, 2.552), (0.0, 2.5)),
    (0.632, (0.0, 2.683), (0.12, 2.632)),
    (0.7, (0.275, 2.747), (0.375, 2.7)),
    (0.8, (0.683, 2.837), (0.75, 2.8)),
    (0.9, (1.096, 2.922), (1.125, 2.9)),
    (1.0, (1.5, 3.0), (1.5, 3.0)),
])
def test_U5_attraction_domain(alpha: float, numeric: tuple[float, float], eq74: tuple[float, float]) -> None:
    lo, hi = numeric_stable_range(alpha)
    assert lo == pytest.approx(numeric[0], abs=0.01)
    assert hi == pytest.approx(numeric[1], abs=0.01)
    assert attraction_domain(alpha) == pytest.approx(eq74, abs=1e-9)


def test_U5_characteristic_polynomial() -> None:
    # eq. 7.3 coefficients written out independently
    a, s = 0.5, 1.3
    coeffs = [1.0, -1 - a + s, a / 2, a / 3 + a * a / 6,
              -a**3 / 24 - a * a / 24 + a / 12, a**3 / 24 - a * a / 8 + a / 12]
    roots = characteristic_roots(a, s)
    assert len(roots) == 5
    assert np.abs(np.polyval(coeffs, roots)).max() < 1e-9
    assert np.abs(roots).max() < 1.0  # inside (0, 2.552)
    assert np.abs(characteristic_roots(0.5, 2.6)).max() > 1.0


def test_validate_parameters() -> None:
    validate_parameters(0.632, (0.1, 0.3, 0.0, 0.79))  # rho3 = 0 is allowed (no obstacles)
    with pytest.raises(ValueError, match="rho2"):
        validate_parameters(0.5, (0.2, -0.4, 0.8, 0.8))
    with pytest.raises(ValueError, match="alpha"):
        validate_parameters(0.0, (0.2, 0.4, 0.8, 0.8))
    with pytest.raises(ValueError, match="alpha"):
        validate_parameters(1.5, (0.2, 0.4, 0.8, 0.8))
    with pytest.raises(ValueError, match="rho"):
        validate_parameters(0.5, (0.2, 0.4, 0.8))
    with pytest.raises(ValueError, match="rho4"):
        check_parameters(0.5, (0.2, 0.4, 0.8, float("nan")))


def test_memory_term_short_and_long_history() -> None:
    w = (0.5, 0.25, 0.125, 0.0625)
    assert memory_term(w, []) == (0.0, 0.0)
    assert memory_term(w, [(1.0, 2.0)]) == pytest.approx((0.5, 1.0))
    assert memory_term(w, [(1.0, 0.0), (0.0, 4.0)]) == pytest.approx((0.5, 1.0))
    hist = [(1.0, -1.0)] * 6  # entries beyond r are ignored
    assert memory_term(w, hist) == pytest.approx((0.9375, -0.9375))


def test_clamp() -> None:
    assert clamp(3.0, 4.0, 1.0) == pytest.approx((0.6, 0.8))
    assert clamp(0.03, -0.04, 0.1) == (0.03, -0.04)
    assert clamp(0.0, 0.0, 0.1) == (0.0, 0.0)


# --- deployment ---------------------------------------------------------------------------------------------------

def test_U6_k_first_distance_ratio() -> None:
    for k, want in zip(range(1, 6), (1.000, 0.525, 0.373, 0.301, 0.262), strict=True):
        assert k_first_distance_ratio(k) == pytest.approx(want, abs=1e-3)


def test_U7_k_first_threshold() -> None:
    assert k_first_threshold_dbm(-75.0, 2) == pytest.approx(-71.99, abs=0.01)
    assert k_first_threshold_dbm(-75.0, 1) == pytest.approx(-75.0, abs=1e-12)


@pytest.mark.parametrize("sigma", [1, -1])
def test_U9_theodorus_spiral(sigma: int) -> None:
    d, x0, phi0, n = 3.0, (2.0, -1.0), 0.7, 12
    pts = theodorus_spiral(n, d, x0, phi0, sigma)
    assert len(pts) == n
    for m, (x, y) in enumerate(pts, start=1):
        assert math.hypot(x - x0[0], y - x0[1]) == pytest.approx(d * math.sqrt(m + 1), abs=1e-9)
    for a, b in itertools.pairwise(pts):
        assert math.hypot(b[0] - a[0], b[1] - a[1]) == pytest.approx(d, abs=1e-9)
    # first robot at 45 deg from the spiral orientation, then increments 35.26, 30, 26.57 deg
    bearings = [math.atan2(y - x0[1], x - x0[0]) for x, y in pts]
    first = (bearings[0] - phi0 + math.pi) % (2 * math.pi) - math.pi
    assert first == pytest.approx(sigma * math.pi / 4, abs=1e-9)
    incs = [(b - a + math.pi) % (2 * math.pi) - math.pi for a, b in itertools.pairwise(bearings)]
    for got, want in zip(incs, (math.atan(1 / math.sqrt(2)), math.pi / 6, math.atan(0.5)), strict=False):
        assert got == pytest.approx(sigma * want, abs=1e-9)
    assert math.degrees(abs(incs[0])) == pytest.approx(35.26, abs=0.01)
    angles = theodorus_angles(4, sigma)
    assert [round(math.degrees(abs(v)), 2) for v in angles] == [45.0, 80.26, 110.26, 136.83]


@pytest.mark.parametrize("sigma", [1, -1])
def test_U10_est_reproduces_spiral(sigma: int) -> None:
    rng = np.random.default_rng(10 + sigma)
    for _ in range(5):
        x0 = (float(rng.uniform(-50, 50)), float(rng.uniform(-50, 50)))
        phi0 = float(rng.uniform(-math.pi, math.pi))
        d = float(rng.uniform(0.5, 5.0))
        n = 9
        ideal = theodorus_spiral(n, d, x0, phi0, sigma)
        placed = [ideal[0], ideal[1]]  # scouts 1 and 2 come from the ranger's first leg
        for i in range(1, n - 1):
            a, b = placed[i - 1], placed[i]
            theta = math.atan2(b[1] - a[1], b[0] - a[0])
            placed.append(est_next(a, b, theta, d, i, sigma))
        for got, want in zip(placed, ideal, strict=True):
            assert got == pytest.approx(want, abs=1e-9)
        for i in range(1, n - 1):
            a, b = ideal[i - 1], ideal[i]
            # heading from x_i and x_{i+1} when theta is not given
            assert est_next(a, b, None, d, i, sigma) == pytest.approx(ideal[i + 1], abs=1e-9)
            # equivalent geometry: one leg further, perpendicular (turn sigma) to x_{i+1}'s radius
            rx, ry = b[0] - x0[0], b[1] - x0[1]
            nr = math.hypot(rx, ry)
            want = (b[0] - sigma * d * ry / nr, b[1] + sigma * d * rx / nr)
            assert est_next(a, b, None, d, i, sigma) == pytest.approx(want, abs=1e-9)


def test_est_next_rejects_bad_index() -> None:
    with pytest.raises(ValueError):
        est_next((0.0, 0.0), (1.0, 0.0), 0.0, 1.0, 0, 1)
    with pytest.raises(ValueError):
        est_next((0.0, 0.0), (1.0, 0.0), 0.0, 1.0, 1, 2)


# --- graph --------------------------------------------------------------------------------------------------------

def _path(n: int) -> np.ndarray:
    a = np.zeros((n, n), dtype=int)
    for i in range(n - 1):
        a[i, i + 1] = a[i + 1, i] = 1
    return a


def test_U12_connectivity_metric() -> None:
    for n in (2, 5, 8):
        full = np.ones((n, n), dtype=int) - np.eye(n, dtype=int)
        assert fiedler(full) == pytest.approx(n, abs=1e-9)
        assert connectivity_metric(full) == pytest.approx(1.0, abs=1e-9)
    assert fiedler(_path(5)) == pytest.approx(2 - 2 * math.cos(math.pi / 5), abs=1e-9)
    assert round(fiedler(_path(5)), 3) == 0.382
    assert connectivity_metric(_path(5)) == pytest.approx(0.382 / 5, abs=1e-3)
    split = np.zeros((4, 4), dtype=int)
    split[0, 1] = split[1, 0] = split[2, 3] = split[3, 2] = 1
    assert connectivity_metric(split) == 0.0
    assert fiedler(np.zeros((1, 1))) == 0.0


def test_U12_multihop_path() -> None:
    c = multihop_matrix(_path(6))
    want = np.array([[abs(i - j) for j in range(6)] for i in range(6)])
    assert np.array_equal(c, want)
    split = np.zeros((5, 5), dtype=int)
    split[0, 1] = split[1, 0] = split[1, 2] = split[2, 1] = split[3, 4] = split[4, 3] = 1
    c = multihop_matrix(split)
    assert c[0, 2] == 2 and c[0, 3] == 0 and c[3, 4] == 1 and c[2, 2] == 0


def test_adjacency() -> None:
    nan = float("nan")
    dist = np.array([[0.0, 2.0, 3.5], [2.0, 0.0, nan], [3.5, nan, 0.0]])
    assert np.array_equal(adjacency(dist, "distance", 3.0), [[0, 1, 0], [1, 0, 0], [0, 0, 0]])
    rssi = np.array([[0.0, -70.0, -80.0], [-75.0, 0.0, 0.0], [-80.0, -74.0, -30.0]])
    assert np.array_equal(adjacency(rssi, "rssi", -75.0), [[0, 1, 0], [1, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="rssi"):
        adjacency(dist, "metres", 3.0)


def test_connectivity_vector_signs() -> None:
    # beyond d_max: pulled toward the neighbour by the excess; inside: pushed away
    assert connectivity_vector(0, 0, [(5.0, 0.0, 5.0)], "distance", 3.0, -75.0) == pytest.approx((2.0, 0.0))
    assert connectivity_vector(0, 0, [(1.0, 0.0, 1.0)], "distance", 3.0, -75.0) == pytest.approx((-2.0, 0.0))
    # weak signal: attraction of k_q * (q_min - L); strong: repulsion
    assert connectivity_vector(1, 1, [(1.0, 3.0, -80.0)], "rssi", 3.0, -75.0, k_q=0.1) == pytest.approx((0.0, 0.5))
    assert connectivity_vector(1, 1, [(1.0, 3.0, -60.0)], "rssi", 3.0, -75.0) == pytest.approx((0.0, -15.0))
    both = connectivity_vector(0, 0, [(5.0, 0.0, 5.0), (0.0, 4.0, 4.0)], "distance", 3.0, -75.0)
    assert both == pytest.approx((2.0, 1.0))
    assert connectivity_vector(2, 2, [(2.0, 2.0, 10.0)], "distance", 3.0, -75.0) == (0.0, 0.0)


def test_choose_neighbours_order_and_ties() -> None:
    cands = [(3, 2.0), (2, 1.0), (1, 1.0), (0, 5.0)]
    assert choose_neighbours(cands, 2, "distance") == [1, 2]
    assert choose_neighbours(cands, 10, "distance") == [1, 2, 3, 0]
    assert choose_neighbours(cands, 0, "distance") == []
    rssi = [(5, -70.0), (4, -60.0), (2, -60.0), (7, -94.0)]
    assert choose_neighbours(rssi, 3, "rssi") == [2, 4, 5]
    assert choose_neighbours([(1, float("nan")), (2, 3.0)], 1, "distance") == [2]


# --- fuzzy --------------------------------------------------------------------------------------------------------

def test_U13_bell() -> None:
    assert bell(1.0) == pytest.approx(1.0, abs=1e-12)
    assert bell(0.5) == pytest.approx(0.5, abs=1e-12)
    assert bell(0.0) == pytest.approx(1 / 65, abs=1e-12)
    assert bell(1.5) == pytest.approx(0.5, abs=1e-12)  # absolute value: symmetric about c


def test_context_metrics() -> None:
    assert swarm_activity(0.05, 0.1) == pytest.approx(0.5)
    assert swarm_activity(0.3, 0.1) == 1.0
    assert socialization(1.0, 4.0) == pytest.approx(0.75)
    assert socialization(0.0, 0.0) == 1.0
    assert obstacle_proximity(3.0, 3.0) == 0.0  # nothing sensed: g = R_w
    assert obstacle_proximity(0.75, 3.0) == pytest.approx(0.75)
    assert proximity_distance(0.75, 3.0) == pytest.approx(0.75)
    assert proximity_distance(3.5, 3.0) == 0.0
    assert proximity_rssi(-75.0, -75.0) == 0.0
    assert proximity_rssi(-75.0 + 10 * math.log10(2), -75.0) == pytest.approx(0.5)  # twice the power
    assert proximity_rssi(-65.0, -75.0) == pytest.approx(0.9)
    assert proximity_rssi(-80.0, -75.0) == 0.0


def test_fuzzy_obstacle_close_raises_rho3() -> None:
    f = FuzzyAdapter()
    _, r1, r2, r3, _ = f.adapt(0.2, 0.3, 1.0, 0.8, 1.0)
    assert r3 > 0.7
    assert r1 >= 0.02
    assert r2 < 0.2  # R3: Close -> rho2 Small
    calm = f.adapt(0.2, 0.3, 0.0, 0.8, 1.0)
    assert calm[3] == 0.0  # nothing sensed -> rho3 = 0


def test_fuzzy_far_or_disconnected_raises_rho4() -> None:
    f = FuzzyAdapter()
    far = f.adapt(0.2, 0.3, 0.0, 0.0, 1.0)
    assert far[4] > 0.7
    disconnected = f.adapt(0.2, 0.3, 0.0, 0.9, 0.0)
    assert disconnected[4] > 0.7
    near = f.adapt(0.2, 0.3, 0.0, 0.9, 1.0)
    assert near[4] < 0.2
    # alpha: chaotic subgroup -> Small, idle -> Large (R1), nominal pull when the link is at risk (R2)
    assert f.adapt(1.0, 0.5, 0.0, 0.9, 1.0)[0] < 0.45
    assert f.adapt(0.0, 0.5, 0.0, 0.9, 1.0)[0] > 0.75
    assert 0.6 < f.adapt(0.0, 0.5, 0.0, 0.0, 1.0)[0] < 0.75


def test_fuzzy_output_bounds() -> None:
    rng = np.random.default_rng(7)
    adapters = [FuzzyAdapter(), FuzzyAdapter(rho2_sets=(0.9, 1.2), rho3_sets=(0.5, 1.0), rho4_sets=(0.9, 1.2))]
    grid = [0.0, 0.5, 1.0]
    cases = [tuple(rng.uniform(0, 1, 5)) for _ in range(500)]
    cases += [(a, s, o, p, c) for a in grid for s in grid for o in grid for p in grid for c in grid]
    for f in adapters:
        for args in cases:
            alpha, *rho = f.adapt(*args)
            assert 0.0 < alpha <= 0.8
            assert sum(rho) <= 1.98 + 1e-9
            assert rho[0] >= 0.02 - 1e-12
            assert min(rho) >= 0.0
    # the second adapter's sets alone exceed the budget: scaled so that sum(rho) = 1.98 with rho1 at the floor
    out = adapters[1].adapt(0.0, 0.0, 1.0, 0.0, 0.0)
    assert sum(out[1:]) == pytest.approx(1.98)
    assert out[1] == pytest.approx(0.02)
