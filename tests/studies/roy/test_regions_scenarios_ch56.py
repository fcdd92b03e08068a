"""Chapters 5 and 6's scenario files: each loads, validates and builds its planner; the lanes' targets reach chapter
6's planner; ``with_agents`` keeps the swarm's area; a short mission per chapter runs deterministically and does what
its first seconds should (chapter 5: the first regions packed and released; chapter 6: one region of N pi r_s^2)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from bridge.core.config import ConfigError
from bridge.studies.roy.regions_scenarios import SCENARIO_DIR, load_scenario, make_planner, planner_params
from bridge.studies.roy.regions_world import run_mission

NAMES = ("ch5-a", "ch6-case1", "ch6-case2", "ch6-case3")


@pytest.mark.parametrize("name", NAMES)
def test_each_file_loads_validates_and_builds_its_planner(name: str) -> None:
    sc = load_scenario(name)
    assert sc.version == f"{name}-v1"
    planner = make_planner(sc)
    assert planner.p.r_s == sc.metrics.r_s  # the density's r_s is the planner's
    chapter = name[:3]
    assert sc.planner.name == chapter and sc.metrics.density_rule == chapter


def test_the_lanes_targets_and_window_reach_chapter_6s_planner() -> None:
    sc = load_scenario("ch6-case1")
    kw = planner_params(sc)
    assert kw["targets"] == [[50.0, 80.0], [26.0, 80.0], [72.0, 80.0]] and kw["lane_map"] == [1, 0, 2]
    p = make_planner(sc).p
    assert p.lane_map == (1, 0, 2) and p.d_max == 5.0  # Table 6.1's window, the sonar reaching farther (10)
    assert sc.sensing.d_max == 10.0
    assert load_scenario("ch6-case3").world.movers[0].radius == 2.0
    assert "targets" not in planner_params(load_scenario("ch6-case2"))  # one target: the observation's


@pytest.mark.parametrize("n", [50, 250, 1000])
def test_with_agents_keeps_the_swarms_area_and_the_lanes(n: int) -> None:
    sc = load_scenario("ch6-case2")
    big = sc.with_agents(n)
    assert big.agents.n == n and big.version == sc.version
    r_s = big.planner.params["r_s"]
    assert n * math.pi * r_s**2 == pytest.approx(100 * math.pi * 0.5**2)
    assert big.metrics.r_s == pytest.approx(r_s) and big.planner.params["r_robot"] == pytest.approx(0.5 * r_s)
    assert big.planner.params["detector"] == sc.planner.params["detector"]  # thresholds in units: lanes unchanged
    assert make_planner(big).p.r_s == pytest.approx(r_s)
    with pytest.raises(ValueError, match=r"agents\.n"):
        sc.with_agents(0)


def test_ch5_first_region_is_packed_and_released_deterministically() -> None:
    sc = load_scenario("ch5-a")
    a = run_mission(sc, make_planner(sc), seed=1, max_time_s=16.0)
    b = run_mission(sc, make_planner(sc), seed=1, max_time_s=16.0)
    assert a.summary_json() == b.summary_json()
    s = a.summary
    regions = [e for e in s["events"] if e["kind"] == "region"]
    releases = [e for e in s["events"] if e["kind"] == "barrier"]
    assert regions and regions[0]["n"] == 14 and regions[0]["method"] in ("lattice", "relaxed")
    assert regions[0]["circles"] >= 14
    assert releases and releases[0]["reason"] == "all in circles"  # every agent in its circle (B8), no timeout
    assert s["contacts"] == 0 and not s["arrived"]


def test_ch6_first_seconds_one_region_of_the_swarms_area_deterministically() -> None:
    sc = load_scenario("ch6-case2")
    a = run_mission(sc, make_planner(sc), seed=1, max_time_s=4.0)
    assert a.summary_json() == run_mission(sc, make_planner(sc), seed=1, max_time_s=4.0).summary_json()
    assert a.summary_json() != run_mission(sc, make_planner(sc), seed=2, max_time_s=4.0).summary_json()
    s = a.summary
    first = next(e for e in s["events"] if e["kind"] == "region")
    assert first["area"] == pytest.approx(100 * math.pi * 0.25)  # eq. 6.8's A_e
    assert "split" not in s["event_counts"]  # the wall is 7 units ahead of the swarm, beyond its window
    assert s["density"]["mean"] is not None and 0.0 <= s["density"]["mean"] <= 1.0


def test_a_wrong_chapter_5_or_6_parameter_is_named(tmp_path: Path) -> None:
    for name in ("ch5-a", "ch6-case2"):
        src = load_scenario(name)
        text = (SCENARIO_DIR / f"{name}.toml").read_text(encoding="utf-8")
        p = tmp_path / f"{name}.toml"
        p.write_text(text.replace("params = { r_s", "params = { nonsense = 1, r_s"), encoding="utf-8")
        with pytest.raises(ConfigError) as e:
            load_scenario(p)
        assert str(p) in str(e.value) and "planner.params.nonsense" in str(e.value) and src.name == name
