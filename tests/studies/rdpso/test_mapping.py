"""The chapter 8 mapping objective (bridge/numerical/entropy_map.py; the objective family's ``mapping`` field, and
bridge/studies/rdpso/mapping.py in a session): entropy map maths, the numerical runner with the mapping field, the
windowed bests of EPSO/PPSO, B13's smoke cells, and a short co-simulation with the mapping objective."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError, load_config, to_toml
from bridge.core.recorder import iter_messages
from bridge.numerical import runner as numerical
from bridge.numerical.entropy_map import EntropyMap, entropy, normalised_auc
from bridge.numerical.objectives import MappingField
from bridge.studies.rdpso.mapping import config_occupancy
from swarm_logic.families.baselines.common import WindowBest

ROOT = Path(__file__).resolve().parents[3]


def small_map(wall: bool = False, r_w: float = 2.0) -> EntropyMap:
    """A 10 x 10 m map of 1 m cells; optionally a wall at column 5 from row 0 to row 8 (a gap at the top row)."""
    occ = np.zeros((10, 10), bool)
    if wall:
        occ[0:9, 5] = True
    return EntropyMap((0.0, 0.0, 10.0, 10.0), occ, 1.0, r_w)


def test_entropy_is_eq_8_2_in_bits() -> None:
    assert entropy(np.array(0.5)) == pytest.approx(1.0)
    assert entropy(np.array([0.0, 1.0])) == pytest.approx([0.0, 0.0], abs=1e-9)
    p = 0.1
    assert entropy(np.array(p)) == pytest.approx(-p * math.log2(p) - (1 - p) * math.log2(1 - p))


def test_an_observation_explores_the_disc_in_sight_and_nothing_else() -> None:
    m = small_map(r_w=2.0)
    assert m.eta() == 0.0 and np.all(m.p == 0.5)
    m.observe(np.array([2.5]), np.array([2.5]))  # cell (2, 2)
    seen = m.explored
    jj, ii = np.nonzero(seen)
    assert np.all(np.hypot(ii - 2, jj - 2) <= 2.0 + 1e-9)
    assert seen.sum() == 13  # the cells of a radius-2 disc on a grid
    assert np.all(m.p[seen] == pytest.approx(0.1))  # one free observation from 0.5
    assert m.eta() == pytest.approx(13 / 100)
    m.observe(np.array([2.5]), np.array([2.5]))  # a second scan: surer, no more explored
    assert m.p[2, 2] < 0.1 and m.eta() == pytest.approx(13 / 100)


def test_a_wall_blocks_line_of_sight_and_is_seen_as_occupied() -> None:
    m = small_map(wall=True, r_w=3.0)
    m.observe(np.array([3.5]), np.array([3.5]))  # cell (3, 3), the wall in column 5
    assert m.explored[3, 4] and m.p[3, 4] < 0.5  # free, in sight
    assert m.explored[3, 5] and m.p[3, 5] > 0.5  # the wall's face: seen, occupied
    assert not m.explored[3, 6]  # behind the wall: unknown
    assert m.p[3, 6] == 0.5
    free_explored = (m.explored & ~m.truth).sum()
    assert m.eta() == pytest.approx(free_explored / m.free_cells)
    assert m.free_cells == 100 - 9


def test_the_objective_ranks_frontiers_and_is_zero_inside_explored_space() -> None:
    m = small_map(r_w=2.0)
    xs = np.arange(10) + 0.5
    for x in xs:  # explore the bottom three rows
        for y in (0.5, 1.5):
            m.observe(np.array([x]), np.array([y]))
    v = m.value(np.array([5.5, 5.5, 5.5]), np.array([0.5, 2.5, 8.5]))
    assert np.all((v >= 0) & (v <= 1))
    assert v[1] > 0.2  # at the front of the unexplored top part
    assert v[2] == 0.0  # nothing explored within reach: no frontier
    assert v[1] > v[0]  # deeper in explored space, the front is farther away (or out of reach)
    assert m.value(5.5, 2.5).shape == ()


def test_eta_is_monotone_and_auc_bounded_in_a_run() -> None:
    field = MappingField((30.0, 20.0), np.array([[10.0, 5.0, 12.0, 15.0]]), cell_m=0.5, r_w_m=2.0)
    res = numerical.run("epso", {"dx_max_m": 1.0, "send_jitter_s": 0.0, "log_every": 0, "range_m": 15.0,
                                 "memory_iterations": 5}, 6, 40, field, (30.0, 20.0),
                        np.array([[10.0, 5.0, 12.0, 15.0]]), numerical.LinkModel(range_m=15.0), seed=2)
    eta = field.eta_curve(40)
    assert len(eta) == 41 and eta[0] > 0
    assert np.all(np.diff(eta) >= 0)  # explored cells stay explored
    assert eta[-1] > eta[0]  # the robots moved and mapped more
    auc = normalised_auc(eta)
    assert eta[0] <= auc <= eta[-1] <= 1.0
    assert res.mean.max() > 0  # the robots sensed the objective
    assert normalised_auc(np.ones(501)) == 1.0 and normalised_auc(np.zeros(3)) == 0.0


def test_window_best_forgets() -> None:
    w = WindowBest(3)
    w.add(0, 5.0, (0.0, 0.0))
    w.add(1, 1.0, (1.0, 0.0))
    assert w.best() == (5.0, (0.0, 0.0))
    w.add(3, 2.0, (3.0, 0.0))  # the 5.0 of iteration 0 is 3 iterations old: forgotten
    assert w.best() == (2.0, (3.0, 0.0))
    keep = WindowBest(0)
    for k, v in enumerate((1.0, 4.0, 2.0)):
        keep.add(k, v, (float(k), 0.0))
    assert keep.best() == (4.0, (1.0, 0.0))


def test_b13_smoke_cells_run() -> None:
    from bridge.studies.rdpso.benchmark_experiments import ALGORITHMS, algorithm_params, garage_obstacles, mapping_trial

    obs = garage_obstacles()
    assert len(obs) == 56
    assert 0.04 < float(np.sum((obs[:, 2] - obs[:, 0]) * (obs[:, 3] - obs[:, 1]))) / 2975.0 < 0.05
    for alg in ALGORITHMS:
        assert algorithm_params(alg, 10, 30.0)["dx_max_m"] == 1.0
    eta, _ = mapping_trial("gso", 10, 30.0, 20, seed=1)
    assert len(eta) == 21 and 0 < eta[0] < eta[-1] < 1


def test_objective_config_is_checked(tmp_path: Path) -> None:
    raw = tomllib.loads((ROOT / "hil_configs" / "rdpso" / "mapping_arena.toml").read_text())
    raw["objective"] |= {"r_w_m": 0.05}
    bad = tmp_path / "bad.toml"
    bad.write_text(to_toml(raw))
    with pytest.raises(ConfigError, match=r"bad.toml: objective: .*r_w_m = 0.05 is smaller than one cell"):
        load_config(bad)
    raw["objective"] = {"kind": "light", "cell_m": 0.2}
    bad.write_text(to_toml(raw))
    with pytest.raises(ConfigError, match=r"objective: .*cell_m do\(es\) not apply to kind = 'light'"):
        load_config(bad)
    occ = config_occupancy(load_config(ROOT / "hil_configs" / "rdpso" / "mapping_arena.toml"), 0.1)
    assert occ.shape == (40, 40) and occ[28, 13] and not occ[5, 5]  # the crate at (1.3, 2.8); open floor


def test_a_mapping_session_grows_eta_and_reports_it(tmp_path: Path) -> None:
    from tests.core.test_session import _check_messages_match_their_schemas, run

    raw = tomllib.loads((ROOT / "hil_configs" / "rdpso" / "mapping_arena.toml").read_text())
    raw["session"] |= {"duration_s": 8.0, "name": "mapping-smoke"}
    cfg = tmp_path / "mapping.toml"
    cfg.write_text(to_toml(raw))
    code, s = run(cfg, tmp_path / "run", "--duration", "8", timeout=600)
    assert code == 0, s.get("error")
    m = s["mapping"]
    assert m["scans"] == 16  # every 0.5 s from t = 0 (the start poses) to 7.5 s
    assert 0 < m["eta_exp_every_10_scans"][0] < m["eta_exp"] <= 1
    assert 0 < m["auc"] < m["eta_exp"]
    rec = [(t, json.loads(payload)) for topic, t, payload in iter_messages(tmp_path / "run" / "session.mcap")
           if topic == "/world/mapping"]
    assert len(rec) == m["scans"] and rec[-1][1]["scans"] == m["scans"]  # one message a scan, at its time
    assert [round(t / 1e9, 3) for t, _ in rec[:3]] == [0.0, 0.5, 1.0]
    eta = [r["eta_exp"] for _, r in rec]
    assert eta[-1] == pytest.approx(m["eta_exp"], abs=1e-5) and eta == sorted(eta)  # the map only gains
    assert all(r["explored_free_cells"] == round(r["eta_exp"] * r["free_cells"]) for _, r in rec)
    bits = [r["entropy_bits"] for _, r in rec]
    assert bits == sorted(bits, reverse=True) and bits[-1] < bits[0]  # what the swarm minimises, going down
    _check_messages_match_their_schemas(tmp_path / "run" / "session.mcap")
