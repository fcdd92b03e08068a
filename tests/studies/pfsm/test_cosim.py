"""The PFSM search on emulated foot-bots: the scenario generator places the robots where the numerical model does,
the study's loop functions score a session as the numerical model scores a run (discoveries, energy, P_STA), and a
session ends once every target is found."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bridge.core.config import ConfigError, load_config, to_toml
from bridge.core.launcher import run_session
from bridge.core.plan import make_plan
from bridge.core.recorder import iter_messages
from bridge.studies.pfsm.cosim_experiments import scenario_config
from bridge.studies.pfsm.numerical import Arena, deploy, p_sta


def test_the_scenario_is_the_numerical_models_deployment(tmp_path: Path) -> None:
    raw = scenario_config(10, 20, 7)
    dep = deploy(Arena(5.0), 10, 20, 7)
    s, t = raw["robots"]
    assert (s["count"], s["behaviour"], t["count"], t["behaviour"]) == (10, "pfsm_searcher", 20, "pfsm_target")
    assert [p[:2] for p in s["placement"]["poses"]] == [[round(float(x), 4), round(float(y), 4)] for x, y in
                                                        dep.searchers]
    assert [p[:2] for p in t["placement"]["poses"]] == [[round(float(x), 4), round(float(y), 4)] for x, y in
                                                        dep.targets]
    p = tmp_path / "s.toml"
    p.write_text(to_toml(raw))
    cfg = load_config(p)
    assert cfg.robot_count == 30 and cfg.arena.grey_at(0.5, 2.0) == 0.5 and cfg.arena.grey_at(3.0, 2.0) == 1.0


def test_a_bad_search_section_names_the_field(tmp_path: Path) -> None:
    raw = scenario_config(10, 10, 1)
    raw["search"]["tick_s"] = 0
    p = tmp_path / "s.toml"
    p.write_text(to_toml(raw))
    with pytest.raises(ConfigError, match=r"search.tick_s: Input should be greater than 0"):
        load_config(p)


@pytest.mark.session
def test_a_session_finds_its_targets_and_scores_them_as_eq_2_says(tmp_path: Path) -> None:
    """Three searchers in the base, two targets ahead of them: both are found, the session ends at the second
    discovery, and E_total, T_total and P_STA are what the samples and eq. 2 give."""
    raw = scenario_config(3, 2, 5, max_s=120.0, robots_per_process=5)
    raw["robots"][0]["placement"]["poses"] = [[0.5, 1.5, 0.0], [0.5, 2.5, 0.0], [0.5, 3.5, 0.0]]
    raw["robots"][1]["placement"]["poses"] = [[2.2, 1.6, 0.0], [2.4, 3.4, 0.0]]
    p = tmp_path / "s.toml"
    p.write_text(to_toml(raw))
    out = tmp_path / "out"
    res = run_session(str(p), None, str(out), progress=None, plot=False)
    assert res.code == 0
    summary = json.loads((out / "summary.json").read_text())
    s = summary["search"]
    assert s["found"] == 2 and s["all_found"] and set(s["found_s"]) == {"3", "4"}
    t_total = max(s["found_s"].values())
    assert s["t_total_s"] == pytest.approx(t_total) and summary["sim_time_s"] <= t_total + 0.2  # it ended there
    assert 0 < s["e_total"] <= 3 * round(t_total / 0.1)  # at most every searcher walking every tick
    assert s["p_sta"] == pytest.approx(p_sta(s["e_total"], t_total, 2, 2, 25.0, 3))
    found = [json.loads(d) for topic, _t, d in iter_messages(out / "session.mcap") if topic == "/world/pfsm_found"]
    assert sorted(f["target"] for f in found) == [3, 4]
    rab = summary["radio"]["rab"]
    assert rab["robots"] == 5 and rab["emitted"] > 0 and rab["received"] > 0


def test_a_target_in_a_wall_and_a_cell_that_cannot_fit_its_robots_are_named(tmp_path: Path) -> None:
    raw = scenario_config(10, 10, 3)
    raw["robots"][1]["placement"]["poses"][4] = [4.96, 2.0, 0.0]  # 4 cm from the east wall: the body is in it
    p = tmp_path / "s.toml"
    p.write_text(to_toml(raw))
    with pytest.raises(ConfigError, match=r"robots\[1\]\.placement\.poses\[4\]: \(4\.96, 2\.0\) is inside a wall"):
        make_plan(load_config(p), str(p))  # what the launcher and `swarm-sitl validate` check before anything starts
    with pytest.raises(ValueError, match=r"the base region \(1\.0 x 5\.0 m\) cannot hold 120 searchers"):
        scenario_config(120, 10, 3)
