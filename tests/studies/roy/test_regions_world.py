"""The chapters 4-6 numerical model: ray casting, blocked moves, failures, determinism, scenario validation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bridge.core.config import ConfigError
from bridge.studies.roy.regions_scenarios import load_scenario, make_planner, planner_params
from bridge.studies.roy.regions_world import RegionsWorld, run_mission

WALL_X = 10.0


def _scenario(tmp_path: Path, body: str = "", name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(
        f"""
name = "test"
version = "test-v1"
[world]
size = [20.0, 20.0]
segments = [[[{WALL_X}, 2.0], [{WALL_X}, 18.0]]]
circles = [[5.0, 15.0, 1.0]]
[agents]
n = 1
start_lo = [6.0, 9.0]
start_hi = [6.01, 9.01]
v_max = 1.0
[mission]
targets = [[18.0, 10.0]]
arrival_radius = 1.0
timeout_s = 5.0
[planner]
name = "ch4"
{body}
""",
        encoding="utf-8",
    )
    return p


def test_sonar_reads_a_known_wall(tmp_path: Path) -> None:
    w = RegionsWorld(load_scenario(_scenario(tmp_path)), seed=3)
    w.heading[:] = 0.0  # beam 0 along +x, beam 2 along +y, beam 4 along -x
    r = w.cast()
    assert r[0, 0] == pytest.approx(WALL_X - w.pos[0, 0], abs=1e-9)
    assert math.isnan(r[0, 4])  # the west wall is 6 units away, beyond d_max = 5
    w.pos[0] = (5.0, 11.0)  # the circle (5, 15, r 1) is 3 units north
    assert w.cast()[0, 2] == pytest.approx(3.0, abs=1e-9)


def test_a_move_into_a_wall_slides_or_stops(tmp_path: Path) -> None:
    w = RegionsWorld(load_scenario(_scenario(tmp_path)), seed=3)
    w.pos[0] = (WALL_X - 0.02, 9.0)
    w.step(np.array([[1.0, 0.0]]))  # straight at the wall: stays west of it
    assert w.pos[0, 0] < WALL_X and w.pos[0, 0] == pytest.approx(WALL_X - 0.02)
    w.step(np.array([[1.0, 1.0]]))  # at 45 degrees: slides north along it, never through
    assert w.pos[0, 0] < WALL_X and w.pos[0, 1] > 9.0
    assert w.contacts == 2
    w.pos[0] = (5.0, 13.97)  # a move into the circle is refused
    w.step(np.array([[0.0, 1.0]]))
    assert w.pos[0, 1] == pytest.approx(13.97)


def test_velocity_saturates_and_failed_agents_stop(tmp_path: Path) -> None:
    sc = load_scenario(_scenario(tmp_path)).model_copy()
    sc = sc.model_copy(
        update={
            "agents": sc.agents.model_copy(update={"n": 10, "start_lo": (1.0, 1.0), "start_hi": (8.0, 8.0)}),
            "failures": sc.failures.model_copy(update={"fraction": 0.2, "times": [0.1]}),
        }
    )
    w = RegionsWorld(sc, seed=5)
    assert np.sum(np.isfinite(w.fail_at)) == 2
    start = w.pos.copy()
    for _ in range(10):
        w.step(np.tile([0.0, 3.0], (10, 1)))
    moved = w.pos[:, 1] - start[:, 1]
    dead = np.isfinite(w.fail_at)
    assert np.allclose(moved[~dead], 10 * 0.05 * 1.0)  # saturated at v_max = 1
    assert np.allclose(moved[dead], 2 * 0.05 * 1.0)  # moved until t = 0.1, then stopped


def test_same_seed_same_summary_bytes() -> None:
    sc = load_scenario("ch4-a")
    a = run_mission(sc, make_planner(sc), seed=2, max_time_s=8.0).summary_json()
    b = run_mission(sc, make_planner(sc), seed=2, max_time_s=8.0).summary_json()
    c = run_mission(sc, make_planner(sc), seed=3, max_time_s=8.0).summary_json()
    assert a == b and a != c


@pytest.mark.parametrize(
    ("body", "field", "why"),
    [
        ("", "agents.v_max", "greater than 0"),
        ("params = { split = 'middle' }", "planner.params.split", "expected one of"),
        ("params = { nonsense = 1 }", "planner.params.nonsense", "not a parameter"),
    ],
)
def test_a_wrong_file_names_file_field_and_reason(tmp_path: Path, body: str, field: str, why: str) -> None:
    p = _scenario(tmp_path, body)
    text = p.read_text().replace("v_max = 1.0", "v_max = 0.0") if field == "agents.v_max" else p.read_text()
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert str(p) in str(e.value) and field in str(e.value) and why in str(e.value)


def test_unknown_planner_and_target_outside(tmp_path: Path) -> None:
    p = _scenario(tmp_path)
    p.write_text(p.read_text().replace('name = "ch4"', 'name = "ch9"'))
    with pytest.raises(ConfigError, match=r"planner\.name: unknown region planner 'ch9'"):
        load_scenario(p)
    p = _scenario(tmp_path)
    p.write_text(p.read_text().replace("[[18.0, 10.0]]", "[[25.0, 10.0]]"))
    with pytest.raises(ConfigError, match=r"target 0 .* lies outside the world"):
        load_scenario(p)


def test_shipped_scenarios_load_with_versions() -> None:
    for name in ("ch4-a", "ch4-maze-50", "ch4-failures-50", "ch4-mover"):
        sc = load_scenario(name)
        assert sc.version.startswith(name + "-v")
        assert planner_params(sc)["v_max"] == sc.agents.v_max
        assert make_planner(sc).p.v_max == sc.agents.v_max
    assert load_scenario("ch4-failures-50").with_failures(0.2).failures.fraction == 0.2
