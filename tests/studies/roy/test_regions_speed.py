"""The numerical model's speed work changes no result: the edge grids give the same sonar ranges and moves as testing
every edge, and short missions keep the summary bytes they had before it (digests pinned from the model as it was)."""

from __future__ import annotations

import copy
import hashlib

import numpy as np
import pytest
from scipy.spatial import cKDTree

from bridge.studies.roy.regions_scenarios import load_scenario, make_planner
from bridge.studies.roy.regions_world import EdgeGrid, RegionsWorld, run_mission
from swarm_logic.families.roy.regions.laws import kernel_sum, saturate, split_merge_law, unique_rows

SHIPPED = ("ch4-a", "ch4-maze-50", "ch4-mover", "ch5-a", "ch6-case1", "ch6-case2", "ch6-case3")

# (scenario, agents (None: the file's), seed, simulated seconds (None: to the end), sha256 of summary_json()); pinned
# before the edge grids, the vectorised lookups of chapter 6's planner and the other speed work. These bytes move only
# with a change of results: re-pin with the reason in the commit. (sin, cos and exp may round differently on another
# CPU family: the grid tests below are the machine-independent check.)
PINNED = [
    ("ch6-case2", 50, 1, None, "22cb9f5624daac4f98f6c36c11dd75706ac698807b3ab02949b60dbcf57cedb1"),
    ("ch6-case2", 1000, 1, 10.0, "711328d6ceaba0096f3314de50b84a854cffb225881e10cb0f3284775f7731cb"),
    ("ch6-case3", 6, 2, None, "4e8deb1e8b035420549ea4ef3e95b18b01942505d7e8950bd56d16c3635b5ac7"),
    ("ch6-case1", 1000, 1, 5.0, "fca1558ca9b9a4aa6d7ea18cc485091ae1cc0535a341186491675284037c477d"),
    ("ch4-a", None, 1, 60.0, "64667b6396ace84793c6214b3587f98ed89c1daa7cd1ba4323063105a2d0f32a"),
    ("ch5-a", None, 1, 40.0, "89c05883552f1b02adb3c59738b230336664f203cdcc7caea227463a2a5c1b17"),
    ("ch4-mover", None, 1, 40.0, "5be5f74bbf67a95fd63314f036fb6ff6f5bc9c7d196ec316e506f010608fc446"),
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


@pytest.mark.parametrize(("name", "n", "seed", "max_s", "digest"), PINNED)
def test_short_missions_keep_their_summary_bytes(
    name: str, n: int | None, seed: int, max_s: float | None, digest: str
) -> None:
    sc = load_scenario(name)
    if n is not None:
        sc = sc.with_agents(n)
    res = run_mission(sc, make_planner(sc), seed, max_time_s=max_s)
    assert hashlib.sha256(res.summary_json().encode()).hexdigest() == digest
