"""The binary cooperative bat (chapter 7's comparison) as a gain optimiser: the bit coding, the batching contract,
its search, the warm start, the transfer maps (each step checked by hand) and ``RoyApf`` tuning with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bridge.studies.roy.numerical import Ch3Scenario, Swarm, ch3_batch, ch3_trial, deploy
from swarm_logic.families.roy.binary_bat import (
    binary_bat,
    binary_bat_batch,
    binary_bat_draws,
    decode,
    encode,
)
from swarm_logic.families.roy.controller import RoyApf
from swarm_logic.families.roy.pso import single
from tests.studies.roy.test_numerical import same_run

LO, HI = np.full(4, 0.1), np.full(4, 10.0)
OPTIMUM = np.array([4.4, 0.31, 6.64, 2.5])


def sphere(k: np.ndarray) -> np.ndarray:
    return np.sum((np.atleast_2d(k) - OPTIMUM) ** 2, axis=1)


def test_the_grid_round_trips_through_its_bits() -> None:
    bits = 5
    n = np.random.default_rng(0).integers(0, 2**bits, size=(7, 4))
    grid = LO + (HI - LO) * n / (2**bits - 1)
    b = encode(grid, LO, HI, bits)
    assert b.shape == (7, 4 * bits) and set(np.unique(b)) <= {0.0, 1.0}
    assert np.allclose(decode(b, LO, HI, bits), grid, rtol=0, atol=1e-12)
    assert np.array_equal(encode(decode(b, LO, HI, bits), LO, HI, bits), b)
    # most significant bit first: 0b10011 = 19 on the first gain
    one = np.array([[1, 0, 0, 1, 1] + [0] * 15], float)
    assert decode(one, LO, HI, bits)[0, 0] == pytest.approx(0.1 + 9.9 * 19 / 31)
    # a point off the grid goes to its nearest grid point, one outside the box to the edge
    assert np.allclose(
        decode(encode(np.array([0.1 + 9.9 * 2.4 / 31, 0.1, 11.0, -3.0]), LO, HI, bits), LO, HI, bits),
        [0.1 + 9.9 * 2 / 31, 0.1, 10.0, 0.1],
    )


@pytest.mark.parametrize("transfer", ["sigmoid", "v_shaped"])
def test_a_problem_gives_the_same_result_alone_and_in_a_batch(transfer: str) -> None:
    """Three problems with their own optima and warm starts: each one's result is bit-identical to its run alone."""
    optima = np.array([OPTIMUM, [1.0, 2.0, 3.0, 4.0], [9.0, 0.5, 0.5, 9.0]])
    x0 = np.array([[9.0, 9.0, 0.5, 9.0], [5.0, 5.0, 5.0, 5.0], [0.2, 0.3, 9.9, 1.0]])
    u = np.random.default_rng(4).random((3, binary_bat_draws(8, 6, 4, 6)))

    def f(k: np.ndarray) -> np.ndarray:
        return np.sum((k - optima[:, None, :]) ** 2, axis=-1)

    best, val = binary_bat_batch(f, LO, HI, u, 8, 6, 6, transfer=transfer, x0=x0)
    for i in range(3):
        b1, v1 = binary_bat_batch(
            single(lambda k, i=i: np.sum((k - optima[i]) ** 2, axis=-1)),
            LO,
            HI,
            u[i : i + 1],
            8,
            6,
            6,
            transfer=transfer,
            x0=x0[i : i + 1],
        )
        assert np.array_equal(best[i], b1[0]) and val[i] == v1[0]
    assert not np.array_equal(best[0], best[1])
    again = binary_bat(sphere, LO, HI, np.random.default_rng(9), 8, 6, 6, transfer=transfer)
    assert np.array_equal(again[0], binary_bat(sphere, LO, HI, np.random.default_rng(9), 8, 6, 6, transfer=transfer)[0])


@pytest.mark.parametrize("transfer", ["sigmoid", "v_shaped"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_it_finds_a_quadratics_minimum_to_within_one_grid_step(transfer: str, seed: int) -> None:
    lo, hi, bits = np.array([0.0, -1.0]), np.array([3.0, 2.0]), 5
    opt = np.array([1.234, 0.777])
    best, val = binary_bat(
        lambda k: np.sum((k - opt) ** 2, axis=-1),
        lo,
        hi,
        np.random.default_rng(seed),
        bats=20,
        iters=60,
        bits=bits,
        transfer=transfer,
    )
    step = (hi - lo) / (2**bits - 1)
    assert np.all(np.abs(best - opt) <= step)
    assert np.allclose(decode(encode(best, lo, hi, bits), lo, hi, bits), best)  # a grid point
    assert val == pytest.approx(float(np.sum((best - opt) ** 2)))


@pytest.mark.parametrize("transfer", ["sigmoid", "v_shaped"])
def test_the_warm_start_is_kept_exactly_when_nothing_beats_it(transfer: str) -> None:
    """OPTIMUM lies off the 8-bit grid: no bat can beat it, and the call returns it unchanged (not its grid point)."""
    best, val = binary_bat(sphere, LO, HI, np.random.default_rng(2), 10, 10, transfer=transfer, x0=OPTIMUM)
    assert np.array_equal(best, OPTIMUM) and val == 0.0
    worse = np.array([9.0, 9.0, 0.5, 9.0])
    best, val = binary_bat(sphere, LO, HI, np.random.default_rng(2), 10, 10, transfer=transfer, x0=worse)
    assert val < 0.2 * float(sphere(worse)[0])


def test_an_unknown_transfer_names_the_choices() -> None:
    with pytest.raises(ValueError, match="sigmoid, v_shaped"):
        binary_bat(sphere, LO, HI, np.random.default_rng(0), transfer="s_shaped")
    with pytest.raises(ValueError, match="bbat_transfer"):
        RoyApf.resolve({"optimiser": "binary_bat", "bbat_transfer": "s_shaped"})
    with pytest.raises(ValueError, match="bbat_bits"):
        RoyApf.resolve({"bbat_bits": 0})


def one_step(transfer: str, draws: tuple[float, float, float, float]) -> float:
    """One iteration of two bats on a 2-bit gain over [0, 3] (grid 0, 1, 2, 3), f(x) = (x - 1)^2: bat 0 at 00 (0,
    f 1) is the best, bat 1 at 11 (3, f 4). With f = 1, bat 1's velocity is (11 - 00) = (1, 1). No walk (pulse 0
    and the walk test 0), acceptance test 0. ``draws`` are the transfer uniforms: bat 0's two bits, bat 1's two."""
    bats, bits = 2, 2
    u = np.zeros(binary_bat_draws(bats, 1, 1, bits))
    u[:4] = [0.9, 0.9, 0.1, 0.1]  # start: bat 0 = 00, bat 1 = 11 (a bit is 1 when its uniform < 0.5)
    u[4:6] = 0.5  # r_0
    k = 6 + 3 * bats  # the iteration's beta, walk and acceptance tests are 0; then the transfer uniforms
    u[k : k + 4] = draws
    u[k + 4 :] = 0.99  # no walk flips (no walk either)
    best = binary_bat_batch(
        single(lambda x: (x[:, 0] - 1.0) ** 2),
        np.zeros(1),
        np.full(1, 3.0),
        u[None],
        bats,
        1,
        bits,
        f_min=1.0,
        f_max=1.0,
        transfer=transfer,
    )[0]
    return float(best[0, 0])


def test_the_sigmoid_sets_each_bit_from_its_velocity() -> None:
    """Bat 1's bits are 1 with probability S(-1) = 0.269 each (ours: towards the best; 0.5 with the velocity ignored,
    0.731 with S(v) as printed). Transfer uniforms 0.4 and 0.1 set 01 = 1, the minimum; ignoring the velocity or
    the other sign would set 11 = 3, no better than bat 0's 0. Bat 0 (v = 0: probability 0.5 each) draws 0.9, 0.9
    and stays at 00. The first bit's threshold lies at S(-1) = 0.2689."""
    assert 0.5 * (1 - math.tanh(0.5)) == pytest.approx(1 / (1 + math.e))
    assert one_step("sigmoid", (0.9, 0.9, 0.4, 0.1)) == 1.0
    assert one_step("sigmoid", (0.9, 0.9, 0.27, 0.1)) == 1.0
    assert one_step("sigmoid", (0.9, 0.9, 0.26, 0.1)) == 0.0  # 11: no better, bat 0 stays the best


def test_the_v_shaped_map_flips_each_bit_with_its_velocity() -> None:
    """V(1) = |2/pi arctan(pi/2)| = 0.639: bat 1 flips its first bit (uniform 0.5 < 0.639) and keeps the second
    (0.7), landing on 01 = 1; with the velocity ignored nothing flips. Bat 0 (v = 0) never flips."""
    assert abs(2 / math.pi * math.atan(math.pi / 2)) == pytest.approx(0.6390, abs=1e-4)
    assert one_step("v_shaped", (0.0, 0.0, 0.5, 0.7)) == 1.0
    assert one_step("v_shaped", (0.0, 0.0, 0.63, 0.7)) == 1.0
    assert one_step("v_shaped", (0.0, 0.0, 0.64, 0.7)) == 0.0  # no flip: bat 1 stays at 3, bat 0 the best


SMALL = {"optimiser": "binary_bat", "bat_pop": 6, "bat_iters": 5, "oa_law": "bounded"}


@pytest.mark.parametrize("transfer", ["sigmoid", "v_shaped"])
def test_roy_apf_tunes_with_it_and_the_batched_runner_agrees(transfer: str) -> None:
    """``RoyApf`` through the SonPI protocols (``Swarm``): every gain it sets is the warm start or a point of the
    ``bbat_bits`` grid, and the batched runner gives the same run alone and among others, to the bit."""
    params = {**SMALL, "bbat_transfer": transfer, "bbat_bits": 6}
    sc = Ch3Scenario()
    sw = Swarm(sc, deploy(sc, 3), 3, params)
    sw.run(max_s=1.0, until_arrived=False)
    g = np.array(sw.gains)  # (ticks, agents, 4)
    assert g.shape[0] == 20 and np.all(np.isfinite(g))
    n = (g - 0.1) / 9.9 * 63
    warm = np.array([4.4, 0.31, 6.64, 2.5])
    tuned = ~np.all(g == warm, axis=-1)
    assert tuned.mean() > 0.5
    assert np.allclose(n[tuned], np.rint(n[tuned]), atol=1e-9)
    together = ch3_batch([5, 3], params, max_s=1.0)
    assert same_run(together[1], ch3_trial(3, params, max_s=1.0))
