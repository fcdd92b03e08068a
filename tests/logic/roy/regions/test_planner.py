"""The planners' contract: observations and plans check their shapes, a plan's law is applied by name."""

import numpy as np
import pytest

from swarm_logic.families.roy.regions import laws
from swarm_logic.families.roy.regions.planner import Observation, Plan, Region, velocities
from swarm_logic.families.roy.regions.shapes import Ellipse


def obs(n: int, m: int = 8) -> Observation:
    return Observation(
        0.0,
        np.arange(n),
        np.zeros((n, 2)),
        np.zeros(n),
        np.full((n, m), np.nan),
        np.linspace(0, 2 * np.pi, m, endpoint=False),
        np.array([35.0, 35.0]),
    )


def test_observation_shapes():
    assert len(obs(3).ids) == 3
    with pytest.raises(ValueError, match="ranges"):
        Observation(0.0, np.arange(2), np.zeros((2, 2)), np.zeros(2), np.zeros((2, 5)), np.zeros(8), np.zeros(2))
    with pytest.raises(ValueError, match="positions"):
        Observation(0.0, np.arange(2), np.zeros((3, 2)), np.zeros(2), np.zeros((2, 8)), np.zeros(8), np.zeros(2))


def test_plan_applies_its_law_by_name():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 5, (6, 2))
    goals = np.tile([2.0, 2.0], (6, 1))
    plan = Plan(1.0, np.arange(6), goals, "scalable", {"k_c": 4.4, "k_f": 5.0, "r_s": 0.6})
    np.testing.assert_array_equal(velocities(plan, x, v_max=0.3), laws.scalable_law(x, goals, 4.4, 5.0, 0.6, v_max=0.3))
    desired = np.where(np.eye(6) == 0, 2.0, 0.0)
    f = Plan(1.0, np.arange(6), goals, "formation", {"desired": desired.tolist(), "k_c": 4.4, "k_f": 5.0})
    np.testing.assert_array_equal(velocities(f, x), laws.formation_law(x, goals, 4.4, 5.0, desired))
    bare = Plan(
        1.0, np.arange(6), goals, "formation", {"desired": desired.tolist(), "k_c": 4.4, "k_f": 5.0, "safety": None}
    )
    np.testing.assert_array_equal(velocities(bare, x), laws.formation_law(x, goals, 4.4, 5.0, desired, safety=None))
    with pytest.raises(ValueError, match="positions"):
        velocities(plan, x[:5])


def test_plan_refuses_unknown_law_and_logs_as_json():
    with pytest.raises(ValueError, match="law"):
        Plan(0.0, np.arange(2), np.zeros((2, 2)), "teleport")
    p = Plan(
        0.5,
        np.arange(2),
        np.zeros((2, 2)),
        "packing",
        regions=(
            Region(0, ellipse=Ellipse(1.0, 1.0, 2.0, 1.0)),
            Region(1, vertices=np.array([[0, 0], [2, 0], [2, 1], [0, 1.0]])),
        ),
        events=({"kind": "held", "why": "barrier"},),
    )
    d = p.as_dict()
    assert d["regions"][0]["kind"] == "ellipse" and d["regions"][1]["area"] == pytest.approx(2.0)
    assert d["regions"][0]["area"] == pytest.approx(np.pi * 2.0)
    with pytest.raises(ValueError, match="exactly one"):
        Region(0)
