"""Chapters 4-7's figures (A10 and the tables' statistics): TVI, the three structural densities, both formation
errors, SOI, unused area, summaries and the linear fit, checked against direct computations over all pairs."""

import math

import numpy as np
import pytest

from bridge.studies.roy.metrics import (
    formation_error,
    formation_error_ef,
    linear_fit,
    obstacle_sensing,
    pair_shares,
    path_lengths,
    region_statistics,
    structural_density,
    summarise,
    travel_variance_index,
    unused_area,
)


def dense(xy):
    """Every ordered pair's distance, the way the co-simulation's scoring computed it before."""
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    return d, ~np.eye(len(xy), dtype=bool)


def test_tvi_a10():
    assert travel_variance_index([3.0, 3.0, 3.0, 3.0]) == pytest.approx(1.0)
    assert travel_variance_index([0.0, 0.0, 7.5, 0.0, 0.0]) == pytest.approx(1 / 5)
    assert travel_variance_index([0.0, 0.0]) == 1.0
    assert travel_variance_index([1.0, 2.0, 3.0]) == pytest.approx(36 / 42)
    with pytest.raises(ValueError, match="finite"):
        travel_variance_index([1.0, -1.0])
    track = np.array([[[0, 0], [0, 0]], [[3, 4], [0, 1]], [[3, 4], [0, 2]], [[np.nan, 0], [0, 3]]], float)
    assert path_lengths(track).tolist() == [5.0, 3.0]  # a step to or from a lost position counts 0


@pytest.mark.parametrize(
    "rule, scale, lo, hi, lo_in, hi_in",
    [("ch4", 0.6, 0.6, 1.2, True, False), ("ch5", 1.0, 2.0, 4.0, False, True), ("ch6", 1.0, 0.0, 2.0, True, True)],
)
def test_structural_density_matches_all_pairs(rule, scale, lo, hi, lo_in, hi_in):
    rng = np.random.default_rng(11)
    for n in (2, 7, 300):
        xy = rng.uniform(0, math.sqrt(n) * 1.5, (n, 2))
        xy[: n // 2] = np.round(xy[: n // 2] * 2) / 2  # lattice points: distances exactly on the bounds
        d, off = dense(xy)
        ok = off & ((d >= lo) if lo_in else (d > lo)) & ((d <= hi) if hi_in else (d < hi))
        got = structural_density(xy, scale, rule)
        assert got == ok.sum() / (n * (n - 1)) and 0.0 <= got <= 1.0
    assert structural_density(np.zeros((1, 2)), 1.0) == 0.0


def test_structural_density_figures():
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(3) / 2]])
    assert structural_density(tri * 2.0, 1.0, "ch6") == 1.0  # neighbours at 2 r_s: cohesive (eq. 6.25)
    assert structural_density(tri * 2.1, 1.0, "ch6") == 0.0
    assert structural_density(tri * 3.0, 1.0, "ch5") == 1.0 and structural_density(tri * 2.0, 1.0, "ch5") == 0.0
    assert structural_density(tri * 0.9, 0.6, "ch4") == 1.0 and structural_density(tri * 1.2, 0.6, "ch4") == 0.0
    with pytest.raises(ValueError, match="rule"):
        structural_density(tri, 1.0, "ch7")  # type: ignore[arg-type]


def test_structural_density_of_a_thousand_agents():
    """A hexagonal block of 1000 agents 1.99 r_s apart: every agent linked to its <= 6 neighbours under chapter
    6's rule, counted without forming the 10^6 pairs."""
    i, j = np.meshgrid(np.arange(40), np.arange(25))
    xy = np.c_[(i + 0.5 * (j % 2)).ravel(), (j * math.sqrt(3) / 2).ravel()] * 1.99
    assert len(xy) == 1000
    d, off = dense(xy)
    assert structural_density(xy, 1.0, "ch6") == (off & (d <= 2.0)).sum() / (1000 * 999)
    links = structural_density(xy, 1.0, "ch6") * 999
    assert 5.0 < links < 6.0  # the mean degree of a finite hexagonal block


def test_formation_error_ch7_is_the_pairs_outside_2_to_3_r_s_as_before():
    rng = np.random.default_rng(5)
    for n in (2, 3, 6, 50):
        for r_s in (0.113, 1.0):
            xy = rng.uniform(0, 3 * r_s * math.sqrt(n), (n, 2))
            xy[:2] = [[0.0, 0.0], [2 * r_s, 0.0]]  # a pair exactly on the lower bound
            d, off = dense(xy)
            pairs = n * (n - 1)
            close, far = float((off & (d < 2 * r_s)).sum()) / pairs, float((off & (d > 3 * r_s)).sum()) / pairs
            assert pair_shares(xy, r_s) == (close, far)  # bit-identical
            assert formation_error(xy, r_s) == close + far
            assert 0.0 <= formation_error(xy, r_s) <= 1.0
            assert formation_error(xy, r_s, "literal") == 1.0
    assert formation_error(np.zeros((1, 2)), 1.0) == 0.0


def test_formation_error_ef_eq_4_22():
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(3) / 2]])
    adj = np.ones((3, 3)) - np.eye(3)
    assert formation_error_ef(tri * 2.0, 2.0, adj) == pytest.approx(0.0, abs=1e-12)
    assert formation_error_ef(tri * 3.0, 2.0, adj) == pytest.approx(6 * (4 - 9) ** 2)
    path = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]])
    assert formation_error_ef(tri * 3.0, 2.0, path) == pytest.approx(4 * 25)
    with pytest.raises(ValueError, match="adjacency"):
        formation_error_ef(tri, 1.0, np.ones((2, 2)))


def test_soi_counts_agents_per_obstacle():
    owner = [0, 0, 1, 2, 2, 3, 4, 4]
    obstacle = [0, 0, 0, 0, 1, 1, -1, 2]
    s = obstacle_sensing(owner, obstacle)
    assert s.so == (3, 2, 1) and s.soi == pytest.approx(3 / 6) and s.dropped == 1
    none = obstacle_sensing([], [])
    assert none.so == () and none.soi == 0.0
    assert obstacle_sensing([1], [0], n_obstacles=3).so == (1, 0, 0)


def test_unused_area_summaries_and_the_time_fit():
    assert unused_area(57.65, 50, 0.606) == pytest.approx(57.65 - 50 * math.pi * 0.606**2)
    s = summarise([1.0, 2.0, 3.0, 4.0, math.nan])
    assert (s.n, s.mean, s.median, s.min, s.max) == (4, 2.5, 2.5, 1.0, 4.0)
    assert s.sd == pytest.approx(math.sqrt(1.25)) and s.cov == pytest.approx(math.sqrt(1.25) / 2.5)
    assert (s.q1, s.q3, s.iqr) == (1.75, 3.25, 1.5)
    assert summarise([]).as_dict()["mean"] is None
    st = region_statistics([2.0, 2.0], [1.0, 3.0])
    assert st["area"].mean == pytest.approx(4 * math.pi) and st["b"].cov == pytest.approx(0.5)
    n = [50, 100, 250, 500, 1000]
    fit = linear_fit(n, [43.18, 58.69, 124.95, 237.41, 461.52])  # Table 6.2's means
    assert (round(fit.intercept, 1), round(fit.slope, 3), round(fit.r2, 4)) == (16.4, 0.444, 0.9997)
    fit = linear_fit(n, [340.54, 603.27, 1460.17, 2850.92, 5615.91])  # Table 6.3's
    assert (round(fit.intercept, 1), round(fit.slope, 2), round(fit.r2, 5)) == (61.2, 5.56, 0.99998)
    with pytest.raises(ValueError, match="distinct"):
        linear_fit([1, 1], [2, 3])


def test_structural_density_within_sub_swarms():
    # two sub-swarms of 5 packed agents, 50 apart (after a split): every pair inside a sub-swarm is within 2 r_s
    a = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [0.5, 0.5], [0.25, 0.25]])
    xy = np.concatenate([a, a + np.array([50.0, 0.0])])
    groups = np.array([0] * 5 + [1] * 5)
    assert structural_density(xy, 1.0, "ch6") == pytest.approx(40 / 90)  # eq. 6.25 over all 10: the split lowers D
    assert structural_density(xy, 1.0, "ch6", groups) == 1.0  # within the sub-swarms: it does not
    # one agent of no sub-swarm (-1) is left out; a far member lowers its sub-swarm's share (links 12 + 20 of 12 + 20)
    far = xy.copy()
    far[4] = (20.0, 0.0)
    assert structural_density(far, 1.0, "ch6", np.array([0, 0, 0, 0, -1, 1, 1, 1, 1, 1])) == 1.0
    assert structural_density(far, 1.0, "ch6", groups) == pytest.approx((12 + 20) / (20 + 20))
    assert structural_density(xy, 1.0, "ch6", np.full(10, -1)) == 0.0
    with pytest.raises(ValueError, match="groups"):
        structural_density(xy, 1.0, "ch6", groups[:3])
