"""The search benchmark: the targets' field, RDPSO and GSO finding targets from the foot-bots' deployment, messages
counted, paired seeds (the same deployment for every algorithm) and determinism."""

from __future__ import annotations

import numpy as np
import pytest

from bridge.experiments.runner import execute_experiment
from bridge.studies.pfsm.benchmark import (
    NEAR_M,
    REACH_M,
    TargetField,
    benchmark_trial,
    ci95,
    pfsm_trial,
    swarm_trial,
)
from bridge.studies.pfsm.numerical import TICK_S, Arena, Deployment


def test_target_field_is_a_cone_per_live_target_and_discovery_removes_it() -> None:
    f = TargetField(5.0, np.array([[3.0, 2.0], [4.8, 4.8]]))
    v = f.value(np.array([3.0, 3.0 + REACH_M / 2, 0.0]), np.array([2.0, 2.0, 0.0]))
    assert v.tolist() == pytest.approx([1.0, 0.5, 0.0])
    f.observe(np.array([1.0]), np.array([1.0]), 0)  # the start: nobody near, nothing moved yet
    assert f.found_at == [None, None] and f.moved == {}
    f.observe(np.array([3.0 + 0.9 * NEAR_M]), np.array([2.0]), 1)
    assert f.found_at == [1, None] and f.moved == {1: 1} and not f.all_found()
    assert float(f.value(np.array([3.0]), np.array([2.0]))[0]) == 0.0  # its peak is gone; the other is out of reach
    f.observe(np.array([4.8]), np.array([4.8 - 1.001 * NEAR_M]), 2)  # just beyond the near distance
    assert f.found_at == [1, None] and f.moved[2] == 1
    f.observe(np.array([4.8]), np.array([4.8 - 0.999 * NEAR_M]), 3)
    assert f.found_at == [1, 3] and f.all_found()
    assert f.value(np.array([4.8]), np.array([4.8])).tolist() == [0.0]


def small(targets: list[tuple[float, float]]) -> tuple[Arena, Deployment]:
    """Eight searchers spread in the base of a 5 m arena, targets within a field's reach of them (all on one line,
    GSO's swarm would only gather round its brightest member, who never moves)."""
    sp = np.array([(0.2, 2.0), (0.8, 2.2), (0.4, 2.6), (0.9, 1.8), (0.6, 3.0), (0.3, 1.5), (0.7, 2.8), (0.5, 2.4)])
    return Arena(5.0), Deployment(sp, np.zeros(len(sp)), np.array(targets, float))


@pytest.mark.parametrize("alg", ["rdpso", "gso"])
def test_rdpso_and_gso_find_targets_in_reach_and_count_messages(alg: str) -> None:
    arena, dep = small([(1.6, 2.3), (1.9, 1.7)])
    m = swarm_trial(alg, arena, dep, seed=4)
    assert m["found"] == 2 and m["all_found"]
    assert 0 < m["t_total_s"] < 600.0  # the run ended with the last discovery (numerical.run's until)
    assert m["e_total"] == 8 * round(m["t_total_s"] / TICK_S)  # every searcher, every tick
    assert 0 < m["e_moving"] <= m["e_total"]
    assert m["msgs_per_robot"] == pytest.approx(m["t_total_s"], abs=1.0)  # one frame per robot and 1 s iteration
    assert m["heard_per_robot_s"] > 0 and m["p_sta"] > 0


def test_pfsm_counts_one_broadcast_per_searcher_and_tick() -> None:
    arena, dep = small([(1.6, 2.3)])
    m = pfsm_trial(arena, dep, seed=2)
    assert m["found"] == 1
    assert m["msgs_per_robot"] == pytest.approx(m["run_s"] / TICK_S)
    assert m["msgs_per_robot_s"] == pytest.approx(1 / TICK_S)


def test_same_seed_same_metrics() -> None:
    for alg in ("pfsm", "rdpso", "gso"):
        assert benchmark_trial(alg, 5.0, 10, 10, 7) == benchmark_trial(alg, 5.0, 10, 10, 7)


def test_one_scenario_trial_has_one_deployment_for_every_algorithm(tmp_path) -> None:
    run = execute_experiment("search-benchmark", trials=1, jobs=1, out=tmp_path, smoke=True, progress=False,
                             only={"side": ["5.0"], "searchers": ["10"]})
    assert not run.failed
    by_alg = {o.trial.cell["alg"]: o for o in run.outcomes}
    assert set(by_alg) == {"pfsm", "rdpso", "gso"}
    seeds = {o.trial.seed for o in by_alg.values()}
    assert len(seeds) == 1  # alg is left out of the seed: one deploy() draw, the same starts and targets for all
    for o in by_alg.values():
        assert o.result is not None and o.result.metrics["found"] > 0 and o.result.metrics["msgs_per_robot"] > 0
    report = (tmp_path / "report.md").read_text()
    assert "## Comparison" in report and "| 5 | 10 | 10 | RDPSO |" in report


def test_ci95() -> None:
    m, h = ci95(np.array([1.0, 2.0, 3.0]))
    assert m == 2.0 and h == pytest.approx(2.4841, rel=1e-4)  # t(0.975, 2) x 1 / sqrt(3)
    assert np.isnan(ci95(np.array([5.0]))[1])
