"""The numerical model's speed work changes no result: the edge grids give the same sonar ranges and moves as testing
every edge, the knn law worked out once per spot gives the bits of its per-agent form, and a mission is the same
bytes from the same seed."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.spatial import cKDTree

from bridge.studies.roy.regions_scenarios import load_scenario, make_planner
from bridge.studies.roy.regions_world import EdgeGrid, RegionsWorld, run_mission
from swarm_logic.families.roy.regions.laws import kernel_sum, saturate, split_merge_law, unique_rows

SHIPPED = ("ch4-a", "ch4-maze-50", "ch4-mover", "ch5-a", "ch6-case1", "ch6-case2", "ch6-case3")

# (scenario, agents (None: the file's), seed, simulated seconds): short missions, run twice
SAME_BYTES = [
    ("ch6-case2", 1000, 1, 2.0),
    ("ch6-case3", 6, 2, 12.0),
    ("ch4-mover", None, 1, 8.0),
    ("ch5-a", None, 1, 8.0),
]


def _every_edge(w: RegionsWorld) -> EdgeGrid:
    """One cell holding every edge: the brute-force reference."""
    size = np.asarray(w.sc.world.size, float)
    return EdgeGrid(w.edges, np.full(2, -1e6), size + 1e6, 4e6, 1e7)


def _scatter_poses(w: RegionsWorld, rng: np.random.Generator) -> None:
    """Poses all over the map (through walls too: the grids must not care), a quarter right next to an edge."""
    size = np.asarray(w.sc.world.size, float)
    w.pos = rng.uniform(-0.5, size + 0.5, (w.n, 2))
    if len(w.edges):
        k = rng.integers(0, len(w.edges), w.n // 4)
        s = rng.uniform(0, 1, (len(k), 1))
        w.pos[: len(k)] = w.edges[k, 0] + s * (w.edges[k, 1] - w.edges[k, 0]) + rng.normal(0, 0.03, (len(k), 2))
    w.heading = rng.uniform(-np.pi, np.pi, w.n)


@pytest.mark.parametrize("name", SHIPPED)
def test_the_grids_cast_and_move_as_testing_every_edge(name: str) -> None:
    rng = np.random.default_rng(7)
    w = RegionsWorld(load_scenario(name).with_agents(400), seed=1)
    for _ in range(3):
        _scatter_poses(w, rng)
        ref = copy.deepcopy(w)
        ref.beam_grid = ref.move_grid = _every_edge(w)
        fast, slow = w.cast(), ref.cast()
        assert np.isfinite(slow).sum() > w.n  # beams do meet edges
        assert np.array_equal(fast, slow, equal_nan=True)
        u = rng.normal(0, 2 * w.v_max, (w.n, 2))
        w.step(u)
        ref.step(u)
        assert ref.contacts > 0  # some moves do hit an edge
        assert np.array_equal(w.pos, ref.pos) and w.contacts == ref.contacts
        assert np.array_equal(w.heading, ref.heading)


def _knn_law_per_agent(x: np.ndarray, centre: np.ndarray, obs: np.ndarray, r_s: float, k_f: float = 2.5) -> np.ndarray:
    """Eq. 6.5 "knn" (8 nearest within 3 r_s) as it was written before the speed work: one query per agent."""
    pts = np.concatenate([x, obs])
    k = min(9, len(pts))
    _, idx = cKDTree(pts).query(x, k=k, distance_upper_bound=3 * r_s)
    idx = idx.reshape(len(x), k)
    i = np.repeat(np.arange(len(x)), k).reshape(len(x), k)
    keep = (idx < len(pts)) & (idx != i)
    return saturate(-12.0 * (x - centre) + k_f * kernel_sum(x, i[keep], idx[keep], r_s, others=pts), 1.0)


def test_the_knn_law_works_once_per_spot_and_gives_the_same_bits() -> None:
    """Swarms stack agents on one spot: clumps bigger and smaller than the neighbour count, a wall of repeated sonar
    points, per-agent centres; the law per distinct spot equals the law per agent bit for bit."""
    rng = np.random.default_rng(3)
    for trial in range(40):
        spots = rng.uniform(0, 4, (int(rng.integers(1, 40)), 2))
        x = spots[rng.integers(0, len(spots), int(rng.integers(2, 300)))]
        x[: len(x) // 3] += rng.normal(0, 0.05, (len(x) // 3, 2))  # a third off the spots
        obs = np.repeat(rng.uniform(0, 4, (int(rng.integers(0, 30)), 2)), int(rng.integers(1, 5)), axis=0)
        centre = rng.uniform(0, 4, (len(x), 2)) if trial % 2 else np.array([2.0, 2.0])
        r_s = float(rng.uniform(0.05, 0.5))
        fast = split_merge_law(x, centre, obs, mode="knn", r_s=r_s, neighbours=8, v_max=1.0)
        assert np.array_equal(fast, _knn_law_per_agent(x, centre, obs, r_s))
    first, same = unique_rows(x)
    assert len(first) < len(x) and np.array_equal(x[first][same], x)


@pytest.mark.parametrize(("name", "n", "seed", "max_s"), SAME_BYTES)
def test_a_mission_is_the_same_bytes_from_the_same_seed(name: str, n: int | None, seed: int, max_s: float) -> None:
    """Same seed, same summary bytes (events included); another seed, other bytes. (Byte-identity across a change
    of the model is checked by comparing missions before and after it on one machine: sin, cos and exp may round
    differently on another CPU family, so digests are not pinned here.)"""
    sc = load_scenario(name)
    if n is not None:
        sc = sc.with_agents(n)
    runs = [run_mission(sc, make_planner(sc), s, max_time_s=max_s).summary_json() for s in (seed, seed, seed + 1)]
    assert runs[0] == runs[1] and runs[0] != runs[2]
