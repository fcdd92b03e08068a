"""The convergence phase alone (``ConvergePlanner``, region planner ``converge``): the plan's law brings point agents
into the circle and the planner says so once; its gain is Theorem 1's; six agents use Delta_tri."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm_logic.families.roy.regions.converge import ConvergeParams, ConvergePlanner
from swarm_logic.families.roy.regions.formation import DELTA_TRI
from swarm_logic.families.roy.regions.laws import theorem1_kc
from swarm_logic.families.roy.regions.planner import PLANNERS, Observation, velocities


def obs(t: float, ids: list[int], x: np.ndarray) -> Observation:
    n = len(ids)
    return Observation(
        t,
        np.array(ids),
        np.asarray(x, float),
        np.zeros(n),
        np.full((n, 5), np.nan),
        np.radians([-90, -45, 0, 45, 90]),
        np.zeros(2),
    )


def run(
    planner: ConvergePlanner, ids: list[int], x: np.ndarray, seconds: float, v_max: float = 1.5, dt: float = 0.05
) -> tuple[np.ndarray, list[dict]]:
    """Single integrators following the plan's law, re-planned every 0.25 s."""
    events: list[dict] = []
    plan = None
    for k in range(round(seconds / dt)):
        t = k * dt
        if k % round(planner.period_s / dt) == 0:
            plan = planner.plan(obs(t, ids, x))
            events += [dict(e, t_plan=t) for e in plan.events]
        x = x + dt * velocities(plan, x, v_max=v_max)
    return x, events


def test_three_agents_converge_into_the_circle_round_their_first_centroid() -> None:
    x0 = np.array([[2.0, 3.0], [14.0, 5.0], [8.0, 16.0]])
    p = ConvergePlanner(r_c=3.0)
    x, events = run(p, [4, 1, 2], x0, 30.0)
    centre = x0.mean(axis=0)
    assert p.summary()["centre"] == pytest.approx(list(centre))
    kinds = [e["kind"] for e in events]
    assert kinds[0] == "region" and kinds.count("all_inside") == 1 and kinds.count("inside") == 3
    assert "outside" not in kinds
    done = next(e for e in events if e["kind"] == "all_inside")
    assert done["agents"] == [1, 2, 4]
    # 5.5 to 8.6 units away at 1.5 units/s: the last one enters at 3.5 s (a plan period's resolution)
    assert done["t"] == 3.5
    # at rest: an equilateral triangle round the centre, 1.62 units out (eq. 4.6's balance of pull and repulsion)
    assert np.hypot(*(x - centre).T) == pytest.approx([1.623] * 3, abs=0.01)
    # the formation term keeps them apart (all pairs of three, rho = 2 r_s = 2)
    d = [math.dist(x[i], x[j]) for i in range(3) for j in range(i)]
    assert d == pytest.approx([2.811] * 3, abs=0.01)
    assert events[0]["k_c"] == pytest.approx(theorem1_kc(3, 5.0, 2.0, 3.0))
    last = p.plan(obs(31.0, [4, 1, 2], x))
    assert last.done and last.law == "formation" and not last.events
    assert last.ids.tolist() == [1, 2, 4] and np.allclose(last.goals, centre)


def test_a_given_centre_and_gain_are_used_and_the_region_is_drawn() -> None:
    p = ConvergePlanner(centre=[10.0, 10.0], r_c=2.0, k_c=4.0)
    plan = p.plan(obs(0.0, [0, 1], np.array([[1.0, 1.0], [3.0, 1.0]])))
    assert plan.params["k_c"] == 4.0 and np.allclose(plan.goals, [[10, 10], [10, 10]])
    (region,) = plan.regions
    assert region.ellipse is not None and region.ellipse.a == 2.0 and region.as_dict()["x"] == 10.0
    assert not plan.done


def test_six_agents_use_the_triangle_and_an_absent_agent_leaves_the_plan() -> None:
    p = ConvergePlanner()
    x = np.array([[0, 0], [2, 0], [4, 0], [0, 2], [2, 2], [4, 2]], float)
    plan = p.plan(obs(0.0, list(range(6)), x))
    assert np.array_equal(np.array(plan.params["desired"]) > 0, DELTA_TRI.astype(bool))
    plan = p.plan(obs(0.25, [0, 1, 2, 3, 5], np.delete(x, 4, axis=0)))
    assert plan.ids.tolist() == [0, 1, 2, 3, 5] and np.array(plan.params["desired"]).sum() == 2.0 * 20
    with pytest.raises(ValueError, match="Delta_tri has 6 agents, 5"):
        ConvergePlanner(graph="tri").plan(obs(0.0, [0, 1, 2, 3, 5], np.delete(x, 4, axis=0)))


def test_no_agent_at_the_first_observation_holds_without_a_centre() -> None:
    p = ConvergePlanner()
    plan = p.plan(obs(0.0, [], np.zeros((0, 2))))
    assert plan.events == ({"kind": "held", "reason": "no agent"},) and p.centre is None


@pytest.mark.parametrize(
    "kw, field",
    [
        ({"r_c": 0.0}, "r_c"),
        ({"k_c": -1.0}, "k_c"),
        ({"graph": "ring"}, "graph"),
        ({"centre": (1.0,)}, "centre"),
        ({"safety": {"nope": 1.0}}, "safety"),
        ({"k_f": math.inf}, "k_f"),
    ],
)
def test_bad_parameters_are_refused_naming_the_field(kw: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        ConvergeParams(**kw)


def test_it_is_registered_by_name() -> None:
    assert PLANNERS.get("converge") is ConvergePlanner
