"""Range readings to obstacle points: the projection, the window, eq. 4.26's boundary test, the eclipse test and the
drop counts."""

import json
import math

import numpy as np
import pytest

from swarm_logic.families.roy.regions.sensing import SensingParams, fan_angles, ring_angles, sense


def test_projection_per_beam_relative_to_heading():
    x = np.array([[1.0, 2.0]])
    ranges = np.full((1, 8), np.nan)
    ranges[0, 2] = 3.0  # beam 3: 90° from the heading
    out = sense(x, np.array([math.pi / 4]), ranges, ring_angles(8))
    # heading 45° + beam 90° = 135°: erratum 9's point x + d [cos, sin], not a sum over beams
    assert out.points == pytest.approx(np.array([[1.0 - 3.0 / math.sqrt(2), 2.0 + 3.0 / math.sqrt(2)]]))
    assert out.owner.tolist() == [0] and out.beam.tolist() == [2]
    assert out.dropped["no_echo"] == 7


def test_fan_is_the_sonpi_front_five():
    assert np.degrees(fan_angles(5, math.radians(45))) == pytest.approx([-90, -45, 0, 45, 90])
    assert np.degrees(ring_angles(8)) == pytest.approx(np.arange(8) * 45.0)
    with pytest.raises(ValueError, match="m"):
        ring_angles(0)


def test_garbage_window_and_counts():
    x = np.array([[0.0, 0.0], [10.0, 0.0]])
    ranges = np.array([[np.nan, -1.0, np.inf, 0.3, 2.0], [6.0, 4.0, np.nan, np.nan, 1.0]])
    out = sense(x, np.zeros(2), ranges, fan_angles(5, 0.5), SensingParams(d_min=0.5, d_max=5.0))
    assert out.dropped == {"no_echo": 3, "garbage": 2, "out_of_window": 2, "boundary": 0, "eclipse": 0}
    assert len(out) == 3 and sorted(out.owner.tolist()) == [0, 1, 1]
    logged = json.loads(json.dumps(out.as_dict(), allow_nan=False))
    assert logged["dropped"]["garbage"] == 2 and len(logged["points"]) == 3


def test_bad_pose_is_garbage_not_a_crash():
    x = np.array([[np.nan, 0.0], [0.0, 0.0]])
    out = sense(x, np.array([0.0, np.inf]), np.full((2, 8), 2.0), ring_angles(8))
    assert len(out) == 0 and out.dropped["garbage"] == 16


def test_boundary_filter_eq_4_26():
    # an agent 1.5 from the centre, r_c = 2.5: only readings >= 1.0 lie beyond the virtual circle
    x = np.array([[1.5, 0.0]])
    ranges = np.array([[0.8, 1.0, 3.0, np.nan]])
    out = sense(x, np.zeros(1), ranges, ring_angles(4), boundary=(np.zeros(2), 2.5))
    assert out.dropped["boundary"] == 1 and len(out) == 2


def test_eclipse_drops_teammate_hits_only():
    # agent 0 sees agent 1 (1.0 ahead) and a wall (3.0 to the left); agent 1's own body never eclipses its points
    x = np.array([[0.0, 0.0], [1.0, 0.0]])
    ranges = np.array([[1.0, 3.0, np.nan, np.nan], [0.2, np.nan, np.nan, np.nan]])
    out = sense(x, np.zeros(2), ranges, ring_angles(4), SensingParams(r_robot=0.5, eclipse_eps=0.1))
    assert out.dropped["eclipse"] == 1  # agent 0's hit on agent 1
    assert out.points == pytest.approx(np.array([[0.0, 3.0], [1.2, 0.0]]))  # 0.2 from its own agent: kept


def test_shape_errors_name_the_field():
    with pytest.raises(ValueError, match="ranges"):
        sense(np.zeros((2, 2)), np.zeros(2), np.zeros((2, 3)), ring_angles(8))
    with pytest.raises(ValueError, match="d_max"):
        SensingParams(d_min=2.0, d_max=1.0)


def test_thousand_agents_vectorised():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 80, (1000, 2))
    ranges = rng.uniform(-1, 6, (1000, 8))
    ranges[rng.random((1000, 8)) < 0.3] = np.nan
    out = sense(x, rng.uniform(-3, 3, 1000), ranges, ring_angles(8))
    assert len(out) + sum(out.dropped.values()) == 8000
    assert out.points.shape == (len(out), 2) and np.isfinite(out.points).all()
